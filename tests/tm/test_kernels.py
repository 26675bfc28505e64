"""The compiled loops (tm/kernels.py) against the numpy formulas they replaced, float for float.

The references below are the numpy code of ``tm.reach`` before the kernels (vectorised over
vehicles, slots and pairs).  Comparisons are exact (``np.array_equal``: the same IEEE operations in
the same order; only the sign of a zero may differ, which ``==`` ignores), over random claims with
empty slots, ties at table grid points, shorter horizons and unions of boxes, and on a real class's
synthesised tables.
"""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from controllers.classes import get_class
from controllers.settings import SynthesisSettings
from controllers.synthesis import rotate_pairs
from controllers.tolerances import GEOMETRY_TOL, REACH_LOOKUP_MARGIN
from tm.lane import lane_class
from tm.reach import (PREFILTER_TOL_FACTOR, ReachClaims, _boxes_overlap, claims_conflict, reach_claims,
                      slot_aabb, split_pad)
from tm.slot_boxes import SlotBoxes


# ------------------------------------------------------------------ references (numpy, as before)
def _ref_reach(rm, X, centre, heading, index, body_offset=0.0, body_pad=None):
    n, K, T = len(X), rm.K, rm.tables
    E = rotate_pairs(X - np.hstack([centre, np.zeros((n, 2))]), -heading)
    k = np.arange(1, K + 1)
    m = np.maximum(index[:, None] - k[None, :], 0)
    Kr = K - 1
    mm = m[:, :Kr]
    Aa, Ac = rm.Ak_al[1:], rm.Ak_ac[1:]
    ra, ry = rm.r_al[1:], rm.r_ac[1:]
    cp = np.outer(E[:, 0], Aa[:, 0, 0]) + np.outer(E[:, 2], Aa[:, 0, 1])
    cv = np.outer(E[:, 0], Aa[:, 1, 0]) + np.outer(E[:, 2], Aa[:, 1, 1])
    cy = np.outer(E[:, 1], Ac[:, 0, 0]) + np.outer(E[:, 3], Ac[:, 0, 1])
    v_lo = np.maximum(cv - ra[:, 1], T.v_lo[mm])
    v_hi = np.minimum(cv + ra[:, 1], T.v_hi[mm])
    off = np.broadcast_to(np.asarray(body_offset, dtype=float), (n,))
    c, s = np.abs(np.cos(off)), np.abs(np.sin(off))
    fx = 0.5 * (rm.length * c + rm.width * s)
    fy = 0.5 * (rm.length * s + rm.width * c)
    fx_lo, fx_hi, fy_lo, fy_hi = fx, fx, fy, fy
    if body_pad is not None:
        plo, phi = split_pad(body_pad, n)
        fx_lo, fy_lo, fx_hi, fy_hi = fx + plo[:, 0], fy + plo[:, 1], fx + phi[:, 0], fy + phi[:, 1]
    P = np.empty((4, n, K))
    P[0, :, :Kr] = np.maximum(np.maximum(cp - ra[:, 0], T.h(mm, v_hi + REACH_LOOKUP_MARGIN)), T.p_lo[mm])
    P[1, :, :Kr] = np.minimum(np.minimum(cp + ra[:, 0], T.g(mm, v_lo - REACH_LOOKUP_MARGIN)), T.p_hi[mm])
    my = mm
    if rm.across is not None:
        ly = np.minimum(rm.across.index(E) + 1, index)
        my = np.maximum(ly[:, None] - k[None, :Kr], 0)
    P[2, :, :Kr] = np.maximum(cy - ry[:, 0], T.y_lo[my])
    P[3, :, :Kr] = np.minimum(cy + ry[:, 0], T.y_hi[my])
    P[0, :, Kr:], P[1, :, Kr:] = T.p_lo[0], T.p_hi[0]
    P[2, :, Kr:], P[3, :, Kr:] = T.y_lo[0], T.y_hi[0]
    empty = (P[0] > P[1]) | (P[2] > P[3])
    P[0] -= fx_lo[:, None]
    P[1] += fx_hi[:, None]
    P[2] -= fy_lo[:, None]
    P[3] += fy_hi[:, None]
    P[0][empty] = P[2][empty] = np.inf
    P[1][empty] = P[3][empty] = -np.inf
    return np.stack([P[0], P[2]], axis=-1), np.stack([P[1], P[3]], axis=-1)


