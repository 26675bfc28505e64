"""Claims (tubes) of vehicles and the conflict test between them.

A claim is a family ``f``, a centre ``c`` (a waypoint), a set-membership
index ``l``, a heading ``θ`` and a footprint ``(length, width)``.  Its
footprint rectangle ``R(θ)`` is centred on the vehicle's state position.

* ``union`` claim (paper's condition (9)): ``c + H^{max(l-1,0)} ⊕ R(θ)``,
  with ``H`` the prefix hull of the family (``H^l = P^l`` when nested).
* ``timed`` claim sequence (design 3d): ``c + P^{max(l-k,0)} ⊕ R(θ)`` for
  ``k = 1, 2, ...``: where the vehicle's position can be at ``t + k``.

Two claims conflict under ``union`` when their union polygons are closer
than ``GEOMETRY_TOL``, under ``timed`` when their ``k``-th polygons are, for
some ``k = 1 .. max(l_i, l_j, 1)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.tolerances import GEOMETRY_TOL
from tm.families import FamilyTable
from tm.geometry import broad_phase, intersect_sat_indexed, minkowski_sum, rectangles

__all__ = ["Claims", "claim_conflicts", "conflicting_pairs", "CHECK_KINDS"]

CHECK_KINDS = ("union", "timed")


@dataclass(frozen=True, eq=False)
class Claims:
    """A batch of ``n`` claims (arrays of length ``n``).

    Parameters
    ----------
    table : FamilyTable
    family : ndarray of int, shape (n,)
    centre : ndarray, shape (n, 2)
    index : ndarray of int, shape (n,)
        ``0 <= index < table.n_levels[family]``.
    heading, length, width : ndarray, shape (n,)
    """

    table: FamilyTable
    family: np.ndarray
    centre: np.ndarray
    index: np.ndarray
    heading: np.ndarray
    length: np.ndarray
    width: np.ndarray

    def __post_init__(self) -> None:
        n = len(self.family)
        if self.centre.shape != (n, 2):
            raise ValueError(f"Claims.centre: shape must be ({n}, 2), got {self.centre.shape}")
        for name in ("index", "heading", "length", "width"):
            if getattr(self, name).shape != (n,):
                raise ValueError(f"Claims.{name}: shape must be ({n},), got {getattr(self, name).shape}")
        if n and (self.index.min() < 0 or np.any(self.index >= self.table.n_levels[self.family])):
            raise ValueError("Claims.index: must be in 0 .. N_f of the claim's family")

    def __len__(self) -> int:
        return len(self.family)

    def take(self, idx) -> Claims:
        """The claims at ``idx`` (int array or bool mask)."""
        return Claims(self.table, self.family[idx], self.centre[idx], self.index[idx],
                      self.heading[idx], self.length[idx], self.width[idx])

    @staticmethod
    def concat(first: Claims, *others: Claims) -> Claims:
        """Claims of ``first`` followed by those of ``others`` (same family table)."""
        parts = (first,) + others
        if any(c.table is not first.table for c in others):
            raise ValueError("Claims.concat: all claims must share one FamilyTable")
        return Claims(first.table, *(np.concatenate([getattr(c, f) for c in parts])
                                     for f in ("family", "centre", "index", "heading", "length", "width")))

    def aabb(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounding boxes ``(lo, hi)`` of the union claims; they contain every ``timed`` polygon too."""
        rows = self.table.rows(self.family, np.maximum(self.index - 1, 0))
        c, s = np.cos(self.heading), np.sin(self.heading)
        ac, as_ = np.abs(c), np.abs(s)
        a, b = 0.5 * self.length, 0.5 * self.width          # footprint half extents, turned
        ex, ey = a * ac + b * as_, a * as_ + b * ac
        lo, hi = self.table.lo[rows], self.table.hi[rows]   # copies (fancy indexing)
        rot = self.table.rotate[self.family]
        if rot.any():  # road-frame sets turn with the heading: box of the rotated hull
            box = rot & self.table.hull_box[rows]
            if box.any():  # a rectangle [lo, hi] turned by θ: centre turned, |R| half extents
                sel = slice(None) if box.all() else box
                L, H = lo[sel], hi[sel]
                mx, my = 0.5 * (L[:, 0] + H[:, 0]), 0.5 * (L[:, 1] + H[:, 1])
                hx, hy = 0.5 * (H[:, 0] - L[:, 0]), 0.5 * (H[:, 1] - L[:, 1])
                cb, sb, acb, asb = c[sel], s[sel], ac[sel], as_[sel]
                rx, ry = acb * hx + asb * hy, asb * hx + acb * hy
                cx, cy = cb * mx - sb * my, sb * mx + cb * my
                lo[sel, 0], lo[sel, 1] = cx - rx, cy - ry
                hi[sel, 0], hi[sel, 1] = cx + rx, cy + ry
            other = rot & ~box
            if other.any():
                P = _rotate(self.table.hulls[rows[other]], self.heading[other])
                lo[other], hi[other] = P.min(axis=1), P.max(axis=1)
        e = np.column_stack([ex, ey])
        return self.centre + lo - e, self.centre + hi + e

    def _polygons(self, stack: np.ndarray, level: np.ndarray, idx) -> np.ndarray:
        sel = slice(None) if idx is None else idx
        fam = self.family[sel]
        rows = self.table.rows(fam, level[sel])
        heading = self.heading[sel]
        rect = rectangles(heading, self.length[sel], self.width[sel])
        sets = stack[rows]
        rot = self.table.rotate[fam]
        if rot.any():
            sets = sets.copy()
            sets[rot] = _rotate(sets[rot], heading[rot])
        return minkowski_sum(sets, rect) + self.centre[sel][:, None, :]

    def polygons(self, idx=None) -> np.ndarray:
        """Union claim polygons ``c + H^{max(l-1,0)} ⊕ R(θ)``, shape (n, K, 2)."""
        return self._polygons(self.table.hulls, np.maximum(self.index - 1, 0), idx)

    def polygons_at(self, k: int, idx=None) -> np.ndarray:
        """``k``-th timed claim polygons ``c + P^{max(l-k,0)} ⊕ R(θ)``, shape (n, K, 2)."""
        if k < 1:
            raise ValueError(f"polygons_at: k must be >= 1, got {k}")
        return self._polygons(self.table.levels, np.maximum(self.index - k, 0), idx)


