"""Per-level position tables of a movement-authority family (design.md §7).

For the along-road factor ``T^m`` (a convex polygon in ``(p, v)``, centred on the
waypoint ``c``) the traffic manager's reach-tightened claims need, for a velocity
bound ``w``,

* ``g_m(w) = max{p : (p, v) ∈ T^m, v >= w}``: the furthest a state of ``T^m`` whose
  velocity is at least ``w`` can be ahead of ``c`` (``-inf`` when no such state), and
* ``h_m(w) = min{p : (p, v) ∈ T^m, v <= w}``: the furthest it can be behind ``c``
  when its velocity is at most ``w`` (``+inf`` when none).

Both are tabulated on a uniform velocity grid and looked up on the safe side:
``g`` is non-increasing in ``w``, so :meth:`AuthorityTables.g` reads the grid point at
or below ``w`` (a value >= the true one); ``h`` is non-increasing too, so
:meth:`AuthorityTables.h` reads the grid point at or above ``w`` (a value <= the true
one).  Computed values are rounded outward by ``AUTHORITY_TABLE_TOL``.  The tables also
hold the velocity range of every level and the across-road position extent, so a claim
box needs no polygon at run time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers import tolerances as tol
from controllers.synthesis import SetFamily, SynthesisError, along_factor

__all__ = ["AuthorityTables", "build_tables", "g_exact", "h_exact"]

#: Default velocity resolution of the tables (m/s): at the steepest boundary slope of the car's
#: sets (dp/dv ~ v / a ~ 6 s) the safe-side lookup then gives away at most ~6 cm.
DEFAULT_DV = 0.01


def _crossings(V: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Positions where the polygon's edges cross ``v = w`` (NaN where an edge does not): (W, k)."""
    P0, P1 = V, np.roll(V, -1, axis=0)
    dv = P1[:, 1] - P0[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[:, None] - P0[None, :, 1]) / dv[None, :]
    ok = (dv[None, :] != 0) & (t >= 0) & (t <= 1)
    p = P0[None, :, 0] + t * (P1[None, :, 0] - P0[None, :, 0])
    return np.where(ok, p, np.nan)