def _ref_timed(a, i, b, j, tol):
    """Every slot (pre-filter, then the separating-axis test on the boxes or unions of boxes)."""
    K = max(a.lo.shape[1], b.lo.shape[1])
    out = np.zeros(len(i), dtype=bool)
    A, B = a.slot_boxes, b.slot_boxes
    pad = PREFILTER_TOL_FACTOR * tol
    for t, (p, q) in enumerate(zip(i, j)):
        for k in range(K):
            xa, xb = min(k, A.shape[2] - 1), min(k, B.shape[2] - 1)
            if not (A[0, p, xa] <= B[1, q, xb] + pad and B[0, q, xb] <= A[1, p, xa] + pad and
                    A[2, p, xa] <= B[3, q, xb] + pad and B[2, q, xb] <= A[3, p, xa] + pad):
                continue
            ka, kb = min(k, a.lo.shape[1] - 1), min(k, b.lo.shape[1] - 1)
            if a.tight is None and b.tight is None:
                hit = _boxes_overlap(a.centre[p], a.heading[p], a.lo[p, ka], a.hi[p, ka],
                                     b.centre[q], b.heading[q], b.lo[q, kb], b.hi[q, kb], tol)
            else:  # some box of one slot meets some box of the other
                sa, sb = a.slot_union(), b.slot_union()
                hit = any(_boxes_overlap(sa.centre[x], sa.heading[x], -sa.half[x], sa.half[x],
                                         sb.centre[y], sb.heading[y], -sb.half[y], sb.half[y], tol)
                          for x in range(sa.start[p, ka], sa.start[p, ka] + sa.count[p, ka])
                          for y in range(sb.start[q, kb], sb.start[q, kb] + sb.count[q, kb]))
            if hit:
                out[t] = True
                break
    return out


# ------------------------------------------------------------------ claims
@pytest.fixture(scope="module")
def car_model(shared_set_cache):
    return lane_class(get_class("car"), SynthesisSettings(cache_dir=shared_set_cache)).reach


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 30), pad=st.sampled_from([None, 2, 4]),
       offset=st.booleans())
def test_reach_claims_equal_the_numpy_formulas(car_model, seed, n, pad, offset):
    """Random states around random waypoints (some on the tables' velocity grid, where the lookup
    rounds), random indices 0..N, footprints turned and padded: the same boxes and world boxes."""
    rm = car_model
    rng = np.random.default_rng(seed)
    centre = rng.uniform(-50, 50, (n, 2))
    heading = rng.uniform(-np.pi, np.pi, n)
    E = np.column_stack([rng.uniform(-30, 5, n), rng.uniform(-1, 1, n), rng.uniform(-2, 16, n),
                         rng.uniform(-0.5, 0.5, n)])
    grid = rng.random(n) < 0.3  # velocities on the tables' grid points: ties in the lookup
    E[grid, 2] = rm.tables.w0 + rm.tables.dw * rng.integers(0, rm.tables.G.shape[1], grid.sum())
    X = np.hstack([centre, np.zeros((n, 2))]) + rotate_pairs(E, heading)
    index = rng.integers(0, rm.N + 1, n)
    body_pad = None if pad is None else rng.uniform(0, 2, (n, pad))
    body_offset = rng.uniform(0, 0.5, n) if offset else 0.0
    got = reach_claims(rm, X, centre, heading, index, body_offset=body_offset, body_pad=body_pad)
    lo, hi = _ref_reach(rm, X, centre, heading, index, body_offset, body_pad)
    assert np.array_equal(got.lo, lo) and np.array_equal(got.hi, hi)
    assert np.array_equal(got.slot_boxes, slot_aabb(centre, heading, lo, hi))


