"""The fleet's claims in the co-simulation loop: what each vehicle claims, built once per step.

:class:`FleetClaims` is the part of :class:`bridge.cosim.Cosim` that turns the groups' states into
the traffic manager's claims: authority mode's reach-tightened claims (:mod:`tm.reach_book`) with
the world's body padding (SUMO's, :mod:`bridge.sumo_body`, looked up through
:class:`bridge.pad_memo.PadMemo`), the current claims reused between steps where sound
(:class:`tm.reach_cache.ClaimCache`), the requesters' claims computed once per step and shared by
every rule that reads them (junction gate, pedestrians, the decision), the entry claims of waiting
vehicles and which vehicles' claims may meet them (:meth:`FleetClaims.near_rows`).  In paper mode
only the requests' centred claims (:meth:`FleetClaims.request_claims`) are used.

It reads the loop's groups (shared, never copied) and knows nothing of SUMO beyond the optional
world methods ``register_pads`` and ``claim_pads``.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from bridge.groups import _Group, _headings, live_groups
from bridge.pad_memo import PadMemo
from bridge.path_fleet import PathFleet
from controllers.tolerances import GEOMETRY_TOL
from tm.claims import Claims
from tm.manager import FleetState, TrafficManager
from tm.reach import ReachClaims, candidate_pairs, world_aabb
from tm.reach_book import ReachBook, footprint_claims
from tm.reach_cache import ClaimCache

__all__ = ["FleetClaims"]


class FleetClaims:
    """Claims of the loop's groups (see the module docstring).

    Parameters
    ----------
    groups : dict of str to _Group
        The loop's groups, in fleet order (read, not copied: they change as the loop runs).
    classes : dict of str to VehicleClass
    world
        The loop's world (its optional ``register_pads`` / ``claim_pads``).
    tm : TrafficManager
        Paper mode's centred claims.
    reach : ReachBook or None
        Authority mode's claim models (None: paper mode).
    paths : PathFleet or None
        Path-frame plants (None: road frame).
    cache : bool
        Reuse current claims between steps (authority mode).
    route_arc : callable
        ``route_arc(spec)``: arc lengths of a spec's waypoints (the body headings of path frames).
    """

    def __init__(self, groups: dict[str, _Group], classes: dict, world, tm: TrafficManager,
                 reach: ReachBook | None, paths: PathFleet | None, cache: bool,
                 route_arc: Callable[[object], np.ndarray]):
        self.groups = groups
        self.classes = classes
        self.world = world
        self.tm = tm
        self.reach = reach
        self.paths = paths
        self._route_arc = route_arc
        #: current claims reused between steps where sound (authority mode with a cache; None: fresh
        #: claims every step); with the world's body padding a shifted claim only where its pad still
        #: covers the one needed now
        self.cache = ClaimCache(reach) if (reach is not None and cache) else None
        #: per vehicle: its claims' footprint padding at rest on its first waypoint (bridge.sumo_body)
        self._pads: dict[str, np.ndarray] = {}
        #: the groups' claim padding (world.claim_pads), looked up once per step
        self._pad_memo = PadMemo(world)
        #: this step's claims of its requests, computed once (:meth:`request_claims`, :meth:`requested_reach`)
        self._req_cache: tuple | None = None
        #: authority: ``(step, ids, claims in force after its decision)`` (:meth:`near_rows`)
        self.in_force: tuple | None = None
        #: the waiting vehicles' entry claims: ``(id -> (row, spec), claims, indices)`` (:meth:`entry_claims`)
        self._entry: tuple = ({}, None, None)

    @property
    def authority(self) -> bool:
        return self.reach is not None

    # -------------------------------------------------------------- padding
    def spec_pads(self, sp, stop: int = 0) -> np.ndarray:
        """The claims' footprint padding (4,) of ``sp`` at rest on its first waypoint (``stop``: for its
        claims of waypoint ``stop`` from there, the world's ``entry_pads``), preparing the
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
                hi = (self.ahead(sp.vclass), float(T.y_hi[T.N]))
                if self.paths is not None:
                    hb = self.paths.body_headings(sp.id, sp.waypoints, self._route_arc(sp))
                    pads = fn(sp, lo, hi, "path", hb)
                else:
                    pads = fn(sp, lo, hi)
            if pads is None:
                pads = np.zeros(4)
            self._pads[sp.id] = pads
        if stop:
            fn = getattr(self.world, "entry_pads", None)
            got = fn(sp.id, stop) if (self.authority and fn is not None) else None
            return np.zeros(4) if got is None else got
        return pads

    def group_pads(self, g: _Group, offset: int = 0) -> np.ndarray:
        """The claims' footprint padding (n, 4) of a group's vehicles for waypoints ``k + offset``
        (``world.claim_pads``; zeros without it or in paper mode)."""
        if not (self.authority and hasattr(self.world, "claim_pads")):
            return np.zeros((len(g.ids), 4))
        # a run-out past the arrival waypoint (never driven): the arrival waypoint's padding
        return self._pad_memo.pads(id(g), g.ids, np.minimum(g.k + offset, g.k_end), offset)

    def fleet_pads(self) -> np.ndarray:
        """:meth:`group_pads` of every vehicle, in fleet order."""
        return np.vstack([self.group_pads(g) for g in live_groups(self.groups)])

    def ahead(self, vclass: str) -> float:
        """How far past its waypoint (along its frame) a vehicle's position may be for the padding."""
        from bridge.sumo_body import AHEAD_M

        return float(self.reach.models[vclass].tables.p_hi[0]) + AHEAD_M

    def place(self, g: _Group, offset: int = 0, rows=None):
        """Path-frame vehicles of group ``g`` (``rows``) placed in the world for waypoints ``k + offset``
        (:class:`tm.path_claims.PathPlace`); None for road-frame plants."""
        if self.paths is None:
            return None
        return self.paths.place(list(self.groups.values()), g, offset, rows)

    # -------------------------------------------------------------- claims
    def reach_claims(self, requests: FleetState | None = None, rows: np.ndarray | None = None) -> ReachClaims:
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
                    parts.append((c, g.X[r], cen[r], hd[r], g.l[r], self.group_pads(g)[r],
                                  self.place(g, 0, None if rows is None else np.flatnonzero(r))))
            else:
                r = np.asarray(requests.requesting[o:o + len(g.ids)], dtype=bool)
                cen, hd, _ = g.centres(1)
                parts.append((c, g.X[r], cen[r], hd[r], g.req_l[r], self.group_pads(g, 1)[r],
                              self.place(g, 1, np.flatnonzero(r))))
            o += len(g.ids)
        return self.reach.claims(parts)

    def _cached_requests(self, t: int, state: FleetState, kind: str, build):
        """``(r, claims of rows r, extra)`` for step ``t``'s requesters ``r``; ``build(state) -> (claims of
        state's requesters, extra)`` runs for the first state of the step asked about, later states take
        their rows from it (within a step the fleet is the same and requests are only ever withheld:
        signals, junction tokens, pedestrians)."""
        r = np.flatnonzero(state.requesting)
        c = self._req_cache
        if c is None or (c[0], c[2]) != (t, kind) or c[1] is not state.ids or not np.isin(r, c[3]).all():
            c = self._req_cache = (t, state.ids, kind, r, *build(state))
        return r, c[4].take(np.searchsorted(c[3], r)), c[5]

    def request_claims(self, t: int, state: FleetState) -> tuple[Claims, np.ndarray, Claims]:
        """Paper mode: the fleet's current claims, the requesters ``r`` and the claims of their
        requests (once per step ``t``: the junction gate and the pedestrian rule share them)."""
        def build(st):
            cur = self.tm.claims(st)
            q = np.flatnonzero(st.requesting)
            return Claims(cur.table, cur.family[q], st.req_centre[q], st.req_index[q], st.req_heading[q],
                          cur.length[q], cur.width[q]), cur
        r, new, cur = self._cached_requests(t, state, "paper", build)
        return cur, r, new

    def requested_reach(self, t: int, state: FleetState) -> ReachClaims:
        """Authority mode: reach claims of the requesters for their requested waypoints, in fleet order
        (once per step ``t``: the pedestrian rule and the TM's decision share them)."""
        return self._cached_requests(t, state, "reach", lambda st: (self.reach_claims(st), None))[1]

    def current(self, t: int) -> ReachClaims:
        """Authority mode: every vehicle's reach claims at step ``t``, in fleet order: from the
        :class:`ClaimCache` (the monitor's claims of this same state, or shifted where sound) or,
        without a cache, fresh."""
        return self.cache.current(t, self.parts()) if self.cache is not None else self.reach_claims()

    def parts(self) -> list:
        """Every vehicle's current claim inputs with ids, in fleet order (for :class:`ClaimCache`)."""
        parts = []
        for c, g in self.groups.items():
            if g.ids:
                cen, hd, _ = g.centres()
                parts.append((c, g.ids, g.X, cen, hd, g.l, self.group_pads(g), self.place(g)))
        return parts

    def fresh(self, t: int) -> ReachClaims | Claims:
        """Authority mode: every vehicle's claims from its state now, offered to the cache for step
        ``t`` (the same state decides then)."""
        out = self.reach_claims()
        if self.cache is not None:
            self.cache.offer(t, self.parts(), out)
        return out

    def commit(self, go: np.ndarray) -> None:
        """Authority mode: the granted requesters' claims become their claims in force (the cache)."""
        if self.cache is not None:
            self.cache.commit(go)

    def entry_claims(self, ready: list, cand: FleetState, with_index: bool = False, starts: list | None = None):
        """Reach claims of the ready vehicles (specs) at rest on their first waypoints (in ``ready``'s
        order); with ``with_index``: also their membership indices.  ``starts``: per row a
        :class:`bridge.departure.Start` (another place or a speed, :mod:`bridge.departure`) or None (at
        rest on the first waypoint).  A vehicle's entry claims depend on its spec and start alone (its
        waypoints, class and padding there), so they are computed once, at its first admission
        attempt, and kept while it waits."""
        starts = [None] * len(ready) if starts is None else list(starts)
        bank = self._entry
        keys = [(sp.id, st) for sp, st in zip(ready, starts)]
        missing = [i for i, (sp, key) in enumerate(zip(ready, keys)) if bank[0].get(key, (None, None))[1] is not sp]
        if len(bank[0]) > 4 * len(ready) + 256:  # vehicles admitted long ago: start over
            bank = self._entry = ({}, None, None)
            missing = list(range(len(ready)))
        if missing:
            got, idx = self._entry_fresh([ready[i] for i in missing], cand.family[missing], cand.centre[missing],
                                         cand.heading[missing], [starts[i] for i in missing])
            base = 0 if bank[1] is None else len(bank[1])
            ids = dict(bank[0])
            ids.update((keys[i], (base + r, ready[i])) for r, i in enumerate(missing))
            bank = self._entry = (ids, got if bank[1] is None else ReachClaims.concat(bank[1], got),
                                  idx if bank[2] is None else np.concatenate([bank[2], idx]))
        rows = np.fromiter((bank[0][key][0] for key in keys), dtype=np.intp, count=len(ready))
        out = bank[1].take(rows)
        return (out, bank[2][rows]) if with_index else out

    def _entry_fresh(self, ready: list, family: np.ndarray, centre: np.ndarray, heading: np.ndarray,
                     starts: list):
        """:meth:`entry_claims` computed: ``(claims, indices)`` in ``ready``'s order."""
        parts, rows = [], []
        for c, g in self.groups.items():
            idx = np.flatnonzero(family == c)
            if len(idx):
                pads = np.array([self.spec_pads(ready[i], 0 if starts[i] is None else starts[i].stop)
                                 for i in idx]).reshape(len(idx), -1)
                if self.paths is None:
                    cen, hd, place = centre[idx].copy(), heading[idx].copy(), None
                else:  # at rest on the start of its path: (0, 0), heading 0
                    cen, hd = np.zeros((len(idx), 2)), np.zeros(len(idx))
                    place = self.paths.entry_place([ready[i] for i in idx], centre[idx], heading[idx])
                X = self.classes[c].model.equilibrium(cen)
                index = g.ctl.index(X, cen, hd)
                shifted = [r for r, i in enumerate(idx.tolist()) if starts[i] is not None]
                for r in shifted:  # another start (bridge.departure): its state, first stop point, index
                    sp, st = ready[idx[r]], starts[idx[r]]
                    X[r], cen[r], hd[r], w, wh = self.start_state(sp, st)
                    index[r] = st.index
                    if place is not None:
                        place.centre[r], place.heading[r] = w, wh
                parts.append((c, X, cen, hd, index, pads, place))
                rows.append(idx)
        inv = np.empty(len(ready), dtype=np.intp)
        inv[np.concatenate(rows)] = np.arange(len(ready))
        return self.reach.claims(parts).take(inv), np.concatenate([p[4] for p in parts])[inv]

    def start_state(self, sp, st):
        """A start ``st`` (:class:`bridge.departure.Start`) of spec ``sp`` in its plant's frame: ``(x0,
        centre, heading, world centre, world heading)``, ``x0`` the state on waypoint ``st.k`` at
        ``st.speed`` along the route, the others of its stop point ``st.stop``."""
        x0 = self.start_x0(sp, st.k, st.speed)
        cen, hd, w, wh = self.stop_points(sp, np.array([st.stop]))
        return x0, cen[0], float(hd[0]), w[0], float(wh[0])

    def start_x0(self, sp, k: int, speed: float) -> np.ndarray:
        """The plant state (4,) of spec ``sp`` with its centre on waypoint ``k`` at ``speed`` (m/s) along
        the route (road frame: the segment leaving ``k``)."""
        W = np.asarray(sp.waypoints, dtype=float)
        if self.paths is None:
            d = W[min(k + 1, len(W) - 1)] - W[k] if k + 1 < len(W) else W[k] - W[k - 1]
            h = float(np.arctan2(d[1], d[0]))
            return np.array([W[k, 0], W[k, 1], speed * np.cos(h), speed * np.sin(h)])
        S = self.paths.waypoints(sp.id, W, self._route_arc(sp))[:, 0]
        return np.array([S[k], 0.0, speed, 0.0])

    def stop_points(self, sp, ks: np.ndarray):
        """Waypoints ``ks`` of spec ``sp`` as stop points: ``(centre (m, 2), heading (m,))`` in its plant's
        frame and ``(centre, heading)`` in the world (headings of the segments arriving there)."""
        W = np.asarray(sp.waypoints, dtype=float)
        Hw = _headings(W)
        ks = np.asarray(ks, dtype=np.intp)
        if self.paths is None:
            return W[ks], Hw[ks], W[ks], Hw[ks]
        S = self.paths.waypoints(sp.id, W, self._route_arc(sp))[:, 0]
        return np.column_stack([S[ks], np.zeros(len(ks))]), np.zeros(len(ks)), W[ks], Hw[ks]

    def occupied_parts(self, t: int, cur: FleetState | None, entry: ReachClaims,
                       poses: Callable[[], tuple[np.ndarray, np.ndarray]]) -> tuple[ReachClaims, ReachClaims]:
        """Authority mode: what the entry claims ``entry`` of step ``t`` must miss (condition (12)), in two
        parts: the reach claims (from the next step on) of the vehicles ``cur`` (None: none) whose
        claims may meet them (:meth:`near_rows`), and every vehicle's footprint now, padded (one slot:
        every step; ``poses()``: their centres and body headings; road frame: ``cur``'s headings)."""
        if cur is None:
            empty = footprint_claims(np.zeros((0, 2)), [], [], [])
            return empty, empty
        now = self.reach_claims(rows=self.near_rows(t, cur.ids, cur.centre, entry))
        pos, body = poses()
        body = cur.heading if self.paths is None else body
        return now, footprint_claims(pos, body, cur.length, cur.width, pad=self.fleet_pads())

    def near_rows(self, t: int, ids: list, centre: np.ndarray, entry: ReachClaims) -> np.ndarray | None:
        """The vehicles (bool, fleet order ``ids``; ``centre`` their current waypoints in the world)
        whose claims at step ``t`` may meet the entry claims
        ``entry``: those whose claims in force after step ``t - 1``'s decision do (world boxes of all
        their slots within twice GEOMETRY_TOL).  Their claims from ``x(t)`` lie in those
        (``S_k(t+1) ⊆ S_{k+1}(t)``: the reach nests, the index drops, the padding only shrinks as its
        window moves on), so the others' cannot meet ``entry`` and admission decides alike without
        them.  None (every vehicle) when that does not hold: no decision that step, a vehicle not in
        it, or a tube escape (:attr:`in_force` cleared by the loop)."""
        f = self.in_force
        if f is None or f[0] != t - 1:
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
