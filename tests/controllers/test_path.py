"""The path frame (controllers/path.py): construction, the map to the world, kinks, projection.

Tolerances.  Coordinates here are O(1..100) m; float round-off in the map is ~1e-14 relative, so
identities of the map are checked to 1e-9 m.  Merged collinear runs are checked against
``PATH_COLLINEAR_TOL_M`` (what the construction promises).
"""

import numpy as np
import pytest
from hypothesis import assume, given, settings, strategies as st

from controllers.path import PathError, PathFrame
from controllers.tolerances import PATH_COLLINEAR_TOL_M
from tests.polylines import random_polyline
from tests.reference import merge_loop

TOL = 1e-9
seeds = st.integers(0, 2**32 - 1)


def seg_distance(p, V):
    """Distance of points p (m, 2) to the polyline V."""
    a, b = V[:-1], V[1:]
    ab = b - a
    t = np.clip(np.einsum("mij,ij->mi", p[:, None] - a[None], ab) / np.einsum("ij,ij->i", ab, ab), 0, 1)
    return np.min(np.linalg.norm(p[:, None] - (a[None] + t[..., None] * ab[None]), axis=2), axis=1)


# ----------------------------------------------------------------------------- construction
@pytest.mark.parametrize("W, match", [
    ([[0.0, 0.0]], "two distinct"),
    ([[1.0, 2.0], [1.0, 2.0], [1.0, 2.0 + 1e-12]], "two distinct"),
    (np.zeros((0, 2)), "two distinct"),
    ([[0.0, 0.0], [np.nan, 1.0], [2.0, 0.0]], "point 1 is not finite"),
    ([[0.0, 0.0], [1.0, np.inf]], "point 1 is not finite"),
    ([0.0, 1.0, 2.0], "must be \\(P, 2\\)"),
    ([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], "must be \\(P, 2\\)"),
])
def test_bad_polylines_are_refused_clearly(W, match):
    with pytest.raises(PathError, match=match):
        PathFrame(W)
    assert issubclass(PathError, ValueError)


def test_a_subsampled_straight_is_one_segment_and_corners_stay():
    x = np.linspace(0.0, 100.0, 35)
    W = np.column_stack([x, 0.5 * x]) @ np.array([[np.cos(0.3), np.sin(0.3)], [-np.sin(0.3), np.cos(0.3)]])
    f = PathFrame(W)
    assert f.n_segments == 1
    assert f.length == pytest.approx(np.hypot(100.0, 50.0), abs=TOL)
    L = np.vstack([W, W[-1] + np.array([[0.0, 3.0], [0.0, 6.0], [0.0, 9.0]])])  # a corner, then straight
    g = PathFrame(L)
    assert g.n_segments == 2 and len(g.turn) == 1
    np.testing.assert_allclose(g.vertices, L[[0, len(W) - 1, -1]], atol=TOL)


def test_duplicates_merge_reversals_do_not():
    f = PathFrame([[0, 0], [0, 0], [1, 0], [1, 1e-12], [2, 0]])
    assert f.n_segments == 1 and f.length == pytest.approx(2.0, abs=TOL)
    r = PathFrame([[0, 0], [2, 0], [1, 0]])  # a reversal is a kink (180 degrees), never merged
    assert r.n_segments == 2 and abs(abs(r.turn[0]) - np.pi) < 1e-12
    with np.errstate(all="raise"):  # back onto the first point: no division by a zero chord
        b = PathFrame([[0, 0], [1, 0], [0, 0]])
    assert b.n_segments == 2 and b.length == pytest.approx(2.0)


def _subsampled(rng, n_seg):
    """A route as the bridge makes it: a random polyline with every segment subsampled about 1 m
    apart (long collinear runs), some points nudged across by about the tolerance."""
    P = random_polyline(rng, n_seg, min_len=1.0, max_len=60.0)
    out = [P[:1]]
    for p, q in zip(P[:-1], P[1:]):
        m = max(int(np.ceil(np.hypot(*(q - p)))), 1)
        out.append(p + np.linspace(0.0, 1.0, m + 1)[1:, None] * (q - p))
    W = np.vstack(out)
    nudge = rng.random(len(W)) < 0.1
    W[nudge] += rng.choice([-2.0, -1.0, -0.5, 0.5, 1.0, 2.0], (int(nudge.sum()), 1)) * PATH_COLLINEAR_TOL_M * \
        rng.normal(size=(int(nudge.sum()), 2))
    return W