def g_exact(V: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``g(w)`` of the convex polygon with vertices ``V`` (k, 2) in ``(p, v)``, no rounding."""
    w = np.atleast_1d(np.asarray(w, dtype=float))
    cand = np.where(V[None, :, 1] >= w[:, None], V[None, :, 0], -np.inf)
    cr = _crossings(V, w)
    return np.maximum(cand.max(axis=1), np.nanmax(np.where(np.isnan(cr), -np.inf, cr), axis=1))


def h_exact(V: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``h(w)`` of the convex polygon with vertices ``V`` (k, 2) in ``(p, v)``, no rounding."""
    w = np.atleast_1d(np.asarray(w, dtype=float))
    cand = np.where(V[None, :, 1] <= w[:, None], V[None, :, 0], np.inf)
    cr = _crossings(V, w)
    return np.minimum(cand.min(axis=1), np.nanmin(np.where(np.isnan(cr), np.inf, cr), axis=1))


def _ccw(V: np.ndarray) -> np.ndarray:
    """Vertices of a convex polygon in counter-clockwise order (sorted by angle about the centroid)."""
    c = V.mean(axis=0)
    return V[np.argsort(np.arctan2(V[:, 1] - c[1], V[:, 0] - c[0]))]


def _chain(V: np.ndarray, right: bool) -> tuple[np.ndarray, np.ndarray]:
    """The right (``p`` largest) or left boundary of a CCW convex polygon as ``(v, p)`` with ``v``
    increasing: CCW from the bottom runs up the right side, clockwise up the left side."""
    k = len(V)
    v = V[:, 1]
    lo_i = np.flatnonzero(v == v.min())
    hi_i = np.flatnonzero(v == v.max())
    order = np.arange(k) if right else np.arange(k)[::-1]  # CCW, or clockwise
    pos = np.empty(k, dtype=np.intp)
    pos[order] = np.arange(k)
    # start: the bottom vertex furthest along the walk's bottom edge (rightmost / leftmost)
    start = max(lo_i, key=lambda i: (V[i, 0] if right else -V[i, 0]))
    seq = np.roll(order, -int(pos[start]))
    stop = int(np.flatnonzero(np.isin(seq, hi_i))[0])
    idx = seq[:stop + 1]
    return V[idx, 1], V[idx, 0]


def _g_fast(V: np.ndarray, w: np.ndarray) -> np.ndarray:
    """:func:`g_exact` on a grid via the right boundary (concave): ``p_right(max(w, v*))``."""
    vc, pc = _chain(V, right=True)
    vstar = vc[int(np.argmax(pc))]
    out = np.interp(np.maximum(w, vstar), vc, pc)
    return np.where(w > vc[-1], -np.inf, out)


def _h_fast(V: np.ndarray, w: np.ndarray) -> np.ndarray:
    """:func:`h_exact` on a grid via the left boundary (convex): ``p_left(min(w, v_*))``."""
    vc, pc = _chain(V, right=False)
    vstar = vc[int(np.argmin(pc))]
    out = np.interp(np.minimum(w, vstar), vc, pc)
    return np.where(w < vc[0], np.inf, out)


@dataclass(frozen=True, eq=False)
class AuthorityTables:
    """Safe-side tables of one family's levels ``0 .. N`` (read-only arrays).

    Attributes
    ----------
    w0, dw : float
        Velocity grid ``w_j = w0 + j dw``, ``j = 0 .. W-1``.
    G, H : ndarray, shape (N+1, W)
        ``g_m(w_j)`` rounded up and ``h_m(w_j)`` rounded down.
    v_lo, v_hi : ndarray, shape (N+1,)
        Velocity range of the along factor of ``T^m``.
    p_lo, p_hi : ndarray, shape (N+1,)
        Along-road position range of ``T^m``.
    y_lo, y_hi : ndarray, shape (N+1,)
        Across-road position range of ``T^m``.
    """

    w0: float
    dw: float
    G: np.ndarray
    H: np.ndarray
    v_lo: np.ndarray
    v_hi: np.ndarray
    p_lo: np.ndarray
    p_hi: np.ndarray
    y_lo: np.ndarray
    y_hi: np.ndarray

    @property
    def N(self) -> int:
        return self.G.shape[0] - 1

    def g(self, m: np.ndarray, w: np.ndarray) -> np.ndarray:
        """Upper bound on ``g_m(w)`` (elementwise over ``m``, ``w``): grid point at or below ``w``."""
        j = np.clip(np.floor((np.asarray(w, dtype=float) - self.w0) / self.dw), 0, self.G.shape[1] - 1)
        return self.G[np.asarray(m, dtype=np.intp), j.astype(np.intp)]

    def h(self, m: np.ndarray, w: np.ndarray) -> np.ndarray:
        """Lower bound on ``h_m(w)``: grid point at or above ``w``."""
        j = np.clip(np.ceil((np.asarray(w, dtype=float) - self.w0) / self.dw), 0, self.H.shape[1] - 1)
        return self.H[np.asarray(m, dtype=np.intp), j.astype(np.intp)]


def build_tables(family: SetFamily, dw: float = DEFAULT_DV) -> AuthorityTables:
    """Tables of every level of ``family`` (its along factor must be 2-D: ``(p, v)``).

    Raises
    ------
    SynthesisError
        If the along factor is not two-dimensional, or ``dw`` is not > 0.
    """
    if not dw > 0:
        raise SynthesisError(f"authority tables: the velocity resolution dw must be > 0 m/s, got {dw}")
    k_al = along_factor(family)
    f = family.factors[k_al]
    if len(f.states) != 2 or 2 not in f.states:
        raise SynthesisError(f"{family.model.name}: authority tables need a 2-D along factor (p_x, v_x), "
                             f"this one has states {f.states.tolist()}")
    ip, iv = list(f.states).index(0), list(f.states).index(2)
    polys = [_ccw(lev.vertices[:, [ip, iv]]) for lev in f.levels]
    v_lo = np.array([P[:, 1].min() for P in polys])
    v_hi = np.array([P[:, 1].max() for P in polys])
    w0 = float(np.floor(v_lo.min() / dw) * dw)
    W = int(np.ceil((v_hi.max() - w0) / dw)) + 1
    w = w0 + dw * np.arange(W)
    G = np.vstack([_g_fast(P, w) for P in polys]) + tol.AUTHORITY_TABLE_TOL
    H = np.vstack([_h_fast(P, w) for P in polys]) - tol.AUTHORITY_TABLE_TOL
    ylo, yhi = [], []
    k_y = next(k for k, fa in enumerate(family.factors) if 1 in fa.states)
    fy = family.factors[k_y]
    jy = list(fy.states).index(1)
    for lev in fy.levels:
        ylo.append(lev.vertices[:, jy].min())
        yhi.append(lev.vertices[:, jy].max())
    arrs = dict(G=G, H=H, v_lo=v_lo, v_hi=v_hi, p_lo=np.array([P[:, 0].min() for P in polys]),
                p_hi=np.array([P[:, 0].max() for P in polys]), y_lo=np.array(ylo), y_hi=np.array(yhi))
    for a in arrs.values():
        a.flags.writeable = False
    return AuthorityTables(w0=w0, dw=float(dw), **arrs)
