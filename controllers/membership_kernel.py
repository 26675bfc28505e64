"""Nested-level membership index of polar-table factors in one compiled loop (numba).

:func:`controllers.stmpc._nested_index` finds ``min{l : e ∈ T^l}`` by a binary search over the
levels, for every row at once, each step a vectorised membership test; with the sector tables of
:class:`controllers.stmpc._Polar` a test is one ``searchsorted`` and one row.  Done per row in a
compiled loop the same search is a few dozen operations instead of a dozen array passes per step
(the index is asked for several times per vehicle and step: requests, claims' across extent,
control).  :class:`PolarStack` holds the sector tables of one or several factors side by side;
:func:`polar_index` is the binary search with the membership of every factor (the joint index of
:meth:`controllers.stmpc.STMPC.index`: a level holds a row when every factor's level does).

Same floating-point operations as ``_Polar.inside`` (the angles ``arctan2`` are computed by the
caller with numpy, once per row: the search adds ``4 pi l`` as numpy did), so the same indices:
``tests/controllers/test_membership_kernel.py``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from controllers.tolerances import MEMBERSHIP_TOL

__all__ = ["PolarStack", "polar_index"]


class PolarStack:
    """The sector tables of factors ``polars`` (each a :class:`controllers.stmpc._Polar`) concatenated:
    ``keys``, ``a0``, ``a1``, ``b`` (flat), ``kstart`` (F + 1,) the factors' ranges in them,
    ``first``, ``last`` (F, L) each level's sector range, flat indices."""

    def __init__(self, polars):
        off = np.concatenate([[0], np.cumsum([len(p.keys) for p in polars])]).astype(np.intp)
        self.keys = np.concatenate([p.keys for p in polars])
        self.a0 = np.concatenate([p.a0 for p in polars])
        self.a1 = np.concatenate([p.a1 for p in polars])
        self.b = np.concatenate([p.b for p in polars])
        self.kstart = off
        self.first = np.stack([np.asarray(p.first, dtype=np.intp) + o for p, o in zip(polars, off)])
        self.last = np.stack([np.asarray(p.last, dtype=np.intp) + o for p, o in zip(polars, off)])

    def index(self, xy: list, N: int, steps: int) -> np.ndarray:
        """``min{l : (x_f, y_f) ∈ level l of factor f for every f}`` per row (``N + 1`` where none),
        ``xy``: per factor its error's two coordinates ``(x, y)`` (n,) each, in the tables' order."""
        X = np.ascontiguousarray(np.stack([p[0] for p in xy]), dtype=float)
        Y = np.ascontiguousarray(np.stack([p[1] for p in xy]), dtype=float)
        return polar_index(np.arctan2(Y, X), X, Y, self.keys, self.a0, self.a1, self.b, self.kstart, self.first,
                           self.last, N, steps, MEMBERSHIP_TOL)


@njit(cache=True)
def polar_index(ang, X, Y, keys, a0, a1, b, kstart, first, last, N, steps, tol):
    """The binary search of :func:`controllers.stmpc._nested_index` over ``[0, N + 1]`` per row,
    membership by the sector tables of every factor (``ang``, ``X``, ``Y``: (F, n))."""
    F, n = X.shape
    out = np.empty(n, dtype=np.intp)
    c4 = 4.0 * np.pi
    for i in range(n):
        lo, hi = 0, N + 1
        for _ in range(steps):
            if lo >= hi:
                break
            mid = min((lo + hi) // 2, N)
            ok = True
            for f in range(F):
                q = ang[f, i] + c4 * mid
                L, H = kstart[f], kstart[f + 1]  # searchsorted(keys, q, side="right") in the factor's keys
                while L < H:
                    m = (L + H) >> 1
                    if keys[m] <= q:
                        L = m + 1
                    else:
                        H = m
                pos = L - 1
                if pos < first[f, mid]:  # before the level's first vertex: wrap
                    pos = last[f, mid]
                if not (a0[pos] * X[f, i] + a1[pos] * Y[f, i] - b[pos] <= tol):
                    ok = False
                    break
            if ok:
                hi = mid
            else:
                lo = mid + 1
        out[i] = hi
    return out
