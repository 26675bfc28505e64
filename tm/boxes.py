"""Axis-aligned box joins for the junction layer (:mod:`tm.junctions`), vectorised.

Boxes are ``(lo, hi)`` arrays of shape (n, 2), ``lo <= hi``; touching counts as
meeting everywhere.  :class:`BoxGrid` pairs query boxes with boxes on a uniform
grid, :class:`GuardIndex` pairs boxes with zone guards by a sorted sweep along x,
:func:`corridor_hits` tests corridors (runs of boxes) against the boxes of their
own zone, :func:`boxes_meet` two small sets of boxes densely.
"""

from __future__ import annotations

import numpy as np

from controllers.tolerances import GEOMETRY_TOL, SWEEP_MARGIN
from tm.kernels import any_boxes_meet, rows_meet_any, sets_meet

__all__ = ["BoxGrid", "GuardIndex", "corridor_hits", "box_pairs_meet", "boxes_meet", "meets_any", "polygons_meet",
           "polygon_sets_meet", "ranges"]


def ranges(start: np.ndarray, count: np.ndarray) -> np.ndarray:
    """The indices ``start[i], ..., start[i] + count[i] - 1`` of every ``i``, in order, as one array."""
    start, count = np.asarray(start, dtype=np.intp), np.asarray(count, dtype=np.intp)
    return np.repeat(start - np.cumsum(count) + count, count) + np.arange(int(count.sum()), dtype=np.intp)


def _cells(lo: np.ndarray, hi: np.ndarray, cell: float):
    """Every (box, grid cell) pair of boxes no wider than ``cell``: at most 2 x 2 cells a box."""
    c0 = np.floor(lo / cell).astype(np.int64)
    c1 = np.floor(hi / cell).astype(np.int64)
    box, key = [], []
    for dx in (0, 1):
        for dy in (0, 1):
            ok = (c0[:, 0] + dx <= c1[:, 0]) & (c0[:, 1] + dy <= c1[:, 1])
            box.append(np.flatnonzero(ok))
            key.append((c0[ok, 0] + dx) * (1 << 32) + (c0[ok, 1] + dy))
    return np.concatenate(box), np.concatenate(key)


class BoxGrid:
    """Boxes ``(lo[j], hi[j])`` bucketed on a uniform grid of square cells no smaller than the
    widest box (so a box covers at most 2 x 2 cells), for :meth:`pairs`."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray, cell: float):
        self.lo, self.hi, self.cell = lo, hi, cell
        box, key = _cells(lo, hi, cell)
        order = np.argsort(key, kind="stable")
        self.key, self.box = key[order], box[order]

    def pairs(self, q_lo: np.ndarray, q_hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(i, j)``: every query box ``i`` (no wider than the cell) that meets box ``j``
        (touching counts), each pair once.  Boxes sharing a cell are tested exactly on both
        axes; a pair is kept in one cell only, the one holding the larger of the two lower
        corners.  (A sweep along x alone met every vehicle of the same north-south road.)"""
        if not len(q_lo) or not len(self.lo):
            return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)
        qb, qk = _cells(q_lo, q_hi, self.cell)
        start = np.searchsorted(self.key, qk, side="left")
        count = np.searchsorted(self.key, qk, side="right") - start
        i = np.repeat(qb, count)
        k = np.repeat(qk, count)
        j = self.box[ranges(start, count)]
        lo, hi = self.lo, self.hi
        ok = (hi[j, 0] >= q_lo[i, 0]) & (lo[j, 0] <= q_hi[i, 0]) & (lo[j, 1] <= q_hi[i, 1]) & (hi[j, 1] >= q_lo[i, 1])
        i, j, k = i[ok], j[ok], k[ok]
        ref = np.floor(np.maximum(q_lo[i], lo[j]) / self.cell).astype(np.int64)
        once = ref[:, 0] * (1 << 32) + ref[:, 1] == k
        return i[once], j[once]


