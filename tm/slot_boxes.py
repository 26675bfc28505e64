"""Claim slots as unions of oriented boxes (path-frame vehicles' exact covers, :mod:`tm.path_claims`).

A path-frame vehicle's slot ``S_k`` is the cover of a path interval: one oriented box per path
segment the interval meets (:func:`tm.path_cover.stack_box_cover`).  Kept as that union, a slot
nests exactly as its interval does (``S_k(t+1) ⊆ S_{k+1}(t)``: the cover of a sub-interval lies in
the cover of the interval, box by box), which a single bounding box in a frame chosen per slot
does not: a fresh slot bounded in a new frame can stick out of the old one (measured: ``grid``
seed 1, nine claim violations between fresh claims).  Two slots meet iff some box of one meets
some box of the other (separating-axis test per pair of boxes, :func:`tm.kernels.timed_pairs_tight`).

:class:`SlotBoxes` holds the boxes of ``n`` vehicles' ``K`` slots as one flat list of boxes and,
per vehicle and slot, the first box and the count; shifting, taking rows and padding slots only
move those indices.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tm.kernels import slot_bounds

__all__ = ["SlotBoxes"]


@dataclass(frozen=True, eq=False)
class SlotBoxes:
    """Oriented boxes ``centre + R(heading) [-half, half]`` (flat, ``q`` of them) and the boxes of
    each vehicle's slots: ``start``, ``count`` (n, K) (a slot with no box is empty)."""

    centre: np.ndarray
    heading: np.ndarray
    half: np.ndarray
    start: np.ndarray
    count: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        return self.start.shape

    @staticmethod
    def from_frames(centre, heading, lo, hi) -> "SlotBoxes":
        """One box per slot: ``centre`` (n, 2) or (n, K, 2), ``heading`` (n,) or (n, K), ``lo, hi``
        (n, K, 2) in those frames (empty where ``lo > hi``)."""
        lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
        n, K = lo.shape[:2]
        per = 1 if not n else -1  # (an empty set: nothing to infer the slot axis from)
        C = np.broadcast_to(np.asarray(centre, dtype=float).reshape(n, per, 2), (n, K, 2))
        H = np.broadcast_to(np.asarray(heading, dtype=float).reshape(n, per), (n, K))
        ok = (lo[..., 0] <= hi[..., 0]) & (lo[..., 1] <= hi[..., 1])
        m = np.flatnonzero(ok.ravel())
        L, U = lo.reshape(-1, 2)[m], hi.reshape(-1, 2)[m]
        mid, h = 0.5 * (L + U), H.reshape(-1)[m]
        c, s = np.cos(h), np.sin(h)
        cen = C.reshape(-1, 2)[m] + np.column_stack([c * mid[:, 0] - s * mid[:, 1], s * mid[:, 0] + c * mid[:, 1]])
        count = ok.astype(np.intp)
        start = (np.cumsum(count.ravel()) - count.ravel()).reshape(n, K)
        return SlotBoxes(cen, h, 0.5 * (U - L), start, count)

    @staticmethod
    def from_cover(boxes, n: int, K: int) -> "SlotBoxes":
        """From :class:`tm.path_cover.PathBoxes` of ``n * K`` intervals (vehicle-major)."""
        return SlotBoxes(boxes.centre, boxes.heading, boxes.half, boxes.start.reshape(n, K),
                         boxes.count.reshape(n, K))

    # ------------------------------------------------------------------ index moves
    def _with(self, start, count) -> "SlotBoxes":
        return SlotBoxes(self.centre, self.heading, self.half, start, count)

    def shift(self) -> "SlotBoxes":
        """Slot ``k`` <- slot ``k + 1``, the last repeated (:meth:`tm.reach.ReachClaims.shift`)."""
        sh = lambda a: np.concatenate([a[:, 1:], a[:, -1:]], axis=1)  # noqa: E731
        return self._with(sh(self.start), sh(self.count))

    def take(self, idx) -> "SlotBoxes":
        return self._with(self.start[idx], self.count[idx])

    def pad(self, K: int) -> "SlotBoxes":
        """``K`` slots, the last repeated."""
        k = self.start.shape[1]
        if k >= K:
            return self
        rep = lambda a: np.concatenate([a, np.repeat(a[:, -1:], K - k, axis=1)], axis=1)  # noqa: E731
        return self._with(rep(self.start), rep(self.count))

    @staticmethod
    def concat(*parts: "SlotBoxes") -> "SlotBoxes":
        """Rows of every part in order (same ``K``); the parts' boxes side by side, as they are (slots
        that share boxes keep sharing them: :meth:`compact` spells them out)."""
        off = np.cumsum([0] + [len(p.heading) for p in parts[:-1]])
        return SlotBoxes(np.vstack([p.centre for p in parts]), np.concatenate([p.heading for p in parts]),
                         np.vstack([p.half for p in parts]),
                         np.vstack([p.start + o for p, o in zip(parts, off)]), np.vstack([p.count for p in parts]))

    @staticmethod
    def assemble(n: int, K: int, pieces) -> "SlotBoxes":
        """Rows ``rows`` (1-D) of the result from each ``(rows, SlotBoxes)`` of ``pieces`` (with as
        many rows, ``K`` slots); every row must be given once.  Boxes compacted."""
        start = np.zeros((n, K), dtype=np.intp)
        count = np.zeros((n, K), dtype=np.intp)
        C, H, Hf, o = [], [], [], 0
        for rows, sb in pieces:
            start[rows] = sb.start + o
            count[rows] = sb.count
            C.append(sb.centre)
            H.append(sb.heading)
            Hf.append(sb.half)
            o += len(sb.heading)
        if not C:
            return SlotBoxes(np.zeros((0, 2)), np.zeros(0), np.zeros((0, 2)), start, count)
        return SlotBoxes(np.vstack(C), np.concatenate(H), np.vstack(Hf), start, count).compact()

    def compact(self) -> "SlotBoxes":
        """The same slots with only the boxes they use, in slot order."""
        cnt = self.count.ravel()
        total = int(cnt.sum())
        if total == len(self.heading):
            return self
        first = np.cumsum(cnt) - cnt
        src = np.repeat(self.start.ravel() - first, cnt) + np.arange(total)
        return SlotBoxes(self.centre[src], self.heading[src], self.half[src], first.reshape(self.start.shape),
                         self.count)

    # ------------------------------------------------------------------ geometry
    def aabb(self) -> np.ndarray:
        """World bounding boxes ``(4, n, K)`` of every slot (empty: inverted, ``+inf, -inf``).

        A run of slots with the same boxes (a vehicle at rest: every slot past its index is
        ``T^0``'s, :func:`tm.path_claims.path_reach_claims`; a shifted last slot) is bounded once,
        at its first slot, and copied along the run."""
        return self.aabb_union()[0]

    def aabb_union(self) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`aabb` and, in the same pass, the bounds over each vehicle's slots, ``(n, 4)``:
        ``x_lo, x_hi, y_lo, y_hi`` (``+inf, -inf`` when every slot is empty)."""
        n, K = self.start.shape
        if not len(self.heading) or not n or not K:
            out = np.empty((4, n, K))
            out[0] = out[2] = np.inf
            out[1] = out[3] = -np.inf
            return out, np.tile([np.inf, -np.inf, np.inf, -np.inf], (n, 1))
        c, s = np.abs(np.cos(self.heading)), np.abs(np.sin(self.heading))
        ex = c * self.half[:, 0] + s * self.half[:, 1]
        ey = s * self.half[:, 0] + c * self.half[:, 1]
        return slot_bounds(self.centre[:, 0] - ex, self.centre[:, 0] + ex, self.centre[:, 1] - ey,
                           self.centre[:, 1] + ey, np.ascontiguousarray(self.start, dtype=np.intp),
                           np.ascontiguousarray(self.count, dtype=np.intp))
