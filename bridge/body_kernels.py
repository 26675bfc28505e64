"""Compiled lookups of the claims' body padding on path-frame routes (:class:`bridge.sumo_body.PadTable`).

A waypoint's padding is a maximum over the route's samples of SUMO's body reach beyond the
rectangle, for the samples of the waypoint's box still ahead of the vehicle.  The numpy code looked
one vehicle and waypoint up at a time (a few hundred lookups per step at 1,000 vehicles: the
junction gate's paths, the claims of every group), a dozen small array calls each; these loops do
the same comparisons and maxima on the same floats (``tests/bridge/test_body_kernels.py`` compares
them exactly with the numpy code).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["sample_range", "path_pad_run", "path_pads_many"]


@njit(cache=True)
def _search(sig, x, right):
    """``np.searchsorted(sig, x, side="right" if right else "left")``."""
    lo, hi = 0, len(sig)
    while lo < hi:
        m = (lo + hi) >> 1
        if sig[m] < x or (right and sig[m] == x):
            lo = m + 1
        else:
            hi = m
    return lo


@njit(cache=True)
def sample_range(sig, arc, box_lo, box_hi):
    """``[lo, hi)``: the samples ``j`` with ``box_lo <= sig[j] - arc <= box_hi`` of a waypoint at arc
    ``arc`` (:meth:`bridge.sumo_body.PadTable._path_run`): bisection on ``arc + bound``, then the
    rounding's +-1 settled on the comparison itself."""
    n = len(sig)
    lo = _search(sig, arc + box_lo, False)
    hi = _search(sig, arc + box_hi, True)
    if lo > 0 and sig[max(lo - 1, 0)] - arc >= box_lo:
        lo -= 1
    if lo < n and sig[min(lo, n - 1)] - arc < box_lo:
        lo += 1
    if hi < n and sig[min(hi, n - 1)] - arc <= box_hi:
        hi += 1
    if hi > 0 and sig[max(hi - 1, 0)] - arc > box_hi:
        hi -= 1
    return lo, hi


@njit(cache=True)
def path_pad_run(sig, arc, box_lo, box_hi, reach_T, half, j0):
    """:meth:`bridge.sumo_body.PadTable._path_run`: ``(pads (4,), j1)``, the maxima of ``reach - half``
    over the waypoint's samples from ``j0`` on (0 where not positive) and the last window start with
    the same pads (``-1``: the pads are zero from there on, any window start)."""
    out = np.zeros(4)
    lo, hi = sample_range(sig, arc, box_lo, box_hi)
    a, b = max(lo, j0), hi
    if a >= b:
        return out, -1
    r = np.empty(4)
    any_pos = False
    for p in range(4):
        m = reach_T[p, a] - half[p]
        for j in range(a + 1, b):
            v = reach_T[p, j] - half[p]
            if v > m:
                m = v
        r[p] = m
        any_pos = any_pos or m > 0.0
    if not any_pos:
        return out, -1
    last = b - a - 1
    for p in range(4):
        if r[p] > 0.0:
            j = b - 1
            while reach_T[p, j] - half[p] != r[p]:  # the last sample reaching the maximum
                j -= 1
            last = min(last, j - a)
        out[p] = r[p] if r[p] >= 0.0 else 0.0
    return out, a + last


@njit(cache=True)
def path_pads_many(sig, arc_k, ks, box_lo, box_hi, reach_T, half, j0):
    """:meth:`bridge.sumo_body.PadTable.pads_many` (path frame): the pads (m, 4) of waypoints ``ks`` for
    the window starting at sample ``j0``: per side the maximum of the reach over the samples, less the
    half extent, at least 0."""
    m = len(ks)
    out = np.zeros((m, 4))
    for i in range(m):
        lo, hi = sample_range(sig, arc_k[ks[i]], box_lo, box_hi)
        a = max(lo, j0)
        if a >= hi:
            continue
        for p in range(4):
            x = reach_T[p, a]
            for j in range(a + 1, hi):
                if reach_T[p, j] > x:
                    x = reach_T[p, j]
            d = x - half[p]
            out[i, p] = d if d >= 0.0 else 0.0
    return out
