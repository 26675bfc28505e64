"""Pedestrians: no claim is granted over a walking region a pedestrian can reach within its horizon.

Pedestrians are not controlled by muvsim (SUMO moves them); they are only
bounded: a pedestrian's body is a disk of radius ``r`` around its position
``p`` and it walks at most ``v`` m/s.  The shared space of vehicles and
pedestrians is the net's *walking regions* (crossings and walking areas,
convex polygons from the bridge).

The rule (:meth:`PedestrianRule.withhold`), for a request whose new claim has
the timed polygons ``S_k = c + P^{max(l-k, 0)} ⊕ R(θ)`` (:mod:`tm.claims`;
the vehicle's footprint is inside ``S_k`` at step ``t + k`` whatever the
check, by the tube), ``k = 1 .. K`` with ``K = max(l, 1) + hold_steps``:
the request is withheld when for some ``k``, some walking region ``G`` and
some pedestrian ``p``

* ``S_k`` meets ``G``,
* ``G`` is within ``reach_k = r + j + v (k + lag) Ts`` of ``p``, and
* ``S_k`` is within ``reach_k`` of ``p``.

Authority mode (:meth:`PedestrianRule.withhold_reach`): the same three tests on the
reach-tightened boxes ``S_k`` of :mod:`tm.reach` (slot ``k``: where the footprint can be at step
``t + k``), for ``k = 1 .. min(max(l, 1) + hold_steps, K)``: the steps by which the tube has brought
the vehicle into ``T^0`` at its stop point, as in paper mode (``K`` slots; empty boxes meet
nothing).  Time-indexed: a box that meets a walking region only at step ``k`` is tested against
the ``k``-step reach, not the whole horizon's, and it is sound because ``S_k`` bounds where the
vehicle can be at step ``k``.

The three tests are implied by "``S_k ∩ G`` is within ``reach_k`` of ``p``",
so the rule withholds at least whenever that exact condition holds: sound
(and somewhat conservative).  ``lag`` covers positions read one simulator
step before the decision takes effect; ``j`` the jumps of a SUMO person's
position where it passes from one lane's shape to the next (sidewalk, walking
area, crossing: up to 0.85 m in one 0.1 s step, 0.55 m beyond ``v Ts``, none
beyond ``v k Ts`` over 5 steps or more; measured in tests/bridge/test_pedestrians.py).  Withholding only ever removes
requests, so the vehicles' own invariant ("deny all keeps the claims
disjoint") is untouched.

What it covers: at grant time no pedestrian can reach, within the claim's
horizon, a walking region where the claim's polygon at that step lies.  A
denied request keeps the vehicle's current claim, granted earlier under the
same test: it can still stop inside it (the tube), and since a claim not
granted only shrinks (``S_k(t+1) ⊆ S_{k+1}(t)`` in authority mode, ``P^{l-k}``
in paper mode) the grant-time test keeps covering it up to that claim's
horizon.  What it does not: a pedestrian who walks in later onto a region
that a vehicle's *held* claim (its hold region: ``P^0``, or ``T^0`` at the
stop point in authority mode, kept while its requests are denied) covers,
after that horizon -- muvsim cannot stop SUMO's pedestrians, and they do not
yield to vehicles moved by ``moveToXY``.  :func:`footprint_contacts`
measures that (the ``pedestrian_conflicts`` counter).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from controllers.tolerances import GEOMETRY_TOL
from tm.claims import Claims
from tm.geometry import convex_hull, intersect_sat, rectangles
from tm.reach import ReachClaims, world_aabb

__all__ = ["PedestrianSettings", "PedestrianRule", "footprint_contacts", "point_polygon_distance",
           "SUMO_PED_SPEED_BOUND", "STRIPING_SPEED_FACTOR"]

#: Factor from a striping pedestrian's walking speed to its speed bound: lateral speed at most
#: ``max(0.4 v, v - v_x)`` gives at most ``sqrt(1 + 0.4^2) v``.
STRIPING_SPEED_FACTOR = math.sqrt(1.16)

#: Default bound on a SUMO pedestrian's speed (m/s).  SUMO's default pedestrian type walks at
#: ``desiredMaxSpeed`` 1.39 m/s times its speed factor, drawn from ``normc(1, 0.1, 0.2, 2)`` (at most 2):
#: 2.78 m/s forward.  The striping model adds a lateral speed of at most ``max(0.4 v, v - v_x)``
#: (``LATERAL_SPEED_FACTOR`` 0.4), so the speed is at most ``sqrt(1 + 0.4^2) v`` = 2.99 m/s; rounded up.
SUMO_PED_SPEED_BOUND = 3.0


@dataclass(frozen=True)
class PedestrianSettings:
    """Settings of the pedestrian rule (validated).

    Parameters
    ----------
    enabled : bool
        Apply the rule (``False``: requests are never withheld for pedestrians; only for tests
        and comparisons, it removes the pedestrians' protection).
    v_max : float
        Bound on any pedestrian's speed (m/s), :data:`SUMO_PED_SPEED_BOUND` by default; a scenario
        whose pedestrian vTypes walk faster must raise it.
    radius : float
        Radius of a pedestrian's body (m); SUMO's default person is 0.48 x 0.21 m (half diagonal 0.27).
    lag_steps : int
        Steps between reading the pedestrians' positions and the decision taking effect (>= 0).
    hold_s : float
        Seconds beyond the claim's own horizon for which the hold region is kept clear too (>= 0).
    jump_m : float
        Allowance (m) for a position jumping further than the speed allows (SUMO at lane changes).
    """

    enabled: bool = True
    v_max: float = SUMO_PED_SPEED_BOUND
    radius: float = 0.3
    lag_steps: int = 1
    hold_s: float = 0.0
    jump_m: float = 0.75

    def __post_init__(self) -> None:
        if not isinstance(self.enabled, bool):
            raise ValueError(f"PedestrianSettings.enabled: must be true or false, got {self.enabled!r}")
        for name in ("v_max", "radius", "hold_s", "jump_m"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
                raise ValueError(f"PedestrianSettings.{name}: must be a finite number >= 0, got {v!r}")
        if isinstance(self.lag_steps, bool) or not isinstance(self.lag_steps, int) or self.lag_steps < 0:
            raise ValueError(f"PedestrianSettings.lag_steps: must be an integer >= 0, got {self.lag_steps!r}")


def point_polygon_distance(P: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Distance of points ``q (n, 2)`` to CCW convex polygons ``P (n, K, 2)`` (0 inside).

    Repeated vertices (padding) are allowed.
    """
    P = np.asarray(P, dtype=float)
    q = np.asarray(q, dtype=float)
    A, B = P, np.roll(P, -1, axis=1)
    D = B - A
    R = q[:, None, :] - A
    cross = D[..., 0] * R[..., 1] - D[..., 1] * R[..., 0]
    inside = np.all(cross >= -GEOMETRY_TOL, axis=1)
    dd = np.einsum("nkd,nkd->nk", D, D)
    t = np.einsum("nkd,nkd->nk", R, D)
    t = np.clip(np.divide(t, dd, out=np.zeros_like(t), where=dd > 0), 0.0, 1.0)
    d = np.linalg.norm(R - t[..., None] * D, axis=-1).min(axis=1)
    return np.where(inside, 0.0, d)


def _pad(polys: list[np.ndarray]) -> np.ndarray:
    """Polygons of different sizes as one array, each padded with its last vertex."""
    K = max(len(p) for p in polys)
    return np.stack([np.vstack([p, np.repeat(p[-1:], K - len(p), axis=0)]) for p in polys])


class PedestrianRule:
    """Withholds requests whose claims meet walking regions that pedestrians can reach.

    Parameters
    ----------
    settings : PedestrianSettings
    regions : list of ndarray (k_g, 2)
        Walking regions (crossings, walking areas) as point sets; each is replaced by its convex hull
        (an outer bound, so the rule stays sound for non-convex walking areas).
    Ts : float
        Control step (s).
    """

    def __init__(self, settings: PedestrianSettings, regions, Ts: float) -> None:
        if not isinstance(settings, PedestrianSettings):
            raise TypeError(f"settings: must be a PedestrianSettings, got {type(settings).__name__}")
        if not Ts > 0:
            raise ValueError(f"Ts: must be > 0 s, got {Ts}")
        self.settings = settings
        self.Ts = float(Ts)
        hulls = []
        for g, pts in enumerate(regions):
            pts = np.asarray(pts, dtype=float)
            if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 3 or not np.all(np.isfinite(pts)):
                raise ValueError(f"walking region {g}: must be >= 3 finite (x, y) points, got shape {pts.shape}")
            hulls.append(convex_hull(pts))
        self.regions = _pad(hulls) if hulls else np.zeros((0, 3, 2))
        self.lo = self.regions.min(axis=1) if hulls else np.zeros((0, 2))
        self.hi = self.regions.max(axis=1) if hulls else np.zeros((0, 2))
        self.hold_steps = int(math.ceil(settings.hold_s / self.Ts - 1e-9))
        #: The speed bound in use (m/s): ``settings.v_max``, raised by :meth:`raise_speed`.
        self.v_max = float(settings.v_max)

    def raise_speed(self, v: float) -> None:
        """Raise the speed bound to ``v`` (m/s) if it is larger: a faster pedestrian appeared."""
        self.v_max = max(self.v_max, float(v))

    def reach(self, k) -> np.ndarray:
        """``r + j + v (k + lag) Ts``: how far from its position a pedestrian's body can be at step ``k``."""
        s = self.settings
        return s.radius + s.jump_m + self.v_max * (np.asarray(k, dtype=float) + s.lag_steps) * self.Ts

    def horizon(self, index: np.ndarray) -> np.ndarray:
        """Steps ``K = max(l, 1) + hold_steps`` checked for claims of index ``l``."""
        return np.maximum(np.asarray(index), 1) + self.hold_steps

    def withhold(self, claims: Claims, peds: np.ndarray) -> np.ndarray:
        """Which of the (new, paper-mode) ``claims`` must not be granted, given pedestrians at ``peds``.

        Parameters
        ----------
        claims : Claims
            The claims the requests would make (one per request).
        peds : ndarray, shape (P, 2)
            Pedestrians' positions (m).

        Returns
        -------
        ndarray of bool, shape (len(claims),)
        """
        if self._idle(len(claims), peds):
            return np.zeros(len(claims), dtype=bool)
        lo, hi = claims.aabb()
        return self._withhold(self.horizon(claims.index), lo, hi,
                              lambda k, idx: (claims.polygons_at(k, idx), np.ones(len(idx), dtype=bool)), peds)

    def withhold_reach(self, claims: ReachClaims, index, peds: np.ndarray) -> np.ndarray:
        """Which of the (new) reach-tightened claims (authority mode, :mod:`tm.reach`) must not be granted.

        The same rule as :meth:`withhold`, on the boxes ``S_k`` (slot ``k``: where the vehicle's
        footprint can be at step ``t + k``) for ``k = 1 .. min(max(l, 1) + hold_steps, K)`` with ``l``
        the claim's index (the step by which the tube has reached ``T^0``, as in paper mode) and ``K``
        the claims' slots.  Empty boxes meet nothing.

        Parameters
        ----------
        claims : ReachClaims
            The claims the requests would make (one per request).
        index : ndarray of int, shape (len(claims),)
            Their membership indices (``l``, at most the class's ``N``).
        peds : ndarray, shape (P, 2)
            Pedestrians' positions (m).

        Returns
        -------
        ndarray of bool, shape (len(claims),)
        """
        n = len(claims)
        index = np.asarray(index, dtype=np.intp).reshape(-1)
        if len(index) != n:
            raise ValueError(f"withhold_reach: {n} claims but {len(index)} indices")
        if self._idle(n, peds):
            return np.zeros(n, dtype=bool)
        K = np.minimum(self.horizon(index), claims.lo.shape[1])
        lo, hi = world_aabb(claims)
        return self._withhold(K, lo, hi, lambda k, idx: _reach_boxes(claims, k, idx), peds)

    def _idle(self, n: int, peds) -> bool:
        """Nothing to check: rule off, no claim, no pedestrian or no walking region."""
        return (not self.settings.enabled or n == 0 or len(np.asarray(peds).reshape(-1, 2)) == 0
                or len(self.regions) == 0)

    def _withhold(self, K: np.ndarray, lo: np.ndarray, hi: np.ndarray, polygons_at, peds) -> np.ndarray:
        """The rule on claims with horizons ``K (n,)``, world boxes ``lo, hi (n, 2)`` containing every
        ``S_k``, and ``polygons_at(k, idx) -> (S (c, m, 2) CCW convex, nonempty (c,))``."""
        n = len(K)
        out = np.zeros(n, dtype=bool)
        peds = np.asarray(peds, dtype=float).reshape(-1, 2)
        r_max = float(self.reach(K.max()))
        # pedestrian-region distances; only pedestrians that can reach some region matter
        P, G = len(peds), len(self.regions)
        pi, gi = np.repeat(np.arange(P), G), np.tile(np.arange(G), P)
        d_pg = point_polygon_distance(self.regions[gi], peds[pi]).reshape(P, G)
        near = d_pg.min(axis=1) <= r_max
        if not near.any():
            return out
        peds, d_pg = peds[near], d_pg[near]
        # broad phase: claims whose bounding box meets a region's box and some pedestrian's reach
        meets_g = np.all((lo[:, None] <= self.hi[None] + GEOMETRY_TOL) & (hi[:, None] >= self.lo[None] - GEOMETRY_TOL),
                         axis=2)                                                     # (n, G)
        gap = np.maximum(np.maximum(lo[:, None] - peds[None], peds[None] - hi[:, None]), 0.0)
        meets_p = np.hypot(gap[..., 0], gap[..., 1]) <= r_max                        # (n, P')
        cand = np.flatnonzero(meets_g.any(axis=1) & meets_p.any(axis=1))
        for k in range(1, int(K[cand].max()) + 1 if len(cand) else 1):
            cand = cand[(K[cand] >= k) & ~out[cand]]
            if not len(cand):
                break
            reach = float(self.reach(k))
            S, nonempty = polygons_at(k, cand)                                       # (c, m, 2)
            ci, gj = np.nonzero(meets_g[cand] & nonempty[:, None])
            hit = intersect_sat(S[ci], self.regions[gj], GEOMETRY_TOL)               # S_k meets G
            ci, gj = ci[hit], gj[hit]
            if not len(ci):
                continue
            # pedestrians that can reach one of the regions S_k meets
            can = np.zeros((len(cand), len(peds)), dtype=bool)
            np.logical_or.at(can, ci, d_pg[:, gj].T <= reach)
            a, b = np.nonzero(can & meets_p[cand])
            if not len(a):
                continue
            close = point_polygon_distance(S[a], peds[b]) <= reach                   # S_k within reach of p
            out[cand[np.unique(a[close])]] = True
        return out


def _reach_boxes(claims: ReachClaims, k: int, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World corners (c, 4, 2, CCW) of boxes ``S_k`` of claims ``idx``, and which are nonempty
    (an empty box's corners are the centre: never used)."""
    lo, hi = claims.lo[idx, k - 1], claims.hi[idx, k - 1]
    ok = np.all(lo <= hi, axis=1)
    lo, hi = np.where(ok[:, None], lo, 0.0), np.where(ok[:, None], hi, 0.0)
    C = np.stack([lo, np.column_stack([hi[:, 0], lo[:, 1]]), hi, np.column_stack([lo[:, 0], hi[:, 1]])], axis=1)
    c, s = np.cos(claims.heading[idx])[:, None], np.sin(claims.heading[idx])[:, None]
    W = np.stack([c * C[..., 0] - s * C[..., 1], s * C[..., 0] + c * C[..., 1]], axis=-1)
    return W + claims.centre[idx][:, None, :], ok


def footprint_contacts(ids, centre, heading, length, width, ped_ids, peds, radius: float) -> set:
    """Pairs ``(vehicle, pedestrian)`` whose footprint and body meet (body: disk of ``radius``).

    Parameters
    ----------
    ids : sequence of str
    centre : ndarray, shape (V, 2)
        Footprint centres (m).
    heading, length, width : ndarray, shape (V,)
    ped_ids : sequence of str
    peds : ndarray, shape (P, 2)
    radius : float
    """
    centre = np.asarray(centre, dtype=float).reshape(-1, 2)
    peds = np.asarray(peds, dtype=float).reshape(-1, 2)
    if not len(centre) or not len(peds):
        return set()
    half = 0.5 * np.hypot(length, width)
    d = np.hypot(centre[:, None, 0] - peds[None, :, 0], centre[:, None, 1] - peds[None, :, 1])
    v, p = np.nonzero(d <= half[:, None] + radius)
    if not len(v):
        return set()
    rect = rectangles(np.asarray(heading)[v], np.asarray(length)[v], np.asarray(width)[v]) + centre[v][:, None]
    touch = point_polygon_distance(rect, peds[p]) <= radius
    return {(ids[a], ped_ids[b]) for a, b in zip(v[touch].tolist(), p[touch].tolist())}