class GuardIndex:
    """Guard boxes ``(lo[z], hi[z])`` sorted by their lower x, for :meth:`pairs`."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray):
        self.lo, self.hi = lo, hi
        self.order = np.argsort(lo[:, 0], kind="stable")
        self.x_sorted = lo[self.order, 0]
        self.width_x = float((hi[:, 0] - lo[:, 0]).max()) if len(lo) else 0.0

    def pairs(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(i, z)``: every box ``i`` (``lo, hi`` of shape (n, 2)) that meets guard ``z``.

        Box ``i`` can only meet the guards whose lower x lies in ``[lo_x - widest guard,
        hi_x]`` (a ``searchsorted`` range, started ``SWEEP_MARGIN`` lower against rounding);
        those candidate pairs are then tested on both axes.  Pairs sorted by ``i``.
        """
        zx = self.x_sorted
        start = np.searchsorted(zx, lo[:, 0] - self.width_x - SWEEP_MARGIN, side="left")
        count = np.maximum(np.searchsorted(zx, hi[:, 0], side="right") - start, 0)
        i = np.repeat(np.arange(len(lo)), count)
        q = ranges(start, count)
        z = self.order[q]
        zl, zh = self.lo, self.hi
        ok = (lo[i, 0] <= zh[z, 0]) & (hi[i, 0] >= zl[z, 0]) & (lo[i, 1] <= zh[z, 1]) & (hi[i, 1] >= zl[z, 1])
        return i[ok], z[ok]


def corridor_hits(zone_q, row_q, first, c_lo, c_hi, zone_b, row_b, b_lo, b_hi) -> np.ndarray:
    """Per query ``q``: whether one of its corridor boxes ``first[q]:first[q + 1]`` meets a box
    ``row_b[k]`` of its own zone (``zone_b`` ascending), other than its own row ``row_q[q]``.

    Candidates and the boxes of their zone are paired by ``searchsorted`` on the zone, then
    each pair's corridor boxes are tested against its box (touching counts)."""
    hits = np.zeros(len(zone_q), dtype=bool)
    if not len(zone_b) or not len(zone_q):
        return hits
    s = np.searchsorted(zone_b, zone_q, side="left")
    cnt = np.searchsorted(zone_b, zone_q, side="right") - s
    q = np.repeat(np.arange(len(zone_q)), cnt)
    k = ranges(s, cnt)
    j = row_b[k]
    # the corridor's bounding box first: most pairs of a zone are far apart
    cb_lo = np.minimum.reduceat(c_lo, first[:-1], axis=0)
    cb_hi = np.maximum.reduceat(c_hi, first[:-1], axis=0)
    near = (j != row_q[q]) & np.all((cb_lo[q] <= b_hi[j]) & (cb_hi[q] >= b_lo[j]), axis=1)
    q, j = q[near], j[near]
    if not len(q):
        return hits
    n_box = first[q + 1] - first[q]
    qq = np.repeat(q, n_box)
    jj = np.repeat(j, n_box)
    bb = ranges(first[q], n_box)
    meet = np.all((c_lo[bb] <= b_hi[jj]) & (c_hi[bb] >= b_lo[jj]), axis=1)
    hits[qq[meet]] = True
    return hits


def box_pairs_meet(lo1: np.ndarray, hi1: np.ndarray, lo2: np.ndarray, hi2: np.ndarray) -> np.ndarray:
    """(n, m) bool: whether box ``(lo1[i], hi1[i])`` meets box ``(lo2[j], hi2[j])`` (touching counts)."""
    return np.all((lo1[:, None, :] <= hi2[None]) & (hi1[:, None, :] >= lo2[None]), axis=2)


def _compiled(lo1, hi1, lo2, hi2) -> bool:
    """Whether the compiled box loops take these: float (n, d) / (m, d) boxes, one shape per side."""
    return (lo1.ndim == hi1.ndim == lo2.ndim == hi2.ndim == 2 and lo1.shape == hi1.shape and lo2.shape == hi2.shape
            and lo1.shape[1] == lo2.shape[1] and all(a.dtype == np.float64 for a in (lo1, hi1, lo2, hi2)))


