"""The world cover of path-frame claims (tm/path_cover.py): sound, tight, and the overhang at kinks.

Tolerance.  A footprint counts as covered when its corners lie in one box of its interval within
``GEOMETRY_TOL`` = 1e-9 m: coordinates are O(100) m and the box and the footprint are computed by
different float expressions of the same point (``V + (s - S) T + n N`` against the box centre plus
its half extents), which differ by round-off of ~1e-13 m.  Corners in one box put the (convex)
footprint in that box, hence in the union: a stronger statement than the one the TM needs.  The
check is shown to fail on covers that leave out the body's overhang at a kink.
"""

import numpy as np
import pytest
from hypothesis import assume, given, settings, strategies as st

from controllers.path import PathError, PathFrame
from controllers.tolerances import GEOMETRY_TOL
from tm.geometry import intersect_sat, rectangles
from tm.path_cover import PathBoxes, path_box_cover, path_footprints, points_in_boxes
from tests.polylines import random_polyline

seeds = st.integers(0, 2**32 - 1)
CAR = (5.0, 1.8)


def samples(frame, s_lo, s_hi, n_lo, n_hi, k=7, rng=None):
    """Path points of each interval: a k x 3 grid with the corners, every interior vertex and the
    last float before it (the pose just before the kink, the overhang's worst case), and random
    points.  Returns owner (p,), s (p,), n (p,)."""
    O, S, N = [], [], []
    for j in range(len(s_lo)):
        ss = list(np.linspace(s_lo[j], s_hi[j], k))
        V = frame.arc[1:-1]
        V = V[(V >= s_lo[j]) & (V <= s_hi[j])]
        ss += list(V) + list(np.maximum(np.nextafter(V, -np.inf), s_lo[j]))
        if rng is not None:
            ss += list(rng.uniform(s_lo[j], s_hi[j], 5))
        nn = [n_lo[j], 0.5 * (n_lo[j] + n_hi[j]), n_hi[j]]
        g = np.array([(a, b) for a in ss for b in nn])
        O += [j] * len(g)
        S += list(g[:, 0])
        N += list(g[:, 1])
    return np.array(O, dtype=np.intp), np.array(S), np.array(N)


def uncovered_corners(frame, boxes, owner, s, n, length, width):
    """Footprint corners (of the sampled poses) in no box of their interval: the union check."""
    C = path_footprints(frame, s, n, length, width)                      # (p, 4, 2)
    inside = points_in_boxes(boxes, np.repeat(owner, 4), C.reshape(-1, 1, 2), GEOMETRY_TOL).any(axis=1)
    return int((~inside).sum())


def footprints_not_in_one_box(frame, boxes, owner, s, n, length, width):
    C = path_footprints(frame, s, n, length, width)
    return int((~points_in_boxes(boxes, owner, C, GEOMETRY_TOL).any(axis=1)).sum())


def random_intervals(rng, frame, m):
    s_lo = rng.uniform(-10.0, frame.length + 5.0, m)
    s_hi = s_lo + rng.uniform(0.0, 30.0, m) * (rng.random(m) > 0.1)   # some zero-length intervals
    n_lo = rng.uniform(-1.5, 1.0, m)
    n_hi = n_lo + rng.uniform(0.0, 1.0, m) * (rng.random(m) > 0.1)
    return s_lo, s_hi, n_lo, n_hi


# ----------------------------------------------------------------------------- soundness
@settings(max_examples=60, deadline=None)
@given(seeds, st.integers(1, 12), st.floats(0.5, 12.0), st.floats(0.5, 3.0))
def test_every_footprint_of_the_interval_lies_in_one_box(seed, n_seg, length, width):
    """Random polylines (kinks up to 45 degrees, segments 0.3-10 m), random intervals."""
    rng = np.random.default_rng(seed)
    f = PathFrame(random_polyline(rng, n_seg, min_len=0.3))
    s_lo, s_hi, n_lo, n_hi = random_intervals(rng, f, 12)
    boxes = path_box_cover(f, s_lo, s_hi, n_lo, n_hi, length, width)
    owner, s, n = samples(f, s_lo, s_hi, n_lo, n_hi, rng=rng)
    assert footprints_not_in_one_box(f, boxes, owner, s, n, length, width) == 0
    assert uncovered_corners(f, boxes, owner, s, n, length, width) == 0


