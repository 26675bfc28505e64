"""The compiled padding lookups (bridge/body_kernels.py) against the numpy code they replaced in
:class:`bridge.sumo_body.PadTable` (copied below as the reference): the same sample ranges, maxima
and run ends, exactly, on random sample grids, waypoint arcs on and between samples (the +-1 of the
rounding), boxes, reaches with ties and window starts."""

import sys

import numpy as np
from hypothesis import given, settings, strategies as st

from bridge.body_kernels import path_pad_run, path_pads_many


def _ref_range(sig, arc, box_lo, box_hi):
    n = len(sig)
    lo = np.searchsorted(sig, arc + box_lo, side="left")
    hi = np.searchsorted(sig, arc + box_hi, side="right")
    lo -= (lo > 0) & (sig[np.maximum(lo - 1, 0)] - arc >= box_lo)
    lo += (lo < n) & (sig[np.minimum(lo, n - 1)] - arc < box_lo)
    hi += (hi < n) & (sig[np.minimum(hi, n - 1)] - arc <= box_hi)
    hi -= (hi > 0) & (sig[np.maximum(hi - 1, 0)] - arc > box_hi)
    return lo, hi


def _ref_run(sig, arc_k, k, box_lo, box_hi, reach_T, half, j0):
    lo, hi = _ref_range(sig, arc_k[np.array([k])], box_lo, box_hi)
    a, b = max(int(lo[0]), j0), int(hi[0])
    if a >= b:
        return np.zeros(4), sys.maxsize
    v = reach_T[:, a:b] - half[:, None]
    r = v.max(axis=1)
    pos = r > 0.0
    if not pos.any():
        return np.zeros(4), sys.maxsize
    last = (b - a - 1) - np.argmax(v[pos][:, ::-1] == r[pos, None], axis=1)
    return np.maximum(r, 0.0), a + int(last.min())


def _ref_many(sig, arc_k, ks, box_lo, box_hi, reach_T, half, j0):
    out = np.zeros((len(ks), 4))
    lo, hi = _ref_range(sig, arc_k[ks], box_lo, box_hi)
    a = np.maximum(lo, j0)
    ok = a < hi
    if not ok.any():
        return out
    a, b = a[ok], hi[ok]
    idx = np.empty(2 * len(a), dtype=np.intp)
    idx[0::2], idx[1::2] = a, b
    m = np.maximum.reduceat(reach_T, idx, axis=1)[:, 0::2]
    out[ok] = np.maximum(m.T - half, 0.0)
    return out


@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 200), ties=st.booleans())
def test_padding_lookups_equal_the_numpy_code(seed, n, ties):
    rng = np.random.default_rng(seed)
    sig = np.linspace(0.0, 0.1 * (n - 1), n)
    K = 12
    arc_k = np.sort(np.where(rng.random(K) < 0.4, sig[rng.integers(0, n, K)], rng.uniform(-2, sig[-1] + 2, K)))
    box_lo, box_hi = -float(rng.uniform(0, 3)), float(rng.uniform(0, 6))
    if ties:  # box edges at sample differences: samples exactly on an edge (the rounding's +-1)
        i = rng.integers(0, n, 4)
        box_lo, box_hi = float(min(sig[i[0]] - sig[i[1]], 0.0)), float(max(sig[i[2]] - sig[i[3]], 0.0))
    reach_T = rng.uniform(0, 4, (4, n + 1))
    if ties:  # equal maxima along a side: the run's end is the last of them
        reach_T = np.round(reach_T)
    half = rng.uniform(0.5, 3.5, 4)
    for k in range(K):
        j0 = int(rng.integers(-1, n + 1))
        got = path_pad_run(sig, float(arc_k[k]), box_lo, box_hi, reach_T, half, j0)
        want = _ref_run(sig, arc_k, k, box_lo, box_hi, reach_T, half, j0)
        assert np.array_equal(got[0], want[0])
        assert (sys.maxsize if got[1] < 0 else got[1]) == want[1]
    ks = rng.integers(0, K, 20)
    j0 = int(rng.integers(0, n))
    assert np.array_equal(path_pads_many(sig, arc_k, ks, box_lo, box_hi, reach_T, half, j0),
                          _ref_many(sig, arc_k, ks, box_lo, box_hi, reach_T, half, j0))


