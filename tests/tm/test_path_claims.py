"""Path-frame claims drawn in the world (tm/path_claims.py, PathStack, stack_box_cover,
cover_bounds) and tube escapes of bodies that turn with their path (tm/reach_book.tube_escapes).

Tolerances.  Containment is checked within ``GEOMETRY_TOL`` = 1e-9 m (world coordinates O(100) m:
the same point computed by two float expressions differs by ~1e-13 m).  The stack is compared with
one frame at a time bit for bit where the arithmetic is the same (segment indices) and within
1e-9 m where the stack adds and removes an arc offset (centres).
"""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from controllers.classes import builtin_classes
from controllers.path import PathError, PathFrame, PathStack
from controllers.plant import step as plant_step
from controllers.settings import ControllerSettings, SynthesisSettings
from controllers.stmpc import STMPC
from controllers.synthesis import rotate_pairs, synthesize
from controllers.tolerances import GEOMETRY_TOL
from tm.path_claims import PathPlace, bare_model, path_reach_claims
from tm.path_cover import cover_bounds, path_box_cover, path_footprints, stack_box_cover
from tm.reach_book import ReachBook, tube_escapes
from tests.polylines import random_polyline

seeds = st.integers(0, 2**32 - 1)


def _frames(rng, n):
    return [PathFrame(random_polyline(rng, int(rng.integers(1, 8)))) for _ in range(n)]


@settings(max_examples=40, deadline=None)
@given(seeds)
def test_the_stack_maps_and_covers_as_each_frame_alone(seed):
    rng = np.random.default_rng(seed)
    frames = _frames(rng, int(rng.integers(1, 5)))
    stack = PathStack(frames)
    fid = rng.integers(0, len(frames), 60)
    s = np.array([rng.uniform(-20.0, frames[f].length + 20.0) for f in fid])
    s[::7] = [frames[f].arc[int(rng.integers(0, len(frames[f].arc)))] for f in fid[::7]]  # on vertices
    n = rng.uniform(-2.0, 2.0, len(s))
    xy, h = stack.to_world(fid, s, n)
    for f in range(len(frames)):
        m = fid == f
        xy_f, h_f = frames[f].to_world(s[m], n[m])
        assert np.abs(xy[m] - xy_f).max(initial=0.0) <= 1e-9
        assert np.array_equal(h[m], h_f)
        assert np.array_equal(stack.segment(fid[m], s[m]) - stack.first[f], frames[f].segment(s[m]))
    s_hi = s + rng.uniform(0.0, 25.0, len(s))
    n_lo, n_hi = n - 0.3, n + 0.4
    got = stack_box_cover(stack, fid, s, s_hi, n_lo, n_hi, 2.5, 2.5, 0.9, 0.9)
    for q in range(len(s)):
        one = path_box_cover(frames[fid[q]], s[q], s_hi[q], n_lo[q], n_hi[q], 5.0, 1.8)
        b = slice(got.start[q], got.start[q] + got.count[q])
        assert got.count[q] == one.count[0]
        assert np.abs(got.centre[b] - one.centre).max() <= 1e-9
        assert np.abs(got.half[b] - one.half).max() <= 1e-9


def test_a_stack_rejects_bad_frames_and_indices():
    with pytest.raises(PathError, match="every frame must be a PathFrame"):
        PathStack([np.zeros((2, 2))])
    stack = PathStack([PathFrame([[0.0, 0.0], [10.0, 0.0]])])
    with pytest.raises(PathError, match="frame index out of 0 .. 0"):
        stack.to_world([1], [0.0], [0.0])


@settings(max_examples=40, deadline=None)
@given(seeds)
def test_cover_bounds_hold_every_box_and_are_exact_for_one_box(seed):
    rng = np.random.default_rng(seed)
    frame = _frames(rng, 1)[0]
    m = 30
    s_lo = rng.uniform(-5.0, frame.length, m)
    s_hi = s_lo + rng.uniform(0.0, 20.0, m)
    s_hi[-1] = s_lo[-1] - 1.0  # an empty interval
    boxes = path_box_cover(frame, s_lo, s_hi, -0.2, 0.3, 5.0, 1.8)
    centre = rng.uniform(-50, 50, (m, 2))
    heading = rng.uniform(-np.pi, np.pi, m)
    lo, hi = cover_bounds(boxes, centre, heading)
    assert np.all(np.isinf(lo[-1])) and np.all(lo[-1] > hi[-1])
    P = boxes.polygons()                                              # (q, 4, 2) world corners
    local = rotate_pairs((P - centre[boxes.owner][:, None, :]).reshape(-1, 2),
                         -np.repeat(heading[boxes.owner], 4)).reshape(-1, 4, 2)
    assert np.all(local >= lo[boxes.owner][:, None, :] - GEOMETRY_TOL)
    assert np.all(local <= hi[boxes.owner][:, None, :] + GEOMETRY_TOL)
    one = boxes.count == 1  # one box in its own frame: the bounds are the box itself
    b = boxes.start[one]
    lo1, hi1 = cover_bounds(path_box_cover(frame, s_lo[one], s_hi[one], -0.2, 0.3, 5.0, 1.8), boxes.centre[b],
                            boxes.heading[b])
    assert np.abs(hi1 - boxes.half[b]).max(initial=0.0) <= 1e-9 and np.abs(lo1 + boxes.half[b]).max(initial=0.0) <= 1e-9