def _rotate(P: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """Rotate polygons ``(n, K, 2)`` about the origin by ``heading (n,)`` (CCW order is kept)."""
    c, s = np.cos(heading)[:, None], np.sin(heading)[:, None]
    x, y = P[..., 0], P[..., 1]
    return np.stack([c * x - s * y, s * x + c * y], axis=-1)


def _pair_test(claims: Claims, i, j, level, stack, is_box, lo, hi, tol) -> np.ndarray:
    """Whether ``c + stack[level] ⊕ R(θ)`` of claims ``i[t]`` and ``j[t]`` meet (within ``tol``).

    Pairs of two oriented boxes -- a rotating family whose set is a rectangle of its
    frame, plus the footprint turned the same way -- take a four-axis separating-axis
    test in closed form; the others the general polygon test.
    """
    fam = claims.family
    rows = claims.table.rows(fam, level)
    box = is_box[rows] & claims.table.rotate[fam]
    both = box[i] & box[j]
    out = np.empty(len(i), dtype=bool)
    if both.any():
        out[both] = _obb_overlap(claims, rows, lo, hi, i[both], j[both], tol)
    rest = ~both
    if rest.any():
        a, b = i[rest], j[rest]
        uniq, inv = np.unique(np.concatenate([a, b]), return_inverse=True)
        n = len(a)
        out[rest] = intersect_sat_indexed(claims._polygons(stack, level, uniq), inv[:n], inv[n:], tol)
    return out


def _obb_overlap(claims: Claims, rows, lo, hi, i, j, tol) -> np.ndarray:
    """Separating-axis test of oriented boxes ``centre + R(θ) ([lo, hi] ⊕ footprint)``: the
    four edge normals; separated when a gap exceeds ``tol`` (as :func:`intersect_sat`)."""
    def box(v):
        r = rows[v]
        c, s = np.cos(claims.heading[v]), np.sin(claims.heading[v])
        mx, my = 0.5 * (lo[r, 0] + hi[r, 0]), 0.5 * (lo[r, 1] + hi[r, 1])
        cx = claims.centre[v, 0] + c * mx - s * my
        cy = claims.centre[v, 1] + s * mx + c * my
        hx = 0.5 * (hi[r, 0] - lo[r, 0]) + 0.5 * claims.length[v]
        hy = 0.5 * (hi[r, 1] - lo[r, 1]) + 0.5 * claims.width[v]
        return cx, cy, c, s, hx, hy

    ax, ay, ac, as_, ahx, ahy = box(i)
    bx, by, bc, bs, bhx, bhy = box(j)
    dx, dy = bx - ax, by - ay
    # |cos| and |sin| of the angle between the boxes' axes
    cc = np.abs(ac * bc + as_ * bs)
    ss = np.abs(ac * bs - as_ * bc)
    sep = np.abs(dx * ac + dy * as_) - (ahx + bhx * cc + bhy * ss) > tol      # a's u axis
    sep |= np.abs(-dx * as_ + dy * ac) - (ahy + bhx * ss + bhy * cc) > tol    # a's v axis
    sep |= np.abs(dx * bc + dy * bs) - (bhx + ahx * cc + ahy * ss) > tol      # b's u axis
    sep |= np.abs(-dx * bs + dy * bc) - (bhy + ahx * ss + ahy * cc) > tol     # b's v axis
    return ~sep


def claim_conflicts(claims: Claims, i, j, check: str = "union", tol: float = GEOMETRY_TOL) -> np.ndarray:
    """Narrow phase: whether claims ``i[t]`` and ``j[t]`` conflict, for each pair ``t``.

    Parameters
    ----------
    claims : Claims
    i, j : ndarray of int, shape (p,)
    check : {"union", "timed"}
    tol : float
        Touching within ``tol`` counts as a conflict.

    Returns
    -------
    ndarray of bool, shape (p,)
    """
    i = np.asarray(i, dtype=np.intp)
    j = np.asarray(j, dtype=np.intp)
    p = len(i)
    if check not in CHECK_KINDS:
        raise ValueError(f"check: must be one of {CHECK_KINDS}, got {check!r}")
    if p == 0:
        return np.zeros(0, dtype=bool)
    if check == "union":
        return _pair_test(claims, i, j, np.maximum(claims.index - 1, 0), claims.table.hulls,
                          claims.table.hull_box, claims.table.lo, claims.table.hi, tol)
    out = np.zeros(p, dtype=bool)
    kmax = np.maximum(np.maximum(claims.index[i], claims.index[j]), 1)
    active = np.arange(p)
    for k in range(1, int(kmax.max()) + 1):
        active = active[kmax[active] >= k]
        if len(active) == 0:
            break
        t = claims.table
        hit = _pair_test(claims, i[active], j[active], np.maximum(claims.index - k, 0), t.levels, t.level_box,
                         t.level_lo, t.level_hi, tol)
        out[active[hit]] = True          # early exit: a conflicting pair is decided
        active = active[~hit]
    return out


def conflicting_pairs(claims: Claims, check: str = "union", mask=None,
                      tol: float = GEOMETRY_TOL) -> tuple[np.ndarray, np.ndarray]:
    """All conflicting pairs ``i < j`` among ``claims`` (broad phase + narrow phase).

    Parameters
    ----------
    claims : Claims
    check : {"union", "timed"}
    mask : array_like of bool, optional
        Only pairs with at least one claim in ``mask``.
    tol : float
    """
    lo, hi = claims.aabb()
    i, j = broad_phase(lo, hi, tol, mask=mask)
    hit = claim_conflicts(claims, i, j, check, tol)
    return i[hit], j[hit]
