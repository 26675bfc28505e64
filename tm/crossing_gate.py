"""Crossings for movement-authority vehicles: a stop point never rests on a crossing (issue 12).

In ``--controller authority`` mode a vehicle's current waypoint ``c`` is its stop point: denied
from now on, it comes to rest in ``T^0(c)`` and its footprint stays in the *hold box*
``T^0(c) ⊕ footprint`` (:meth:`tm.authority_reach.AuthorityReach.hold_half`).  The pedestrian
rule (:mod:`tm.pedestrians`) withholds every request whose claim a pedestrian can reach, so a
vehicle whose stop point had moved onto a crossing stopped there when persons came near; SUMO's
persons then wait for the vehicle standing on their crossing, and its claims stay within their
reach: a deadlock (measured on the 4-arm junction of tests/bridge/test_pedestrians.py: 1 of 9
cars and 2 of 5 persons arrived in 120 s).

The rule, like a junction entry (:mod:`tm.authority_gate`):

* **run**: a maximal run of waypoints of the route whose hold box (world bounding box, at the
  arriving and leaving headings) meets a crossing region; its *entry* ``e`` is the first waypoint
  of the run, its *exit* ``x`` the first one after it (the hold box misses every crossing again),
  its region ``G`` the crossings the run meets;
* **entry**: a request that moves the stop point from before a run (``k < e``) into it
  (``e <= k + 1 < x``) is withheld unless

  - the run exits (the route does not end on the crossing) and the stop point may reach ``x``
    without a junction token it does not hold (``x <= limit``, given by the caller);
  - **room at the exit**: no other vehicle's standing box (the last slot of its claim, ``T^0`` at
    its stop point ⊕ footprint, where it stays if denied from now on) meets the hold box at
    ``x``;
  - **no pedestrian can reach the run before the vehicle has cleared it**: every pedestrian is
    farther than ``reach(H) + jump_m`` with ``H = (x - e) + N + hold_steps`` from ``G`` and from
    every walking region of the pedestrian rule (walking areas too) that the run's claim boxes
    meet (:meth:`tm.authority_reach.AuthorityReach.claim_half` at the waypoints ``e .. x``: a
    walking area beside the crossing that the claims' across half-width reaches).

Why ``H``: after entry the stop point moves one waypoint per grant, ``x - e`` grants until it
is past the run, and the pedestrian rule checks each of those requests over the slots
``k <= max(l, 1) + hold_steps <= N + hold_steps`` (``l <= N``): at step ``t + j`` a pedestrian
withholds only if it can reach a walking region those claims meet (inside the run: ``G`` and the
walking regions beside it, above) within ``N + hold_steps`` steps from where it is then, which is
within ``v j Ts + jump_m`` of where it is now (the speed bound over ``j`` steps plus the one jump
allowance of a SUMO position, measured in tests/bridge/test_pedestrians.py), so from now within
``reach(N + hold_steps + j) + jump_m``.  A pedestrian farther than that from those regions therefore
cannot withhold any request of the passage; once the stop point is past the run the vehicle rests,
if denied, with its footprint off every crossing.

What it covers and what not: with the entry granted, the pedestrians present cannot stop the
vehicle on the crossing, and a vehicle standing past the exit cannot either.  The traffic manager
may still deny a passage request for another vehicle's claims (a vehicle entering the exit road
from elsewhere), and a person appearing within ``reach(H)`` during the passage may still withhold
it: then the vehicle can stop on the crossing, as before; so may a pedestrian near a walking
region that only the passage claims' part behind the entry meets (not counted above).  Safety
is untouched: the rule only ever withholds requests (every grant is still checked by the
pedestrian rule and the traffic manager).

Pure numpy, no simulator.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np

from controllers.tolerances import GEOMETRY_TOL
from tm.authority_reach import AuthorityReach
from tm.geometry import convex_hull, intersect_sat
from tm.pedestrians import PedestrianRule, point_polygon_distance

__all__ = ["CrossingGate"]


def _box_corners(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """CCW corners (n, 4, 2) of axis-aligned boxes ``lo, hi (n, 2)``."""
    return np.stack([lo, np.column_stack([hi[:, 0], lo[:, 1]]), hi, np.column_stack([lo[:, 0], hi[:, 1]])], axis=1)


def _pad_to(P: np.ndarray, k: int) -> np.ndarray:
    """Padded polygons ``P (m, j, 2)``, ``j <= k``, with ``k`` vertices each (last vertex repeated)."""
    if P.shape[1] == k:
        return P
    if not len(P):
        return np.zeros((0, k, 2))
    return np.concatenate([P, np.repeat(P[:, -1:], k - P.shape[1], axis=1)], axis=1)


class CrossingGate:
    """Withholds requests that would put a movement-authority vehicle's stop point on a crossing it
    cannot clear (module notes).

    Parameters
    ----------
    crossings : list of ndarray (k_g, 2)
        Crossing regions as point sets (each replaced by its convex hull, an outer bound).
    classes : mapping of str to AuthorityReach
        Every class a vehicle may have (its hold box).
    horizon : mapping of str to int
        Per class ``N + hold_steps``: the largest slot the pedestrian rule checks for its requests.
    rule : PedestrianRule
        The pedestrian rule (its reach ``r + j + v (k + lag) Ts``, jump allowance and speed bound).
    """

    def __init__(self, crossings, classes: Mapping[str, AuthorityReach], horizon: Mapping[str, int],
                 rule: PedestrianRule) -> None:
        if not isinstance(rule, PedestrianRule):
            raise TypeError(f"rule: must be a PedestrianRule, got {type(rule).__name__}")
        missing = sorted(set(classes) - set(horizon))
        if missing:
            raise ValueError(f"horizon: no entry for class(es) {missing}")
        bad = {c: h for c, h in horizon.items() if isinstance(h, bool) or not isinstance(h, (int, np.integer)) or h < 0}
        if bad:
            raise ValueError(f"horizon: must be integers >= 0 (steps), got {bad}")
        hulls = []
        for g, pts in enumerate(crossings):
            pts = np.asarray(pts, dtype=float)
            if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 3 or not np.all(np.isfinite(pts)):
                raise ValueError(f"crossing {g}: must be >= 3 finite (x, y) points, got shape {pts.shape}")
            hulls.append(convex_hull(pts))
        K = max((len(h) for h in hulls), default=3)
        self.regions = np.stack([np.vstack([h, np.repeat(h[-1:], K - len(h), axis=0)]) for h in hulls]) \
            if hulls else np.zeros((0, 3, 2))
        self.lo = self.regions.min(axis=1) if hulls else np.zeros((0, 2))
        self.hi = self.regions.max(axis=1) if hulls else np.zeros((0, 2))
        self.classes = dict(classes)
        self.horizon = {c: int(h) for c, h in horizon.items()}
        self.rule = rule
        #: vehicle id -> its route's runs over crossings (:meth:`runs`)
        self._runs: dict[str, tuple] = {}
        #: requests withheld by this gate, over the run
        self.withheld = 0

    def __len__(self) -> int:
        return len(self.regions)

    def runs(self, vid: str, vclass: str, W: np.ndarray, H: np.ndarray) -> tuple:
        """``(entry, exit, exits, regions)`` of vehicle ``vid``'s route (waypoints ``W (K, 2)``,
        arriving headings ``H (K,)``): per run over crossings its first waypoint, the first waypoint
        after it (the last one when the route ends in the run: ``exits`` False) and the indices of
        the crossings it meets.  Cached per vehicle (they depend on its route only)."""
        found = self._runs.get(vid)
        if found is not None:
            return found
        W, H = np.asarray(W, dtype=float), np.asarray(H, dtype=float)
        half = self.classes[vclass].hold_half(H, np.r_[H[1:], H[-1:]])
        lo, hi = W - half, W + half
        meets = np.zeros((len(W), len(self.regions)), dtype=bool)
        if len(self.regions):
            near = np.all((lo[:, None] <= self.hi[None] + GEOMETRY_TOL) & (hi[:, None] >= self.lo[None] - GEOMETRY_TOL),
                          axis=2)
            i, g = np.nonzero(near)
            if len(i):
                meets[i, g] = intersect_sat(_box_corners(lo[i], hi[i]), self.regions[g], GEOMETRY_TOL)
        on = meets.any(axis=1)
        d = np.diff(np.r_[0, on.astype(np.int8), 0])
        starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1)   # run = [start, end)
        exits = ends < len(W)
        regions = tuple(np.flatnonzero(meets[s:e].any(axis=0)) for s, e in zip(starts, ends))
        found = self._runs[vid] = (starts, np.where(exits, ends, len(W) - 1), exits, regions)
        return found

    def forget(self, live) -> None:
        """Drop the cached routes of vehicles not in ``live``."""
        live = set(live)
        self._runs = {v: r for v, r in self._runs.items() if v in live}

    def withhold(self, ids, family, routes, requesting: np.ndarray, peds: np.ndarray,
                 stand_lo: np.ndarray, stand_hi: np.ndarray, limit: Callable[[int], int] | None = None) -> np.ndarray:
        """Which requests must not be granted: entries into a run the vehicle cannot clear.

        Parameters
        ----------
        ids : sequence of str
            Vehicle ids, in fleet order (n).
        family : sequence of str
            Their classes.
        routes : sequence of (W, H, k)
            Per vehicle its waypoints (K, 2), arriving headings (K,) and current waypoint ``k``
            (the request moves the stop point to ``k + 1``).
        requesting : ndarray of bool, shape (n,)
        peds : ndarray, shape (P, 2)
            Pedestrians' positions (m).
        stand_lo, stand_hi : ndarray, shape (n, 2)
            World boxes where each vehicle stays if denied from now on (the last slot of its
            current claim); inverted boxes meet nothing.
        limit : callable, optional
            ``limit(i)``: the furthest waypoint vehicle ``i``'s stop point may reach without a
            junction token it does not hold (:meth:`tm.authority_gate.AuthorityGate.stop_limit`);
            asked only for entries (default: no limit).

        Returns
        -------
        ndarray of bool, shape (n,)
            True where a request is withheld (a subset of ``requesting``).
        """
        n = len(ids)
        requesting = np.asarray(requesting, dtype=bool).reshape(-1)
        if len(requesting) != n or len(routes) != n or len(family) != n:
            raise ValueError(f"CrossingGate.withhold: {n} ids, {len(family)} classes, {len(routes)} routes and "
                             f"{len(requesting)} request flags: one each per vehicle")
        out = np.zeros(n, dtype=bool)
        if not len(self.regions) or not requesting.any() or not self.rule.settings.enabled:
            return out
        if len(self._runs) > 4 * n + 1000:  # vehicles gone: drop their routes
            self.forget(ids)
        peds = np.asarray(peds, dtype=float).reshape(-1, 2)
        stand_lo, stand_hi = np.asarray(stand_lo, dtype=float), np.asarray(stand_hi, dtype=float)
        for i in np.flatnonzero(requesting).tolist():
            W, H, k = routes[i]
            k = int(k)
            entry, exit_, exits, regions = self.runs(ids[i], family[i], W, H)
            hit = np.flatnonzero((entry <= k + 1) & (k + 1 < np.where(exits, exit_, len(W))) & (k < entry))
            if not len(hit):
                continue
            j = int(hit[0])
            out[i] = not self._may_enter(i, family[i], W, H, int(entry[j]), int(exit_[j]), bool(exits[j]),
                                         regions[j], peds, stand_lo, stand_hi,
                                         None if limit is None else int(limit(i)))
        self.withheld += int(out.sum())
        return out

    def _may_enter(self, i, vclass, W, H, e, x, exits, regions, peds, stand_lo, stand_hi, limit) -> bool:
        """The entry conditions of the module notes for vehicle row ``i`` and run ``[e, x)``."""
        if not exits or (limit is not None and x > limit):
            return False
        half = self.classes[vclass].hold_half(H[x:x + 1], H[min(x + 1, len(H) - 1):][:1])[0]
        lo, hi = W[x] - half, W[x] + half
        others = np.ones(len(stand_lo), dtype=bool)
        others[i] = False
        if np.any(others & np.all((stand_lo <= hi + GEOMETRY_TOL) & (stand_hi >= lo - GEOMETRY_TOL), axis=1)):
            return False
        if not len(peds):
            return True
        steps = (x - e) + self.horizon[vclass]
        reach = float(self.rule.reach(steps)) + self.rule.settings.jump_m
        A, B = self.regions[regions], self._walks_along(vclass, W, H, e, x)
        G = np.concatenate([_pad_to(A, max(A.shape[1], B.shape[1])), _pad_to(B, max(A.shape[1], B.shape[1]))])
        # every (pedestrian, region) pair: regions tiled over pedestrians, each pedestrian repeated per region
        d = point_polygon_distance(np.tile(G, (len(peds), 1, 1)), np.repeat(peds, len(G), axis=0))
        return bool(d.min() > reach)

    def _walks_along(self, vclass: str, W: np.ndarray, H: np.ndarray, e: int, x: int) -> np.ndarray:
        """The pedestrian rule's walking regions (m, k, 2) that the claim boxes at waypoints ``e .. x``
        meet (:meth:`~tm.authority_reach.AuthorityReach.claim_half`)."""
        R = self.rule.regions
        if not len(R):
            return R
        idx = np.arange(e, x + 1)
        half = self.classes[vclass].claim_half(H[idx], H[np.minimum(idx + 1, len(H) - 1)])
        lo, hi = W[idx] - half, W[idx] + half
        near = np.all((lo[:, None] <= self.rule.hi[None] + GEOMETRY_TOL)
                      & (hi[:, None] >= self.rule.lo[None] - GEOMETRY_TOL), axis=2)
        i, g = np.nonzero(near)
        if not len(i):
            return R[:0]
        hit = intersect_sat(_box_corners(lo[i], hi[i]), R[g], GEOMETRY_TOL)
        return R[np.unique(g[hit])]