# ------------------------------------------------------------------ the timed check
def _random_claims(rng, n, K, tight):
    centre = rng.uniform(-15, 15, (n, 2))
    heading = rng.uniform(-np.pi, np.pi, n)
    lo = rng.uniform(-6, 2, (n, K, 2))
    hi = lo + rng.uniform(-0.5, 6, (n, K, 2))          # some empty slots (hi < lo)
    c = ReachClaims(centre, heading, lo, hi)
    if not tight:
        return c
    count = rng.integers(0, 3, (n, K))
    q = int(count.sum())
    start = (np.cumsum(count.ravel()) - count.ravel()).reshape(n, K)
    sb = SlotBoxes(rng.uniform(-15, 15, (q, 2)), rng.uniform(-np.pi, np.pi, q), rng.uniform(0.1, 3, (q, 2)),
                   start, count)
    return ReachClaims(centre, heading, lo, hi, sb)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), ka=st.integers(1, 6), kb=st.integers(1, 6),
       tight=st.sampled_from([(False, False), (True, False), (True, True)]))
def test_timed_check_equals_every_slot_by_numpy(seed, ka, kb, tight):
    """Random claims of different horizons, plain or unions of boxes (and mixed), random pairs:
    the kernel's answer is the reference's, slot by slot, and both see hits and misses."""
    rng = np.random.default_rng(seed)
    a, b = _random_claims(rng, 8, ka, tight[0]), _random_claims(rng, 7, kb, tight[1])
    i, j = rng.integers(0, 8, 60), rng.integers(0, 7, 60)
    got = claims_conflict(a, i, b, j, "timed")
    assert np.array_equal(got, _ref_timed(a, i, b, j, GEOMETRY_TOL))
    assert np.array_equal(claims_conflict(b, j, a, i, "timed"), got)  # symmetric


def test_timed_check_sees_both_answers():
    """The random claims above are not all hits or all misses (the comparison would prove little)."""
    rng = np.random.default_rng(3)
    a, b = _random_claims(rng, 8, 4, False), _random_claims(rng, 7, 3, False)
    i, j = rng.integers(0, 8, 200), rng.integers(0, 7, 200)
    got = claims_conflict(a, i, b, j, "timed")
    assert 0 < got.sum() < len(got)


@pytest.mark.parametrize("K", [1, 2, 5, 17])
def test_timed_check_with_equal_horizons_equals_every_slot_by_numpy(K):
    """Equal horizons (the kernel's pass over every slot's pre-filter first): the reference's answer,
    on pairs that pass no pre-filter, pass one but no separating-axis test, and meet."""
    rng = np.random.default_rng(K)
    a, b = _random_claims(rng, 40, K, False), _random_claims(rng, 30, K, False)
    i, j = np.divmod(np.arange(40 * 30), 30)                       # every pair
    got = claims_conflict(a, i, b, j, "timed")
    assert np.array_equal(got, _ref_timed(a, i, b, j, GEOMETRY_TOL))
    A, B, pad = a.slot_boxes, b.slot_boxes, PREFILTER_TOL_FACTOR * GEOMETRY_TOL
    passed = ((A[0][i] <= B[1][j] + pad) & (B[0][j] <= A[1][i] + pad) &
              (A[2][i] <= B[3][j] + pad) & (B[2][j] <= A[3][i] + pad)).any(axis=1)
    assert got.any() and (~passed).any() and (passed & ~got).any()


@pytest.fixture(scope="module")
def bus_model(shared_set_cache):
    return lane_class(get_class("bus"), SynthesisSettings(cache_dir=shared_set_cache)).reach


