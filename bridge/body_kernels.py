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

from controllers.search_kernel import bisect

__all__ = ["sample_range", "path_pad_run", "path_pads_many", "nearest_on_segments"]


@njit(cache=True)
def sample_range(sig, arc, box_lo, box_hi):
    """``[lo, hi)``: the samples ``j`` with ``box_lo <= sig[j] - arc <= box_hi`` of a waypoint at arc
    ``arc`` (:meth:`bridge.sumo_body.PadTable._path_run`): bisection on ``arc + bound``, then the
    rounding's +-1 settled on the comparison itself."""
    n = len(sig)
    lo = bisect(sig, arc + box_lo, 0, n, False)
    hi = bisect(sig, arc + box_hi, 0, n, True)
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


@njit(cache=True)
def nearest_on_segments(Px, Py, A, i0, i1, px, py, one):
    """:meth:`bridge.body_fleet._Ragged.nearest_xy`'s projection (``_nearest``) as one loop: per row
    ``r`` (the last axis of ``px``, ``py`` (B, n)) the nearest point of the segments from global
    point ``i0[r]`` up to ``i1[r] - 1`` (``one``: its first segment only), the first of equal
    distances; returns the arc positions and signed offsets (left +), (B, n).  Each segment's
    quantities by ``_Ragged._segments``' operations and the projection by ``_nearest``'s, in their
    order, so the same floats (``tests/bridge/test_body_kernels.py`` compares them exactly); a row
    without a whole segment takes its first, as ``_nearest`` does.  The numpy form broadcast every
    row against its group's longest polyline: the largest cost of building a route's padding table
    (SUMO's ``A10KW``, 120 s under cProfile: 12.6 of 93 s)."""
    B, n = px.shape
    sig = np.empty((B, n))
    off = np.empty((B, n))
    last = len(A) - 1
    for r in range(n):
        a0 = i0[r]
        a1 = a0 + 1 if one else i1[r] - 1
        if a1 <= a0:
            a1 = a0 + 1
        for b in range(B):
            x, y = px[b, r], py[b, r]
            best = np.inf
            bj, bu, bqx, bqy = a0, 0.0, 0.0, 0.0
            for j in range(a0, a1):
                k = min(j + 1, last)
                dx = Px[k] - Px[j]
                dy = Py[k] - Py[j]
                ln2 = max(dx * dx + dy * dy, 1e-18)
                ax, ay = Px[j], Py[j]
                u = ((x - ax) * dx + (y - ay) * dy) / ln2
                u = min(max(u, 0.0), 1.0)
                qx = ax + u * dx
                qy = ay + u * dy
                d = np.hypot(x - qx, y - qy)
                if j == a0 or d < best:
                    best, bj, bu, bqx, bqy = d, j, u, qx, qy
            k = min(bj + 1, last)
            dx = Px[k] - Px[bj]
            dy = Py[k] - Py[bj]
            sq = np.sqrt(max(dx * dx + dy * dy, 1e-18))
            ux, uy = dx / sq, dy / sq
            sig[b, r] = A[bj] + bu * sq
            off[b, r] = ux * (y - bqy) - uy * (x - bqx)
    return sig, off
