"""Position-set families of the vehicle classes, stacked for vectorised look-up.

A family is the list ``P^0, ..., P^N`` of 2-D position projections of a
class's ST-MPC sets, CCW convex polygons centred at the origin.  The traffic
manager needs, per family and level ``l``:

* ``P^l`` itself (the ``timed`` check compares ``P^{max(l-k,0)}``), and
* the *prefix hull* ``H^l = conv(P^0 ∪ ... ∪ P^l)``, a convex superset of
  the union in the paper's condition (9).  For nested families
  (``P^0 ⊆ P^1 ⊆ ...``, the ST-MPC case) ``H^l = P^l`` exactly and the
  table stores ``P^l`` itself; otherwise the hull keeps the ``union`` check
  sound (conservative).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from controllers.tolerances import CONTAINMENT_TOL, GEOMETRY_TOL
from tm.geometry import convex_hull, halfspaces, is_convex_ccw

__all__ = ["FamilyTable", "FamilyError", "build_family_table", "pad_polygons"]


class FamilyError(ValueError):
    """Invalid family of position sets; the message names the family and level."""


def pad_polygons(polys: Sequence[np.ndarray], k: int | None = None) -> np.ndarray:
    """Stack polygons ``(k_i, 2)`` into ``(n, k, 2)`` by repeating each one's last vertex."""
    k = k or max(len(p) for p in polys)
    out = np.empty((len(polys), k, 2))
    for t, p in enumerate(polys):
        out[t, :len(p)] = p
        out[t, len(p):] = p[-1]
    return out


def _contains(P: np.ndarray, Q: np.ndarray) -> bool:
    """Whether convex polygon ``P`` contains every vertex of ``Q`` (within CONTAINMENT_TOL)."""
    A, b = halfspaces(P)
    return bool(np.all(Q @ A.T <= b + CONTAINMENT_TOL))