def test_claims_of_several_classes_written_in_place_equal_their_concatenation(car_model, bus_model):
    """:func:`tm.reach.reach_claims_many` (one set of arrays, the longer horizon) equals the classes'
    own claims concatenated with :meth:`ReachClaims.concat` (the shorter horizon padded with its
    last slot), boxes included."""
    from tm.reach import reach_claims_many

    assert car_model.K != bus_model.K  # the padding is exercised
    rng = np.random.default_rng(5)
    groups = []
    for rm, n in ((car_model, 7), (bus_model, 4), (car_model, 3)):
        centre, heading = rng.uniform(-40, 40, (n, 2)), rng.uniform(-np.pi, np.pi, n)
        E = np.column_stack([rng.uniform(-20, 2, n), rng.uniform(-0.5, 0.5, n), rng.uniform(0, 12, n),
                             rng.uniform(-0.3, 0.3, n)])
        X = np.hstack([centre, np.zeros((n, 2))]) + rotate_pairs(E, heading)
        groups.append((rm, X, centre, heading, rng.integers(0, rm.N + 1, n), 0.0, rng.uniform(0, 1, (n, 4))))
    got = reach_claims_many(groups)
    want = ReachClaims.concat(*(reach_claims(*g[:5], body_offset=g[5], body_pad=g[6]) for g in groups))
    for name in ("centre", "heading", "lo", "hi", "slot_boxes"):
        assert np.array_equal(getattr(got, name), getattr(want, name)), name
    # the bounds over each row's slots, made in the same pass (reach_boxes), are numpy's over the boxes
    assert "union_bounds" in got.__dict__
    b = got.slot_boxes
    ref = np.stack([b[0].min(axis=1), b[1].max(axis=1), b[2].min(axis=1), b[3].max(axis=1)], axis=1)
    assert np.array_equal(got.union_bounds, ref)
    rows = np.array([12, 0, 8, 3])  # carried by take
    assert np.array_equal(got.take(rows).__dict__["union_bounds"], ref[rows])


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), tight=st.booleans())
def test_union_boxes_are_the_slot_boxes_bounds(seed, tight):
    """:func:`tm.reach.union_aabb` (compiled) equals numpy's minima and maxima over the slots, empty
    slots and claims with no slot at all included (inverted)."""
    from tm.reach import union_aabb

    rng = np.random.default_rng(seed)
    c = _random_claims(rng, 9, int(rng.integers(1, 6)), tight)
    b = c.slot_boxes
    assert ("union_bounds" in c.__dict__) == tight  # unions of boxes: bounded in the slot boxes' pass
    lo, hi = union_aabb(c)
    assert np.array_equal(lo, np.stack([b[0].min(axis=1), b[2].min(axis=1)], axis=1))
    assert np.array_equal(hi, np.stack([b[1].max(axis=1), b[3].max(axis=1)], axis=1))