@settings(max_examples=150, deadline=None)
@given(seeds, st.integers(1, 25), st.floats(0.0, 0.3))
def test_blocked_merge_keeps_the_vertices_the_loop_keeps(seed, n_seg, p_fixed):
    """The blocked merge keeps exactly the vertices of the one-candidate-at-a-time loop, on subsampled
    routes (runs longer than a block, points nudged by about the tolerance, reversals from the random
    turns' sums) with random fixed vertices: the same arithmetic, so equal index arrays (no tolerance)."""
    from controllers.path import _merge_collinear
    rng = np.random.default_rng(seed)
    W = _subsampled(rng, n_seg)
    W = W[np.concatenate([[True], np.hypot(*np.diff(W, axis=0).T) > 1e-9])]
    fixed = rng.random(len(W)) < p_fixed
    for fx in (None, fixed):
        np.testing.assert_array_equal(_merge_collinear(W, PATH_COLLINEAR_TOL_M, fx),
                                      merge_loop(W, PATH_COLLINEAR_TOL_M, fx))


def test_blocked_merge_keeps_the_vertices_of_the_old_matvec_loop_on_routes():
    """Against the replaced loop verbatim (``mid @ d``, whose rounding may differ in the last bit from
    the elementwise products): the same vertices on 200 subsampled routes, none of them within a few
    ulp of the tolerance."""
    from controllers.path import _merge_collinear
    rng = np.random.default_rng(12)
    for _ in range(200):
        W = _subsampled(rng, int(rng.integers(2, 20)))
        W = W[np.concatenate([[True], np.hypot(*np.diff(W, axis=0).T) > 1e-9])]
        np.testing.assert_array_equal(_merge_collinear(W, PATH_COLLINEAR_TOL_M),
                                      merge_loop(W, PATH_COLLINEAR_TOL_M, matvec=True))


def test_the_frame_is_immutable():
    f = PathFrame([[0, 0], [1, 0], [1, 1]])
    with pytest.raises(AttributeError):
        f.arc = np.zeros(3)
    with pytest.raises(ValueError):
        f.arc[0] = 1.0


@settings(max_examples=60, deadline=None)
@given(seeds, st.integers(1, 12))
def test_every_input_point_lies_on_the_frame_polyline(seed, n_seg):
    rng = np.random.default_rng(seed)
    P = random_polyline(rng, n_seg)
    # subsample every segment (collinear points with round-off) and add exact duplicates
    W = [P[0]]
    for a, b in zip(P[:-1], P[1:]):
        k = int(rng.integers(1, 5))
        W += list(a + (b - a) * (np.arange(1, k + 1) / k)[:, None])
        if rng.random() < 0.2:
            W.append(W[-1].copy())
    W = np.array(W)
    f = PathFrame(W)
    assert seg_distance(W, f.vertices).max() <= PATH_COLLINEAR_TOL_M
    assert f.n_segments <= n_seg
    # the arc length is the input's (no length lost or added by merging)
    assert f.length == pytest.approx(np.linalg.norm(np.diff(P, axis=0), axis=1).sum(), abs=1e-7)
    assert np.all(np.abs(f.turn) > 1e-12)


# ----------------------------------------------------------------------------- the map
def test_to_world_on_an_l_shape():
    f = PathFrame([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]])
    xy, h = f.to_world([5.0, 10.0, 15.0, -2.0, 23.0], [1.0, 1.0, 1.0, -0.5, 0.0])
    np.testing.assert_allclose(xy, [[5, 1], [9, 0], [9, 5], [-2, -0.5], [10, 13]], atol=TOL)
    np.testing.assert_allclose(h, [0, np.pi / 2, np.pi / 2, 0, np.pi / 2], atol=TOL)
    xy2, h2 = f.to_world(np.array([[1.0, 2.0], [3.0, 4.0]]), 0.0)  # any shape, broadcast
    assert xy2.shape == (2, 2, 2) and h2.shape == (2, 2)
    with pytest.raises(PathError, match="finite"):
        f.to_world([1.0, np.nan], 0.0)


