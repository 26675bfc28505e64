"""Requests withheld before the traffic manager decides: signals, junction tokens, pedestrians.

Step 1 of the co-simulation (:mod:`bridge.cosim`) ends with every vehicle's request; before the TM
sees them, :class:`RequestFilters` withholds, in this order,

- requests past a planned stop's waypoint until its dwell is served (SUMO's ``<stop>``,
  :class:`bridge.vehicle_stops.StopBook`);
- requests that would take a vehicle past a red (or yellow with room to stop) stop line
  (:func:`tm.signals.withhold`, link states read from the world once per step); vehicles standing
  at a red give their junction tokens back;
- requests into a junction guard without one of its tokens (the liveness layer: paper mode
  :class:`tm.junctions.JunctionGate`, authority mode :class:`tm.authority_gate.AuthorityGate`);
- requests whose claim meets a walking region a pedestrian can reach in time
  (:class:`tm.pedestrians.PedestrianRule`) and, in authority mode, requests that would put a stop
  point on a crossing the vehicle cannot clear (:class:`tm.crossing_gate.CrossingGate`).

The rules themselves live in ``tm/``; this class gathers their inputs from the loop's groups and
the world (its optional ``link_states``, ``link_time_to_red``, ``pedestrians``, ``ped_speed_max``
and ``claim_pads``) and counts what it withheld.
"""

from __future__ import annotations

import time
from dataclasses import replace
from functools import partial
from typing import Callable

import numpy as np

from bridge.fleet_claims import FleetClaims
from bridge.groups import live_groups
from bridge.vehicle_stops import StopBook
from tm.crossing_gate import CrossingGate
from tm.junctions import JunctionFleet
from tm.manager import FleetState
from tm.pedestrians import STRIPING_SPEED_FACTOR, PedestrianRule
from tm.reach import ReachClaims, claim_polygons_of, world_aabb
from tm.signals import LineTiming, SignalBook, SignalSettings, withhold as signal_withhold

__all__ = ["RequestFilters"]