@settings(max_examples=40, deadline=None)
@given(seeds, st.integers(2, 10))
def test_anything_touching_a_footprint_touches_a_box(seed, n_seg):
    """What the TM relies on: a rectangle meeting some footprint of the claim meets one of its
    boxes (:func:`tm.geometry.intersect_sat` on the boxes' polygons)."""
    rng = np.random.default_rng(seed)
    f = PathFrame(random_polyline(rng, n_seg, min_len=0.5))
    s_lo, s_hi, n_lo, n_hi = random_intervals(rng, f, 6)
    ok = s_lo <= s_hi
    boxes = path_box_cover(f, s_lo, s_hi, n_lo, n_hi, *CAR)
    owner, s, n = samples(f, s_lo, s_hi, n_lo, n_hi, k=4, rng=rng)
    keep = ok[owner] & (n_lo <= n_hi)[owner]
    owner, s, n = owner[keep], s[keep], n[keep]
    assume(len(owner))
    F = path_footprints(f, s, n, *CAR)
    # probes: small rectangles centred on a random point of each footprint (they meet it)
    w = rng.random((len(owner), 2))
    centre = F[:, 0] + w[:, :1] * (F[:, 1] - F[:, 0]) + w[:, 1:] * (F[:, 3] - F[:, 0])
    Q = centre[:, None, :] + rectangles(rng.uniform(-np.pi, np.pi, len(owner)), rng.uniform(0.01, 2.0, len(owner)),
                                        rng.uniform(0.01, 2.0, len(owner)))
    assert intersect_sat(F, Q).all()
    polys = boxes.polygons()
    c = boxes.count[owner]
    pairs = np.repeat(np.arange(len(owner)), c)
    b = np.concatenate([np.arange(boxes.start[o], boxes.start[o] + boxes.count[o]) for o in owner])
    hit = np.zeros(len(owner), dtype=bool)
    np.logical_or.at(hit, pairs, intersect_sat(polys[b], Q[pairs]))
    assert hit.all()


# ----------------------------------------------------------------------------- the overhang at a kink
def _clipped(frame, boxes: PathBoxes) -> PathBoxes:
    """A cover that leaves out the overhang: each box clipped to its segment's arc range along the
    segment (the footprint's L/2 kept only at the route's ends)."""
    seg, M = boxes.segment, frame.n_segments
    h = boxes.heading
    T = np.column_stack([np.cos(h), np.sin(h)])
    lo_a = np.einsum("ij,ij->i", boxes.centre - frame.vertices[seg], T) - boxes.half[:, 0]
    hi_a = lo_a + 2 * boxes.half[:, 0]
    L = frame.arc[seg + 1] - frame.arc[seg]
    lo_a = np.where(seg == 0, lo_a, np.maximum(lo_a, 0.0))
    hi_a = np.where(seg == M - 1, hi_a, np.minimum(hi_a, L))
    mid_old = np.einsum("ij,ij->i", boxes.centre - frame.vertices[seg], T)
    centre = boxes.centre + (0.5 * (lo_a + hi_a) - mid_old)[:, None] * T
    half = np.column_stack([0.5 * (hi_a - lo_a), boxes.half[:, 1]])
    return PathBoxes(boxes.owner, seg, centre, h, half, boxes.start, boxes.count, boxes.shape)


def _along_path(frame, s_lo, s_hi, n_lo, n_hi, length, width) -> PathBoxes:
    """A cover that treats the body as bending with the path: ``[s_lo - L/2, s_hi + L/2]`` laid
    along the segments with the body's width only."""
    return path_box_cover(frame, np.asarray(s_lo) - 0.5 * length, np.asarray(s_hi) + 0.5 * length,
                          n_lo, n_hi, 0.0, width)


@pytest.mark.parametrize("turn_deg", [10.0, 22.5, 45.0, -45.0])
def test_the_check_catches_a_cover_without_the_overhang(turn_deg):
    t = np.radians(turn_deg)
    f = PathFrame([[-20.0, 0.0], [0.0, 0.0], [20.0 * np.cos(t), 20.0 * np.sin(t)]])
    s_lo, s_hi = np.array([12.0, 19.0, 15.0]), np.array([28.0, 19.999, 20.0])   # across, up to, onto the kink
    n_lo, n_hi = np.array([-0.2, -0.2, 0.0]), np.array([0.2, 0.2, 0.0])
    owner, s, n = samples(f, s_lo, s_hi, n_lo, n_hi)
    good = path_box_cover(f, s_lo, s_hi, n_lo, n_hi, *CAR)
    assert uncovered_corners(f, good, owner, s, n, *CAR) == 0
    assert footprints_not_in_one_box(f, good, owner, s, n, *CAR) == 0
    for bad in (_clipped(f, good), _along_path(f, s_lo, s_hi, n_lo, n_hi, *CAR)):
        assert uncovered_corners(f, bad, owner, s, n, *CAR) > 0
        assert footprints_not_in_one_box(f, bad, owner, s, n, *CAR) > 0


