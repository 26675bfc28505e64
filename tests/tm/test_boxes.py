"""Box joins of the junction layer (tm.boxes) against testing every pair densely.

Exact comparisons: every join tests the same ``<=`` / ``>=`` inequalities on the same floats
as the dense reference (touching counts as meeting in both); coordinates are rounded so that
shared edges and corners occur.
"""

import numpy as np
from hypothesis import example, given, settings, strategies as st

from tm.boxes import BoxGrid, GuardIndex, box_pairs_meet, boxes_meet, corridor_hits, meets_any


def _dense(q_lo, q_hi, b_lo, b_hi):
    return np.all((q_lo[:, None, :] <= b_hi[None]) & (q_hi[:, None, :] >= b_lo[None]), axis=2)


def _pairs(m):
    return sorted(zip(*map(list, np.nonzero(m))))


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n_zones=st.integers(1, 30), n_boxes=st.integers(0, 60))
@example(seed=186409337, n_zones=1, n_boxes=1)  # hi - (hi - lo) rounded above lo: missed before
def test_guard_pairs_are_exactly_the_boxes_that_meet_guards(seed, n_zones, n_boxes):
    """The sorted-sweep guard lookup returns the same (box, guard) pairs as testing every box
    against every guard, sorted by box."""
    rng = np.random.default_rng(seed)
    g_lo = rng.uniform(0, 200, (n_zones, 2)) - 7.3   # guards: zones enlarged by a radius
    g_hi = g_lo + rng.uniform(1, 40, (n_zones, 2)) + 2 * 7.3
    guards = GuardIndex(g_lo, g_hi)
    lo = rng.uniform(-20, 220, (n_boxes, 2))
    hi = lo + rng.uniform(0, 30, (n_boxes, 2))
    if n_boxes:  # a box exactly touching a guard's edge
        lo[0, 0] = g_hi[0, 0]
        hi[0, 0] = lo[0, 0] + 5.0
        lo[0, 1], hi[0, 1] = g_lo[0, 1], g_hi[0, 1]
    i, z = guards.pairs(lo, hi)
    assert sorted(zip(i.tolist(), z.tolist())) == _pairs(_dense(lo, hi, g_lo, g_hi))
    assert list(i) == sorted(i)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n_q=st.integers(0, 40), n_b=st.integers(0, 80),
       scale=st.sampled_from([1.0, 10.0, 100.0]))
