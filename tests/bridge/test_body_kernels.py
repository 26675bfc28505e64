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
