"""The co-simulation loop: vehicles under ST-MPC, the traffic manager, and a world adapter.

The loop only talks to a :class:`World` adapter (the free plane, or SUMO
through :mod:`bridge.sumo_world`), to the controllers and to the traffic
manager.  One step (``Ts``) is:

1. every active vehicle computes its membership index ``l`` w.r.t. its
   current waypoint and, when it may switch (``terminal``: ``l = 0``;
   ``early``: its state lies in the next waypoint's domain), a request
   ``(l', r̄)`` w.r.t. the next waypoint; requests into a junction guard
   without one of its tokens are withheld (liveness: :mod:`tm.junctions`),
   and so are requests whose claim meets a walking region a pedestrian can
   reach within its horizon (:mod:`tm.pedestrians`) and, in authority mode,
   requests that would move a stop point onto a crossing the vehicle cannot
   clear (:mod:`tm.crossing_gate`);
2. the TM grants or denies the requests (:class:`tm.manager.TrafficManager`);
3. granted vehicles switch; every vehicle applies the terminal law or the
   QP of eq. (6) (:class:`controllers.stmpc.STMPC`, vectorised per class);
4. the plant steps with the disturbance policy; the index must strictly
   decrease until 0 and then stay 0 (tube invariant, counted otherwise);
5. vehicles at their last waypoint with ``l = 0`` arrive; waiting vehicles
   whose initial tube is free (condition (12)) and misses every token holder's
   corridor are admitted;
6. the monitor checks footprints and claims; the world is pushed and stepped.
"""

from __future__ import annotations

import time
from types import SimpleNamespace
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from controllers.classes import VehicleClass
from controllers.plant import DISTURBANCES, step as plant_step
from controllers.settings import AUTHORITY_MAX_LEVELS, ControllerSettings, SynthesisSettings
from controllers import tolerances as tol
from controllers.speed_limits import SpeedSettings, bound_at, free_flow_time, route_speeds
from controllers.stmpc import STMPC
from controllers.synthesis import synthesize
from bridge.departure import DepartPlan, Start, start_ladder
from bridge.fleet_claims import FleetClaims
from bridge.groups import _Group, _headings, live_groups
from bridge.path_fleet import FRAMES, PathFleet
from bridge.request_filters import RequestFilters
from bridge.vehicle_stops import PlannedStop, StopBook
from tm.reach import ReachClaims, world_aabb
from tm.reach_book import ReachBook, admit_reach, footprint_claims
from tm.authority_gate import AuthorityGate
from tm.authority_reach import AuthorityReach
from tm.junctions import ClassReach, JunctionGate, Zone
from tm.manager import FleetState, TrafficManager
from tm.pedestrians import PedestrianRule, footprint_contacts
from tm.crossing_gate import CrossingGate
from tm.monitor import Monitor
from tm.settings import TMSettings
from tm.signals import SignalBook, SignalSettings, StopLines, stop_bounds

#: Valid values of :attr:`CosimSettings.controller`.
CONTROLLERS = ("paper", "authority")

__all__ = ["CONTROLLERS", "Zone", "VehicleSpec", "CosimSettings", "World", "FreePlaneWorld", "Cosim", "VehicleRecord"]


@dataclass(frozen=True)
class VehicleSpec:
    """A vehicle to run: id, class name, waypoints (K, 2) at most delta apart, departure time;
    optionally the speed limit (m/s) of the lane under each waypoint (``speed_limits``, (K,)):
    the controller keeps the vehicle at or below it (with look-ahead, see
    :mod:`controllers.speed_limits` and :class:`CosimSettings.speed`)."""

    id: str
    vclass: str
    waypoints: np.ndarray
    depart_s: float = 0.0
    speed_limits: np.ndarray | None = None
    #: signalised stop lines the route crosses (positions along these waypoints), see tm.signals
    stop_lines: StopLines | None = None
    #: the waypoint at which the vehicle arrives, passing it at speed; the waypoints after it are a
    #: run-out beyond the route's end (where nothing else drives: a network's dead end) on which the
    #: vehicle is never driven -- its stop point and claims may reach there, so it need not brake
    #: for the end of its route (SUMO's vehicles leave there at speed).  None: the vehicle arrives
    #: at rest on its last waypoint.
    arrive_k: int | None = None
    #: where and how fast SUMO would start it (its departPos / departSpeed, :mod:`bridge.departure`):
    #: admission tries that start first; None: at rest on its first waypoint (authority mode only)
    depart: DepartPlan | None = None
    #: planned stops on the waypoints (SUMO's ``<stop>``, :mod:`bridge.vehicle_stops`), in route order
    stops: tuple[PlannedStop, ...] = ()
    #: waypoints on the internal lanes of a straight connection (SUMO's direction ``s``), bool (K,):
    #: no curve speed from their shape there (:func:`controllers.speed_limits.route_speeds`); None: none
    straight: np.ndarray | None = None
    #: names of the junction zones its route passes through (a SUMO route: the junctions its edges start
    #: and end at, :meth:`bridge.waypoints.NetGeometry.route_junctions`); authority mode's junction
    #: layer leaves it out of every other zone's tokens (:class:`tm.junctions.JunctionGate`, ``through``).
    #: None: every zone whose guard its route reaches (the free plane's routes)
    junctions: frozenset[str] | None = None

    @property
    def arrival_index(self) -> int:
        """Index of the waypoint the vehicle arrives at (:attr:`arrive_k`, or the last)."""
        return len(self.waypoints) - 1 if self.arrive_k is None else int(self.arrive_k)

    @property
    def driven_waypoints(self) -> np.ndarray:
        """The waypoints up to the arrival waypoint (a run-out after it is never driven)."""
        return np.asarray(self.waypoints, dtype=float)[:self.arrival_index + 1]

    @property
    def route_length_m(self) -> float:
        return float(np.linalg.norm(np.diff(self.driven_waypoints, axis=0), axis=1).sum())