# ------------------------------------------------------------------ path-frame covers
def _ref_stack_box_cover(stack, fid, sl, sh, nl, nh, bk, fr, rt, lf):
    """tm.path_cover.stack_box_cover's numpy body before the kernel (centre, heading, half, start, count)."""
    m = len(sl)
    ok = (sl <= sh) & (nl <= nh)
    i0 = stack.first_meeting(fid, np.where(ok, sl, 0.0))
    i1 = stack.segment(fid, np.where(ok, sh, 0.0))
    count = np.where(ok, i1 - i0 + 1, 0)
    start = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.intp) if m else np.zeros(0, np.intp)
    owner = np.repeat(np.arange(m), count)
    seg = i0[owner] + (np.arange(len(owner)) - start[owner])
    f = fid[owner]
    S0 = np.where(seg == stack.first[f], -np.inf, stack.start[seg])
    S1 = np.where(seg == stack.last[f], np.inf, stack.end[seg])
    a = np.maximum(sl[owner], S0) - stack.start[seg]
    b = np.minimum(sh[owner], S1) - stack.start[seg]
    nlo, nhi = nl[owner], nh[owner]
    heading = stack.heading[seg].copy()
    tangent, normal = stack.tangent[seg], stack.normal[seg]
    r = np.flatnonzero(stack.body_heading[seg] != heading)
    if len(r):
        d = heading[r] - stack.body_heading[seg[r]]
        c, sn = np.cos(d), np.sin(d)
        xs = np.stack([a[r], a[r], b[r], b[r]])
        ys = np.stack([nlo[r], nhi[r], nlo[r], nhi[r]])
        u, v = c * xs - sn * ys, sn * xs + c * ys
        a, b, nlo, nhi = a.copy(), b.copy(), nlo.copy(), nhi.copy()
        a[r], b[r], nlo[r], nhi[r] = u.min(0), u.max(0), v.min(0), v.max(0)
        heading[r] = stack.body_heading[seg[r]]
        tangent, normal = tangent.copy(), normal.copy()
        tangent[r] = np.column_stack([np.cos(heading[r]), np.sin(heading[r])])
        normal[r] = np.column_stack([-tangent[r, 1], tangent[r, 0]])
    lo_x, hi_x = a - bk[owner], b + fr[owner]
    lo_y, hi_y = nlo - rt[owner], nhi + lf[owner]
    mx, my = 0.5 * (lo_x + hi_x), 0.5 * (lo_y + hi_y)
    centre = stack.vertices[seg] + mx[:, None] * tangent + my[:, None] * normal
    half = np.column_stack([0.5 * (hi_x - lo_x), 0.5 * (hi_y - lo_y)])
    return centre, heading, half, start, count, owner


def _ref_cover_bounds(centre, heading, half, start, count, owner, pc, ph):
    m = len(start)
    lo, hi = np.full((m, 2), np.inf), np.full((m, 2), -np.inf)
    h = ph[owner]
    c, s = np.cos(h), np.sin(h)
    d = centre - pc[owner]
    u, v = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
    dh = heading - h
    cc, ss = np.abs(np.cos(dh)), np.abs(np.sin(dh))
    eu, ev = cc * half[:, 0] + ss * half[:, 1], ss * half[:, 0] + cc * half[:, 1]
    has = np.flatnonzero(count > 0)
    if len(has):
        at = start[has]
        lo[has, 0], lo[has, 1] = np.minimum.reduceat(u - eu, at), np.minimum.reduceat(v - ev, at)
        hi[has, 0], hi[has, 1] = np.maximum.reduceat(u + eu, at), np.maximum.reduceat(v + ev, at)
    return lo, hi


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), lean=st.booleans())
def test_path_covers_equal_the_numpy_formulas(seed, lean):
    """Random polyline frames (bodies leaning on some chords, or none), random intervals on them (some
    empty, some past a frame's ends) and one-sided extents: the boxes, their per-interval bounds in
    random frames, exactly as the numpy code computed them."""
    from controllers.path import PathFrame, PathStack
    from tm.path_cover import cover_bounds, stack_box_cover

    rng = np.random.default_rng(seed)
    frames = []
    for _ in range(int(rng.integers(1, 4))):
        P = np.cumsum(rng.uniform(1, 12, (int(rng.integers(3, 9)), 2)) * rng.choice([-1, 1], (1, 2)), axis=0)
        leans = np.where(rng.random(len(P) - 1) < 0.5, rng.uniform(-0.5, 0.5, len(P) - 1), 0.0) if lean else None
        frames.append(PathFrame(P, leans))
    stack = PathStack(frames)
    m = 25
    fid = rng.integers(0, len(frames), m)
    L = np.array([frames[f].length for f in fid])
    sl = rng.uniform(-5, L + 5)
    sh = sl + rng.uniform(-2, 25, m)
    nl = rng.uniform(-2, 1, m)
    nh = nl + rng.uniform(-0.5, 2, m)
    ext = [rng.uniform(0, 3, m) for _ in range(4)]
    got = stack_box_cover(stack, fid, sl, sh, nl, nh, *ext)
    centre, heading, half, start, count, owner = _ref_stack_box_cover(stack, fid, sl, sh, nl, nh, *ext)
    assert np.array_equal(got.centre, centre) and np.array_equal(got.heading, heading)
    assert np.array_equal(got.half, half) and np.array_equal(got.start, start) and np.array_equal(got.count, count)
    pc, ph = rng.uniform(-30, 30, (m, 2)), rng.uniform(-np.pi, np.pi, m)
    lo, hi = cover_bounds(got, pc, ph)
    rlo, rhi = _ref_cover_bounds(centre, heading, half, start, count, owner, pc, ph)
    assert np.array_equal(lo, rlo) and np.array_equal(hi, rhi)