class RequestFilters:
    """The loop's request filters (see the module docstring).

    Parameters
    ----------
    signals : SignalSettings
    world
        The loop's world.
    groups : dict of str to _Group
        The loop's groups (read, not copied).
    junctions : JunctionGate or AuthorityGate
        The liveness layer (with no zone it withholds nothing).
    claims : FleetClaims
        The requesters' claims, computed once per step.
    poses : callable
        ``poses() -> (centres (n, 2), body headings (n,))`` of the fleet, in fleet order.
    pedestrians : PedestrianRule, optional
    crossing_gate : CrossingGate, optional
        Authority mode with pedestrians.
    stops : StopBook, optional
        The vehicles' planned stops (none by default).
    Ts : float
        Step length (s): a stop's dwell is counted in simulated seconds.
    """

    def __init__(self, signals: SignalSettings, world, groups: dict, junctions, claims: FleetClaims,
                 poses: Callable[[], tuple[np.ndarray, np.ndarray]], pedestrians: PedestrianRule | None = None,
                 crossing_gate: CrossingGate | None = None, stops: StopBook | None = None, Ts: float = 0.1):
        self.stops = stops if stops is not None else StopBook({})
        self.Ts = float(Ts)
        self.signals = signals
        self.world = world
        self.groups = groups
        self.junctions = junctions
        self.claims = claims
        self._poses = poses
        self.pedestrians = pedestrians
        self.crossing_gate = crossing_gate
        # traffic lights (tm.signals): the vehicles' stop lines; link states read once per step
        self.signal_book = SignalBook(signals)
        self._link_state: np.ndarray | None = None
        self._junction_fleet: JunctionFleet | None = None  # this step's fleet as the junction gate saw it
        self._claims_now: ReachClaims | None = None        # authority: this step's claims before the decision
        self.pedestrian_withheld = 0  # requests and admissions withheld for pedestrians
        #: this step's withheld requests: vehicle id -> the rule's name (``planned stop``, ``signal``,
        #: ``junction token``, ``pedestrians``; :mod:`analysis.waits`)
        self.withheld_by: dict[str, str] = {}
        #: the step being filtered, and the time its junction tokens took (ms)
        self.t = 0
        self.ms_gate = 0.0

    @property
    def authority(self) -> bool:
        return self.claims.authority

    def apply(self, t: int, state: FleetState | None, claims_now: ReachClaims | None) -> FleetState | None:
        """Step ``t``'s state with the requests the rules withhold turned off (None: no vehicle);
        ``claims_now``: every vehicle's claims before the decision (authority mode)."""
        self.t = t
        self.ms_gate = 0.0
        self._link_state = None
        self._junction_fleet = None
        self._claims_now = claims_now
        self.withheld_by = {}
        if state is not None and len(self.stops):
            state = self._noted("planned stop", state, self._stops(state))
        if state is not None and len(self.signal_book):
            state = self._noted("signal", state, self._signals(state))
        elif self.junctions.standing:
            self.junctions.give_back(())
        if state is not None and self.junctions.zones:
            tg = time.perf_counter()
            state = self._noted("junction token", state, self._gate(state))
            self.ms_gate += (time.perf_counter() - tg) * 1e3
        if state is not None and self.pedestrians is not None and state.requesting.any():
            state = self._noted("pedestrians", state, self._walkers(state))
        return state

    def _noted(self, rule: str, before: FleetState, after: FleetState) -> FleetState:
        """``after``, the requests it withheld from ``before`` noted in :attr:`withheld_by` as ``rule``'s."""
        for i in np.flatnonzero(before.requesting & ~after.requesting).tolist():
            self.withheld_by.setdefault(before.ids[i], rule)
        return after

    # -------------------------------------------------------------- planned stops
    def _k_speed(self) -> tuple[np.ndarray, np.ndarray]:
        """The fleet's current waypoints and speeds, in fleet order (from the groups' states)."""
        live = live_groups(self.groups)
        return (np.concatenate([g.k for g in live]),
                np.concatenate([np.linalg.norm(g.X[:, 2:4], axis=1) for g in live]))

    def _stops(self, state: FleetState) -> FleetState:
        """Withhold the requests of vehicles at a planned stop whose dwell is not served yet."""
        k, speed = self._k_speed()
        req, _ = self.stops.withhold(self.t * self.Ts, state.ids, k, state.index, speed, state.requesting)
        return replace(state, requesting=req)

    # -------------------------------------------------------------- signals
    def _signal_lines(self, ids, centre, heading, length):
        """The fleet's stop lines (:meth:`tm.signals.SignalBook.gather`) from the groups' states."""
        pos, _ = self._poses()
        k, speed = self._k_speed()
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
        req, held = signal_withhold(self.signals, state.requesting, k, row, bound,
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
        live = live_groups(self.groups)
        cap = np.concatenate([g.cap for g in live])
        decel = np.concatenate([np.full(len(g.ids), g.ctl.authority.decel) for g in live])
        return LineTiming(commit=got[0], rest_past=got[1], time_to_red=np.asarray(to_red)[slot], v_cap=cap,
                          decel=decel)

    def count_red_crossings(self, fleet: Callable[[], FleetState | None]) -> None:
        """Front bumpers that crossed a stop line on red in this step (``red_violations``);
        ``fleet()``: the fleet now (asked only when this step read link states)."""
        if self._link_state is None:
            return
        cur = fleet()
        if cur is None:
            return
        _, _, (row, _, s_line, slot, front) = self._signal_lines(cur.ids, cur.centre, cur.heading, cur.length)
        self.signal_book.count_crossings(cur.ids, front, row, s_line, self._link_state[slot])

    # -------------------------------------------------------------- junction tokens
    def _stop_table(self, ahead: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Authority mode: every vehicle's waypoint ``min(k + ahead, K - 1)``, its headings there and at
        the next, and its padding there, in fleet order (:attr:`tm.junctions.JunctionFleet.stops`): the
        padding from the fleet claims' memo (:meth:`bridge.fleet_claims.FleetClaims.group_pads`, the
        step's claims ask for ``ahead`` 0 and 1 too), which pads ``min(k + ahead, k_end)``: the same
        waypoint, a route's arrival waypoint ``k_end`` being at most its last, ``K - 1``
        (the co-simulation checks every spec's ``arrive_k`` when it starts: ``1 .. K - 2``)."""
        live = live_groups(self.groups)
        W, H_in, H_out = (np.concatenate(a) for a in zip(*(g.stop_points(ahead) for g in live)))
        return W, H_in, H_out, np.vstack([self.claims.group_pads(g, ahead) for g in live])

    def _gate(self, state: FleetState) -> FleetState:
        """Withhold requests into a zone guard whose token another vehicle holds (see
        :class:`tm.junctions.Zone`; authority mode: stop points past an entry line,
        :mod:`tm.authority_gate`)."""
        r = np.flatnonzero(state.requesting)
        if self.authority:  # the rules are on the stop points: the new claims' boxes are not used
            cur_lo, cur_hi = world_aabb(self._claims_now)
            new_lo = new_hi = np.zeros((len(r), 2))
        else:
            cur, r, new = self.claims.request_claims(self.t, state)
            cur_lo, cur_hi = cur.aabb()
            new_lo = new_hi = np.zeros((0, 2))
            if len(r):
                new_lo, new_hi = new.aabb()
        fn = getattr(self.world, "claim_pads", None) if self.authority else None
        pads = None
        if fn is not None:  # the claims' body padding along a route (SUMO: bridge.sumo_body)
            k_end = np.concatenate([g.k_end for g in live_groups(self.groups)])

            def route_pads(rows, idx, ids=state.ids):  # a run-out (never driven): the arrival waypoint's
                p = fn([ids[r] for r in rows.tolist()], np.minimum(idx, k_end[rows]))
                return np.zeros((len(idx), 4)) if p is None else p
            pads = route_pads
        # authority mode: the oriented boxes of a vehicle's current claims, when a rule asks (tm.authority_gate)
        polys = partial(claim_polygons_of, self._claims_now) if self.authority else None
        fleet = JunctionFleet(state.ids, state.family, cur_lo, cur_hi,
                              tuple((g.W, g.H, g.k) for g in live_groups(self.groups)), pads, polys,
                              self._stop_table if self.authority else None)
        req = self.junctions.withhold(self.t, fleet, state.requesting, new_lo, new_hi)
        self._junction_fleet = fleet
        if not len(r):
            return state
        return replace(state, requesting=req)

    # -------------------------------------------------------------- pedestrians
    def peds(self) -> tuple[list, np.ndarray]:
        """Persons' ids and positions from the world (none if it has no pedestrians)."""
        get = getattr(self.world, "pedestrians", None)
        return get() if get is not None else ([], np.zeros((0, 2)))

    def ped_speed(self) -> None:
        """Raise the rule's speed bound to the fastest pedestrian the world has seen (striping factor)."""
        v = getattr(self.world, "ped_speed_max", 0.0)
        self.pedestrians.raise_speed(v * STRIPING_SPEED_FACTOR)

    def _walkers(self, state: FleetState) -> FleetState:
        """Withhold requests whose new claim meets a walking region a pedestrian can reach in time."""
        peds = self.peds()[1]
        if not len(peds):
            return state
        self.ped_speed()
        r = np.flatnonzero(state.requesting)
        if self.authority:  # reach claims, slot k against the pedestrians' k-step reach (tm.pedestrians)
            stop = self.pedestrians.withhold_reach(self.claims.requested_reach(self.t, state), state.req_index[r], peds)
        else:
            stop = self.pedestrians.withhold(self.claims.request_claims(self.t, state)[2], peds)
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
        routes = [(W, H, k) for g in live_groups(self.groups) for W, H, k in zip(g.W, g.H, g.k.tolist())]
        b = self._claims_now.slot_boxes[:, :, -1]  # where each vehicle stays if denied from now on
        fleet = self._junction_fleet
        limit = None if fleet is None else (lambda i: self.junctions.stop_limit(fleet, i))
        stop = self.crossing_gate.withhold(state.ids, state.family, routes, state.requesting, peds,
                                           np.column_stack([b[0], b[2]]), np.column_stack([b[1], b[3]]), limit)
        if not stop.any():
            return state
        return replace(state, requesting=state.requesting & ~stop)

    def admissible(self, ok: np.ndarray, entry: tuple | None, cand_claims) -> np.ndarray:
        """Admission: of the candidates ``ok``, those whose entry claims no pedestrian can reach in
        time (authority: ``entry = (reach claims, indices)``; paper: ``cand_claims()`` their centred
        claims); the others counted as withheld."""
        if self.pedestrians is None or not ok.any():
            return ok
        peds = self.peds()[1]
        if not len(peds):
            return ok
        self.ped_speed()
        stop = ok & (self.pedestrians.withhold_reach(*entry, peds) if entry is not None
                     else self.pedestrians.withhold(cand_claims(), peds))
        self.pedestrian_withheld += int(stop.sum())
        return ok & ~stop