@dataclass(frozen=True)
class CosimSettings:
    """Options of one co-simulation run (validated)."""

    tm: TMSettings = field(default_factory=TMSettings)
    switching: str = "early"
    disturbance: str = "random"
    solver: str = "exact"
    seed: int = 0
    duration_s: float | None = None
    Ts: float = 0.1
    signals: SignalSettings = field(default_factory=SignalSettings)
    #: ``paper``: the paper's sets, eq. (6) and centred claims; ``authority``: movement-authority
    #: sets and cost with reach-tightened claims (design.md §7; classes with ``comfort_decel``)
    controller: str = "paper"
    #: lane limits and curve speeds as speed bounds (controllers.speed_limits)
    speed: SpeedSettings = field(default_factory=SpeedSettings)
    #: authority mode: reuse current claims between steps (:class:`tm.reach_cache.ClaimCache`);
    #: False decides on fresh claims every step (the reference the cache is checked against)
    claim_cache: bool = True
    #: the plant's frame: ``path`` steps it in path coordinates along its route (turns at the curve
    #: speed, routes with any angle; :mod:`bridge.path_fleet`), ``road`` in the world with errors in
    #: the frame of the waypoint's segment (the paper's); ``auto``: ``path`` in authority mode,
    #: ``road`` in paper mode (whose centred claims are drawn in the road frame)
    frame: str = "auto"

    @property
    def path_frame(self) -> bool:
        """Whether the plants run in path coordinates."""
        return self.frame == "path" or (self.frame == "auto" and self.controller == "authority")

    def __post_init__(self) -> None:
        if not isinstance(self.speed, SpeedSettings):
            raise ValueError(f"CosimSettings.speed: must be a SpeedSettings, got {self.speed!r}")
        if self.controller not in CONTROLLERS:
            raise ValueError(f"CosimSettings.controller: must be one of {CONTROLLERS}, got {self.controller!r}")
        if self.frame not in FRAMES:
            raise ValueError(f"CosimSettings.frame: must be one of {FRAMES}, got {self.frame!r}")
        if self.frame == "path" and self.controller != "authority":
            raise ValueError("CosimSettings.frame: 'path' needs controller 'authority' (the paper's centred "
                             "claims are drawn in the road frame); use frame 'road' or 'auto'")
        if not isinstance(self.claim_cache, bool):
            raise ValueError(f"CosimSettings.claim_cache: must be True or False, got {self.claim_cache!r}")
        if not isinstance(self.signals, SignalSettings):
            raise ValueError(f"CosimSettings.signals: must be a SignalSettings, got {self.signals!r}")
        ControllerSettings(solver=self.solver, switching=self.switching)  # validates both
        if self.disturbance not in DISTURBANCES:
            raise ValueError(f"CosimSettings.disturbance: must be one of {DISTURBANCES}, "
                             f"got {self.disturbance!r}")
        if self.duration_s is not None and not self.duration_s > 0:
            raise ValueError(f"CosimSettings.duration_s: must be > 0 s or None, got {self.duration_s}")


class World(Protocol):
    """What the loop needs from a simulator."""

    def insert(self, spec: VehicleSpec, vclass: VehicleClass, k: int = 0) -> None: ...
    def push(self, ids: list[str], centre: np.ndarray, heading: np.ndarray) -> None: ...
    def finish(self, vid: str) -> None: ...
    def step(self) -> list[tuple[str, str]]: ...


class FreePlaneWorld:
    """No simulator: muvsim's own plant and geometric monitor are the whole world."""

    def insert(self, spec, vclass, k: int = 0) -> None:
        pass

    def push(self, ids, centre, heading) -> None:
        pass

    def finish(self, vid) -> None:
        pass

    def step(self) -> list:
        return []


@dataclass
class VehicleRecord:
    """Per-vehicle KPI accumulator."""

    id: str
    vclass: str
    depart_s: float
    route_length_m: float
    admitted_s: float | None = None
    arrived_s: float | None = None
    denials: int = 0
    stop_episodes: int = 0
    stopped_steps: int = 0
    closest_m: float = np.inf
    speed_sum: float = 0.0
    steps: int = 0
    #: route time at the limits the front is under (lane limits, the class bound), s; None: length / v_max
    free_flow_s: float | None = None
    #: largest (speed - lane limit under the front) over the run (m/s); -inf until it drove
    speed_limit_excess: float = -np.inf
    #: the speed it entered with (m/s; bridge/departure.py: 0 at rest)
    depart_speed_mps: float = 0.0


