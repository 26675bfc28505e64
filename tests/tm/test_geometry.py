"""Geometry layer: Minkowski sums, broad phase, separating axes, distances, LP.

Tolerances.  Random polygons have extents O(0.1..10) m; float round-off in
sums and projections is ~1e-14 relative, so exact identities are checked to
1e-9 (GEOMETRY_TOL).  LP answers (HiGHS) are trusted to VERIFY_TOL = 1e-7:
SAT and LP must agree whenever the LP depth is farther than 1e-6 from zero
(an intersection depth, in m).
"""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.spatial import ConvexHull

from controllers.tolerances import GEOMETRY_TOL
from tests.tm.helpers import box, random_convex
from tm.families import pad_polygons
from tm.geometry import (aabb, broad_phase, check_all_pairs_lp, convex_hull, intersect_lp, intersect_sat,
                         intersect_sat_indexed,
                         is_convex_ccw, lp_depth, min_pair_distance, minkowski_sum, polygon_distance, rectangles)

seeds = st.integers(0, 2**32 - 1)
DIRS = np.stack([np.cos(np.linspace(0, 2 * np.pi, 97)), np.sin(np.linspace(0, 2 * np.pi, 97))], axis=1)


def support(P, d):
    return (np.asarray(P) @ d.T).max(axis=0)