def _is_box(P: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Rows of the padded stack ``P (T, K, 2)`` that are their bounding box ``[lo, hi]``:
    every vertex at a corner (within GEOMETRY_TOL) and all four corners present."""
    on = [(np.abs(P[..., d] - lo[:, None, d]) <= GEOMETRY_TOL, np.abs(P[..., d] - hi[:, None, d]) <= GEOMETRY_TOL)
          for d in (0, 1)]
    at_corner = (on[0][0] | on[0][1]) & (on[1][0] | on[1][1])
    corners = [(on[0][a] & on[1][b]).any(axis=1) for a in (0, 1) for b in (0, 1)]
    return at_corner.all(axis=1) & np.logical_and.reduce(corners)


@dataclass(frozen=True, eq=False)
class FamilyTable:
    """All families' levels in one padded stack (read-only arrays).

    Attributes
    ----------
    keys : tuple of str
        Family keys; family ``f`` is ``keys[f]``.
    offset : ndarray of int, shape (F,)
        Row of level 0 of family ``f`` in the stacks.
    n_levels : ndarray of int, shape (F,)
        ``N_f + 1``.
    levels : ndarray, shape (T, K, 2)
        ``P^l`` of every family, padded.
    hulls : ndarray, shape (T, Kh, 2)
        Prefix hulls ``H^l``, padded.
    lo, hi : ndarray, shape (T, 2)
        Bounding box of ``H^l`` (contains the box of every ``P^m``, ``m <= l``).
    nested : ndarray of bool, shape (F,)
        Whether ``P^l ⊆ P^{l+1}`` for every level (within CONTAINMENT_TOL).
    rotate : ndarray of bool, shape (F,)
        Families whose sets are expressed in the vehicle's road frame: a claim
        rotates them by its heading (like the footprint).
    """

    keys: tuple
    offset: np.ndarray
    n_levels: np.ndarray
    levels: np.ndarray
    hulls: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    nested: np.ndarray
    rotate: np.ndarray | None = None
    #: Per row: the hull ``H^l`` (``hull_box``) or level ``P^l`` (``level_box``) is an
    #: axis-aligned rectangle of its family frame (a claim of a rotating family is then
    #: an oriented box: the narrow phase's fast path); ``level_lo, level_hi`` bound ``P^l``.
    hull_box: np.ndarray = field(init=False)
    level_box: np.ndarray = field(init=False)
    level_lo: np.ndarray = field(init=False)
    level_hi: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        if self.rotate is None:
            object.__setattr__(self, "rotate", np.zeros(len(self.keys), dtype=bool))
        object.__setattr__(self, "hull_box", _is_box(self.hulls, self.lo, self.hi))
        object.__setattr__(self, "level_lo", self.levels.min(axis=1))
        object.__setattr__(self, "level_hi", self.levels.max(axis=1))
        object.__setattr__(self, "level_box", _is_box(self.levels, self.level_lo, self.level_hi))
        for name in ("offset", "n_levels", "levels", "hulls", "lo", "hi", "nested", "rotate", "hull_box",
                     "level_box", "level_lo", "level_hi"):
            getattr(self, name).flags.writeable = False

    def family_index(self, family) -> np.ndarray:
        """Family indices of ``family`` (keys, or integer indices checked for range)."""
        arr = np.asarray(family)
        if arr.dtype.kind in "iu":
            if arr.size and (arr.min() < 0 or arr.max() >= len(self.keys)):
                raise FamilyError(f"family index out of range [0, {len(self.keys)})")
            return arr.astype(np.intp)
        out = np.full(arr.shape, -1, dtype=np.intp)
        for f, key in enumerate(self.keys):          # few classes: one vectorised comparison each
            out[arr == key] = f
        if np.any(out < 0):
            bad = sorted({str(k) for k in arr[out < 0].ravel()})
            raise FamilyError(f"unknown family key(s) {bad}; known: {list(self.keys)}")
        return out

    def rows(self, family: np.ndarray, index: np.ndarray) -> np.ndarray:
        """Stack rows of level ``index`` of ``family`` (indices must be in ``0..N_f``)."""
        return self.offset[family] + index


def build_family_table(families: Mapping[str, Sequence[np.ndarray]], rotating=()) -> FamilyTable:
    """Validate families and stack them into a :class:`FamilyTable`.

    Parameters
    ----------
    families : mapping of str to sequence of array_like (k_l, 2)
        Per family key, the CCW convex polygons ``P^0 .. P^N``.
    rotating : collection of str
        Keys of road-frame families (rotated by each claim's heading).

    Raises
    ------
    FamilyError
        Empty mapping or family, non-finite or malformed vertices, or a
        polygon that is not convex and counter-clockwise.
    """
    if not isinstance(families, Mapping) or len(families) == 0:
        raise FamilyError("families: must be a non-empty mapping of key -> list of (k, 2) vertex arrays")
    keys, levels, hulls, nested, n_levels = [], [], [], [], []
    for key, fam in families.items():
        if not isinstance(key, str):
            raise FamilyError(f"families: keys must be str, got {key!r}")
        fam = list(fam)
        if not fam:
            raise FamilyError(f"family {key!r}: needs at least one level (P^0)")
        polys = []
        for l, P in enumerate(fam):
            P = np.asarray(P, dtype=float)
            if P.ndim != 2 or P.shape[1] != 2 or len(P) < 1 or not np.all(np.isfinite(P)):
                raise FamilyError(f"family {key!r} level {l}: must be a finite (k, 2) vertex array, "
                                  f"got shape {P.shape}")
            if not is_convex_ccw(P, GEOMETRY_TOL):
                raise FamilyError(f"family {key!r} level {l}: vertices must form a convex polygon "
                                  "in counter-clockwise order")
            polys.append(P)
        is_nested = all(_contains(polys[l + 1], polys[l]) for l in range(len(polys) - 1))
        fam_hulls = []
        for l, P in enumerate(polys):
            if l == 0 or _contains(P, fam_hulls[-1]):
                fam_hulls.append(P)
            else:
                fam_hulls.append(convex_hull(np.vstack([fam_hulls[-1], P])))
        keys.append(key)
        levels += polys
        hulls += fam_hulls
        nested.append(is_nested)
        n_levels.append(len(polys))
    n_levels = np.array(n_levels, dtype=np.intp)
    H = pad_polygons(hulls)
    return FamilyTable(keys=tuple(keys), offset=np.concatenate([[0], np.cumsum(n_levels)[:-1]]).astype(np.intp),
                       n_levels=n_levels, levels=pad_polygons(levels), hulls=H,
                       lo=H.min(axis=1), hi=H.max(axis=1), nested=np.array(nested, dtype=bool),
                       rotate=np.array([k in set(rotating) for k in keys], dtype=bool))