def test_a_45_degree_kink_the_front_corner_overhangs_the_next_segment_by_1_5_m():
    """The module's figure: a car just before a 45 degree left kink at n = 0."""
    f = PathFrame([[-20.0, 0.0], [0.0, 0.0], [20.0, 20.0]])
    C = path_footprints(f, np.nextafter(20.0, 0.0), 0.0, *CAR)[0]
    T, N = f.tangent[1], f.normal[1]
    across = (C - f.vertices[1]) @ N
    assert across.min() == pytest.approx(-(2.5 * np.sin(np.pi / 4) + 0.9 * np.cos(np.pi / 4)), abs=1e-12)
    assert across.min() < -0.9 - 1.4


# ----------------------------------------------------------------------------- shape of the cover
def test_a_straight_is_one_exact_box():
    f = PathFrame(np.column_stack([np.linspace(0, 60, 21), np.zeros(21)]))
    b = path_box_cover(f, 10.0, 20.0, -0.3, 0.1, 5.0, 2.0)
    assert len(b) == 1
    np.testing.assert_allclose(b.centre, [[15.0, -0.1]], atol=1e-12)
    np.testing.assert_allclose(b.half, [[7.5, 1.2]], atol=1e-12)
    # beyond the ends: the end segments extended
    e = path_box_cover(f, [-8.0, 58.0], [-2.0, 70.0], 0.0, 0.0, 5.0, 2.0)
    np.testing.assert_allclose(e.centre, [[-5.0, 0.0], [64.0, 0.0]], atol=1e-12)
    np.testing.assert_allclose(e.half[:, 0], [5.5, 8.5], atol=1e-12)


@settings(max_examples=40, deadline=None)
@given(seeds, st.integers(1, 10))
def test_one_box_per_segment_met_and_every_box_corner_is_a_footprint_corner(seed, n_seg):
    """Tight: the cover is the closure of the footprints' union, no larger (each box corner is a
    corner of the footprint at an end of its segment's part of the interval, the left limit at a
    kink included)."""
    rng = np.random.default_rng(seed)
    f = PathFrame(random_polyline(rng, n_seg, min_len=0.3))
    s_lo, s_hi, n_lo, n_hi = random_intervals(rng, f, 10)
    b = path_box_cover(f, s_lo, s_hi, n_lo, n_hi, *CAR)
    S = f.arc
    for j in range(len(s_lo)):
        met = [i for i in range(f.n_segments)  # closed ranges, the end segments extended
               if (i == 0 or S[i] <= s_hi[j]) and (i == f.n_segments - 1 or S[i + 1] >= s_lo[j])]
        want = met if (s_lo[j] <= s_hi[j] and n_lo[j] <= n_hi[j]) else []
        got = b.segment[b.start[j]:b.start[j] + b.count[j]].tolist()
        assert got == want
    P = b.polygons()
    for q in range(len(b)):
        j, i = b.owner[q], b.segment[q]
        a = max(s_lo[j], S[i]) if i else s_lo[j]
        e = min(s_hi[j], S[i + 1]) if i < f.n_segments - 1 else s_hi[j]
        corners = []
        for s in (a, e):
            for n in (n_lo[j], n_hi[j]):
                xy = f.vertices[i] + (s - S[i]) * f.tangent[i] + n * f.normal[i]  # segment i's pose
                corners.append(xy + rectangles(f.heading[i], *CAR)[0])
        corners = np.vstack(corners)
        d = np.linalg.norm(P[q][:, None, :] - corners[None], axis=2).min(axis=1)
        assert d.max() <= 1e-9


def test_vectorised_equals_one_at_a_time_and_broadcasts():
    rng = np.random.default_rng(3)
    f = PathFrame(random_polyline(rng, 8))
    s_lo, s_hi, n_lo, n_hi = random_intervals(rng, f, 20)
    allb = path_box_cover(f, s_lo, s_hi, n_lo, n_hi, *CAR)
    for j in range(20):
        one = path_box_cover(f, s_lo[j], s_hi[j], n_lo[j], n_hi[j], *CAR)
        sl = slice(allb.start[j], allb.start[j] + allb.count[j])
        np.testing.assert_array_equal(allb.centre[sl], one.centre)
        np.testing.assert_array_equal(allb.half[sl], one.half)
    grid = path_box_cover(f, s_lo.reshape(4, 5), s_hi.reshape(4, 5), 0.0, 0.1, 5.0, [[1.8]] * 4)
    assert grid.shape == (4, 5) and len(grid.count) == 20