def test_box_pairs_are_exactly_the_meeting_pairs_once(seed, n_q, n_b, scale):
    """The grid join returns every (query, box) pair that meets, touching included, exactly
    once: as testing every pair."""
    rng = np.random.default_rng(seed)
    q_lo = np.round(rng.uniform(-2, 2, (n_q, 2)) * scale)  # rounded: shared edges and corners
    q_hi = q_lo + np.round(rng.uniform(0, 1, (n_q, 2)) * scale)
    b_lo = np.round(rng.uniform(-2, 2, (n_b, 2)) * scale)
    b_hi = b_lo + np.round(rng.uniform(0, 1, (n_b, 2)) * scale)
    widest = max([0.0] + [float((h - l).max()) for l, h in ((q_lo, q_hi), (b_lo, b_hi)) if len(l)])
    i, j = BoxGrid(b_lo, b_hi, widest + 1e-6).pairs(q_lo, q_hi)
    assert sorted(zip(i.tolist(), j.tolist())) == _pairs(_dense(q_lo, q_hi, b_lo, b_hi))


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n_q=st.integers(1, 12), n_b=st.integers(0, 30), n_zones=st.integers(1, 3))
def test_corridor_hits_are_the_dense_test_within_a_zone(seed, n_q, n_b, n_zones):
    """A corridor (a run of boxes) is hit exactly when one of its boxes meets a box of its own
    zone other than its own row, as testing every box of every corridor densely."""
    rng = np.random.default_rng(seed)
    n_box = rng.integers(1, 5, n_q)
    first = np.r_[0, np.cumsum(n_box)]
    c_lo = np.round(rng.uniform(0, 20, (first[-1], 2)))
    c_hi = c_lo + np.round(rng.uniform(0, 4, (first[-1], 2)))
    b_lo = np.round(rng.uniform(0, 20, (n_b, 2)))
    b_hi = b_lo + np.round(rng.uniform(0, 4, (n_b, 2)))
    zone_q = rng.integers(0, n_zones, n_q)
    row_q = rng.integers(0, max(n_b, 1), n_q)
    zone_b = np.sort(rng.integers(0, n_zones, n_b))
    row_b = rng.permutation(n_b)
    hits = corridor_hits(zone_q, row_q, first, c_lo, c_hi, zone_b, row_b, b_lo, b_hi)
    for q in range(n_q):
        sl = slice(first[q], first[q + 1])
        mine = [row_b[k] for k in range(n_b) if zone_b[k] == zone_q[q] and row_b[k] != row_q[q]]
        want = bool(mine) and boxes_meet(c_lo[sl], c_hi[sl], b_lo[mine], b_hi[mine])
        assert hits[q] == want
    assert boxes_meet(np.zeros((1, 2)), np.ones((1, 2)), np.ones((1, 2)), np.full((1, 2), 2.0))  # touching
    assert not boxes_meet(np.zeros((1, 2)), np.ones((1, 2)), np.full((1, 2), 1.5), np.full((1, 2), 2.0))


def _rects(rng, m):
    """``m`` random oriented rectangles (m, 4, 2), counter-clockwise, some touching by construction."""
    from tm.geometry import rectangles
    c = rng.uniform(-15, 15, (m, 2))
    return c[:, None, :] + rectangles(rng.uniform(-np.pi, np.pi, m), rng.uniform(0.5, 8, m), rng.uniform(0.5, 4, m))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2 ** 31), n=st.integers(0, 8))
def test_polygon_sets_meet_is_polygons_meet_of_each_pair(seed, n):
    """The junction gate's batched exit-slot test (tm.boxes.polygon_sets_meet) is, pair by pair,
    whether any two polygons of the pair's sets meet by the separating-axis test (tm.geometry.intersect_sat
    on every combination, no bounding boxes: the same SAT, so exactly), for random rectangles, sets of
    0-4 polygons (empty sets meet nothing) and pairs that share polygons; polygons_meet is one pair."""
    from tm.boxes import polygon_sets_meet, polygons_meet
    from tm.geometry import intersect_sat

    def dense(A, B):
        if not len(A) or not len(B):
            return False
        i, j = np.meshgrid(np.arange(len(A)), np.arange(len(B)), indexing="ij")
        return bool(intersect_sat(A[i.ravel()], B[j.ravel()]).any())
    rng = np.random.default_rng(seed)
    cp, cq = rng.integers(0, 5, n), rng.integers(0, 5, n)
    P, Q = _rects(rng, int(cp.sum())), _rects(rng, int(cq.sum()))
    if n and cq.sum():
        Q[0] = P[0] if cp.sum() else Q[0]               # one exact overlap across sets
    p_of, q_of = np.repeat(np.arange(n), cp), np.repeat(np.arange(n), cq)
    want = [dense(P[p_of == t], Q[q_of == t]) for t in range(n)]
    got = polygon_sets_meet(P, np.cumsum(cp) - cp, cp, Q, np.cumsum(cq) - cq, cq)
    assert got.tolist() == want
    assert [polygons_meet(P[p_of == t], Q[q_of == t]) for t in range(n)] == want
    # sets that share polygons: every pair takes Q's sets in reverse order (read, not copied)
    rev = np.arange(n)[::-1]
    got = polygon_sets_meet(P, np.cumsum(cp) - cp, cp, Q, (np.cumsum(cq) - cq)[rev], cq[rev])
    assert got.tolist() == [dense(P[p_of == t], Q[q_of == rev[t]]) for t in range(n)]


