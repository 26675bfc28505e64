"""Vectorised 2-D convex-polygon geometry for the traffic manager.

Polygons are numpy arrays of vertices in counter-clockwise (CCW) order.  A
batch of ``n`` polygons is an ``(n, k, 2)`` array; polygons with fewer
vertices are padded by repeating their last vertex, which adds zero-length
edges that every function here ignores.

Conventions
-----------
* Two polygons *conflict* when their Euclidean distance is at most ``tol``
  (touching counts).  :func:`intersect_sat` decides this on the separating
  axes (outward edge normals): a gap larger than ``tol`` along some normal
  proves a distance larger than ``tol``.  When the closest features are two
  vertices the largest normal gap is ``d cos(phi)`` (``phi`` the angle
  between the closest-point direction and the nearest normal), so the test
  is conservative: it may call a pair at a distance somewhat above ``tol`` a
  conflict, never the reverse.  Disjointness itself (``tol = 0``) is exact.
* Headings are in radians, counter-clockwise from +x.

Functions
---------
rectangles, minkowski_sum, aabb, edge_normals, is_convex_ccw, convex_hull,
broad_phase, support_normals, intersect_sat, intersect_sat_indexed, polygon_distance, min_pair_distance, halfspaces,
lp_depth, intersect_lp, check_all_pairs_lp.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linprog

from controllers.tolerances import GEOMETRY_TOL
from tm.kernels import grid_pairs

__all__ = [
    "rectangles", "minkowski_sum", "aabb", "edge_normals", "is_convex_ccw", "convex_hull",
    "broad_phase", "support_normals", "intersect_sat", "intersect_sat_indexed", "polygon_distance",
    "min_pair_distance", "halfspaces", "lp_depth", "intersect_lp", "check_all_pairs_lp",
]

_EMPTY_PAIRS = (np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp))
#: Work arrays of the pairwise tests are chunked to about this many floats.
_CHUNK_FLOATS = 1 << 22


# ----------------------------------------------------------------------------- construction
def rectangles(heading, length, width) -> np.ndarray:
    """Oriented rectangles centred at the origin.

    Parameters
    ----------
    heading, length, width : array_like, shape (n,)
        Heading (rad, CCW from +x), extent along the heading and across it.

    Returns
    -------
    ndarray, shape (n, 4, 2)
        CCW vertices: front-right, front-left, rear-left, rear-right.
    """
    th = np.atleast_1d(np.asarray(heading, dtype=float))
    a = 0.5 * np.broadcast_to(np.asarray(length, dtype=float), th.shape)
    b = 0.5 * np.broadcast_to(np.asarray(width, dtype=float), th.shape)
    c, s = np.cos(th), np.sin(th)
    fx, fy = a * c, a * s          # half-length along the heading
    lx, ly = -b * s, b * c         # half-width to the left
    out = np.empty(th.shape + (4, 2))
    out[..., 0, 0], out[..., 0, 1] = fx - lx, fy - ly
    out[..., 1, 0], out[..., 1, 1] = fx + lx, fy + ly
    out[..., 2, 0], out[..., 2, 1] = -fx + lx, -fy + ly
    out[..., 3, 0], out[..., 3, 1] = -fx - lx, -fy - ly
    return out


def _edges(P: np.ndarray) -> np.ndarray:
    """Edge vectors ``P[t+1] - P[t]`` (cyclic); slicing, as np.roll is slow on small arrays."""
    return np.concatenate([P[..., 1:, :], P[..., :1, :]], axis=-2) - P


def minkowski_sum(P, Q) -> np.ndarray:
    """Exact Minkowski sums of convex polygons, batched.

    The edge vectors of both polygons are merged in order of their angle
    (one ``argsort`` over the batch); the sum starts at the sum of the tails
    of each polygon's smallest-angle edge.

    Parameters
    ----------
    P : array_like, shape (n, k, 2) or (k, 2)
    Q : array_like, shape (n, m, 2) or (m, 2)
        CCW convex polygons (padding by a repeated last vertex allowed).
        Leading dimensions broadcast.

    Returns
    -------
    ndarray, shape (n, k + m, 2)
        CCW vertices of ``P ⊕ Q`` (may contain repeated or collinear vertices).
    """
    P = np.asarray(P, dtype=float)
    Q = np.asarray(Q, dtype=float)
    lead = np.broadcast_shapes(P.shape[:-2], Q.shape[:-2])
    k, m = P.shape[-2], Q.shape[-2]
    P = np.broadcast_to(P, lead + P.shape[-2:]).reshape(-1, k, 2)
    Q = np.broadcast_to(Q, lead + Q.shape[-2:]).reshape(-1, m, 2)
    E = np.concatenate([_edges(P), _edges(Q)], axis=1)
    ang = np.arctan2(E[..., 1], E[..., 0])
    ang += (ang < 0) * (2 * np.pi)
    ang[(E[..., 0] == 0) & (E[..., 1] == 0)] = np.inf        # zero edges: last, no effect
    rows = np.arange(len(E))
    start = P[rows, np.argmin(ang[:, :k], axis=1)] + Q[rows, np.argmin(ang[:, k:], axis=1)]
    E = E[rows[:, None], np.argsort(ang, axis=1)]
    out = np.cumsum(E, axis=1)
    out -= E                                                 # exclusive sums: vertex t = start + e_0..e_{t-1}
    out += start[:, None, :]
    return out.reshape(lead + (k + m, 2))


def aabb(P) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned bounding boxes ``(lo, hi)``, each of shape ``P.shape[:-2] + (2,)``."""
    P = np.asarray(P, dtype=float)
    return P.min(axis=-2), P.max(axis=-2)