def test_empty_intervals_get_no_box_and_bad_input_is_refused():
    f = PathFrame([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]])
    b = path_box_cover(f, [5.0, 5.0, 3.0], [4.0, 6.0, 3.0], [0.0, 0.2, 0.0], [0.0, 0.1, 0.0], *CAR)
    assert b.count.tolist() == [0, 0, 1] and len(b) == 1
    with pytest.raises(PathError, match="s_hi must be finite"):
        path_box_cover(f, 0.0, np.nan, 0.0, 0.0, *CAR)
    with pytest.raises(PathError, match=">= 0"):
        path_box_cover(f, 0.0, 1.0, 0.0, 0.0, -1.0, 1.0)


# ----------------------------------------------------------------------------- leaning bodies
def _random_leans(rng, n_chords):
    """Per chord: 0, or one of a few leans up to 30 degrees (runs of equal leans: merged segments)."""
    choice = np.radians([0.0, 0.0, 6.0, -6.0, 30.0, -17.0])
    return choice[rng.integers(0, len(choice), n_chords)]


@settings(max_examples=60, deadline=None)
@given(seeds, st.integers(1, 12), st.floats(0.5, 12.0), st.floats(0.5, 3.0))
def test_every_leaning_footprint_of_the_interval_lies_in_one_box(seed, n_seg, length, width):
    """Frames whose bodies lean (random leans per chord, up to 30 degrees): the footprint at every
    sampled ``(s, n)``, along the body's heading, lies in one box of its interval (tolerance as
    above); and it does not lie in the cover of the frame without the leans wherever a lean is
    met (the check is not vacuous)."""
    rng = np.random.default_rng(seed)
    P = random_polyline(rng, n_seg, min_len=0.3)
    lean = _random_leans(rng, len(P) - 1)
    f = PathFrame(P, lean)
    s_lo, s_hi, n_lo, n_hi = random_intervals(rng, f, 12)
    boxes = path_box_cover(f, s_lo, s_hi, n_lo, n_hi, length, width)
    owner, s, n = samples(f, s_lo, s_hi, n_lo, n_hi, rng=rng)
    assert footprints_not_in_one_box(f, boxes, owner, s, n, length, width) == 0
    assert uncovered_corners(f, boxes, owner, s, n, length, width) == 0
    leaning = f.lean[f.segment(s)] != 0
    assume(leaning.any())
    plain = path_box_cover(PathFrame(P), s_lo, s_hi, n_lo, n_hi, length, width)
    assert footprints_not_in_one_box(f, plain, owner[leaning], s[leaning], n[leaning], length, width) > 0


def test_a_lane_change_cover_along_the_lane_is_0_7_m_narrower_for_a_truck():
    """A truck (7.1 x 2.4 m) 2 m before the end of a lane change (3.2 m across in 30 m, 6.1
    degrees), its claim reaching 3 m on along the new lane: laid along the diagonal, a cover that
    holds the lane-parallel body must be padded by L sin(lean) across (0.75 m) and is then turned
    with the diagonal; laid along the lane it reaches at most ``W/2 + |n|`` beyond the lane's
    centre line plus the diagonal's slant over the 2 m.  The figure of ``grid`` seed 1 (truck 77
    and bus 85, head-on beside each other for good): the leaning cover reaches >= 0.7 m less
    toward the oncoming lane."""
    P = np.array([[0.0, 0.0], [30.0, 0.0], [60.0, -3.2], [90.0, -3.2]])
    lean_deg = float(np.degrees(np.arctan2(3.2, 30.0)))
    f = PathFrame(P, np.radians([0.0, lean_deg, 0.0]))
    L, W = 7.1, 2.4
    s0 = f.arc[2] - 2.0
    lean_box = path_box_cover(f, s0, s0 + 5.0, -0.1, 0.1, L, W)
    # along the diagonal: the body's corner reaches L sin(lean) beyond the rectangle, so the pads
    # needed are (back, front, right, left) = (~0, ~0.4, ~0.75, 0) in the diagonal's axes
    pad_r = L * np.sin(np.radians(lean_deg))
    from tm.path_cover import stack_box_cover
    from controllers.path import PathStack
    flat = stack_box_cover(PathStack([PathFrame(P)]), 0, s0, s0 + 5.0, -0.1, 0.1, L / 2, L / 2 + 0.4,
                           W / 2 + pad_r, W / 2)
    low = lambda b: b.polygons()[:, :, 1].min()  # noqa: E731  (toward the oncoming lane: -y)
    assert low(lean_box) >= -3.2 - W / 2 - 0.1 - 2.0 * np.sin(np.radians(lean_deg)) - 1e-9
    assert low(lean_box) - low(flat) >= 0.7
    # and the lane-parallel body at every sampled pose lies in the leaning cover
    owner, s, n = samples(f, [s0], [s0 + 5.0], [-0.1], [0.1])
    assert footprints_not_in_one_box(f, lean_box, owner, s, n, L, W) == 0