def test_polygon_sets_meet_counts_touching_and_not_a_gap_beyond_the_tolerance():
    """Two unit squares side by side: touching counts (gap 0), 10 tolerances apart they do not meet.
    Rotated by 30 degrees about the same point, where their bounding boxes overlap and the
    separating-axis test decides, a gap of half the tolerance counts as touching too.  (Along an
    axis the bounding boxes are compared exactly, as before the compiled loop: a gap in ``(0, tol]``
    there does not meet.)  The compiled loop and the numpy separating-axis test agree wherever the
    boxes meet."""
    from controllers.tolerances import GEOMETRY_TOL
    from tm.boxes import polygon_sets_meet
    from tm.geometry import intersect_sat

    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    c, s = np.cos(np.pi / 6), np.sin(np.pi / 6)
    rot = np.array([[c, -s], [s, c]])
    cases = [(np.eye(2), 0.0, True), (np.eye(2), 10 * GEOMETRY_TOL, False), (np.eye(2), 0.5, False),
             (rot, 0.0, True), (rot, 0.5 * GEOMETRY_TOL, True), (rot, 10 * GEOMETRY_TOL, False), (rot, 0.5, False)]
    for turn, gap, meets in cases:
        P = (square @ turn.T)[None]
        Q = ((square + [1.0 + gap, 0.0]) @ turn.T)[None]
        got = polygon_sets_meet(P, [0], [1], Q, [0], [1])
        assert got.tolist() == [meets] == intersect_sat(P, Q).tolist(), (gap, turn)
    # empty sets meet nothing; a pair whose sets are empty among others is False
    P = square[None]
    assert polygon_sets_meet(P, [0, 0], [1, 0], P, [0, 0], [1, 1]).tolist() == [True, False]
    assert polygon_sets_meet(np.zeros((0, 4, 2)), [0], [0], P, [0], [1]).tolist() == [False]


@settings(max_examples=300, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(0, 6), m=st.integers(0, 6), nan=st.booleans(),
       grid=st.booleans())
def test_boxes_meet_and_meets_any_compiled_are_the_dense_test(seed, n, m, nan, grid):
    """:func:`boxes_meet` and :func:`meets_any` (compiled, first meeting pair) against the dense test on
    random boxes: touching (integer corners), NaN bounds, empty sides, strided and (1, 2) views."""
    rng = np.random.default_rng(seed)

    def boxes(k):
        lo = rng.integers(-4, 4, (k, 2)).astype(float) if grid else rng.normal(size=(k, 2)) * 3
        hi = lo + (rng.integers(0, 3, (k, 2)) if grid else rng.uniform(0, 2, (k, 2)))
        if nan and k:
            lo[rng.integers(0, k), rng.integers(0, 2)] = np.nan
        return lo, hi
    lo1, hi1 = boxes(n)
    lo2, hi2 = boxes(m)
    want = bool(np.any(box_pairs_meet(lo1, hi1, lo2, hi2)))
    assert boxes_meet(lo1, hi1, lo2, hi2) is want
    wide = np.hstack([lo1, hi1])  # strided views of the same boxes
    assert boxes_meet(wide[:, :2], wide[:, 2:], lo2, hi2) is want
    if m:
        assert boxes_meet(lo1, hi1, lo2[:1], hi2[:1]) is bool(np.any(box_pairs_meet(lo1, hi1, lo2[:1], hi2[:1])))
    rows = meets_any(lo1, hi1, lo2, hi2)  # per row, the same comparisons
    assert rows.dtype == bool and np.array_equal(rows, np.any(box_pairs_meet(lo1, hi1, lo2, hi2), axis=1))
    assert np.array_equal(meets_any(wide[:, :2], wide[:, 2:], lo2, hi2), rows)