def edge_normals(P) -> np.ndarray:
    """Unit outward normals of the edges of CCW polygons (zero for zero-length edges)."""
    E = _edges(np.asarray(P, dtype=float))
    norm = np.hypot(E[..., 0], E[..., 1])
    inv = np.divide(1.0, norm, out=np.zeros_like(norm), where=norm > 0)
    return np.stack([E[..., 1] * inv, -E[..., 0] * inv], axis=-1)


def is_convex_ccw(P, tol: float = GEOMETRY_TOL) -> bool:
    """Whether a single polygon ``(k, 2)`` is convex, counter-clockwise and winds once.

    Edges shorter than ``tol`` (repeated vertices, round-off) are ignored;
    points and segments (zero area) are accepted.
    """
    P = np.asarray(P, dtype=float)
    E = _edges(P)
    E = E[np.linalg.norm(E, axis=1) > tol]
    if len(E) < 3:
        return True
    E1 = np.roll(E, -1, axis=0)
    cross = E[:, 0] * E1[:, 1] - E[:, 1] * E1[:, 0]
    scale = np.linalg.norm(E, axis=1) * np.linalg.norm(E1, axis=1)
    if np.any(cross < -tol * scale):
        return False
    turning = np.arctan2(cross, np.einsum("ij,ij->i", E, E1)).sum()
    return bool(abs(turning - 2 * np.pi) < 1e-6 or abs(turning) < 1e-6)


def convex_hull(points) -> np.ndarray:
    """Convex hull of 2-D points, CCW, without collinear vertices (monotone chain).

    Degenerate inputs give a segment (2 vertices) or a point (1 vertex).
    """
    pts = np.unique(np.asarray(points, dtype=float).reshape(-1, 2), axis=0)   # sorted by x, then y
    if len(pts) <= 2:
        return pts

    def half(seq):
        out: list = []
        for p in seq:
            while len(out) >= 2:
                (ax, ay), (bx, by) = out[-2], out[-1]
                if (bx - ax) * (p[1] - ay) - (by - ay) * (p[0] - ax) <= 0:
                    out.pop()
                else:
                    break
            out.append(p)
        return out

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