def _car():
    vc = builtin_classes()["car"]
    from dataclasses import replace
    fam = synthesize(vc.model, replace(SynthesisSettings(), authority_decel=vc.comfort_decel))
    ctl = STMPC(fam, ControllerSettings(solver="exact", switching="early", mode="authority"))
    book = ReachBook({"car": fam}, {"car": (vc.length, vc.width)})
    return vc, ctl, book


CAR = None


def car():
    global CAR
    if CAR is None:
        CAR = _car()
    return CAR


@settings(max_examples=25, deadline=None)
@given(seeds, st.sampled_from(["random", "adversarial", "none"]))
def test_path_claims_hold_the_body_at_every_step_of_their_tube(seed, policy):
    """A car driven in path coordinates round a random route (every kink up to 60 degrees), its stop
    point a random waypoint ahead: for each k, the body at x(t+k) lies in the world box S_k(t) (its
    corners, within GEOMETRY_TOL), in one box of the slot's cover and in its world bounding box,
    x(t+1) is no tube escape, and the claims of t+1 nest in the shifted claims of t (the
    waypoint-frame boxes, and the covers box by box)."""
    vc, ctl, book = car()
    rng = np.random.default_rng(seed)
    W = random_polyline(rng, 12, min_len=3.0, max_len=15.0, max_turn_deg=60.0)
    frame = PathFrame(W)
    stack = PathStack([frame])
    m = vc.model
    c_s = float(rng.uniform(10.0, frame.length))
    centre = np.array([[c_s, 0.0]])
    cw, _ = frame.to_world(np.array([c_s]), np.array([0.0]))
    place = PathPlace(stack, np.array([0]), cw, np.array([float(rng.uniform(-np.pi, np.pi))]))
    x = m.equilibrium(np.array([c_s - float(rng.uniform(0.0, 40.0)), 0.0]))
    x[2] = float(rng.uniform(0.0, 13.0))
    X = x[None]
    l = ctl.index(X, centre, np.zeros(1))
    if l[0] > ctl.N:
        return
    rm = book.models["car"]
    claims = path_reach_claims(rm, book.bare["car"], X, centre, l, place)
    body = []
    escapes = 0
    for k in range(1, rm.K + 5):
        U = ctl.control(X, centre, l, heading=np.zeros(1))
        X, _ = plant_step(m, X, U, centre, policy, rng, heading=np.zeros(1))
        l_new = ctl.index(X, centre, np.zeros(1))
        assert l_new[0] < l[0] or l[0] == 0 == l_new[0]
        if k == 1:
            xy, h = frame.to_world(X[:, 0], X[:, 1])
            escapes += int(tube_escapes(claims, xy, [vc.length], [vc.width], body_heading=h)[0])
            nxt = path_reach_claims(rm, book.bare["car"], X, centre, l_new, place)
            sh = claims.shift()
            ok = (nxt.lo >= sh.lo - GEOMETRY_TOL) & (nxt.hi <= sh.hi + GEOMETRY_TOL)
            empty = nxt.lo > nxt.hi
            assert np.all(ok | empty.any(axis=-1, keepdims=True))
            # and box by box: every box of a fresh slot lies in one box of the shifted slot
            nt, st_ = nxt.tight, sh.tight
            for jj in range(rm.K):
                for b in range(nt.start[0, jj], nt.start[0, jj] + nt.count[0, jj]):
                    from tm.geometry import rectangles
                    corners = nt.centre[b] + rectangles(np.array([nt.heading[b]]), np.array([2 * nt.half[b, 0]]),
                                                        np.array([2 * nt.half[b, 1]]))[0]
                    assert _in_one_box(st_, 0, jj, corners), jj
        body.append(path_footprints(frame, X[:, 0], X[:, 1], vc.length, vc.width)[0])
        l = l_new
    assert escapes == 0
    t = claims.tight  # the slots as unions of boxes (what the timed check compares)
    for k, C in enumerate(body, start=1):
        j = min(k, rm.K) - 1
        local = rotate_pairs(C - claims.centre[0], -np.repeat(claims.heading[0], 4))
        assert np.all(local >= claims.lo[0, j] - GEOMETRY_TOL) and np.all(local <= claims.hi[0, j] + GEOMETRY_TOL), k
        assert _in_one_box(t, 0, j, C), k
        b = claims.slot_boxes[:, 0, j]  # and its world box, the timed check's pre-filter
        assert C[:, 0].min() >= b[0] - GEOMETRY_TOL and C[:, 0].max() <= b[1] + GEOMETRY_TOL
        assert C[:, 1].min() >= b[2] - GEOMETRY_TOL and C[:, 1].max() <= b[3] + GEOMETRY_TOL


