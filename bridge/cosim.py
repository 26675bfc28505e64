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
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from controllers.classes import VehicleClass
from controllers.plant import DISTURBANCES, step as plant_step
from controllers.settings import AUTHORITY_MAX_LEVELS, ControllerSettings, SynthesisSettings
from controllers.speed_limits import SpeedSettings, free_flow_time, restart_slack, route_speeds
from controllers.stmpc import STMPC
from bridge.groups import _Group, _headings
from bridge.pad_memo import PadMemo
from bridge.path_fleet import FRAMES, PathFleet
from controllers.synthesis import synthesize
from controllers.tolerances import GEOMETRY_TOL
from tm.claims import Claims
from tm.reach import ReachClaims, candidate_pairs, world_aabb
from tm.reach_book import ReachBook, admit_reach, footprint_claims
from tm.authority_gate import AuthorityGate
from tm.authority_reach import AuthorityReach
from tm.reach_cache import ClaimCache
from tm.junctions import ClassReach, JunctionFleet, JunctionGate, Zone
from tm.manager import FleetState, TrafficManager
from tm.pedestrians import STRIPING_SPEED_FACTOR, PedestrianRule, footprint_contacts
from tm.crossing_gate import CrossingGate
from tm.monitor import Monitor
from tm.settings import TMSettings
from tm.signals import LineTiming, SignalBook, SignalSettings, StopLines, withhold as signal_withhold

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

    @property
    def route_length_m(self) -> float:
        return float(np.linalg.norm(np.diff(self.waypoints, axis=0), axis=1).sum())


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

    def insert(self, spec: VehicleSpec, vclass: VehicleClass) -> None: ...
    def push(self, ids: list[str], centre: np.ndarray, heading: np.ndarray) -> None: ...
    def finish(self, vid: str) -> None: ...
    def step(self) -> list[tuple[str, str]]: ...


class FreePlaneWorld:
    """No simulator: muvsim's own plant and geometric monitor are the whole world."""

    def insert(self, spec, vclass) -> None:
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