def _ref_segments(R, i, keys):
    """``_Ragged._segments`` as it was for the numpy projection: per global point ``i``, ``Dx, Dy``
    (to the next point), the squared length ``ln2`` (at least 1e-18), its root ``sq`` and ``Ux, Uy``
    (``d / sq``)."""
    dx, dy = R._segments(i, ("Dx", "Dy"))
    ln2 = np.maximum(dx * dx + dy * dy, 1e-18)
    sq = np.sqrt(ln2)
    got = dict(Dx=dx, Dy=dy, ln2=ln2, sq=sq, Ux=dx / sq, Uy=dy / sq)
    return [got[k] for k in keys]


def _ref_nearest(R, i0, i1, px, py, nseg):
    """``_Ragged._nearest`` as it was in numpy (the reference), on ragged polylines ``R``."""
    M = int(nseg.max(initial=0))
    if M <= 1:  # one segment each: no search
        J = i0
        dx, dy, ln2, sq, ux, uy = _ref_segments(R, J, ("Dx", "Dy", "ln2", "sq", "Ux", "Uy"))
        ax, ay = R.Px[J], R.Py[J]
        u = np.clip(((px - ax) * dx + (py - ay) * dy) / ln2, 0.0, 1.0)
        qx, qy = ax + u * dx, ay + u * dy
        return R.A[J] + u * sq, ux * (py - qy) - uy * (px - qx)
    J = i0[:, None] + np.arange(M)[None, :]  # (n, M)
    valid = J < (i1 - 1)[:, None]
    J = np.where(valid, J, i0[:, None])
    dx, dy, ln2 = _ref_segments(R, J, ("Dx", "Dy", "ln2"))
    ax, ay = R.Px[J], R.Py[J]
    pxm, pym = px[..., None], py[..., None]  # (..., n, 1) against (n, M)
    u = np.clip(((pxm - ax) * dx + (pym - ay) * dy) / ln2, 0.0, 1.0)
    qx, qy = ax + u * dx, ay + u * dy
    dist = np.where(valid, np.hypot(pxm - qx, pym - qy), np.inf)
    j = np.argmin(dist, axis=-1)[..., None]

    def pick(a):
        return np.take_along_axis(np.broadcast_to(a, dist.shape), j, axis=-1)[..., 0]

    uj, qxj, qyj, jj = pick(u), pick(qx), pick(qy), pick(J)
    sq, ux, uy = _ref_segments(R, jj, ("sq", "Ux", "Uy"))
    return R.A[jj] + uj * sq, ux * (py - qyj) - uy * (px - qxj)


@st.composite
def _ragged_queries(draw):
    """Polylines of 1 to 12 segments (some of zero length, some with ties in distance), rows on
    them of like or mixed segment counts, points near and far, one or three offsets a row."""
    from bridge.body_fleet import _Ragged

    lines = []
    for _ in range(draw(st.integers(1, 5))):
        m = draw(st.integers(2, 13))
        P = np.array(draw(st.lists(st.tuples(st.integers(-20, 20), st.integers(-20, 20)), min_size=m, max_size=m)),
                     dtype=float) * draw(st.sampled_from([1.0, 0.5, 0.37]))
        A = np.r_[0.0, np.cumsum(np.hypot(*np.diff(P, axis=0).T))]
        lines.append((P, A))
    R = _Ragged(lines, per_segment=draw(st.booleans()))
    n = draw(st.integers(1, 8))
    g = np.array(draw(st.lists(st.integers(0, len(lines) - 1), min_size=n, max_size=n)), dtype=np.intp)
    B = draw(st.sampled_from([1, 3]))
    pts = np.array(draw(st.lists(st.floats(-30, 30, allow_nan=False, width=32), min_size=2 * B * n,
                                 max_size=2 * B * n)), dtype=float).reshape(2, B, n)
    if B == 1 and draw(st.booleans()):
        pts = pts[:, 0]
    return R, R.start[g], R.start[g] + R.count[g], pts[0], pts[1]


@settings(max_examples=300, deadline=None)
@given(_ragged_queries(), st.booleans())
def test_nearest_on_segments_is_the_numpy_projection(q, first_only):
    """The compiled projection (bridge.body_kernels.nearest_on_segments, FleetBodies' largest cost
    in building padding tables) gives the numpy code's arc positions and offsets exactly (tolerance
    0: the same operations in the same order), on every segment or the first only, one or several
    points a row, rows of different lengths."""
    R, i0, i1, px, py = q
    nseg = i1 - i0 - 1
    if first_only:
        nseg = np.minimum(nseg, 1)
    got = R._nearest(i0, i1, px, py, nseg)
    want = _ref_nearest(R, i0, i1, px, py, nseg)
    assert got[0].shape == want[0].shape == np.shape(px)
    assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