class Cosim:
    """One co-simulation run.

    Composed of the per-class groups (:class:`bridge.groups._Group`: states, waypoints, controllers),
    the traffic manager, the liveness layer (``junctions``), the fleet's claims
    (:class:`bridge.fleet_claims.FleetClaims`), the request filters (signals, junction tokens,
    pedestrians: :class:`bridge.request_filters.RequestFilters`), the monitor and the world.

    Parameters
    ----------
    classes : mapping of str to VehicleClass
        Every class a spec may name.
    specs : list of VehicleSpec
    settings : CosimSettings
    world : World, optional
        Defaults to :class:`FreePlaneWorld`.
    synthesis : SynthesisSettings, optional
    zones : list of Zone, optional
        Junction zones (the liveness layer, :mod:`tm.junctions`).
    observers : list, optional
        Objects with ``on_step(sim, state, decision, row)``, called at the end of every step
        (``state``: the FleetState the TM decided on, or None with no vehicle; ``decision``: the TM's
        Decision or None; ``row``: the step's KPI row). Loggers (MCAP) and KPI accumulators attach here.
    pedestrians : PedestrianRule, optional
        The pedestrian rule (None: no pedestrians); positions come from ``world.pedestrians()``.
    crossings : list, optional
        Authority mode with pedestrians: the crossing regions stop points never rest on
        (:mod:`tm.crossing_gate`).
    """

    def __init__(self, classes, specs, settings: CosimSettings, world=None,
                 synthesis: SynthesisSettings | None = None, zones: list[Zone] | None = None,
                 observers: list | None = None, pedestrians: PedestrianRule | None = None,
                 crossings: list | None = None):
        self.settings = settings
        self.pedestrians = pedestrians
        self.pedestrian_conflicts: set = set()  # unique (vehicle, person) footprint-body contacts
        self.observers = list(observers or [])
        self.world = world or FreePlaneWorld()
        self.classes = _used_classes(classes, specs)
        validate_specs(specs, self.classes, settings.path_frame)
        self.authority = settings.controller == "authority"
        #: path-frame plants (settings.frame): the routes' frames and the fleet's stack
        self.paths = PathFleet() if settings.path_frame else None
        if self.paths is not None:
            # SUMO's bodies lean off the route on lane changes (world.body_leans; authority mode,
            # whose claims cover the world's bodies)
            leans = getattr(self.world, "body_leans", None) if self.authority else None
            for s_ in specs:  # every route must make a frame (a clear error now, not at admission)
                self.paths.frame(s_.id, s_.waypoints, leans(s_) if leans is not None else None)
        cs = ControllerSettings(solver=settings.solver, switching=settings.switching,
                                mode="authority" if self.authority else "paper")
        if self.authority:
            bad = sorted(c for c, vc in self.classes.items() if vc.comfort_decel is None)
            if bad:
                raise ValueError(f"controller 'authority': vehicle class(es) {bad} have no comfort_decel; "
                                 "use classes with one (car, bus, truck) or controller 'paper'")
        syn = synthesis or SynthesisSettings()
        self.families = {c: synthesize(vc.model, replace(syn, authority_decel=vc.comfort_decel,
                                                         max_levels=max(syn.max_levels, AUTHORITY_MAX_LEVELS))
                                       if self.authority else synthesis) for c, vc in self.classes.items()}
        #: claim models (authority mode): reach-tightened, time-indexed claims (tm.reach_book)
        self.reach = ReachBook(self.families, {c: (vc.length, vc.width) for c, vc in self.classes.items()}) \
            if self.authority else None
        sp = settings.speed
        self.groups = {c: _Group(vc, STMPC(self.families[c], cs), decel=_look_ahead_decel(vc),
                                 slack_steps=sp.slack_steps) for c, vc in self.classes.items()}
        #: per-route speed tables (controllers.speed_limits), built on admission
        self._lat_accel = sp.lat_accel if (self.authority and sp.curves) else None
        self.tm = TrafficManager(settings.tm, {c: f.position_sets for c, f in self.families.items()},
                                 rotating=[c for c, vc in self.classes.items() if vc.model.frame == "road"])
        self.monitor = Monitor(settings.tm.check)
        self.pending = sorted(specs, key=lambda s: (s.depart_s, s.id))
        self._heading0: dict[str, float] = {}
        #: per waiting vehicle: ``(spec, its starts, their footprints' poses)`` (:meth:`_starts`)
        self._start_cache: dict[str, tuple] = {}
        self.records = {s.id: VehicleRecord(s.id, s.vclass, s.depart_s, s.route_length_m) for s in specs}
        self._speeds = {}
        for s_ in specs:  # validated speed tables and free-flow times, before anything runs
            self._route_speeds(s_)
        self.rng = np.random.default_rng(settings.seed)
        self.t = 0
        self.step_rows: list[dict] = []
        self.invariant_violations = 0
        self.constraint_violations = 0
        self.collisions_world: set = set()
        self.last_decision = None
        # zones: guards, tokens, corridors and queues (the liveness layer, tm.junctions); in
        # authority mode on the stop points and reach claims (tm.authority_gate)
        self.zones = list(zones or [])
        self.zones_ignored = 0  # zones the liveness layer does not use (none: both modes have one)
        if self.authority:  # each route's own junctions (paper mode: every zone its route reaches, as measured)
            self.junctions = AuthorityGate(self.zones, {
                c: AuthorityReach.of(m.tables, self.classes[c].length, self.classes[c].width,
                                     self.classes[c].model.delta) for c, m in self.reach.models.items()},
                through={s_.id: s_.junctions for s_ in specs if s_.junctions is not None})
            # ordered entry needs time-indexed claims: with the union check a candidate coming up to a
            # holder's path claims the hull of its slots, wider than its standing box (grid seeds 1-2,
            # 900 s: 104 / 76 of 150 arrived with it, 128 / 112 without)
            self.junctions.ordered_entry = settings.tm.check == "timed"
        else:
            self.junctions = JunctionGate(self.zones, {
                c: ClassReach.of(f.position_sets, self.classes[c].length, self.classes[c].width,
                                 self.classes[c].model.frame == "road") for c, f in self.families.items()})
        #: the fleet's claims: reach claims with the world's body padding, reused between steps where
        #: sound (``settings.claim_cache``), the requests' claims once per step
        self.claims = FleetClaims(self.groups, self.classes, self.world, self.tm, self.reach, self.paths,
                                  settings.claim_cache, lambda sp: self._route_speeds(sp).arc)
        self._claims_now: ReachClaims | None = None  # authority: this step's claims before the decision
        crossing_gate = None
        if self.authority and pedestrians is not None and crossings:
            crossing_gate = CrossingGate(crossings, self.junctions.classes,
                                         {c: f.N + pedestrians.hold_steps for c, f in self.families.items()},
                                         pedestrians)
        #: requests withheld before the decision: signals, junction tokens, pedestrians, crossings
        self.filters = RequestFilters(settings.signals, self.world, self.groups, self.junctions, self.claims,
                                      self._poses, pedestrians, crossing_gate,
                                      StopBook({sp.id: sp.stops for sp in specs if sp.stops}), settings.Ts)
        self._ms_request = 0.0  # this step's request indices
        self._window_exits = 0  # vehicle-steps past the padding's stretch (see body_window_exits)

    def _route_speeds(self, spec: VehicleSpec):
        """The speed tables of a spec's route (built once; its record's free-flow time set)."""
        rs = self._speeds.get(spec.id)
        if rs is None:
            vc, sp = self.classes[spec.vclass], self.settings.speed
            try:
                rs = route_speeds(spec.waypoints, spec.speed_limits, vc.v_max, _look_ahead_decel(vc),
                                  self._lat_accel, sp.curve_window_m, apply_lanes=sp.lane_limits,
                                  straight=spec.straight)
            except ValueError as exc:
                raise ValueError(f"vehicle {spec.id}: {exc}") from None
            self._speeds[spec.id] = rs
            rec = self.records.get(spec.id)
            if rec is not None:  # up to the arrival waypoint (a run-out past it is never driven)
                e = spec.arrival_index + 1
                rec.free_flow_s = free_flow_time(rs.arc[:e], rs.lane[:e], 0.5 * vc.length)
        return rs

    # -------------------------------------------------------------- counters
    @property
    def claim_cache(self):
        """Current claims reused between steps (:class:`tm.reach_cache.ClaimCache`; None: fresh claims
        every step, or paper mode): the fleet claims' own."""
        return self.claims.cache

    @property
    def signal_book(self) -> SignalBook:
        """The vehicles' signalised stop lines (:mod:`tm.signals`)."""
        return self.filters.signal_book

    @property
    def pedestrian_withheld(self) -> int:
        """Requests and admissions withheld for pedestrians, over the run."""
        return self.filters.pedestrian_withheld

    @property
    def crossing_withheld(self) -> int:
        """Requests withheld by the crossing gate (authority mode with pedestrians), over the run."""
        gate = self.filters.crossing_gate
        return 0 if gate is None else gate.withheld

    @property
    def body_window_exits(self) -> int:
        """Vehicle-steps (authority mode) with a position outside the stretch the claims' body padding
        was computed for: past its waypoint by more than ``bridge.sumo_body.AHEAD_M`` beyond ``T^0``
        (counted here), or rolled back more than ``BACK_M`` (counted by the world)."""
        return self._window_exits + int(getattr(self.world, "body_window_exits", 0))

    @property
    def red_violations(self) -> int:
        """Stop lines crossed (front bumper) while their link was red, over the run."""
        return self.signal_book.red_violations

    @property
    def zone_holders(self) -> list[dict[str, tuple]]:
        """Per zone: its token holders (id -> route key, corridor boxes lo, hi)."""
        return self.junctions.holders

    # -------------------------------------------------------------- state
    def _fleet(self, with_requests: bool):
        """The fleet's state in fleet order (None with no vehicle); ``with_requests``: every vehicle's
        request index ``l'`` w.r.t. its next waypoint and whether it may ask (design.md §2, step 1)."""
        ids, fam, C, L, H, Ln, Wd = [], [], [], [], [], [], []
        RQ, RC, RL, RH = [], [], [], []
        for c, g in self.groups.items():
            if not g.ids:
                continue
            wcen, whd, _ = g.world_centres()
            ids += g.ids
            fam += [c] * len(g.ids)
            C.append(wcen)
            L.append(g.l)
            H.append(whd)
            Ln.append(np.full(len(g.ids), g.vclass.length))
            Wd.append(np.full(len(g.ids), g.vclass.width))
            if with_requests:
                may, lp, t_index = g.request(self.settings.Ts, self.settings.switching, self.authority)
                self._ms_request += t_index * 1e3
                RQ.append(may)
                wnxt, wnh, _ = g.world_centres(1)
                RC.append(wnxt)
                RL.append(np.minimum(lp, g.ctl.N))
                RH.append(wnh)
        if not ids:
            return None
        cat = np.concatenate
        kw = {}
        if with_requests:
            kw = dict(requesting=cat(RQ), req_centre=np.vstack(RC), req_index=cat(RL), req_heading=cat(RH))
        return FleetState(ids=ids, family=np.array(fam), centre=np.vstack(C), index=cat(L), heading=cat(H),
                          length=cat(Ln), width=cat(Wd), **kw)

    def _requests(self):
        """The fleet state with every vehicle's index and request (None with no vehicle); requests
        withheld by the signals, the junction tokens and the pedestrian rules (:attr:`filters`)."""
        state = self._fleet(with_requests=True)
        self._claims_now = self.claims.current(self.t) if self.authority and state is not None else None
        return self.filters.apply(self.t, state, self._claims_now)

    def _poses(self) -> tuple[np.ndarray, np.ndarray]:
        """World centres (n, 2) and body headings (n,) of the fleet, in fleet order (road frame: the
        plant's positions and the current waypoints' headings)."""
        live = live_groups(self.groups)
        if self.paths is None:
            return np.vstack([g.X[:, :2] for g in live]), np.concatenate([g.centres()[1] for g in live])
        groups = list(self.groups.values())
        poses = [self.paths.pose(groups, g) for g in live]
        return np.vstack([p[0] for p in poses]), np.concatenate([p[1] for p in poses])

    def world_states(self, g: _Group) -> np.ndarray:
        """World states ``(x, y, v_x, v_y)`` of group ``g``'s vehicles (the plant's own in the road frame)."""
        if self.paths is None:
            return g.X[:, :4]
        return self.paths.state(list(self.groups.values()), g)

    # -------------------------------------------------------------- one step (design.md §2)
    def step(self) -> dict:
        s = self.settings
        row = {"t_s": round(self.t * s.Ts, 6)}
        tt = time.perf_counter()
        self._ms_request = 0.0
        # 1. membership indices and requests (controllers), some withheld (signals, junction tokens,
        #    pedestrians: bridge.request_filters)
        state = self._requests()
        dec, n_req, n_go, ms_tm, ms_decide = None, 0, 0, 0.0, 0.0
        if state is not None:
            # 2. TM: Go/Stop for every request
            dec, ms_decide = self._decide(state)
            ms_tm = (time.perf_counter() - tt) * 1e3
            n_req, n_go = int(state.requesting.sum()), int(dec.go.sum())
            # 3a. switch on Go (k <- k + 1, l <- l'); denials counted
            self._switch(state, dec)
            row["edges"] = int(len(dec.edges))
        # 3b. controls (terminal law or the QP of eq. (6)); 4. plant, tube invariant checked
        tc = time.perf_counter()
        self._control()
        ms_ctl = (time.perf_counter() - tc) * 1e3
        if self.authority and state is not None:  # 4a. x(t+1) inside S_1(t) (tube escapes counted)
            self._check_claims(state, dec)
        self.filters.count_red_crossings(lambda: self._fleet(with_requests=False))  # 4b. red crossings
        self.t += 1
        t_next = self.t * s.Ts
        # 5. arrivals; admissions (condition (12)) against the claims of the vehicles now in the network
        self._arrive(t_next)
        admitted = self._admit(t_next)
        # 6. monitor and world (push, step SUMO, its collisions); then the KPI row and observers
        tw = time.perf_counter()
        cur = self._monitor_and_world(row)
        row.update(active=0 if cur is None else len(cur.ids), requests=n_req, grants=n_go,
                   denials=n_req - n_go, admitted=admitted, tm_ms=round(ms_tm, 4),
                   tm_decide_ms=round(ms_decide, 4), request_ms=round(self._ms_request, 4),
                   gate_ms=round(self.filters.ms_gate, 4),
                   controller_ms=round(ms_ctl, 4), world_ms=round((time.perf_counter() - tw) * 1e3, 4))
        self.step_rows.append(row)
        for obs in self.observers:
            obs.on_step(self, state, self.last_decision if state is not None else None, row)
        return row

    def _decide(self, state: FleetState):
        """Step 2: the TM's decision on ``state`` (authority: this step's current claims and the
        requesters' fresh ones) and its time (ms)."""
        td = time.perf_counter()
        if self.authority:
            dec = self.tm.decide_reach(state, self._claims_now, self.claims.requested_reach(self.t, state))
            self.claims.commit(dec.go)
        else:
            dec = self.tm.decide(state)
        ms = (time.perf_counter() - td) * 1e3
        self.last_decision = dec
        self.claims.in_force = (self.t, state.ids, dec.claims) if self.authority else None
        return dec, ms

    def _switch(self, state: FleetState, dec) -> None:
        """Step 3a: granted vehicles switch (``k <- k + 1``, ``l <- l'``); denials and stop episodes counted."""
        o = 0  # the fleet state concatenates the non-empty groups in order
        for g in live_groups(self.groups):
            sl = slice(o, o + len(g.ids))
            o += len(g.ids)
            gmask = np.asarray(dec.go[sl], dtype=bool)
            rmask = np.asarray(state.requesting[sl], dtype=bool)
            if gmask.any():  # the request index of the new waypoint becomes the index
                g.k[gmask] += 1
                g.l[gmask] = g.req_l[gmask]
            denied = rmask & ~gmask
            for i in np.nonzero(denied)[0]:
                rec = self.records[g.ids[i]]
                rec.denials += 1
                rec.stopped_steps += 1
                if not g.denied_last[i]:
                    rec.stop_episodes += 1
            g.denied_last = denied

    def _control(self) -> None:
        """Steps 3b and 4: every vehicle's input (terminal law or the QP of eq. (6)), the plant step with
        the disturbance policy, the tube invariant (index strictly down until 0) and the state
        constraints counted, speed accumulators."""
        s = self.settings
        for g in live_groups(self.groups):
            m = g.vclass.model
            cen, hd, _ = g.centres()
            # the bounds of this step (computed with the requests: a switch moves the waypoint, not the
            # vehicle, and the bounds depend on where the vehicle is)
            U = g.ctl.control(g.X, cen, g.l, ids=g.ids, heading=hd, v_cap=g.cap)
            g.X, _ = plant_step(m, g.X, U, cen, s.disturbance, self.rng, heading=hd)
            l_new = g.ctl.index(g.X, cen, hd)
            bad = ~((l_new < g.l) | ((g.l == 0) & (l_new == 0)))
            self.invariant_violations += int(bad.sum())
            # any index with x in T^l is a valid tube: where a speed bound binds keep the slack it
            # needs (still at most l - 1: the index strictly decreases, claims stay monotone)
            cap_next, lim = g.speed_caps(s.Ts)
            slack = g.slack(s.Ts, 0, cap_next)
            keep = np.minimum(g.l - 1, l_new + slack)
            # no room left: the index falls by the one level a step the invariant allows while a
            # bound binds (the next request is then made whatever the lead: _Group.request)
            g.pinned = (g.l > 1) & (slack > 0) & (l_new + slack >= g.l - 1)
            l_new = np.where(g.l > 0, np.maximum(l_new, keep), l_new)
            speed = np.linalg.norm(g.X[:, 2:4], axis=1)
            np.maximum(g.excess, speed - lim, out=g.excess)
            z = g.ctl.error(g.X, cen, hd)[:, 2:]  # constraints hold in the model's frame
            self.constraint_violations += int(np.sum(np.any((z > m.z_bounds[1] + 1e-7) |
                                                            (z < m.z_bounds[0] - 1e-7), axis=1)))
            g.l = l_new
            g.speed_sum += speed
            g.steps += 1

    def _check_claims(self, state: FleetState, dec) -> None:
        """Step 4a (authority): every position ``x(t+1)`` inside its claim ``S_1(t)`` (the monitor counts
        tube escapes) and within the stretch the body padding covers (``body_window_exits``)."""
        pos, body = self._poses()
        if self.monitor.escapes(dec.claims, pos, state.length, state.width, pad=self.claims.fleet_pads(),
                                body_heading=None if self.paths is None else body):
            self.claims.in_force = None  # claims from x(t+1) need not lie in the shifted ones (near_rows)
        for c, g in self.groups.items():  # positions past the stretch the body padding covers
            if not g.ids:
                continue
            cen, hd, _ = g.centres()
            d = g.X[:, :2] - cen
            along = d[:, 0] * np.cos(hd) + d[:, 1] * np.sin(hd)
            self._window_exits += int(np.sum(along > self.claims.ahead(c)))

    def _arrive(self, t_s: float) -> None:
        """Step 5: vehicles at their last waypoint with ``l = 0``, or past their arrival waypoint
        (:attr:`VehicleSpec.arrive_k`), arrive at ``t_s`` and leave the world."""
        for g in live_groups(self.groups):
            done = g.arrived()
            if done.any():
                self._flush(g, done)
                for i in np.nonzero(done)[0]:
                    rec = self.records[g.ids[i]]
                    rec.arrived_s = t_s
                    # the dwell served at planned stops is not delay (SUMO's timeLoss leaves it out)
                    dwell = self.filters.stops.finish(g.ids[i])
                    if dwell and rec.free_flow_s is not None:
                        rec.free_flow_s += dwell
                    self.world.finish(g.ids[i])
                    self.signal_book.remove(g.ids[i])
                g.remove(done)

    def _monitor_and_world(self, row: dict):
        """Step 6: the monitor's footprint and claim checks, the world pushed and stepped (its collisions),
        pedestrian contacts; the fleet now (None with no vehicle)."""
        cur = self._fleet(with_requests=False)
        if cur is not None:
            pos, body = self._poses()
            if self.paths is not None:  # the bodies lie along their path segments
                cur = replace(cur, heading=body)
            # the world's own bodies (SUMO's), if it has them; first: placing them moves the windows of
            # the claims' body padding (SumoWorld.claim_pads), so the claims below have the padding the
            # next step decides with (offered with another, they missed the offer and were shifted:
            # an outer bound, which denied requests fresh claims grant -- tests/bridge/test_sumo_claim_cache)
            bodies = getattr(self.world, "bodies", None)
            polys = bodies(cur.ids, pos, cur.heading, cur.length, cur.width) if bodies is not None else None
            # the same state decides next step: its claims, as they are, offered to the cache
            fresh = self.claims.fresh(self.t) if self.authority else self.tm.claims(cur)
            ms = self.monitor.step(cur.ids, pos, cur.heading, cur.length, cur.width, claims=fresh,
                                   polygons=polys)
            self.world.push(list(cur.ids), pos, cur.heading)
            if np.isfinite(ms.min_separation) and ms.closest_pair:
                for v in ms.closest_pair:
                    r = self.records[v]
                    r.closest_m = min(r.closest_m, ms.min_separation)
            row.update(footprint_overlaps=ms.footprint_overlaps, claim_violations=ms.claim_violations,
                       min_separation_m=ms.min_separation)
        for pair in self.world.step():
            self.collisions_world.add(tuple(sorted(pair)))
        if self.pedestrians is not None and cur is not None:  # footprints against bodies, after the step
            self.pedestrian_conflicts |= footprint_contacts(cur.ids, pos, cur.heading, cur.length, cur.width,
                                                            *self.filters.peds(), self.pedestrians.settings.radius)
        return cur

    def _first_heading(self, sp: VehicleSpec) -> float:
        h = self._heading0.get(sp.id)
        if h is None:
            W = np.asarray(sp.waypoints[:2], dtype=float)
            h = self._heading0[sp.id] = float(_headings(W)[0])
        return h

    def _admit(self, t_s: float) -> int:
        """Admit the waiting vehicles due by ``t_s`` whose initial tube is free (condition (12)), that miss
        every token holder's corridor and every walking region a pedestrian can reach; returns how many.

        Authority mode: a vehicle with a departure plan (SUMO's ``departPos`` / ``departSpeed``,
        :mod:`bridge.departure`) has several starts, tried in order: round ``j`` tries the ``j``-th
        start of every vehicle not yet admitted, against the claims of the vehicles in the network
        and of those admitted in earlier rounds; in a round the resting starts first, then the moving
        ones against those too (:meth:`_admit_reach`)."""
        n_ready = 0  # pending is sorted by departure: the ready ones are a prefix
        while n_ready < len(self.pending) and self.pending[n_ready].depart_s <= t_s + 1e-9:
            n_ready += 1
        ready = self.pending[:n_ready]
        if not ready:
            return 0
        cand = FleetState(
            ids=[sp.id for sp in ready], family=np.array([sp.vclass for sp in ready]),
            centre=np.array([sp.waypoints[0] for sp in ready]), index=np.zeros(len(ready), dtype=np.intp),
            heading=np.array([self._first_heading(sp) for sp in ready]),
            length=np.array([self.classes[sp.vclass].length for sp in ready]),
            width=np.array([self.classes[sp.vclass].width for sp in ready]))
        chosen: list = [None] * len(ready)
        if self.authority:
            ok = self._admit_reach(ready, cand, chosen)
        else:
            ok = self.tm.admit(_seen_at_entry(self._fleet(with_requests=False), self.families), cand)
            # nor into a junction token holder's corridor (tm.junctions)
            ok = self.junctions.admissible(ok, cand.family, cand.centre, cand.heading)
            # nor onto a walking region a pedestrian can reach
            ok = self.filters.admissible(ok, None, lambda: self.tm.claims(cand))
        n = 0
        for sp, a, st in zip(ready, ok, chosen):
            if a:
                self._enter(sp, t_s, st)
                n += 1
        if n:
            keep = [i for i, a in enumerate(ok) if not a] + list(range(n_ready, len(self.pending)))
            self.pending = [self.pending[i] for i in keep]
        return n

    def _admit_reach(self, ready: list, cand: FleetState, chosen: list) -> np.ndarray:
        """:meth:`_admit` in authority mode: which ready vehicles enter, their starts written to ``chosen``
        (None: at rest on the first waypoint)."""
        starts = [self._starts(sp) for sp in ready]
        # every start's entry claims at once (kept while the vehicle waits): the claims the others
        # must be checked against are those that may meet any of them
        rows = [(i, j) for i, st in enumerate(starts) for j in range(len(st))]
        pick = [i for i, _ in rows]
        # (a start per row: the rows' ids repeat, so not a FleetState; entry_claims reads these three)
        sub = SimpleNamespace(family=cand.family[pick], centre=cand.centre[pick], heading=cand.heading[pick]) \
            if len(rows) > len(ready) else cand
        specs = [ready[i] for i in pick]
        claims, index = self.claims.entry_claims(specs, sub, with_index=True,
                                                 starts=[starts[i][j] for i, j in rows])
        reach_now, feet_now = self.claims.occupied_parts(self.t, self._fleet(with_requests=False), claims,
                                                         self._poses)
        # a vehicle entering at rest must miss the others' footprints now at every step (they may stay);
        # one entering at speed is elsewhere from the next step on: its footprint now must miss theirs,
        # its claims from the next step on their claims (which hold where they will be)
        now = _joined(reach_now, feet_now)
        moving_claims, feet = reach_now, feet_now
        ok = np.zeros(len(ready), dtype=bool)
        at = {key: r for r, key in enumerate(rows)}
        for j in range(max(len(st) for st in starts)):
            todo = [i for i in range(len(ready)) if not ok[i] and j < len(starts[i])]
            if not todo:
                break
            sel = np.array([at[(i, j)] for i in todo], dtype=np.intp)
            e = claims.take(sel)
            moving = np.array([starts[i][j] is not None and starts[i][j].speed > 0 for i in todo])
            got = np.zeros(len(todo), dtype=bool)
            rest = np.flatnonzero(~moving)
            if len(rest):
                got[rest] = admit_reach(now, e.take(rest), self.settings.tm.check)
            mv = np.flatnonzero(moving)
            f_mv = None
            if len(mv):
                # the round's resting starts taken (before the filters below: more cautious) first
                taken = e.take(rest[got[rest]]) if got[rest].any() else None
                f_mv = self._start_footprints([self._start_pose(ready[todo[r]], j) for r in mv])
                got[mv] = admit_reach(_joined(moving_claims, taken), e.take(mv), self.settings.tm.check) & \
                    admit_reach(_joined(feet, taken), f_mv, self.settings.tm.check)
            # nor into a junction token holder's corridor (tm.junctions): a start further on or at speed
            # also with the bounding box of its claims
            shifted = np.array([starts[i][j] is not None for i in todo])
            box = None
            if shifted.any():
                lo, hi = world_aabb(e)
                box = (np.where(shifted[:, None], lo, np.inf), np.where(shifted[:, None], hi, -np.inf))
            poses = [(cand.centre[i], cand.heading[i]) if starts[i][j] is None else self._start_pose(ready[i], j)[:2]
                     for i in todo]
            centre = np.array([p[0] for p in poses]).reshape(-1, 2)
            heading = np.array([p[1] for p in poses], dtype=float)
            got = self.junctions.admissible(got, cand.family[todo], centre, heading, boxes=box)
            # nor onto a walking region a pedestrian can reach
            got = self.filters.admissible(got, (e, index[sel]), None)
            for i, a in zip(todo, got.tolist()):
                if a:
                    ok[i], chosen[i] = True, starts[i][j]
            if got.any():  # the next rounds' starts must miss these too
                new = e.take(np.flatnonzero(got))
                now, moving_claims, feet = _joined(now, new), _joined(moving_claims, new), _joined(feet, new)
                if f_mv is not None and got[mv].any():  # the footprints now of those entering at speed
                    f_new = f_mv.take(np.flatnonzero(got[mv]))
                    now, feet = _joined(now, f_new), _joined(feet, f_new)
        return ok

    @staticmethod
    def _start_footprints(poses: list) -> ReachClaims:
        """The footprints now (one slot) of vehicles entering at starts with poses ``poses``
        (:meth:`_start_pose`), padded as their entry claims."""
        pos, hd, L, Wd, pads = (np.array(a, dtype=float) for a in zip(*poses))
        return footprint_claims(pos.reshape(-1, 2), hd, L, Wd, pad=pads.reshape(len(poses), -1))

    def _start_pose(self, sp: VehicleSpec, j: int) -> tuple:
        """Start ``j`` (moving or shifted, :meth:`_starts`) of ``sp``: ``(centre, heading, length, width,
        pads)`` of its footprint now (the waypoint ``k``, the heading of the segment arriving there, the
        padding of waypoint ``k``'s claims: SUMO's body about it), computed with the starts."""
        return self._start_cache[sp.id][2][j]

    def _starts(self, sp: VehicleSpec) -> list:
        """The starts admission tries for ``sp`` (:func:`bridge.departure.start_ladder`, the plan's speed
        capped at its class's and the route's bound there), each with its first stop point and index:
        ``[None]`` (at rest on its first waypoint) without a plan; a start whose state lies in no tube
        from a stop point before its first edge's end and its first junction guard
        (:meth:`tm.authority_gate.AuthorityGate.entry_limit`) is left out; the last is always None."""
        got = self._start_cache.get(sp.id)
        if got is not None and got[0] is sp:
            return got[1]
        out: list = []
        plan = sp.depart
        if plan is not None:
            g = self.groups[sp.vclass]
            rs = self._route_speeds(sp)
            K = len(sp.waypoints)
            W = np.asarray(sp.waypoints, dtype=float)
            Hw = _headings(W)
            top = min(g.vclass.v_max, float(rs.env[min(plan.k + 1, K - 1)]))
            limit = self._first_stop_limit(sp, W, Hw)
            for k, v in start_ladder(plan, top):
                if k == 0 and v == 0.0:
                    continue  # the old start: None, last
                v = min(v, float(rs.env[min(k + 1, K - 1)]))
                # its first stop point: the nearest waypoint at least its comfortable braking distance
                # ahead (as a vehicle cruising at that speed would hold: it need not brake at once)
                # whose tube holds its state
                reach = rs.arc[k] + v * v / (2.0 * _look_ahead_decel(g.vclass))
                ks = np.arange(k, limit + 1)
                ks = ks[rs.arc[ks] >= reach - 1e-9]
                if not len(ks):
                    continue
                cen, hd, _, _ = self.claims.stop_points(sp, ks)
                X = np.repeat(self.claims.start_x0(sp, k, v)[None], len(ks), axis=0)
                idx = g.ctl.index(X, cen, hd)
                inside = np.flatnonzero(idx <= g.ctl.N)
                if len(inside):
                    stop = int(ks[inside[0]])
                    out.append(Start(k, v, stop, min(int(idx[inside[0]]) + self._start_slack(g, rs, k, v, stop),
                                                     g.ctl.N)))
        vc = self.classes[sp.vclass]
        poses = [(W[st.k], float(Hw[st.k]), vc.length, vc.width, self.claims.spec_pads(sp, st.k)) for st in out]
        out.append(None)
        self._start_cache[sp.id] = (sp, out, poses)
        return out

    def _first_stop_limit(self, sp: VehicleSpec, W: np.ndarray, Hw: np.ndarray) -> int:
        """The furthest first stop point a moving start of ``sp`` (waypoints ``W``, arriving headings
        ``Hw``) may have: its plan's ``stop_max`` (its first planned stop), and before whatever a
        request would have to be let past -- its first junction guard (the token:
        :meth:`tm.authority_gate.AuthorityGate.entry_limit`), its first signalised stop line (the
        light: :func:`tm.signals.stop_bounds`, the bound the signal rule acts on) and its first run
        over a pedestrian crossing (:meth:`tm.crossing_gate.CrossingGate.runs`).  A vehicle never
        enters committed to a junction, a light or a crossing it has not asked for; other edges
        ahead are free to claim, as SUMO's ``departPos="last"`` at speed has them."""
        limit = sp.depart.stop_max
        if isinstance(self.junctions, AuthorityGate):
            limit = min(limit, self.junctions.entry_limit(W, Hw, sp.vclass, sp.id))
        lines = sp.stop_lines
        if lines is not None and len(lines):
            bound = stop_bounds(lines.arc, lines.s_line, self._line_reach(sp.vclass))
            bound = bound[bound >= 0]  # -1: it starts at or past that line, which never acts on it
            if len(bound):
                limit = min(limit, int(bound.min()))
        gate = self.filters.crossing_gate
        if gate is not None:
            entry = gate.runs(sp.id, sp.vclass, W, Hw)[0]
            entry = entry[entry > 0]  # a run it starts in: the gate acts on runs entered later only
            if len(entry):
                limit = min(limit, int(entry[0]) - 1)
        return limit

    def _line_reach(self, vclass: str) -> float:
        """How far past its stop point a vehicle of ``vclass`` at rest may reach with its front (its hold
        region plus half its length): the ``reach`` of its signalised stop lines
        (:func:`tm.signals.stop_bounds`), at admission and in the signal book alike."""
        return self.junctions.classes[vclass].hold + 0.5 * self.classes[vclass].length

    def _start_slack(self, g: _Group, rs, k: int, v: float, stop: int) -> int:
        """Tube levels a moving start (centre on waypoint ``k`` at ``v`` m/s, first stop point ``stop``)
        keeps on top of its minimal index: the slack the loop keeps for a vehicle whose speed bound
        binds (:meth:`bridge.groups._Group.slack`, :class:`controllers.speed_limits.SpeedSettings`),
        0 where no bound of its route binds.

        The minimal index is a minimum-time tube: held without a grant, it makes the vehicle progress
        as if it drove at the class's speed bound.  The loop adds the slack only with a grant (its
        index never rises), so a vehicle entering at its lane's limit whose first requests were
        denied was forced above the limit (SUMO's ``A10KW``: truck8, a 19.44 m/s lane, 20.17 m/s).
        Any ``l`` with ``x0 ∈ T^l`` is a valid tube (the sets are nested) and admission computes the
        start's claims with this index (:meth:`bridge.fleet_claims.FleetClaims.entry_claims`)."""
        if not float(np.min(rs.bound)) < g.v_max - tol.SPEED_BOUND_TOL:
            return 0
        K = len(rs.arc)
        first = np.zeros(1, dtype=np.intp)  # one route, its rows 0 .. K - 1
        front = rs.arc[k] + 0.5 * g.vclass.length + max(v, 0.0) * self.settings.Ts
        cap, _ = bound_at(rs.arc, rs.bound, rs.env, rs.lane, first, first + K - 1, np.array([front]), g.decel)
        return int(g.bound_slack((rs.arc, rs.bound, rs.env, rs.lane), first, first + K - 1, np.array([rs.arc[k]]),
                                 np.array([float(v)]), np.array([rs.arc[stop]]), cap, self.settings.Ts)[0])

    def _enter(self, sp: VehicleSpec, t_s: float, start: Start | None = None) -> None:
        """Vehicle ``sp`` enters its group and the world at ``t_s``: at rest on its first waypoint, or at
        ``start`` (:mod:`bridge.departure`: its centre on waypoint ``start.k`` at ``start.speed``, its
        first stop point ``start.stop``)."""
        g = self.groups[sp.vclass]
        W = np.asarray(sp.waypoints, dtype=float)
        H = _headings(W)
        rs = self._route_speeds(sp)
        world = None
        if self.paths is not None:  # the controller's route: (S_k, 0), heading 0
            world = (W, H)
            W, H = self.paths.waypoints(sp.id, W, rs.arc), np.zeros(len(W))
        if start is None:
            x0 = g.vclass.model.equilibrium(W[0])
            g.add(sp.id, W, H, x0, int(g.ctl.index(x0[None], W[:1], H[:1])[0]), rs, world=world,
                  k_end=sp.arrive_k)
        else:  # its state, first stop point and index there, as admission took them (_starts)
            x0 = self.claims.start_x0(sp, start.k, start.speed)
            g.add(sp.id, W, H, x0, start.index, rs, world=world, k_end=sp.arrive_k, k0=start.stop)
            rec = self.records[sp.id]  # the route and its free-flow time from where it starts
            e = sp.arrival_index + 1
            rec.route_length_m = float(np.linalg.norm(np.diff(sp.driven_waypoints[start.k:], axis=0), axis=1).sum())
            rec.free_flow_s = free_flow_time(rs.arc[start.k:e], rs.lane[start.k:e], 0.5 * g.vclass.length)
            rec.depart_speed_mps = float(start.speed)
        self.records[sp.id].admitted_s = t_s
        self._start_cache.pop(sp.id, None)
        if sp.stop_lines is not None:
            reach = self._line_reach(sp.vclass)
            rest_lead = 0.5 * g.vclass.length - g.ctl.settings.standoff if self.authority else None
            self.signal_book.add(sp.id, sp.stop_lines, reach, rest_lead)
        self.world.insert(sp, g.vclass, 0 if start is None else start.k)

    def _flush(self, g: _Group, mask=None) -> None:
        """Move the group's per-vehicle accumulators (rows ``mask``) into the records."""
        rows = np.arange(len(g.ids)) if mask is None else np.nonzero(mask)[0]
        for i in rows:
            rec = self.records[g.ids[i]]
            rec.speed_sum += float(g.speed_sum[i])
            rec.steps += int(g.steps[i])
            rec.speed_limit_excess = max(rec.speed_limit_excess, float(g.excess[i]))
            g.speed_sum[i] = 0.0
            g.steps[i] = 0

    def flush_records(self) -> None:
        """Bring every :class:`VehicleRecord` up to date (called at the end of :meth:`run`;
        call it before reading ``records`` after stepping by hand)."""
        for g in live_groups(self.groups):
            self._flush(g)

    # -------------------------------------------------------------- run
    @property
    def done(self) -> bool:
        return not self.pending and not any(g.ids for g in self.groups.values())

    def run(self, max_steps: int, progress=None) -> None:
        """Step until every vehicle has arrived, ``duration_s`` or ``max_steps``."""
        if self.t == 0:
            self._admit(0.0)
        limit = max_steps
        if self.settings.duration_s is not None:
            limit = min(limit, int(round(self.settings.duration_s / self.settings.Ts)))
        try:
            while self.t < limit and not self.done:
                self.step()
                if progress is not None:
                    progress(self)
        finally:
            self.flush_records()