def test_rectangles_are_ccw_with_the_right_sides():
    R = rectangles([0.3, -2.0], [4.0, 1.0], [2.0, 0.5])
    for r, L, W, th in zip(R, [4.0, 1.0], [2.0, 0.5], [0.3, -2.0]):
        assert ConvexHull(r).volume == pytest.approx(L * W, rel=1e-12)
        assert is_convex_ccw(r)
        u = np.array([np.cos(th), np.sin(th)])
        assert (r @ u).max() == pytest.approx(L / 2, abs=1e-12)   # front bumper L/2 ahead
        assert np.allclose(r.mean(axis=0), 0, atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(seeds, st.integers(0, 3))
def test_minkowski_sum_is_hull_of_vertex_sums(seed, pad):
    rng = np.random.default_rng(seed)
    P = random_convex(rng, rng.uniform(0.1, 10)) + rng.normal(size=2)
    Q = random_convex(rng, rng.uniform(0.1, 10))
    P_pad = pad_polygons([P], len(P) + pad)                    # padding must not matter
    S = minkowski_sum(P_pad, Q[None])[0]
    hull = (P[:, None] + Q[None]).reshape(-1, 2)
    hull = hull[ConvexHull(hull).vertices]
    scale = np.abs(hull).max()
    assert np.allclose(support(S, DIRS), support(hull, DIRS), atol=1e-9 * scale)
    assert is_convex_ccw(S, 1e-9)
    assert ConvexHull(S).volume == pytest.approx(ConvexHull(hull).volume, rel=1e-9)


def test_minkowski_sum_with_a_horizontal_edge_keeps_its_position():
    """Edges of angle ~0 and ~2pi must not shift the sum (start-vertex choice)."""
    P = box(1.0, 1.0) + np.array([-1e-17, 0.0])
    R = rectangles([1e-17, -1e-17, np.pi], [4.0] * 3, [2.0] * 3)
    S = minkowski_sum(np.broadcast_to(P, (3, 4, 2)), R)
    for s in S:
        assert np.allclose(aabb(s)[0], [-3, -2], atol=1e-12) and np.allclose(aabb(s)[1], [3, 2], atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(seeds)
def test_sat_agrees_with_lp_on_random_convex_polygons(seed):
    rng = np.random.default_rng(seed)
    n = 12
    P = [random_convex(rng, rng.uniform(0.2, 3)) + rng.uniform(-3, 3, size=2) for _ in range(n)]
    Q = [random_convex(rng, rng.uniform(0.2, 3)) + rng.uniform(-3, 3, size=2) for _ in range(n)]
    sat = intersect_sat(pad_polygons(P, 9), pad_polygons(Q, 9))
    for s, p, q in zip(sat, P, Q):
        depth = lp_depth(p, q)
        if abs(depth) > 1e-6:
            assert s == (depth > 0)


@settings(max_examples=40, deadline=None)
@given(seeds)
def test_sat_is_not_fooled_by_round_off_edges(seed):
    """Near-duplicate vertices (1e-13 m apart, any direction) make edges whose normals are
    arbitrary; the one-sided test must stay sound (it uses true supports, not edge offsets).
    Also the indexed variant must equal the paired one."""
    rng = np.random.default_rng(seed)
    P, Q = [], []
    for _ in range(10):
        for out in (P, Q):
            X = random_convex(rng, rng.uniform(0.2, 3)) + rng.uniform(-2, 2, size=2)
            t = int(rng.integers(len(X)))
            X = np.insert(X, t + 1, X[t] + rng.normal(size=2) * 1e-13, axis=0)
            out.append(X)
    Pp, Qp = pad_polygons(P, 10), pad_polygons(Q, 10)
    sat = intersect_sat(Pp, Qp)
    for s, p, q in zip(sat, P, Q):
        depth = lp_depth(p, q)
        if abs(depth) > 1e-6:
            assert s == (depth > 0)
    both = np.concatenate([Pp, Qp])
    assert np.array_equal(intersect_sat_indexed(both, np.arange(10), np.arange(10, 20)), sat)


def test_touching_counts_as_conflict_and_a_gap_does_not():
    a = box(1.0, 1.0)
    for gap, expected in [(0.0, True), (0.5 * GEOMETRY_TOL, True), (1e-6, False)]:
        b = box(1.0, 1.0) + [2.0 + gap, 0.5]
        assert intersect_sat(a[None], b[None])[0] == expected
        assert intersect_lp(a, b) == expected
    corner = box(1.0, 1.0) + [2.0, 2.0]                       # corner to corner
    assert intersect_sat(a[None], corner[None])[0] and intersect_lp(a, corner)


@settings(max_examples=40, deadline=None)
@given(seeds)
def test_polygon_distance_matches_the_separating_direction_dual(seed):
    """For convex sets, dist = max over unit u of (min_Q u·q - max_P u·p); for polygons the
    maximiser is an edge normal or the direction between two vertices: enumerate them all."""
    rng = np.random.default_rng(seed)
    P = random_convex(rng, 1.0)
    Q = random_convex(rng, 1.0) + rng.uniform(-4, 4, size=2)
    d = polygon_distance(P[None], Q[None])[0]
    diffs = (Q[None, :, :] - P[:, None, :]).reshape(-1, 2)
    normals = np.vstack([np.roll(X, -1, 0) - X for X in (P, Q)]) @ np.array([[0, -1], [1, 0]])
    U = np.vstack([diffs, normals, -normals])
    U = U[np.linalg.norm(U, axis=1) > 0]
    U /= np.linalg.norm(U, axis=1, keepdims=True)
    dual = ((Q @ U.T).min(axis=0) - (P @ U.T).max(axis=0)).max()
    assert d == pytest.approx(max(dual, 0.0), abs=1e-9)
    assert (d == 0) == intersect_sat(P[None], Q[None], 0.0)[0]


def test_polygon_distance_hand_computed():
    a = box(1.0, 1.0)
    assert polygon_distance(a[None], (box(1.0, 1.0) + [5.0, 0.0])[None])[0] == pytest.approx(3.0)
    assert polygon_distance(a[None], (box(1.0, 1.0) + [5.0, 6.0])[None])[0] == pytest.approx(5.0)  # 3-4-5
    assert polygon_distance(a[None], (box(1.0, 1.0) + [1.0, 1.0])[None])[0] == 0.0


@settings(max_examples=50, deadline=None)
@given(seeds, st.integers(2, 120), st.booleans())
def test_broad_phase_equals_brute_force_box_overlaps(seed, n, integer):
    rng = np.random.default_rng(seed)
    lo = rng.uniform(0, 30, size=(n, 2))
    ext = rng.pareto(1.5, size=(n, 2)) + 0.1                   # heavy tail: a few huge boxes
    if integer:                                               # many exactly touching boxes
        lo, ext = np.round(lo), np.ceil(ext)
    hi = lo + ext
    mask = rng.random(n) < 0.3
    for m in (None, mask):
        i, j = broad_phase(lo, hi, GEOMETRY_TOL, mask=m)
        got = set(zip(i.tolist(), j.tolist()))
        assert len(got) == len(i)                              # each pair once
        ov = np.all((lo[:, None] <= hi[None] + GEOMETRY_TOL) & (lo[None] <= hi[:, None] + GEOMETRY_TOL), axis=2)
        want = {(a, b) for a in range(n) for b in range(a + 1, n) if ov[a, b] and (m is None or m[a] or m[b])}
        assert got == want


@settings(max_examples=30, deadline=None)
@given(seeds, st.integers(2, 80), st.sampled_from([0.0, 30.0, 1e4, 3e8]))
def test_broad_phase_on_dense_and_sparse_grids_equals_brute_force(seed, n, span):
    """Boxes in one cluster (more pairs than the kernel's first guess, 4 n: its key array grows) and
    in clusters over a span of 30 m (a dense grid: entries ordered by a counting sort), 10 km
    (far more cells than entries: a sort of packed keys) and 3e8 m (keys too large to pack: argsort)."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform(0, span, size=(max(1, n // 8), 2))
    lo = centres[rng.integers(len(centres), size=n)] + rng.uniform(0, 3, size=(n, 2))
    hi = lo + rng.uniform(0.1, 2.0, size=(n, 2))
    mask = rng.random(n) < 0.4
    for m in (None, mask):
        i, j = broad_phase(lo, hi, GEOMETRY_TOL, mask=m)
        got = set(zip(i.tolist(), j.tolist()))
        assert len(got) == len(i) and np.all(np.diff(i * n + j) > 0)   # each pair once, sorted
        ov = np.all((lo[:, None] <= hi[None] + GEOMETRY_TOL) & (lo[None] <= hi[:, None] + GEOMETRY_TOL), axis=2)
        want = {(a, b) for a in range(n) for b in range(a + 1, n) if ov[a, b] and (m is None or m[a] or m[b])}
        assert got == want


@settings(max_examples=30, deadline=None)
@given(seeds, st.integers(2, 40))
def test_min_pair_distance_is_the_brute_force_minimum(seed, n):
    rng = np.random.default_rng(seed)
    polys = rectangles(rng.uniform(-np.pi, np.pi, n), rng.uniform(1, 5, n), rng.uniform(0.5, 2, n)) \
        + rng.uniform(0, rng.uniform(5, 200), size=(n, 1, 2))
    d, i, j = min_pair_distance(polys)
    a, b = np.triu_indices(n, 1)
    brute = polygon_distance(polys[a], polys[b])
    assert d == pytest.approx(brute.min(), abs=1e-12)
    assert polygon_distance(polys[[i]], polys[[j]])[0] == pytest.approx(d, abs=1e-12)


def test_min_pair_distance_with_fewer_than_two():
    assert min_pair_distance(np.zeros((1, 4, 2)))[0] == np.inf


@settings(max_examples=40, deadline=None)
@given(seeds)
def test_convex_hull_matches_scipy(seed):
    rng = np.random.default_rng(seed)
    pts = rng.normal(size=(int(rng.integers(3, 30)), 2))
    H = convex_hull(pts)
    ref = pts[ConvexHull(pts).vertices]
    assert is_convex_ccw(H)
    assert np.allclose(support(H, DIRS), support(ref, DIRS), atol=1e-12)
    assert len(H) == len(ref)


def test_convexity_check_rejects_clockwise_and_reflex():
    P = box(1.0, 1.0)
    assert is_convex_ccw(P)
    assert not is_convex_ccw(P[::-1])
    assert not is_convex_ccw(np.array([[0, 0], [2, 0], [1, 0.2], [2, 2], [0, 2]], dtype=float))
    star = np.array([[np.cos(a), np.sin(a)] for a in np.arange(5) * 4 * np.pi / 5])  # winds twice
    assert not is_convex_ccw(star)


def test_check_all_pairs_lp_finds_exactly_the_overlaps():
    polys = [box(1.0, 1.0) + [3.0 * t, 0.0] for t in range(4)] + [box(2.0, 0.5) + [4.5, 0.0]]
    i, j = check_all_pairs_lp(polys)
    assert set(zip(i.tolist(), j.tolist())) == {(1, 4), (2, 4)}