def _in_one_box(sb, i, k, C) -> bool:
    """Whether the corners ``C`` (4, 2) lie in one box of slot ``k`` of row ``i`` (GEOMETRY_TOL)."""
    for b in range(sb.start[i, k], sb.start[i, k] + sb.count[i, k]):
        local = rotate_pairs(C - sb.centre[b], -np.repeat(sb.heading[b], 4))
        if np.all(np.abs(local) <= sb.half[b] + GEOMETRY_TOL):
            return True
    return False


def test_a_body_outside_its_slot_is_a_tube_escape_whatever_its_heading():
    """The escape counter fires: a body moved 1 m beyond its claim's S_1 (along the claim's frame),
    or turned so that its bounding box no longer fits, is an escape; in place it is not."""
    vc, ctl, book = car()
    frame = PathFrame([[0.0, 0.0], [30.0, 0.0], [30.0, 30.0]])
    c_s = 40.0  # 10 m round the corner
    centre = np.array([[c_s, 0.0]])
    cw, ch = frame.to_world(np.array([c_s]), np.array([0.0]))
    place = PathPlace(PathStack([frame]), np.array([0]), cw, ch)
    X = vc.model.equilibrium(np.array([[c_s - 0.5, 0.0]]))
    l = ctl.index(X, centre, np.zeros(1))
    claims = path_reach_claims(book.models["car"], book.bare["car"], X, centre, l, place)
    xy, h = frame.to_world(X[:, 0], X[:, 1])
    L, Wd = [vc.length], [vc.width]
    assert not tube_escapes(claims, xy, L, Wd, body_heading=h)[0]
    assert tube_escapes(claims, xy + [[0.0, claims.hi[0, 0, 0] + 1.0]], L, Wd, body_heading=h)[0]
    assert tube_escapes(claims, xy, L, Wd, body_heading=h + 0.5 * np.pi)[0]  # a car across its lane


def test_the_timed_check_compares_the_slots_own_boxes():
    """Two claims whose waypoint-frame boxes overlap in slot 1 but whose covers (``tight``) are 1 m
    apart: ``timed`` sees no conflict, ``union`` (waypoint-frame boxes) does; moved together the
    covers conflict under ``timed`` too.  Concatenated with a claim without a cover (a road-frame
    vehicle) the check still compares that one's own box; a slot of two boxes meets through
    either; shift, take and padding move the covers with the claims."""
    from tm.reach import ReachClaims, claims_conflict, pad_slots
    from tm.slot_boxes import SlotBoxes

    K = 2
    coarse_lo = np.array([[[-3.0, -3.0]] * K])
    coarse_hi = np.array([[[3.0, 3.0]] * K])

    def claim(x, with_tight=True, extra=None):
        tight = None
        if with_tight:
            tight = SlotBoxes.from_frames(np.array([[x, 0.0]]), np.zeros(1), np.array([[[-0.5, -0.5]] * K]),
                                          np.array([[[0.5, 0.5]] * K]))
            if extra is not None:  # slot 1: boxes at x and x + extra; slot 2: the box at x
                tight = SlotBoxes(np.array([[x, 0.0], [x + extra, 0.0], [x, 0.0]]), np.zeros(3),
                                  np.full((3, 2), 0.5), np.array([[0, 2]]), np.array([[2, 1]]))
        return ReachClaims(np.array([[x, 0.0]]), np.zeros(1), coarse_lo, coarse_hi, tight)

    far = ReachClaims.concat(claim(0.0), claim(2.0))      # coarse boxes overlap, covers 1 m apart
    assert not claims_conflict(far, [0], far, [1], "timed")[0]
    assert claims_conflict(far, [0], far, [1], "union")[0]
    near = ReachClaims.concat(claim(0.0), claim(0.9))
    assert claims_conflict(near, [0], near, [1], "timed")[0]
    two = ReachClaims.concat(claim(0.0, extra=1.2), claim(2.0))  # slot 1's second box reaches 2.2 - 0.5
    assert claims_conflict(two, [0], two, [1], "timed")[0]
    assert not claims_conflict(two.shift(), [0], two.shift(), [1], "timed")[0]  # slot 2 has one box
    mixed = ReachClaims.concat(claim(0.0), claim(3.0, with_tight=False))  # its own box reaches down to x = 0
    assert claims_conflict(mixed, [0], mixed, [1], "timed")[0]
    mixed = ReachClaims.concat(claim(0.0), claim(4.0, with_tight=False))  # down to x = 1: clear of 0.5
    assert not claims_conflict(mixed, [0], mixed, [1], "timed")[0]
    assert mixed.take([1]).tight.centre[mixed.take([1]).tight.start[0, 0]][0] == 4.0
    assert pad_slots(claim(0.0), 5).tight.count.shape == (1, 5)
    b = two.slot_boxes  # the pre-filter's world boxes hold both boxes of slot 1
    assert b[0, 0, 0] == -0.5 and b[1, 0, 0] == 1.7