def _joined(a: ReachClaims, b: ReachClaims | None) -> ReachClaims:
    """``a`` then ``b`` (``b`` None: ``a``)."""
    return a if b is None else ReachClaims.concat(a, b)


def _seen_at_entry(cur: FleetState | None, families: dict) -> FleetState:
    """Paper mode: the vehicles in the network as admission must see them (an empty state if none).
    A new vehicle appears now: it must miss where the others are now (``P^l``), not only their claims
    from the next step on (``P^{l-1}``); claims of index ``l + 1`` are ``P^l``."""
    if cur is None:
        return FleetState(ids=[], family=np.array([], dtype=str), centre=np.zeros((0, 2)),
                          index=np.zeros(0, dtype=np.intp), heading=np.zeros(0), length=np.zeros(0),
                          width=np.zeros(0))
    top = np.zeros(len(cur.family), dtype=np.intp)
    for c, f in families.items():
        top[cur.family == c] = f.N
    return replace(cur, index=np.minimum(cur.index + 1, top))


def _used_classes(classes, specs) -> dict:
    """The classes the specs name (a clear error naming the unknown ones)."""
    used = sorted({s.vclass for s in specs})
    missing = [c for c in used if c not in classes]
    if missing:
        raise ValueError(f"vehicle class(es) {missing} unknown; valid: {sorted(classes)}")
    return {c: classes[c] for c in used}