class Cosim:
    """One co-simulation run.

    Parameters
    ----------
    classes : mapping of str to VehicleClass
        Every class a spec may name.
    specs : list of VehicleSpec
    settings : CosimSettings
    world : World, optional
        Defaults to :class:`FreePlaneWorld`.
    synthesis : SynthesisSettings, optional
    """

    def __init__(self, classes, specs, settings: CosimSettings, world=None,
                 synthesis: SynthesisSettings | None = None, zones: list[Zone] | None = None,
                 observers: list | None = None, pedestrians: PedestrianRule | None = None,
                 crossings: list | None = None):
        self.settings = settings
        #: The pedestrian rule (None: no pedestrians); positions come from ``world.pedestrians()``.
        self.pedestrians = pedestrians
        self.pedestrian_conflicts: set = set()  # unique (vehicle, person) footprint-body contacts
        self.pedestrian_withheld = 0            # requests and admissions withheld for pedestrians
        #: this step's claims of its requests, computed once (:meth:`_request_claims`, :meth:`_requested_reach`)
        self._req_cache: tuple | None = None
        #: Objects with ``on_step(sim, state, decision, row)``, called at the end of every
        #: step (``state``: the FleetState the TM decided on, or None with no vehicle;
        #: ``decision``: the TM's Decision or None; ``row``: the step's KPI row).
        #: Loggers (MCAP) and KPI accumulators attach here.
        self.observers = list(observers or [])
        self.world = world or FreePlaneWorld()
        used = sorted({s.vclass for s in specs})
        missing = [c for c in used if c not in classes]
        if missing:
            raise ValueError(f"vehicle class(es) {missing} unknown; valid: {sorted(classes)}")
        self.classes = {c: classes[c] for c in used}
        for s in specs:
            W = np.asarray(s.waypoints, dtype=float)
            if W.ndim != 2 or W.shape[1] != 2 or len(W) < 2:
                raise ValueError(f"vehicle {s.id}: waypoints must be (K >= 2, 2), got {W.shape}")
            gaps = np.linalg.norm(np.diff(W, axis=0), axis=1)
            model = self.classes[s.vclass].model
            delta = model.delta
            if np.any(gaps > delta + 1e-9):
                i = int(np.argmax(gaps))
                raise ValueError(f"vehicle {s.id}: waypoints {i} and {i + 1} are {gaps[i]:.3f} m apart; "
                                 f"class {s.vclass!r} needs at most delta = {delta} m")
            if model.frame == "road" and len(W) > 2 and not settings.path_frame:
                h = _headings(W)[1:]
                turn = np.degrees(np.abs((np.diff(h) + np.pi) % (2 * np.pi) - np.pi))
                if np.any(turn > model.turn_max_deg + 1e-6):
                    i = int(np.argmax(turn))
                    raise ValueError(
                        f"vehicle {s.id}: its route turns by {turn[i]:.1f} deg at waypoint {i + 1}; class "
                        f"{s.vclass!r} (road frame) accepts at most {model.turn_max_deg} deg between segments")
        if len({s.id for s in specs}) != len(specs):
            raise ValueError("vehicle ids must be unique")
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
        #: current claims reused between steps where sound (tm.reach_cache; authority mode with
        #: ``settings.claim_cache``; None: fresh claims every step); with the world's body padding
        #: (SUMO's, ``world.claim_pads``): a shifted claim only where its pad still covers the one needed now
        self.claim_cache = ClaimCache(self.reach) if (self.authority and settings.claim_cache) else None
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
        self.records = {s.id: VehicleRecord(s.id, s.vclass, s.depart_s, s.route_length_m) for s in specs}
        self._speeds = {}
        for s_ in specs:  # validated speed tables and free-flow times, before anything runs
            if s_.speed_limits is not None and len(np.asarray(s_.speed_limits)) != len(s_.waypoints):
                raise ValueError(f"vehicle {s_.id}: speed_limits has {len(np.asarray(s_.speed_limits))} "
                                 f"entries, one per waypoint ({len(s_.waypoints)}) is needed")
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
        if self.authority:
            self.junctions = AuthorityGate(self.zones, {
                c: AuthorityReach.of(m.tables, self.classes[c].length, self.classes[c].width,
                                     self.classes[c].model.delta) for c, m in self.reach.models.items()})
        else:
            self.junctions = JunctionGate(self.zones, {
                c: ClassReach.of(f.position_sets, self.classes[c].length, self.classes[c].width,
                                 self.classes[c].model.frame == "road") for c, f in self.families.items()})
        self._claims_now: ReachClaims | None = None  # authority: this step's claims before the decision
        self._in_force: tuple | None = None  # authority: (step, ids, claims in force after its decision)
        self._junction_fleet: JunctionFleet | None = None  # this step's fleet as the junction gate saw it
        #: authority mode with pedestrians: stop points never rest on a crossing they cannot clear
        #: (``crossings``: the crossing regions; tm.crossing_gate)
        self.crossing_gate = None
        if self.authority and pedestrians is not None and crossings:
            self.crossing_gate = CrossingGate(crossings, self.junctions.classes,
                                              {c: f.N + pedestrians.hold_steps for c, f in self.families.items()},
                                              pedestrians)
        self._ms_request = self._ms_gate = 0.0  # this step's request indices and junction tokens
        # traffic lights (tm.signals): the vehicles' stop lines; link states read once per step
        self.signal_book = SignalBook(settings.signals)
        self._link_state: np.ndarray | None = None
        # SUMO's own bodies (bridge.sumo_body): per waypoint the claims' footprint padding
        self._pads: dict[str, np.ndarray | None] = {}
        #: the groups' claim padding (world.claim_pads), looked up once per step (bridge.pad_memo)
        self._pad_memo = PadMemo(self.world)
        self._window_exits = 0  # vehicle-steps past the padding's stretch (see body_window_exits)

    def _route_speeds(self, spec: VehicleSpec):
        """The speed tables of a spec's route (built once; its record's free-flow time set)."""
        rs = self._speeds.get(spec.id)
        if rs is None:
            vc, sp = self.classes[spec.vclass], self.settings.speed
            try:
                rs = route_speeds(spec.waypoints, spec.speed_limits, vc.v_max, _look_ahead_decel(vc),
                                  self._lat_accel, sp.curve_window_m, apply_lanes=sp.lane_limits)
            except ValueError as exc:
                raise ValueError(f"vehicle {spec.id}: {exc}") from None
            self._speeds[spec.id] = rs
            rec = self.records.get(spec.id)
            if rec is not None:
                rec.free_flow_s = free_flow_time(rs.arc, rs.lane, 0.5 * vc.length)
        return rs

    # -------------------------------------------------------------- state
    def _fleet(self, with_requests: bool):
        ids, fam, C, L, H, Ln, Wd = [], [], [], [], [], [], []
        RQ, RC, RL, RH = [], [], [], []
        for c, g in self.groups.items():
            if not g.ids:
                continue
            cen, hd, _ = g.centres()
            wcen, whd, _ = g.world_centres()
            ids += g.ids
            fam += [c] * len(g.ids)
            C.append(wcen)
            L.append(g.l)
            H.append(whd)
            Ln.append(np.full(len(g.ids), g.vclass.length))
            Wd.append(np.full(len(g.ids), g.vclass.width))
            if with_requests:
                tr = time.perf_counter()
                nxt, nh, has = g.centres(1)
                lp = g.ctl.index(g.X, nxt, nh)
                self._ms_request += (time.perf_counter() - tr) * 1e3
                Ts = self.settings.Ts
                g.cap, _ = g.speed_caps(Ts)
                # a binding speed bound asks for a grant with slack (SpeedSettings.slack_steps) and
                # only for one whose tube lets the vehicle keep the bound (a stopped vehicle always asks)
                inside = lp <= g.ctl.N
                # at rest and denied: ask without slack (its claim would reach behind it: liveness)
                want = lp + restart_slack(g.slack(Ts, 1, g.cap), g.l, g.denied_last)
                may = has & g.ctl.may_request(g.X, cen, hd, lp, g.cap if self.authority else None)
                may &= (want <= g.ctl.N) | (g.l == 0)
                lp = np.where(inside, np.minimum(want, g.ctl.N), lp)
                may &= g.ctl.cap_admits(g.X, nxt, nh, lp, g.cap) | (g.l == 0)
                g.req_l = lp
                if self.settings.switching == "terminal":
                    may &= g.l == 0
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
        """The fleet state with every vehicle's index and request (None with no vehicle);
        requests into a junction guard without its token withheld (:meth:`_gate`)."""
        state = self._fleet(with_requests=True)
        self._link_state = None
        self._junction_fleet = None
        self._claims_now = self._current_claims() if self.authority and state is not None else None
        if state is not None and len(self.signal_book):
            state = self._signals(state)
        elif self.junctions.standing:
            self.junctions.give_back(())
        if state is not None and self.zones:
            tg = time.perf_counter()
            state = self._gate(state)
            self._ms_gate += (time.perf_counter() - tg) * 1e3
        if state is not None and self.pedestrians is not None and state.requesting.any():
            state = self._walkers(state)
        return state

    def _signal_lines(self, ids, centre, heading, length):
        """The fleet's stop lines (:meth:`tm.signals.SignalBook.gather`) from the groups' states."""
        live = [g for g in self.groups.values() if g.ids]
        pos, _ = self._poses()
        k = np.concatenate([g.k for g in live])
        speed = np.concatenate([np.linalg.norm(g.X[:, 2:4], axis=1) for g in live])
        return k, speed, self.signal_book.gather(ids, k, centre, heading, pos, 0.5 * length)

    def _signals(self, state: FleetState) -> FleetState:
        """Withhold the requests that would take a vehicle past a red (or yellow with room to stop)
        stop line (:func:`tm.signals.withhold`); nothing with ``signals.mode = ignore``."""
        read = getattr(self.world, "link_states", None)
        self._link_state = read() if read is not None else None
        if self._link_state is None or not len(self._link_state):
            self._link_state = None
            self.junctions.give_back(())
            return state
        k, speed, (row, bound, s_line, slot, front) = self._signal_lines(state.ids, state.centre, state.heading,
                                                                         state.length)
        req, held = signal_withhold(self.settings.signals, state.requesting, k, row, bound,
                                    self._link_state[slot], s_line - front[row], speed,
                                    self._line_timing(state.ids, slot))
        self.signal_book.withheld += int(held.sum())
        # vehicles standing at a red give their junction tokens back (liveness, tm.junctions)
        self.junctions.give_back([state.ids[i] for i in np.flatnonzero(held).tolist()])
        return replace(state, requesting=req)

    def _line_timing(self, ids, slot: np.ndarray) -> LineTiming | None:
        """Authority mode: the time-to-red rule's inputs (:class:`tm.signals.LineTiming`), the time
        until each link is red read from the world (None in paper mode or without a schedule)."""
        read = getattr(self.world, "link_time_to_red", None)
        if not self.authority or read is None:
            return None
        got = self.signal_book.timing_of(ids)
        to_red = read()
        if got is None or to_red is None:
            return None
        live = [g for g in self.groups.values() if g.ids]
        cap = np.concatenate([g.cap for g in live])
        decel = np.concatenate([np.full(len(g.ids), g.ctl.authority.decel) for g in live])
        return LineTiming(commit=got[0], rest_past=got[1], time_to_red=np.asarray(to_red)[slot], v_cap=cap,
                          decel=decel)

    def _peds(self) -> tuple[list, np.ndarray]:
        """Persons' ids and positions from the world (none if it has no pedestrians)."""
        get = getattr(self.world, "pedestrians", None)
        return get() if get is not None else ([], np.zeros((0, 2)))

    def _ped_speed(self) -> None:
        """Raise the rule's speed bound to the fastest pedestrian the world has seen (striping factor)."""
        v = getattr(self.world, "ped_speed_max", 0.0)
        self.pedestrians.raise_speed(v * STRIPING_SPEED_FACTOR)

    def _walkers(self, state: FleetState) -> FleetState:
        """Withhold requests whose new claim meets a walking region a pedestrian can reach in time."""
        peds = self._peds()[1]
        if not len(peds):
            return state
        self._ped_speed()
        r = np.flatnonzero(state.requesting)
        if self.authority:  # reach claims, slot k against the pedestrians' k-step reach (tm.pedestrians)
            stop = self.pedestrians.withhold_reach(self._requested_reach(state), state.req_index[r], peds)
        else:
            stop = self.pedestrians.withhold(self._request_claims(state)[2], peds)
        if stop.any():
            self.pedestrian_withheld += int(stop.sum())
            req = state.requesting.copy()
            req[r[stop]] = False
            state = replace(state, requesting=req)
        if self.crossing_gate is not None and state.requesting.any():
            state = self._crossings(state, peds)
        return state

    def _crossings(self, state: FleetState, peds: np.ndarray) -> FleetState:
        """Authority mode: withhold requests that would put a stop point on a crossing the vehicle
        cannot clear before a pedestrian can reach it, or without room past it (tm.crossing_gate)."""
        live = [g for g in self.groups.values() if g.ids]
        routes = [(W, H, k) for g in live for W, H, k in zip(g.W, g.H, g.k.tolist())]
        b = self._claims_now.slot_boxes[:, :, -1]  # where each vehicle stays if denied from now on
        fleet = self._junction_fleet
        limit = None if fleet is None else (lambda i: self.junctions.stop_limit(fleet, i))
        stop = self.crossing_gate.withhold(state.ids, state.family, routes, state.requesting, peds,
                                           np.column_stack([b[0], b[2]]), np.column_stack([b[1], b[3]]), limit)
        if not stop.any():
            return state
        return replace(state, requesting=state.requesting & ~stop)

    @property
    def crossing_withheld(self) -> int:
        """Requests withheld by the crossing gate (authority mode with pedestrians), over the run."""
        return 0 if self.crossing_gate is None else self.crossing_gate.withheld

    def _count_red_crossings(self) -> None:
        """Front bumpers that crossed a stop line on red in this step (``red_violations``)."""
        if self._link_state is None:
            return
        cur = self._fleet(with_requests=False)
        if cur is None:
            return
        _, _, (row, _, s_line, slot, front) = self._signal_lines(cur.ids, cur.centre, cur.heading, cur.length)
        self.signal_book.count_crossings(cur.ids, front, row, s_line, self._link_state[slot])

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

    @property
    def zone_lo(self) -> np.ndarray:
        """Lower corners of the zones' guards (the zones enlarged by the largest claim radius)."""
        return self.junctions.lo

    @property
    def zone_hi(self) -> np.ndarray:
        """Upper corners of the zones' guards."""
        return self.junctions.hi

    def _gate(self, state: FleetState) -> FleetState:
        """Withhold requests into a zone guard whose token another vehicle holds (see :class:`Zone`;
        authority mode: stop points past an entry line, :mod:`tm.authority_gate`)."""
        r = np.flatnonzero(state.requesting)
        if self.authority:  # the rules are on the stop points: the new claims' boxes are not used
            cur_lo, cur_hi = world_aabb(self._claims_now)
            new_lo = new_hi = np.zeros((len(r), 2))
        else:
            cur, r, new = self._request_claims(state)
            cur_lo, cur_hi = cur.aabb()
            new_lo = new_hi = np.zeros((0, 2))
            if len(r):
                new_lo, new_hi = new.aabb()
        fn = getattr(self.world, "claim_pads", None) if self.authority else None
        pads = None
        if fn is not None:  # the claims' body padding along a route (SUMO: bridge.sumo_body)
            def pads(rows, idx, ids=state.ids):
                p = fn([ids[r] for r in rows.tolist()], idx)
                return np.zeros((len(idx), 4)) if p is None else p
        fleet = JunctionFleet(state.ids, state.family, cur_lo, cur_hi,
                              tuple((g.W, g.H, g.k) for g in self.groups.values() if g.ids), pads)
        req = self.junctions.withhold(self.t, fleet, state.requesting, new_lo, new_hi)
        self._junction_fleet = fleet
        if not len(r):
            return state
        return replace(state, requesting=req)

    def _spec_pads(self, sp: VehicleSpec) -> np.ndarray:
        """The claims' footprint padding (4,) of ``sp`` at rest on its first waypoint, preparing the
        world's padding of its route (``world.register_pads``, SUMO: :mod:`bridge.sumo_body`): how
        far the world's own body reaches beyond the rectangle, for the positions the class's sets
        hold in a waypoint's frame (``T^N``'s projection, cut :data:`~bridge.sumo_body.AHEAD_M`
        past ``T^0``); zeros without one or in paper mode."""
        pads = self._pads.get(sp.id)
        if pads is None:
            fn = getattr(self.world, "register_pads", None)
            if self.authority and fn is not None:
                T = self.reach.models[sp.vclass].tables
                lo = (float(T.p_lo[T.N]), float(T.y_lo[T.N]))
                hi = (self._ahead(sp.vclass), float(T.y_hi[T.N]))
                if self.paths is not None:
                    hb = self.paths.body_headings(sp.id, sp.waypoints, self._route_speeds(sp).arc)
                    pads = fn(sp, lo, hi, "path", hb)
                else:
                    pads = fn(sp, lo, hi)
            if pads is None:
                pads = np.zeros(4)
            self._pads[sp.id] = pads
        return pads

    def _group_pads(self, g: _Group, offset: int = 0) -> np.ndarray:
        """The claims' footprint padding (n, 4) of a group's vehicles for waypoints ``k + offset``
        (``world.claim_pads``; zeros without it or in paper mode)."""
        if not (self.authority and hasattr(self.world, "claim_pads")):
            return np.zeros((len(g.ids), 4))
        return self._pad_memo.pads(id(g), g.ids, np.minimum(g.k + offset, g.K - 1), offset)

    def _ahead(self, vclass: str) -> float:
        """How far past its waypoint (along its frame) a vehicle's position may be for the padding."""
        from bridge.sumo_body import AHEAD_M

        return float(self.reach.models[vclass].tables.p_hi[0]) + AHEAD_M

    def _reach_claims(self, requests: FleetState | None = None, rows: np.ndarray | None = None) -> ReachClaims:
        """Reach claims (authority mode) of every vehicle for its current waypoint, in fleet order;
        with ``requests``: of its requesters for their requested waypoints; with ``rows`` (bool, fleet
        order): of those vehicles only, for their current waypoints."""
        parts, o = [], 0
        for c, g in self.groups.items():
            if not g.ids:
                continue
            if requests is None:
                r = slice(None) if rows is None else np.asarray(rows[o:o + len(g.ids)], dtype=bool)
                if rows is None or r.any():
                    cen, hd, _ = g.centres()
                    parts.append((c, g.X[r], cen[r], hd[r], g.l[r], self._group_pads(g)[r],
                                  self._place(g, 0, None if rows is None else np.flatnonzero(r))))
            else:
                r = np.asarray(requests.requesting[o:o + len(g.ids)], dtype=bool)
                cen, hd, _ = g.centres(1)
                parts.append((c, g.X[r], cen[r], hd[r], g.req_l[r], self._group_pads(g, 1)[r],
                              self._place(g, 1, np.flatnonzero(r))))
            o += len(g.ids)
        return self.reach.claims(parts)

    def _cached_requests(self, state: FleetState, kind: str, build):
        """``(r, claims of rows r, extra)`` for this step's requesters ``r``; ``build(state) -> (claims of
        state's requesters, extra)`` runs for the first state of the step asked about, later states take
        their rows from it (within a step the fleet is the same and requests are only ever withheld:
        signals, junction tokens, pedestrians)."""
        r = np.flatnonzero(state.requesting)
        c = self._req_cache
        if c is None or (c[0], c[2]) != (self.t, kind) or c[1] is not state.ids or not np.isin(r, c[3]).all():
            c = self._req_cache = (self.t, state.ids, kind, r, *build(state))
        return r, c[4].take(np.searchsorted(c[3], r)), c[5]

    def _request_claims(self, state: FleetState) -> tuple[Claims, np.ndarray, Claims]:
        """Paper mode: the fleet's current claims, the requesters ``r`` and the claims of their
        requests (once per step: the junction gate and the pedestrian rule share them)."""
        def build(st):
            cur = self.tm.claims(st)
            q = np.flatnonzero(st.requesting)
            return Claims(cur.table, cur.family[q], st.req_centre[q], st.req_index[q], st.req_heading[q],
                          cur.length[q], cur.width[q]), cur
        r, new, cur = self._cached_requests(state, "paper", build)
        return cur, r, new

    def _requested_reach(self, state: FleetState) -> ReachClaims:
        """Authority mode: reach claims of the requesters for their requested waypoints, in fleet order
        (once per step: the pedestrian rule and the TM's decision share them)."""
        return self._cached_requests(state, "reach", lambda st: (self._reach_claims(st), None))[1]

    def _current_claims(self) -> ReachClaims:
        """Authority mode: every vehicle's reach claims now, in fleet order: from :class:`ClaimCache`
        (the monitor's claims of this same state, or shifted where sound) or, without a cache, fresh."""
        cache = self.claim_cache
        return cache.current(self.t, self._claim_parts()) if cache is not None else self._reach_claims()

    def _claim_parts(self) -> list:
        """Every vehicle's current claim inputs with ids, in fleet order (for :class:`ClaimCache`)."""
        parts = []
        for c, g in self.groups.items():
            if g.ids:
                cen, hd, _ = g.centres()
                parts.append((c, g.ids, g.X, cen, hd, g.l, self._group_pads(g), self._place(g)))
        return parts

    def _entry_claims(self, ready: list[VehicleSpec], cand: FleetState, with_index: bool = False):
        """Reach claims of the ready vehicles at rest on their first waypoints (in ``ready``'s order);
        with ``with_index``: also their membership indices."""
        parts, rows = [], []
        for c in self.groups:
            idx = np.flatnonzero(cand.family == c)
            if len(idx):
                ctl = self.groups[c].ctl
                pads = np.array([self._spec_pads(ready[i]) for i in idx]).reshape(len(idx), -1)
                if self.paths is None:
                    cen, hd, place = cand.centre[idx], cand.heading[idx], None
                else:  # at rest on the start of its path: (0, 0), heading 0
                    cen, hd = np.zeros((len(idx), 2)), np.zeros(len(idx))
                    place = self.paths.entry_place([ready[i] for i in idx], cand.centre[idx], cand.heading[idx])
                X = self.classes[c].model.equilibrium(cen)
                parts.append((c, X, cen, hd, ctl.index(X, cen, hd), pads, place))
                rows.append(idx)
        inv = np.empty(len(ready), dtype=np.intp)
        inv[np.concatenate(rows)] = np.arange(len(ready))
        out = self.reach.claims(parts).take(inv)
        return (out, np.concatenate([p[4] for p in parts])[inv]) if with_index else out

    # -------------------------------------------------------------- one step
    def step(self) -> dict:
        s = self.settings
        t_s = self.t * s.Ts
        row = {"t_s": round(t_s, 6)}
        tt = time.perf_counter()
        self._ms_request = self._ms_gate = 0.0
        # 1. membership indices and requests (controllers), withheld by the junction tokens (tm.junctions)
        state = self._requests()
        n_req = n_go = 0
        ms_tm = ms_decide = 0.0
        if state is not None:
            # 2. TM: Go/Stop for every request
            td = time.perf_counter()
            if self.authority:  # current claims: this step's (from the cache, _requests); requested fresh
                dec = self.tm.decide_reach(state, self._claims_now, self._requested_reach(state))
                if self.claim_cache is not None:
                    self.claim_cache.commit(dec.go)
            else:
                dec = self.tm.decide(state)
            ms_decide = (time.perf_counter() - td) * 1e3
            self.last_decision = dec
            self._in_force = (self.t, state.ids, dec.claims) if self.authority else None
            ms_tm = (time.perf_counter() - tt) * 1e3
            n_req, n_go = int(state.requesting.sum()), int(dec.go.sum())
            # 3a. switch on Go (k <- k + 1, l <- l'); denials counted
            o = 0  # the fleet state concatenates the non-empty groups in order
            for c, g in self.groups.items():
                if not g.ids:
                    continue
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
            row["edges"] = int(len(dec.edges))
        # 3b. controls (terminal law or the QP of eq. (6)); 4. plant, tube invariant checked
        tc = time.perf_counter()
        for c, g in self.groups.items():
            if not g.ids:
                continue
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
            keep = np.minimum(g.l - 1, l_new + g.slack(s.Ts, 0, cap_next))
            l_new = np.where(g.l > 0, np.maximum(l_new, keep), l_new)
            speed = np.linalg.norm(g.X[:, 2:4], axis=1)
            np.maximum(g.excess, speed - lim, out=g.excess)
            z = g.ctl.error(g.X, cen, hd)[:, 2:]  # constraints hold in the model's frame
            self.constraint_violations += int(np.sum(np.any((z > m.z_bounds[1] + 1e-7) |
                                                            (z < m.z_bounds[0] - 1e-7), axis=1)))
            g.l = l_new
            g.speed_sum += speed
            g.steps += 1
        ms_ctl = (time.perf_counter() - tc) * 1e3
        if self.authority and state is not None:  # 4a. x(t+1) inside S_1(t) (tube escapes counted)
            live = [g for g in self.groups.values() if g.ids]
            pos, body = self._poses()
            if self.monitor.escapes(dec.claims, pos, state.length, state.width,
                                    pad=np.vstack([self._group_pads(g) for g in live]),
                                    body_heading=None if self.paths is None else body):
                self._in_force = None  # claims from x(t+1) need not lie in the shifted ones (_near_rows)
            for c, g in self.groups.items():  # positions past the stretch the body padding covers
                if not g.ids:
                    continue
                cen, hd, _ = g.centres()
                d = g.X[:, :2] - cen
                along = d[:, 0] * np.cos(hd) + d[:, 1] * np.sin(hd)
                self._window_exits += int(np.sum(along > self._ahead(c)))
        self._count_red_crossings()  # 4b. stop lines crossed on red (front bumpers)
        self.t += 1
        t_next = self.t * s.Ts
        # 5. arrivals
        for c, g in self.groups.items():
            if not g.ids:
                continue
            done = g.at_last & (g.l == 0)
            if done.any():
                self._flush(g, done)
                for i in np.nonzero(done)[0]:
                    self.records[g.ids[i]].arrived_s = t_next
                    self.world.finish(g.ids[i])
                    self.signal_book.remove(g.ids[i])
                g.remove(done)
        # 5. admissions (condition (12)) against the claims of the vehicles now in the network
        admitted = self._admit(t_next)
        # 6. monitor and world (push, step SUMO, its collisions); then the KPI row and observers
        tw = time.perf_counter()
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
            fresh = self._reach_claims() if self.authority else self.tm.claims(cur)
            if self.claim_cache is not None:  # the same state decides next step: its claims, as they are
                self.claim_cache.offer(self.t, self._claim_parts(), fresh)
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
                                                            *self._peds(), self.pedestrians.settings.radius)
        row.update(active=0 if cur is None else len(cur.ids), requests=n_req, grants=n_go,
                   denials=n_req - n_go, admitted=admitted, tm_ms=round(ms_tm, 4),
                   tm_decide_ms=round(ms_decide, 4), request_ms=round(self._ms_request, 4),
                   gate_ms=round(self._ms_gate, 4),
                   controller_ms=round(ms_ctl, 4), world_ms=round((time.perf_counter() - tw) * 1e3, 4))
        self.step_rows.append(row)
        for obs in self.observers:
            obs.on_step(self, state, self.last_decision if state is not None else None, row)
        return row

    def _place(self, g: _Group, offset: int = 0, rows=None):
        """Path-frame vehicles of group ``g`` (``rows``) placed in the world for waypoints ``k + offset``
        (:class:`tm.path_claims.PathPlace`); None for road-frame plants."""
        if self.paths is None:
            return None
        return self.paths.place(list(self.groups.values()), g, offset, rows)

    def _poses(self) -> tuple[np.ndarray, np.ndarray]:
        """World centres (n, 2) and body headings (n,) of the fleet, in fleet order (road frame: the
        plant's positions and the current waypoints' headings)."""
        live = [g for g in self.groups.values() if g.ids]
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

    def _first_heading(self, sp: VehicleSpec) -> float:
        h = self._heading0.get(sp.id)
        if h is None:
            W = np.asarray(sp.waypoints[:2], dtype=float)
            h = self._heading0[sp.id] = float(_headings(W)[0])
        return h

    def _admit(self, t_s: float) -> int:
        n_ready = 0  # pending is sorted by departure: the ready ones are a prefix
        while n_ready < len(self.pending) and self.pending[n_ready].depart_s <= t_s + 1e-9:
            n_ready += 1
        ready = self.pending[:n_ready]
        if not ready:
            return 0
        cur = self._fleet(with_requests=False)
        cand = FleetState(
            ids=[sp.id for sp in ready], family=np.array([sp.vclass for sp in ready]),
            centre=np.array([sp.waypoints[0] for sp in ready]), index=np.zeros(len(ready), dtype=np.intp),
            heading=np.array([self._first_heading(sp) for sp in ready]),
            length=np.array([self.classes[sp.vclass].length for sp in ready]),
            width=np.array([self.classes[sp.vclass].width for sp in ready]))
        if cur is None:  # empty network: an empty state
            cur = FleetState(ids=[], family=np.array([], dtype=str), centre=np.zeros((0, 2)),
                             index=np.zeros(0, dtype=np.intp), heading=np.zeros(0), length=np.zeros(0),
                             width=np.zeros(0))
        else:
            # A new vehicle appears NOW: it must miss where the others are now (P^l), not only
            # their claims from the next step on (P^{l-1}).  Claims of index l+1 are P^l.
            top = np.zeros(len(cur.family), dtype=np.intp)
            for c, f in self.families.items():
                top[cur.family == c] = f.N
            cur = FleetState(ids=cur.ids, family=cur.family, centre=cur.centre,
                             index=np.minimum(cur.index + 1, top), heading=cur.heading, length=cur.length,
                             width=cur.width)
        if self.authority:  # the others' reach claims and their footprints now (condition (12))
            entry = self._entry_claims(ready, cand, with_index=True)
            now = self._reach_claims(rows=self._near_rows(cur.ids, cur.centre, entry[0])) if len(cur.ids) else None
            pos, body = self._poses() if now is not None else (None, None)
            body = cur.heading if self.paths is None else body
            pads = np.vstack([self._group_pads(g) for g in self.groups.values() if g.ids]) if now is not None else None
            now = ReachClaims.concat(now, footprint_claims(pos, body, cur.length, cur.width, pad=pads)) \
                if now is not None else footprint_claims(np.zeros((0, 2)), [], [], [])
            ok = admit_reach(now, entry[0], self.settings.tm.check)
        else:
            ok = self.tm.admit(cur, cand)
        # nor into a junction token holder's corridor (tm.junctions)
        ok = self.junctions.admissible(ok, cand.family, cand.centre, cand.heading)
        if self.pedestrians is not None and ok.any():  # nor onto a walking region a pedestrian can reach
            peds = self._peds()[1]
            if len(peds):
                self._ped_speed()
                stop = ok & (self.pedestrians.withhold_reach(*entry, peds) if self.authority
                             else self.pedestrians.withhold(self.tm.claims(cand), peds))
                self.pedestrian_withheld += int(stop.sum())
                ok = ok & ~stop
        n = 0
        for sp, a in zip(ready, ok):
            if not a:
                continue
            g = self.groups[sp.vclass]
            W = np.asarray(sp.waypoints, dtype=float)
            H = _headings(W)
            rs = self._route_speeds(sp)
            world = None
            if self.paths is not None:  # the controller's route: (S_k, 0), heading 0
                world = (W, H)
                W, H = self.paths.waypoints(sp.id, W, rs.arc), np.zeros(len(W))
            x0 = g.vclass.model.equilibrium(W[0])
            g.add(sp.id, W, H, x0, int(g.ctl.index(x0[None], W[:1], H[:1])[0]), rs, world=world)
            self.records[sp.id].admitted_s = t_s
            if sp.stop_lines is not None:
                reach = self.junctions.classes[sp.vclass].hold + 0.5 * g.vclass.length
                rest_lead = 0.5 * g.vclass.length - g.ctl.settings.standoff if self.authority else None
                self.signal_book.add(sp.id, sp.stop_lines, reach, rest_lead)
            self.world.insert(sp, g.vclass)
            n += 1
        if n:
            keep = [i for i, a in enumerate(ok) if not a] + list(range(n_ready, len(self.pending)))
            self.pending = [self.pending[i] for i in keep]
        return n

    def _near_rows(self, ids: list, centre: np.ndarray, entry: ReachClaims) -> np.ndarray | None:
        """The vehicles (bool, fleet order ``ids``; ``centre`` their current waypoints in the world)
        whose claims now may meet the entry claims
        ``entry``: those whose claims in force after this step's decision do (world boxes of all
        their slots within twice GEOMETRY_TOL).  Their claims from ``x(t+1)`` lie in those
        (``S_k(t+1) ⊆ S_{k+1}(t)``: the reach nests, the index drops, the padding only shrinks as its
        window moves on), so the others' cannot meet ``entry`` and admission decides alike without
        them.  None (every vehicle) when that does not hold: no decision this step, a vehicle not in
        it, or a tube escape (:meth:`step`, 4a)."""
        f = self._in_force
        if f is None or f[0] != self.t - 1:
            return None
        pos = {v: i for i, v in enumerate(f[1])}
        idx = [pos.get(v) for v in ids]
        if any(i is None for i in idx):
            return None
        lo, hi = world_aabb(f[2])
        idx = np.asarray(idx, dtype=np.intp)
        elo, ehi = world_aabb(entry)
        _, j = candidate_pairs(elo, ehi, lo[idx], hi[idx], 2.0 * GEOMETRY_TOL)
        near = np.zeros(len(ids), dtype=bool)
        near[j] = True
        # the inclusion needs the waypoint the claims in force were built for: any other, fresh
        near |= ~np.all(np.asarray(centre) == f[2].centre[idx], axis=1)
        return near

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
        for g in self.groups.values():
            if g.ids:
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


def _look_ahead_decel(vc: VehicleClass) -> float:
    """Comfort deceleration of the speed look-ahead (m/s^2): the class's ``comfort_decel``, or half
    its along-road input bound for classes without one (the paper's)."""
    return float(vc.comfort_decel) if vc.comfort_decel is not None else 0.5 * float(vc.model.u_bounds[1][0])
