"""``searchsorted`` on a stacked buffer, each query searched only in its own rows (numba).

Several tables share one sorted buffer (every route's arc positions shifted by an offset:
:func:`controllers.speed_limits.bound_at`; every path frame's segment ends:
:class:`controllers.path.PathStack`), and every query's answer is clipped to the rows of its own
table: ``clip(searchsorted(a, x, side), lo, hi)``.  A binary search over the whole buffer (a
million rows at 1,000 vehicles) costs a cache miss per halving and a few array passes around it;
:func:`search_clipped` searches ``[lo, hi]`` alone, in one compiled loop, and gives the same index:
the buffer is sorted, so the first row past ``x`` lies before ``lo`` (then ``lo``), after ``hi``
(then ``hi``) or in the range, where both searches find it.  A NaN query sorts last in numpy (its
index clipped to ``hi``) and fails every comparison here (``hi`` too).
``tests/controllers/test_search_kernel.py`` compares it with numpy on random buffers.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["search_clipped", "bisect"]


@njit(cache=True)
def bisect(a, v, b0, b1, right):
    """The first row of ``a[b0:b1]`` (sorted) past ``v`` (``right``: ``a > v``; else ``a >= v``), else
    ``b1``: ``np.searchsorted(a[b0:b1], v, side) + b0`` for a number ``v``; a NaN ``v`` fails every
    comparison: ``b1`` (numpy sorts NaN last).  Compiled; for compiled callers (:func:`search_clipped`,
    :func:`bridge.body_kernels.sample_range`)."""
    while b0 < b1:
        m = (b0 + b1) // 2
        if (a[m] > v) if right else (a[m] >= v):
            b1 = m
        else:
            b0 = m + 1
    return b0


@njit(cache=True)
def _search_clipped(a, x, lo, hi, right):
    n = len(x)
    out = np.empty(n, dtype=np.intp)
    for q in range(n):
        # numpy's clip: with lo >= hi the upper bound wins (bisect returns it untouched)
        out[q] = bisect(a, x[q], lo[q], hi[q], right) if lo[q] < hi[q] else hi[q]
    return out


def search_clipped(a: np.ndarray, x: np.ndarray, lo, hi, side: str = "left") -> np.ndarray:
    """``np.clip(np.searchsorted(a, x, side), lo, hi)``, each query searched in ``[lo, hi]`` alone.

    Parameters
    ----------
    a : ndarray, shape (R,)
        Sorted (non-decreasing, no NaN).
    x : ndarray, shape (n,)
        Queries.
    lo, hi : int or ndarray of int, shape (n,)
        Each query's bounds, ``0 <= lo`` and ``hi <= R`` (``lo > hi``: ``hi``, as ``np.clip``).
    side : {"left", "right"}
        As ``np.searchsorted``.

    Returns
    -------
    ndarray of intp, shape (n,)
    """
    if side not in ("left", "right"):
        raise ValueError(f"search_clipped: side must be 'left' or 'right', got {side!r}")
    x = np.ascontiguousarray(x, dtype=float).reshape(-1)
    lo = np.ascontiguousarray(np.broadcast_to(np.asarray(lo, dtype=np.intp), x.shape))
    hi = np.ascontiguousarray(np.broadcast_to(np.asarray(hi, dtype=np.intp), x.shape))
    if len(x) and (lo.min() < 0 or hi.max() > len(a)):
        raise ValueError(f"search_clipped: bounds outside the buffer's 0 .. {len(a)}")
    # a strided buffer (a column of a table) as it is: a contiguous copy would cost more than the search
    return _search_clipped(np.asarray(a, dtype=float), x, lo, hi, side == "right")
