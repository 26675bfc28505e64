"""Random families and fleets for the TM tests, and independent reference checks.

The reference checks avoid the code under test: claim polygons are built as
scipy ConvexHulls of vertex sums (not :func:`tm.geometry.minkowski_sum`) and
compared by the LP of :func:`tm.geometry.lp_depth` (not the broad phase nor
the separating axes).  LP answers are trusted to ``VERIFY_TOL`` (1e-7 m),
the order of HiGHS's default primal feasibility tolerance.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull

from controllers.tolerances import VERIFY_TOL
from tm.claims import Claims
from tm.families import pad_polygons
from tm.geometry import convex_hull, intersect_sat, lp_depth
from tm.manager import FleetState


def box(a: float, b: float, c: float | None = None, d: float | None = None) -> np.ndarray:
    """CCW box ``[-a, b] x [-c, d]`` (symmetric ``[-a, a] x [-b, b]`` with two arguments)."""
    if c is None:
        a, b, c, d = a, a, b, b
    return np.array([[-a, -c], [b, -c], [b, d], [-a, d]], dtype=float)


def random_convex(rng: np.random.Generator, scale: float = 1.0, k: int | None = None) -> np.ndarray:
    """A random full-dimensional CCW convex polygon around the origin."""
    while True:
        pts = rng.normal(size=(k or int(rng.integers(3, 9)), 2)) * scale * rng.uniform(0.3, 1.0, size=2)
        P = convex_hull(pts)
        if len(P) >= 3 and ConvexHull(P).volume > 1e-3 * scale**2:
            return P - P.mean(axis=0)


def nested_family(rng: np.random.Generator, n_levels: int, kind: str = "box") -> list[np.ndarray]:
    """``P^0 ⊆ P^1 ⊆ ...``: boxes grown by random non-negative margins, or polygons grown
    by scaling about an interior point (the origin) plus a random box margin."""
    if kind == "box":
        m = rng.uniform(0.1, 1.0, size=4)
        fam = [box(*m)]
        for _ in range(n_levels - 1):
            m = m + rng.uniform(0.0, 0.8, size=4) * (rng.random(4) < 0.8)
            fam.append(box(*m))
        return fam
    P = random_convex(rng, 0.6)
    fam = [P]
    for _ in range(n_levels - 1):
        grow = box(*rng.uniform(0.0, 0.4, size=4))
        P = convex_hull((P[:, None, :] * rng.uniform(1.0, 1.4) + grow[None, :, :]).reshape(-1, 2))
        fam.append(P)
    return fam


def ref_rect(heading: float, length: float, width: float) -> np.ndarray:
    u = np.array([np.cos(heading), np.sin(heading)])
    v = np.array([-u[1], u[0]])
    return np.array([s * length / 2 * u + t * width / 2 * v for s in (-1, 1) for t in (-1, 1)])


def ref_claim_polygon(fam: list[np.ndarray], centre, level: int, heading, length, width) -> np.ndarray:
    """``centre + P^level ⊕ rect``: hull of all vertex sums (scipy)."""
    pts = (np.asarray(fam[level])[:, None, :] + ref_rect(heading, length, width)[None, :, :]).reshape(-1, 2)
    return pts[ConvexHull(pts).vertices] + np.asarray(centre)


def ref_claim_sequence(families: dict, keys, claims: Claims, v: int, k: int) -> np.ndarray:
    """Reference ``k``-th timed polygon of claim ``v`` (k = 1 with nested families is the union claim)."""
    fam = families[keys[v]] if isinstance(keys, (list, tuple, np.ndarray)) else families[keys]
    level = max(int(claims.index[v]) - k, 0)
    return ref_claim_polygon(fam, claims.centre[v], level, claims.heading[v], claims.length[v], claims.width[v])


def lp_overlapping_pairs(families: dict, keys, claims: Claims, check: str) -> list[tuple[int, int]]:
    """Pairs of claims whose reference polygons intersect by more than VERIFY_TOL (LP).

    ``union``: the polygons at k = 1 (nested families only: ``H^{l-1} = P^{l-1}``).
    ``timed``: every k = 1 .. max(l_i, l_j, 1).
    """
    n = len(claims)
    out = []
    for i in range(n):
        for j in range(i + 1, n):
            kmax = 1 if check == "union" else max(int(claims.index[i]), int(claims.index[j]), 1)
            for k in range(1, kmax + 1):
                P = ref_claim_sequence(families, keys, claims, i, k)
                Q = ref_claim_sequence(families, keys, claims, j, k)
                if lp_depth(P, Q) > VERIFY_TOL:
                    out.append((i, j))
                    break
    return out


def random_fleet(rng: np.random.Generator, families: dict, n: int, spread: float,
                 p_request: float = 0.6, hop: float = 2.5) -> FleetState:
    """``n`` vehicles with pairwise disjoint current claims, random footprints, and random
    requests within ``hop`` of the centre.

    Rejection sampling keeps a vehicle whose reference claim polygon is separated by more
    than 1e-6 m from those kept (separating axes, for speed; the invariant tests re-check
    every decision, inputs included, by LP, so a wrong input would fail them loudly)."""
    keys_all = list(families)
    kept: list[tuple] = []
    polys: list[np.ndarray] = []
    tries = 0
    while len(kept) < n and tries < 50 * n:
        tries += 1
        key = keys_all[int(rng.integers(len(keys_all)))]
        N = len(families[key]) - 1
        c = rng.uniform(-spread, spread, size=2)
        l = int(rng.integers(0, N + 1))
        th = float(rng.uniform(-np.pi, np.pi))
        L, W = float(rng.uniform(0.5, 3.0)), float(rng.uniform(0.3, 1.5))
        P = ref_claim_polygon(families[key], c, max(l - 1, 0), th, L, W)
        if not polys or not intersect_sat(pad_polygons([P] * len(polys), 16), pad_polygons(polys, 16), 1e-6).any():
            kept.append((key, c, l, th, L, W))
            polys.append(P)
    V = len(kept)
    keys = [k[0] for k in kept]
    req = rng.random(V) < p_request
    N = np.array([len(families[k]) - 1 for k in keys], dtype=int)
    return FleetState(
        ids=[f"v{t}" for t in range(V)], family=keys,
        centre=np.array([k[1] for k in kept]).reshape(V, 2), index=np.array([k[2] for k in kept], dtype=int),
        heading=np.array([k[3] for k in kept]), length=np.array([k[4] for k in kept]),
        width=np.array([k[5] for k in kept]), requesting=req,
        req_centre=np.array([k[1] for k in kept]).reshape(V, 2) + rng.uniform(-hop, hop, size=(V, 2)),
        req_index=(rng.random(V) * (N + 1)).astype(int), req_heading=rng.uniform(-np.pi, np.pi, size=V))


def disturb(m, x, u, c, policy, rng, sign):
    """A disturbance in D for the reach-claim property tests: ``random`` (uniform in D),
    ``adversarial`` (the vertex of D pushing the nominal successor away from target ``c``), or
    else ``sign`` times the upper vertex of D at every step ("push")."""
    lo, hi = m.d_bounds
    if policy == "random":
        return lo + (hi - lo) * rng.random(m.n)
    if policy == "adversarial":
        err = m.A @ x + m.B @ u - np.concatenate([c, np.zeros(m.n - 2)])
        return np.where(err >= 0, hi, lo)
    return sign * hi


def lane_fleet(lane, lcs, classes, gaps, k0: int = 40) -> int:
    """Place one vehicle per class on ``lane`` (a :class:`tm.lane.Lane`) at rest, from waypoint
    ``k0`` on, ``gaps`` waypoints apart; returns the waypoint after the last one placed."""
    k = k0
    for c, g in zip(classes, gaps):
        lane.place(lcs[c], k)
        k += g
    return k
