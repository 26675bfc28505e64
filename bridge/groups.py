"""The active vehicles of one class as arrays (the co-simulation loop's per-class state)."""

from __future__ import annotations

import numpy as np

from controllers.classes import VehicleClass
from controllers.stmpc import STMPC

__all__ = ["_Group", "_headings"]


class _Group:
    """The active vehicles of one class, as arrays."""

    def __init__(self, vclass: VehicleClass, ctl: STMPC):
        self.vclass = vclass
        self.ctl = ctl
        n = vclass.model.n
        self.ids: list[str] = []
        self.X = np.zeros((0, n))
        self.k = np.zeros(0, dtype=np.intp)
        self.l = np.zeros(0, dtype=np.intp)
        self.W: list[np.ndarray] = []
        self.H: list[np.ndarray] = []
        # every route's waypoints and headings in one buffer, so that the current (or next)
        # waypoints of all vehicles are one gather: row start[i] + k[i] of vehicle i
        self._wbuf = np.zeros((1024, 3))
        self._used = 0
        self.start = np.zeros(0, dtype=np.intp)
        self.K = np.zeros(0, dtype=np.intp)
        # per-vehicle accumulators (flushed into the VehicleRecords by Cosim)
        self.speed_sum = np.zeros(0)
        self.steps = np.zeros(0, dtype=np.intp)
        self.denied_last = np.zeros(0, dtype=bool)
        self.req_l = np.zeros(0, dtype=np.intp)  # request indices of the last TM state

    def add(self, vid, W, H, x0, l0):
        K = len(W)
        live = int(self.K.sum())
        if self._used + K > len(self._wbuf):
            if self._used > 2 * live + 4096:  # mostly removed routes: compact
                rows = np.concatenate([np.arange(s, s + k) for s, k in zip(self.start, self.K)]) \
                    if len(self.K) else np.zeros(0, dtype=np.intp)
                self._wbuf = np.vstack([self._wbuf[rows], np.zeros((max(1024, 2 * (live + K)), 3))])
                self.start = np.concatenate([[0], np.cumsum(self.K)[:-1]]).astype(np.intp) \
                    if len(self.K) else self.start
                self._used = live
            if self._used + K > len(self._wbuf):
                grow = max(len(self._wbuf), K)
                self._wbuf = np.vstack([self._wbuf, np.zeros((grow, 3))])
        self._wbuf[self._used:self._used + K, :2] = W
        self._wbuf[self._used:self._used + K, 2] = H
        self.ids.append(vid)
        self.X = np.vstack([self.X, x0[None]])
        self.k = np.append(self.k, 0)
        self.l = np.append(self.l, l0)
        self.W.append(W)
        self.H.append(H)
        self.start = np.append(self.start, self._used)
        self.K = np.append(self.K, K)
        self._used += K
        self.speed_sum = np.append(self.speed_sum, 0.0)
        self.steps = np.append(self.steps, 0)
        self.denied_last = np.append(self.denied_last, False)
        self.req_l = np.append(self.req_l, 0)

    def remove(self, mask):
        keep = ~mask
        self.ids = [v for v, k in zip(self.ids, keep) if k]
        self.X, self.k, self.l = self.X[keep], self.k[keep], self.l[keep]
        self.W = [w for w, k in zip(self.W, keep) if k]
        self.H = [h for h, k in zip(self.H, keep) if k]
        self.start, self.K = self.start[keep], self.K[keep]
        self.speed_sum, self.steps = self.speed_sum[keep], self.steps[keep]
        self.denied_last, self.req_l = self.denied_last[keep], self.req_l[keep]

    @property
    def at_last(self) -> np.ndarray:
        """Whether each vehicle's current waypoint is its route's last."""
        return self.k == self.K - 1

    def centres(self, offset=0):
        """Waypoints ``k + offset`` (clipped to the last), their headings, and whether they exist."""
        if not self.ids:
            return np.zeros((0, 2)), np.zeros(0), np.zeros(0, dtype=bool)
        row = self._wbuf[self.start + np.minimum(self.k + offset, self.K - 1)]
        return row[:, :2], row[:, 2], self.k + offset < self.K


def _headings(W: np.ndarray) -> np.ndarray:
    """Heading of the segment arriving at each waypoint (the first takes the first segment's)."""
    d = np.diff(W, axis=0)
    h = np.arctan2(d[:, 1], d[:, 0]) if len(d) else np.zeros(0)
    return np.concatenate([h[:1] if len(h) else [0.0], h])