def test_the_lean_case_is_exercised():
    """The random frames above put boxes on leaning segments (else the lean arithmetic goes untested)."""
    from controllers.path import PathFrame, PathStack
    from tm.path_cover import stack_box_cover

    P = np.array([[0.0, 0.0], [10.0, 0.0], [20.0, 5.0], [30.0, 5.0]])
    stack = PathStack([PathFrame(P, np.array([0.0, 0.3, 0.0]))])
    got = stack_box_cover(stack, np.zeros(1, dtype=np.intp), np.array([2.0]), np.array([25.0]), np.array([-0.5]),
                          np.array([0.5]), 2.0, 2.0, 1.0, 1.0)
    assert (stack.body_heading[got.segment] != stack.heading[got.segment]).any()
    ref = _ref_stack_box_cover(stack, np.zeros(1, dtype=np.intp), np.array([2.0]), np.array([25.0]),
                               np.array([-0.5]), np.array([0.5]), *(np.full(1, e) for e in (2.0, 2.0, 1.0, 1.0)))
    assert np.array_equal(got.centre, ref[0]) and np.array_equal(got.half, ref[2])


# ----------------------------------------------------------------------------- exhaustive selection
def _ref_enumerate(size, nodes, leq, excl, w, local):
    """The numpy enumeration ``best_assignments`` replaced (tm/selection.py before it): every
    assignment of every component of one size scored at once, infeasible ones ``-inf``, the first
    argmax."""
    bits = ((np.arange(1 << size)[:, None] >> np.arange(size)) & 1).astype(bool)
    comp = np.full(int(nodes.max()) + 1, -1, dtype=np.intp)
    comp[nodes] = np.arange(len(nodes))[:, None]
    bad = np.zeros((len(nodes), 1 << size), dtype=bool)
    for rows, viol in ((leq, lambda a, b: a & ~b), (excl, lambda a, b: a & b)):
        for (i, j) in rows.tolist():
            bad[comp[i]] |= viol(bits[:, local[i]], bits[:, local[j]])
    score = np.where(bad, -np.inf, w[nodes] @ bits.T)
    return bits[np.argmax(score, axis=1)]