@settings(max_examples=60, deadline=None)
@given(seeds, st.integers(2, 10), st.floats(-2.0, 2.0))
def test_kinks_the_centre_line_is_continuous_and_offsets_jump_by_the_bound(seed, n_seg, n):
    rng = np.random.default_rng(seed)
    f = PathFrame(random_polyline(rng, n_seg, straight_p=0.0))
    assume(f.n_segments >= 2)
    S = f.arc[1:-1]
    before = np.nextafter(S, -np.inf)
    # n = 0: the polyline, continuous through each vertex
    at0, _ = f.to_world(S, 0.0)
    bf0, _ = f.to_world(before, 0.0)
    np.testing.assert_allclose(at0, f.vertices[1:-1], atol=TOL)
    np.testing.assert_allclose(bf0, f.vertices[1:-1], atol=TOL)
    # n != 0: the world point jumps by exactly |n| 2 sin(theta / 2)
    at, h_at = f.to_world(S, n)
    bf, h_bf = f.to_world(before, n)
    jump = np.linalg.norm(at - bf, axis=1)
    np.testing.assert_allclose(jump, abs(n) * 2 * np.sin(np.abs(f.turn) / 2), atol=TOL)
    np.testing.assert_allclose(np.angle(np.exp(1j * (h_at - h_bf))), f.turn, atol=1e-12)
    # body points: at most kink_jump_bound, attained at a corner at the sharpest kink
    L, W = 5.0, 1.8
    corners = np.array([[1, 1], [1, -1], [-1, 1], [-1, -1]]) * [L / 2, W / 2]
    worst = 0.0
    for hb, ha, pb, pa in zip(h_bf, h_at, bf, at):
        for a, b in corners:
            qb = pb + a * np.array([np.cos(hb), np.sin(hb)]) + b * np.array([-np.sin(hb), np.cos(hb)])
            qa = pa + a * np.array([np.cos(ha), np.sin(ha)]) + b * np.array([-np.sin(ha), np.cos(ha)])
            worst = max(worst, float(np.linalg.norm(qa - qb)))
    assert worst <= f.kink_jump_bound(n, L, W) + TOL
    assert worst >= f.kink_jump_bound(n, L, W) - TOL


# ----------------------------------------------------------------------------- projection
@settings(max_examples=80, deadline=None)
@given(seeds, st.integers(1, 10), st.floats(-0.5, 0.5), st.floats(-1.0, 1.0))
def test_round_trip_away_from_kinks(seed, n_seg, n, hint_noise):
    """``to_path(to_world(s, n)) == (s, n)`` for ``s`` at least ``|n| + 1 cm`` from every kink
    (segments >= 1 m and kinks <= 45 degrees: one preimage there, module notes), with a hint up to
    1 m off and a window reaching over several segments."""
    rng = np.random.default_rng(seed)
    f = PathFrame(random_polyline(rng, n_seg))
    s = rng.uniform(-5.0, f.length + 5.0, 200)
    gap = np.abs(s[:, None] - f.arc[None, 1:-1]).min(axis=1) if f.n_segments > 1 else np.full(len(s), np.inf)
    s = s[gap >= abs(n) + 0.01]
    assume(len(s))
    xy, _ = f.to_world(s, n)
    s2, n2 = f.to_path(xy, s + hint_noise, window=3.0)
    np.testing.assert_allclose(s2, s, atol=TOL)
    np.testing.assert_allclose(n2, n, atol=TOL)