# ----------------------------------------------------------------------------- broad phase
def broad_phase(lo, hi, tol: float = GEOMETRY_TOL, mask=None):
    """Pairs of overlapping axis-aligned boxes, by a uniform grid (:func:`tm.kernels.grid_pairs`).

    Every box is entered in the grid cells it covers; pairs are formed within
    each cell and kept only in the cell that holds the corner
    ``max(lo_i, lo_j)`` of their intersection, so each overlapping pair is
    reported once.  Cost is ``O(n log n)`` plus the number of pairs sharing a
    cell.  Cell size: the median box extent, doubled while the boxes would
    cover more than ``8 n`` cells in total.

    Parameters
    ----------
    lo, hi : array_like, shape (n, 2)
        Box corners (``lo <= hi``).
    tol : float
        Boxes closer than ``tol`` count as overlapping.
    mask : array_like of bool, shape (n,), optional
        Keep only pairs with at least one box in ``mask``.

    Returns
    -------
    i, j : ndarray of int, shape (p,)
        Indices with ``i < j``, sorted by ``(i, j)``.
    """
    lo = np.asarray(lo, dtype=float)
    hi = np.asarray(hi, dtype=float)
    n = len(lo)
    if n < 2:
        return _EMPTY_PAIRS
    if mask is not None:
        mask = np.ascontiguousarray(mask, dtype=bool)
        if not mask.any():
            return _EMPTY_PAIRS
    # contiguous 1-D coordinates, grown by tol / 2 each side
    x0, y0 = lo[:, 0] - 0.5 * tol, lo[:, 1] - 0.5 * tol
    x1, y1 = hi[:, 0] + 0.5 * tol, hi[:, 1] + 0.5 * tol
    packed = grid_pairs(x0, x1, y0, y1, mask if mask is not None else np.zeros(0, dtype=bool), mask is not None)
    return packed // n, packed % n