def validate_specs(specs, classes: dict, path_frame: bool) -> None:
    """Check every spec before anything runs: waypoints (K >= 2, 2) at most the class's delta apart,
    road-frame routes without turns sharper than the class accepts (``path_frame``: any angle), an
    arrival waypoint before the last, speed tables of one entry per waypoint, a departure plan
    (:mod:`bridge.departure`) whose stop points lie up to the arrival waypoint, planned stops at
    increasing waypoints up to it, unique ids; a
    ValueError names the vehicle and the field."""
    for s in specs:
        W = np.asarray(s.waypoints, dtype=float)
        if W.ndim != 2 or W.shape[1] != 2 or len(W) < 2:
            raise ValueError(f"vehicle {s.id}: waypoints must be (K >= 2, 2), got {W.shape}")
        gaps = np.linalg.norm(np.diff(W, axis=0), axis=1)
        model = classes[s.vclass].model
        delta = model.delta
        if np.any(gaps > delta + 1e-9):
            i = int(np.argmax(gaps))
            raise ValueError(f"vehicle {s.id}: waypoints {i} and {i + 1} are {gaps[i]:.3f} m apart; "
                             f"class {s.vclass!r} needs at most delta = {delta} m")
        if model.frame == "road" and len(W) > 2 and not path_frame:
            h = _headings(W)[1:]
            turn = np.degrees(np.abs((np.diff(h) + np.pi) % (2 * np.pi) - np.pi))
            if np.any(turn > model.turn_max_deg + 1e-6):
                i = int(np.argmax(turn))
                raise ValueError(
                    f"vehicle {s.id}: its route turns by {turn[i]:.1f} deg at waypoint {i + 1}; class "
                    f"{s.vclass!r} (road frame) accepts at most {model.turn_max_deg} deg between segments")
        if s.arrive_k is not None and not (isinstance(s.arrive_k, (int, np.integer)) and 1 <= s.arrive_k < len(W) - 1):
            raise ValueError(f"vehicle {s.id}: arrive_k must be an int in 1 .. {len(W) - 2} (a waypoint before the "
                             f"last, the run-out after it), got {s.arrive_k!r}")
        if s.speed_limits is not None and len(np.asarray(s.speed_limits)) != len(W):
            raise ValueError(f"vehicle {s.id}: speed_limits has {len(np.asarray(s.speed_limits))} "
                             f"entries, one per waypoint ({len(W)}) is needed")
        last = s.arrival_index
        if s.depart is not None and not s.depart.stop_max <= last:
            raise ValueError(f"vehicle {s.id}: depart.stop_max ({s.depart.stop_max}) must be a waypoint up to its "
                             f"arrival waypoint {last}")
        ks = [st.k for st in s.stops]
        if ks and not (all(1 <= k <= last for k in ks) and all(a < b for a, b in zip(ks, ks[1:]))
                       and all(st.duration_s >= 0 for st in s.stops)):
            raise ValueError(f"vehicle {s.id}: stops must lie at increasing waypoints in 1 .. {last} with "
                             f"durations >= 0, got {[(st.k, st.duration_s) for st in s.stops]}")
    if len({s.id for s in specs}) != len(specs):
        raise ValueError("vehicle ids must be unique")


def _look_ahead_decel(vc: VehicleClass) -> float:
    """Comfort deceleration of the speed look-ahead (m/s^2): the class's ``comfort_decel``, or half
    its along-road input bound for classes without one (the paper's)."""
    return float(vc.comfort_decel) if vc.comfort_decel is not None else 0.5 * float(vc.model.u_bounds[1][0])