def test_to_path_follows_the_hint_where_the_route_passes_near_itself():
    # a hairpin: out along y = 0, back along y = 4
    f = PathFrame([[0.0, 0.0], [50.0, 0.0], [52.0, 2.0], [50.0, 4.0], [0.0, 4.0]])
    p = np.array([[20.0, 1.5]])                       # nearer the outward leg (1.5 m vs 2.5 m)
    s_out, n_out = f.to_path(p, 20.0, window=5.0)
    s_back, n_back = f.to_path(p, f.length - 20.0, window=5.0)
    assert s_out[0] == pytest.approx(20.0) and n_out[0] == pytest.approx(1.5)
    assert s_back[0] == pytest.approx(f.length - 20.0) and n_back[0] == pytest.approx(2.5)  # left of the way back


def test_to_path_in_the_outside_wedge_of_a_kink_gives_the_vertex():
    f = PathFrame([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]])  # left turn; the outside is the right
    s, n = f.to_path(np.array([[10.5, -0.5], [-3.0, 0.0], [10.0, 14.0]]), 10.0, window=30.0)
    np.testing.assert_allclose(s, [10.0, -3.0, 24.0], atol=TOL)          # ends: extended segments
    np.testing.assert_allclose(n, [-np.hypot(0.5, 0.5), 0.0, 0.0], atol=TOL)


def test_to_path_refuses_bad_input():
    f = PathFrame([[0.0, 0.0], [10.0, 0.0]])
    with pytest.raises(PathError, match="finite"):
        f.to_path(np.array([[np.nan, 0.0]]), 0.0)
    with pytest.raises(PathError, match="finite"):
        f.to_path(np.array([[1.0, 0.0]]), np.inf)
    with pytest.raises(PathError, match="\\(m, 2\\)"):
        f.to_path(np.array([1.0, 0.0]), 0.0)
    with pytest.raises(PathError, match="window"):
        f.to_path(np.array([[1.0, 0.0]]), 0.0, window=-1.0)


# ----------------------------------------------------------------------------- body lean
def test_a_lean_keeps_its_vertex_and_turns_the_body_not_the_path():
    """A straight subsampled into 6 chords, the middle two leaning by -6 degrees (a lane change's
    diagonal with SUMO's body along the lane): the frame keeps the vertices where the lean changes
    (3 segments, not 1), maps (s, n) as without a lean, and gives the body heading."""
    W = np.column_stack([np.arange(7) * 3.0, np.zeros(7)])
    lean = np.radians([0, 0, -6, -6, 0, 0])
    f, plain = PathFrame(W, lean), PathFrame(W)
    assert plain.n_segments == 1 and f.n_segments == 3
    np.testing.assert_allclose(f.arc, [0, 6, 12, 18])
    np.testing.assert_allclose(np.degrees(f.lean), [0, -6, 0])
    np.testing.assert_allclose(f.body_heading, f.heading + f.lean)
    s, n = np.array([1.0, 7.5, 13.0]), np.array([0.3, -0.2, 0.0])
    xy, h = f.to_world(s, n)
    xy0, h0 = plain.to_world(s, n)
    np.testing.assert_allclose(xy, xy0, atol=1e-12)
    np.testing.assert_allclose(np.degrees(h), [0, -6, 0], atol=1e-12)
    assert np.all(h0 == 0.0)


def test_leans_within_the_tolerance_merge_and_take_the_first():
    W = np.column_stack([np.arange(4) * 3.0, np.zeros(4)])
    f = PathFrame(W, [0.1, 0.1 + 1e-9, 0.1 - 1e-9])
    assert f.n_segments == 1 and f.lean[0] == 0.1


@pytest.mark.parametrize("lean, match", [([0.1], "one per chord"), ([0.1, np.nan], "finite"),
                                         ([0.0, 1.6], "within 90 degrees")])
def test_bad_leans_are_refused_clearly(lean, match):
    with pytest.raises(PathError, match=match):
        PathFrame([[0, 0], [3, 0], [6, 0]], lean)


def test_a_dropped_duplicate_point_keeps_the_chords_lean():
    """Chords of the kept points take the lean of the input chord they end with."""
    W = [[0, 0], [3, 0], [3, 0], [6, 1]]
    f = PathFrame(W, [0.0, 0.2, -0.1])
    assert f.n_segments == 2
    np.testing.assert_allclose(f.lean, [0.0, -0.1])