def _ref_select(n, leq, excl, w):
    """``select_optimal``'s exhaustive part with :func:`_ref_enumerate` (no forced stops; every
    component small): the Go mask."""
    from tm.selection import components
    go = np.ones(n, dtype=bool)
    edges = np.vstack([leq, excl])
    if not len(edges):
        return go
    label = components(n, edges)
    sizes = np.bincount(label, minlength=n)
    by_comp = np.argsort(label, kind="stable")
    first = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    local = np.empty(n, dtype=np.intp)
    local[by_comp] = np.arange(n) - np.repeat(first, sizes)
    for size in np.unique(sizes[sizes > 1]):
        comps = np.flatnonzero(sizes == size)
        nodes = by_comp[first[comps][:, None] + np.arange(size)]
        inside = np.zeros(n, dtype=bool)
        inside[nodes.ravel()] = True
        go[nodes] = _ref_enumerate(int(size), nodes, leq[inside[leq[:, 0]]], excl[inside[excl[:, 0]]], w, local)
    return go


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(2, 40), st.floats(0.0, 0.12), st.booleans())
def test_exhaustive_selection_equals_the_numpy_enumeration(seed, n, density, ties):
    """``select_optimal`` (compiled enumeration, ``tm.kernels.best_assignments``) gives the Go mask
    of the numpy enumeration it replaced on random constraint graphs of many components up to 14
    requesters, with the manager's weights (integers plus ``u / (2n)``) or exact ties (equal
    weights, no random part: then the first best assignment in counting order decides, in both)."""
    from tm.selection import select_optimal
    rng = np.random.default_rng(seed)
    pairs = np.array([(i, j) for i in range(n) for j in range(n) if i != j and abs(i - j) <= 4]).reshape(-1, 2)
    leq = pairs[rng.random(len(pairs)) < density]
    excl = pairs[(pairs[:, 0] < pairs[:, 1]) & (rng.random(len(pairs)) < 2 * density)]
    weights = np.full(n, 50) if ties else rng.integers(50, 60, n)

    class _NoNoise:  # exact ties: select_optimal adds rng.random(n) / (2n); here zeros
        def random(self, m):
            return np.zeros(m)

    gen = _NoNoise() if ties else np.random.default_rng(seed)
    go = select_optimal(n, np.zeros(n, dtype=int), leq, excl, weights, gen)
    w = np.asarray(weights, dtype=float) + (np.zeros(n) if ties else np.random.default_rng(seed).random(n) / (2 * n))
    from tm.selection import components
    sizes = np.bincount(components(n, np.vstack([leq, excl])), minlength=n) if len(leq) + len(excl) else np.ones(n)
    if sizes.max() > 14:  # a MILP component: not the kernel's
        return
    np.testing.assert_array_equal(go, _ref_select(n, leq, excl, w))


# ------------------------------------------------------------------ the claims after a decision
@pytest.mark.parametrize("p_go", [0.0, 0.4, 1.0])
@pytest.mark.parametrize("kc, kn", [(5, 5), (3, 5), (5, 2)])
def test_result_claims_are_the_new_rows_where_granted_else_the_current(p_go, kc, kn):
    """tm.manager._result_claims (tm.kernels.merge_rows): granted requesters' rows are their new
    claims, every other row the current one, bit for bit, the shorter horizon padded with its last slot."""
    from tm.manager import _Conflicts, _result_claims
    from tm.reach import pad_slots

    rng = np.random.default_rng(kc * 10 + kn)
    V, req = 9, np.array([0, 2, 3, 7, 8])
    cur, new = _random_claims(rng, V, kc, False), _random_claims(rng, len(req), kn, False)
    go = rng.random(len(req)) < p_go
    e = np.zeros((0, 2), dtype=np.intp)
    c = _Conflicts(req=req, cur=cur, new=new, fixed_hits=np.zeros(len(req), dtype=np.intp), leq=e, excl=e, edges=e,
                   edge_kinds=np.zeros(0, dtype="<U9"), seconds=(0.0, 0.0, 0.0))
    got = _result_claims(c, go)
    K = max(kc, kn)
    pc, pn = pad_slots(cur, K), pad_slots(new, K)
    lo, hi, centre, heading = pc.lo.copy(), pc.hi.copy(), cur.centre.copy(), cur.heading.copy()
    lo[req[go]], hi[req[go]], centre[req[go]], heading[req[go]] = pn.lo[go], pn.hi[go], new.centre[go], new.heading[go]
    assert np.array_equal(got.lo, lo) and np.array_equal(got.hi, hi)
    assert np.array_equal(got.centre, centre) and np.array_equal(got.heading, heading)
    assert np.array_equal(np.signbit(got.lo), np.signbit(lo)) and got.lo.shape == (V, K, 2)
    assert not np.shares_memory(got.lo, cur.lo) and not np.shares_memory(got.hi, new.hi)