# ----------------------------------------------------------------------------- narrow phase
def _chunks(n: int, per_item: int):
    step = max(1, _CHUNK_FLOATS // max(per_item, 1))
    for s in range(0, n, step):
        yield slice(s, min(n, s + step))


def support_normals(P) -> tuple[np.ndarray, np.ndarray]:
    """Unit edge normals ``N`` of polygons ``(n, k, 2)`` and their supports ``h = max_v N·v``.

    ``{x : N_e · x <= h_e}`` is a supporting half-plane of the polygon for
    every row, even for a round-off edge whose direction is arbitrary (zero
    normals give the trivial row ``0 <= 0``).
    """
    P = np.asarray(P, dtype=float)
    N = edge_normals(P)
    return N, (N @ P.swapaxes(-1, -2)).max(axis=-1)


def _separated(NP, hP, P, NQ, hQ, Q, tol: float) -> np.ndarray:
    """Some half-plane of one polygon has the other beyond it by more than ``tol``."""
    g1 = (NP @ Q.swapaxes(-1, -2)).min(axis=-1) - hP            # (c, k): gap of Q beyond P's edges
    g2 = (NQ @ P.swapaxes(-1, -2)).min(axis=-1) - hQ
    return (g1 > tol).any(axis=-1) | (g2 > tol).any(axis=-1)


def intersect_sat(P, Q, tol: float = GEOMETRY_TOL) -> np.ndarray:
    """Separating-axis test of paired convex polygons.

    The candidate axes are the outward edge normals of both polygons (for
    convex polygons these suffice: they are the edge normals of
    ``P ⊕ (-Q)``).  Pair ``t`` is separated when, along a normal ``n`` of
    one polygon, the other lies beyond that polygon's support ``h(n)`` by
    more than ``tol``.

    Parameters
    ----------
    P : array_like, shape (n, k, 2)
    Q : array_like, shape (n, m, 2)
        CCW convex polygons; pair ``t`` is ``(P[t], Q[t])``.
    tol : float
        Touching (within ``tol``) counts as conflict.

    Returns
    -------
    ndarray of bool, shape (n,)
        True where the pair conflicts.
    """
    P = np.asarray(P, dtype=float)
    Q = np.asarray(Q, dtype=float)
    n, k, m = P.shape[0], P.shape[1], Q.shape[1]
    out = np.empty(n, dtype=bool)
    for sl in _chunks(n, 4 * k * m):
        p, q = P[sl], Q[sl]
        out[sl] = ~_separated(*support_normals(p), p, *support_normals(q), q, tol)
    return out


def intersect_sat_indexed(polys, i, j, tol: float = GEOMETRY_TOL) -> np.ndarray:
    """:func:`intersect_sat` of the pairs ``(polys[i[t]], polys[j[t]])``.

    Normals and supports are computed once per polygon, not once per pair.
    """
    polys = np.asarray(polys, dtype=float)
    i = np.asarray(i, dtype=np.intp)
    j = np.asarray(j, dtype=np.intp)
    N, h = support_normals(polys)
    k = polys.shape[1]
    out = np.empty(len(i), dtype=bool)
    for sl in _chunks(len(i), 4 * k * k):
        a, b = i[sl], j[sl]
        out[sl] = ~_separated(N[a], h[a], polys[a], N[b], h[b], polys[b], tol)
    return out


def _point_segment_distance(X, A, B) -> np.ndarray:
    """Distances of points ``X (n, k, 2)`` to segments ``A->B (n, m, 2)``: ``(n, k, m)``."""
    D = B - A                                                    # (n, m, 2)
    dd = np.einsum("nmd,nmd->nm", D, D)
    R = X[:, :, None, :] - A[:, None, :, :]                      # (n, k, m, 2)
    t = np.einsum("nkmd,nmd->nkm", R, D)
    t = np.clip(np.divide(t, dd[:, None, :], out=np.zeros_like(t), where=dd[:, None, :] > 0), 0.0, 1.0)
    return np.linalg.norm(R - t[..., None] * D[:, None, :, :], axis=-1)


def polygon_distance(P, Q) -> np.ndarray:
    """Euclidean distance between paired convex polygons (0 where they intersect).

    For disjoint convex polygons the distance is attained between a vertex of
    one and an edge of the other, so it is the smallest vertex-to-edge
    distance both ways.  Cost ``O(n k m)``: use it on near pairs only.

    Parameters
    ----------
    P : array_like, shape (n, k, 2)
    Q : array_like, shape (n, m, 2)

    Returns
    -------
    ndarray, shape (n,)
    """
    P = np.asarray(P, dtype=float)
    Q = np.asarray(Q, dtype=float)
    n, k, m = P.shape[0], P.shape[1], Q.shape[1]
    out = np.empty(n)
    for sl in _chunks(n, 6 * k * m):
        p, q = P[sl], Q[sl]
        d = np.minimum(_point_segment_distance(p, q, q + _edges(q)).min(axis=(1, 2)),
                       _point_segment_distance(q, p, p + _edges(p)).min(axis=(1, 2)))
        d[intersect_sat(p, q, 0.0)] = 0.0
        out[sl] = d
    return out


def min_pair_distance(P) -> tuple[float, int, int]:
    """Smallest distance between any two of the convex polygons ``P (n, k, 2)``.

    Boxes inflated by ``r / 2`` give every pair closer than ``r`` as a broad-
    phase candidate; ``r`` doubles until the nearest candidate is closer
    than ``r``, which proves it the global minimum.  Among the candidates,
    exact distances are computed only where the boxes' gap (a lower bound)
    does not exceed the exact distance of the pair with the smallest gap.

    Returns
    -------
    distance : float
        ``inf`` when ``n < 2``; 0 when two polygons intersect.
    i, j : int
        The pair (``-1, -1`` when ``n < 2``).
    """
    P = np.asarray(P, dtype=float)
    n = len(P)
    if n < 2:
        return np.inf, -1, -1
    lo, hi = aabb(P)
    r = max(float(np.median((hi - lo).max(axis=1))), 1e-3)
    span = float((hi.max(axis=0) - lo.min(axis=0)).max())
    while True:
        i, j = broad_phase(lo - r / 2, hi + r / 2, tol=0.0)
        if len(i):
            gap = np.maximum(np.maximum(lo[i] - hi[j], lo[j] - hi[i]), 0.0)
            bound = np.hypot(gap[:, 0], gap[:, 1])
            t = int(np.argmin(bound))
            # the box gap is a lower bound of the distance, equal to it for boxes apart along one
            # axis, where round-off can put it 1 ulp above: max(.., bound[t]) always keeps pair t
            ub = polygon_distance(P[i[[t]]], P[j[[t]]])[0]
            near = np.flatnonzero(bound <= max(ub, bound[t]))
            d = polygon_distance(P[i[near]], P[j[near]])
            t = int(np.argmin(d))
            if d[t] <= r or r > 2 * span:
                return float(d[t]), int(i[near[t]]), int(j[near[t]])
        r *= 2.0


# ----------------------------------------------------------------------------- LP (the paper's method)
def halfspaces(P, tol: float = GEOMETRY_TOL) -> tuple[np.ndarray, np.ndarray]:
    """H-representation ``A x <= b`` (unit rows) of one CCW convex polygon ``(k, 2)``.

    The rows are the normals of the edges longer than ``tol`` (a shorter
    edge's direction is round-off) plus the four bounding-box rows
    (redundant for full-dimensional polygons; they close segments and points).
    """
    P = np.asarray(P, dtype=float)
    N = edge_normals(P)
    keep = np.linalg.norm(_edges(P), axis=1) > tol
    A = np.vstack([N[keep], np.eye(2), -np.eye(2)])
    lo, hi = P.min(axis=0), P.max(axis=0)
    b = np.concatenate([np.einsum("ij,ij->i", N[keep], P[keep]), hi, -lo])
    return A, b


def lp_depth(P, Q) -> float:
    """``max s`` such that some ``x`` has ``A_P x + s <= b_P`` and ``A_Q x + s <= b_Q``.

    Non-negative iff the polygons intersect (one ``scipy.optimize.linprog``
    call, HiGHS).  Rows are unit normals, so ``s`` is in metres.
    """
    A1, b1 = halfspaces(P)
    A2, b2 = halfspaces(Q)
    A = np.vstack([A1, A2])
    A = np.hstack([A, np.ones((len(A), 1))])
    res = linprog(c=[0.0, 0.0, -1.0], A_ub=A, b_ub=np.concatenate([b1, b2]),
                  bounds=[(None, None)] * 3, method="highs")
    if res.status != 0:
        raise RuntimeError(f"lp_depth: linprog failed: {res.message}")
    return float(-res.fun)


def intersect_lp(P, Q, tol: float = GEOMETRY_TOL) -> bool:
    """LP intersection test of two convex polygons: ``lp_depth(P, Q) >= -tol``."""
    return lp_depth(P, Q) >= -tol


def check_all_pairs_lp(polygons, tol: float = GEOMETRY_TOL) -> tuple[np.ndarray, np.ndarray]:
    """All-pairs LP intersection test: the paper's ``S (S - 1) / 2`` LPs.

    Independent of the broad phase and of the separating-axis test; for
    cross-checks in tests and as the benchmark baseline.

    Parameters
    ----------
    polygons : sequence of array_like (k_i, 2) or ndarray (n, k, 2)

    Returns
    -------
    i, j : ndarray of int
        Conflicting pairs, ``i < j``.
    """
    polys = list(polygons)
    out = [(a, b) for a in range(len(polys)) for b in range(a + 1, len(polys))
           if intersect_lp(polys[a], polys[b], tol)]
    if not out:
        return _EMPTY_PAIRS
    arr = np.array(out, dtype=np.intp)
    return arr[:, 0], arr[:, 1]