def meets_any(lo1: np.ndarray, hi1: np.ndarray, lo2: np.ndarray, hi2: np.ndarray) -> np.ndarray:
    """(n,) bool: whether box ``(lo1[i], hi1[i])`` meets some box ``(lo2[j], hi2[j])`` (touching counts):
    ``box_pairs_meet(...).any(axis=1)``, in one compiled loop (:func:`tm.kernels.rows_meet_any`) that
    stops at each row's first meeting box, for the shapes :func:`boxes_meet` compiles."""
    lo1, hi1, lo2, hi2 = (np.asarray(a) for a in (lo1, hi1, lo2, hi2))
    if _compiled(lo1, hi1, lo2, hi2):
        return rows_meet_any(lo1, hi1, lo2, hi2)
    return np.any(box_pairs_meet(lo1, hi1, lo2, hi2), axis=1)


def boxes_meet(lo1: np.ndarray, hi1: np.ndarray, lo2: np.ndarray, hi2: np.ndarray) -> bool:
    """Whether any box ``(lo1[i], hi1[i])`` meets any box ``(lo2[j], hi2[j])`` (touching counts):
    ``np.any(box_pairs_meet(...))``, in one compiled loop (:func:`tm.kernels.any_boxes_meet`) for
    float boxes of one shape per side (else as :func:`box_pairs_meet`)."""
    lo1, hi1, lo2, hi2 = (np.asarray(a) for a in (lo1, hi1, lo2, hi2))
    if _compiled(lo1, hi1, lo2, hi2):
        return bool(any_boxes_meet(lo1, hi1, lo2, hi2))
    return bool(np.any(box_pairs_meet(lo1, hi1, lo2, hi2)))


def polygons_meet(P: np.ndarray, Q: np.ndarray) -> bool:
    """Whether some convex polygon of ``P`` (p, m, 2) meets some of ``Q`` (q, m', 2), counter-clockwise
    (separating axes, :func:`tm.geometry.intersect_sat`; touching counts), their bounding boxes first."""
    return bool(polygon_sets_meet(P, [0], [len(P)], Q, [0], [len(Q)])[0])


def polygon_sets_meet(P: np.ndarray, p_start: np.ndarray, p_count: np.ndarray, Q: np.ndarray,
                      q_start: np.ndarray, q_count: np.ndarray) -> np.ndarray:
    """:func:`polygons_meet` of ``n`` pairs of polygon sets at once: entry ``t`` is whether some polygon
    of ``P[p_start[t]:p_start[t] + p_count[t]]`` meets some of ``Q[q_start[t]:q_start[t] + q_count[t]]``
    (``P`` (p, m, 2), ``Q`` (q, m', 2), counter-clockwise and convex; sets may share polygons).

    One compiled loop (:func:`tm.kernels.sets_meet`): bounding boxes first, then the separating-axis
    test, stopping at a pair's first polygons that meet.  (In numpy, gathers of every combination
    cost ~0.2 ms a call on the gate's few polygons, thousands of calls a step at 1,000 vehicles.)"""
    p_start = np.ascontiguousarray(p_start, dtype=np.intp).reshape(-1)
    p_count = np.ascontiguousarray(p_count, dtype=np.intp).reshape(-1)
    q_start = np.ascontiguousarray(q_start, dtype=np.intp).reshape(-1)
    q_count = np.ascontiguousarray(q_count, dtype=np.intp).reshape(-1)
    P, Q = np.asarray(P, dtype=float), np.asarray(Q, dtype=float)
    if not P.size or not Q.size:
        return np.zeros(len(p_start), dtype=bool)
    return sets_meet(np.ascontiguousarray(P), p_start, p_count, np.ascontiguousarray(Q), q_start, q_count,
                     GEOMETRY_TOL)