@settings(max_examples=20, deadline=None)
@given(seeds)
def test_equal_slots_are_covered_once_and_as_slot_by_slot(seed):
    """Runs of equal slots (a vehicle at rest at its stop point: every slot past its index is
    ``T^0``'s) are covered once and share their boxes: the claims are the slot-by-slot covers
    (:func:`tm.path_cover.stack_box_cover` and :func:`cover_bounds` of every slot), float for float,
    with fewer boxes."""
    vc, ctl, book = car()
    rng = np.random.default_rng(seed)
    W = random_polyline(rng, 12, min_len=3.0, max_len=15.0, max_turn_deg=60.0)
    frame = PathFrame(W)
    stack = PathStack([frame])
    m, rm = vc.model, book.models["car"]
    n = 6
    c_s = rng.uniform(10.0, frame.length, n)
    centre = np.column_stack([c_s, np.zeros(n)])
    X = np.vstack([m.equilibrium(np.array([c, 0.0])) for c in c_s])  # at rest on their stop points ...
    X[3:, 0] -= rng.uniform(0.0, 30.0, n - 3)                        # ... or behind them, moving
    X[3:, 2] = rng.uniform(0.0, 13.0, n - 3)
    l = np.minimum(ctl.index(X, centre, np.zeros(n)), rm.N)
    cw, _ = frame.to_world(c_s, np.zeros(n))
    place = PathPlace(stack, np.zeros(n, dtype=np.intp), cw, rng.uniform(-np.pi, np.pi, n))
    pad = rng.uniform(0.0, 0.5, (n, 4))
    got = path_reach_claims(rm, book.bare["car"], X, centre, l, place, body_pad=pad)
    # the reference: every slot covered on its own
    path = book.bare["car"]
    from tm.reach import reach_claims
    pc = reach_claims(path, X, centre, np.zeros(n), l)
    K = pc.lo.shape[1]
    empty = ~((pc.lo[..., 0] <= pc.hi[..., 0]) & (pc.lo[..., 1] <= pc.hi[..., 1]))
    s_lo = np.where(empty, 1.0, pc.lo[..., 0] + c_s[:, None]).ravel()
    s_hi = np.where(empty, 0.0, pc.hi[..., 0] + c_s[:, None]).ravel()
    n_lo = np.where(empty, 0.0, pc.lo[..., 1]).ravel()
    n_hi = np.where(empty, 0.0, pc.hi[..., 1]).ravel()
    hl, hw = 0.5 * vc.length, 0.5 * vc.width
    ext = [hl + pad[:, 0], hl + pad[:, 1], hw + pad[:, 2], hw + pad[:, 3]]
    rep = lambda a: np.repeat(a, K, axis=0)  # noqa: E731
    ref = stack_box_cover(stack, rep(place.fid), s_lo, s_hi, n_lo, n_hi, *(rep(e) for e in ext))
    wlo, whi = cover_bounds(ref, rep(place.centre), rep(place.heading))
    np.testing.assert_array_equal(got.lo, wlo.reshape(n, K, 2))
    np.testing.assert_array_equal(got.hi, whi.reshape(n, K, 2))
    t = got.tight
    for i in range(n):
        for k in range(K):
            f = i * K + k
            a = slice(t.start[i, k], t.start[i, k] + t.count[i, k])
            b = slice(ref.start[f], ref.start[f] + ref.count[f])
            for mine, theirs in ((t.centre, ref.centre), (t.heading, ref.heading), (t.half, ref.half)):
                np.testing.assert_array_equal(mine[a], theirs[b])
    assert len(t.heading) < len(ref.heading)  # the runs at rest were covered once
