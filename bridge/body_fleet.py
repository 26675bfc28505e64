"""SUMO's bodies of a whole fleet at once: :class:`bridge.sumo_body.RouteBody` vectorised over vehicles.

Every step the co-simulation needs, for each vehicle, its reference point's arc position and offset
on its route polyline (searched in a window around the last one) and the body SUMO will judge
(front, back, corners).  Per vehicle that is a dozen small numpy calls; at 1,000 vehicles it was
the largest part of a step (``bench_scale.py --sizes 1000 --controller authority``, profiled:
``SumoWorld._poses`` 88 of 255 s).  :class:`FleetBodies` holds every route polyline and every lane
shape in use as one ragged array each (points, arc positions, and arc positions shifted so that
all polylines lie on one increasing axis, for one ``searchsorted`` over all of them), and computes
the same quantities for all rows in one pass: :meth:`FleetBodies.project` and
:meth:`FleetBodies.bodies` give, row by row, what :meth:`RouteBody.project` and
:meth:`RouteBody.bodies` give (the same operations on the same floats; the searches are corrected
to the polyline's own arc positions, so a shift's rounding never changes a segment).

Only ``bridge/`` uses it (:class:`bridge.sumo_world.SumoWorld`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # bridge.sumo_body builds its own bodies with this module (RouteBody.bodies)
    from bridge.sumo_body import RouteBody

__all__ = ["FleetBodies"]

#: Gap (m) between consecutive polylines on the shared, shifted arc axis.
_SHIFT_GAP_M = 1.0
#: How many lanes behind its front lane SUMO's back may lie (as :meth:`RouteBody.bodies`).
_BEHIND_STEPS = 8


class _Ragged:
    """Polylines concatenated: points ``P`` (q, 2), own arc positions ``A`` (q,), shifted arc
    positions ``G`` (increasing over all), and per polyline ``start``, ``count``, ``base``."""

    def __init__(self, lines: list[tuple[np.ndarray, np.ndarray]]) -> None:
        count = np.array([len(p) for p, _ in lines], dtype=np.intp)
        self.start = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.intp) if len(lines) else count
        self.count = count
        self.P = np.vstack([p for p, _ in lines]) if lines else np.zeros((0, 2))
        self.A = np.concatenate([a for _, a in lines]) if lines else np.zeros(0)
        span = np.array([a[-1] for _, a in lines]) + _SHIFT_GAP_M if lines else np.zeros(0)
        self.base = np.concatenate([[0.0], np.cumsum(span)[:-1]]) if lines else span
        self.G = self.A + np.repeat(self.base, count)

    def search(self, row, s, side: str) -> np.ndarray:
        """Per row: ``np.searchsorted(A_row, s, side)`` on the row's own arc positions (0 .. count)."""
        st, cn = self.start[row], self.count[row]
        i = np.clip(np.searchsorted(self.G, self.base[row] + s, side=side) - st, 0, cn)
        A = self.A
        if side == "right":  # i = how many of the row's arcs are <= s
            up = lambda i: (i < cn) & (A[np.minimum(st + i, len(A) - 1)] <= s)  # noqa: E731
            down = lambda i: (i > 0) & (A[st + np.maximum(i - 1, 0)] > s)  # noqa: E731
        else:  # how many are < s
            up = lambda i: (i < cn) & (A[np.minimum(st + i, len(A) - 1)] < s)  # noqa: E731
            down = lambda i: (i > 0) & (A[st + np.maximum(i - 1, 0)] >= s)  # noqa: E731
        while True:  # the shift's rounding can only tie values it should not: rarely any step
            m = up(i)
            if not m.any():
                break
            i = i + m
        while True:
            m = down(i)
            if not m.any():
                break
            i = i - m
        return i

    def at(self, row, s):
        """Points, unit tangents and global segment indices at arc positions ``s`` (clipped), as
        :func:`bridge.sumo_body._at` on each row's polyline."""
        st, cn = self.start[row], self.count[row]
        s = np.clip(np.asarray(s, dtype=float), 0.0, self.A[st + cn - 1])
        i = st + np.clip(self.search(row, s, "right") - 1, 0, cn - 2)
        d = self.P[i + 1] - self.P[i]
        n = np.hypot(d[:, 0], d[:, 1])
        t = d / np.where(n > 0, n, 1.0)[:, None]
        return self.P[i] + t * (s - self.A[i])[:, None], t, i

    def nearest(self, i0, i1, p):
        """Arc positions and signed offsets (left +) of points ``p`` (n, 2) on the segments between
        global point indices ``i0`` and ``i1`` (exclusive, at least two points), as
        :func:`bridge.sumo_body._project` without a window.  Rows are taken in groups of like
        segment counts (up to 1, 2, 4, 8, ...): a row's arrays are as wide as its group's longest
        polyline, not the longest of all (most lanes are one straight segment; a junction's
        internal lanes have a few, a curved road's dozens)."""
        nseg = i1 - i0 - 1
        if len(nseg) and int(nseg.max()) > 1:
            grp = np.ceil(np.log2(np.maximum(nseg, 1))).astype(np.intp)
            if grp.min() != grp.max():
                sigma, e = np.empty(len(p)), np.empty(len(p))
                for g in np.unique(grp).tolist():
                    r = np.flatnonzero(grp == g)
                    sigma[r], e[r] = self._nearest(i0[r], i1[r], p[r], nseg[r])
                return sigma, e
        return self._nearest(i0, i1, p, nseg)

    def _nearest(self, i0, i1, p, nseg):
        M = int(nseg.max(initial=0))
        J = i0[:, None] + np.arange(M)[None, :]
        valid = J < (i1 - 1)[:, None]
        J = np.where(valid, J, i0[:, None])
        a = self.P[J]
        d = self.P[J + 1] - a
        ln2 = np.maximum((d ** 2).sum(axis=2), 1e-18)
        w = p[:, None, :] - a
        u = np.clip((w * d).sum(axis=2) / ln2, 0.0, 1.0)
        q = a + u[..., None] * d
        dist = np.hypot(p[:, None, 0] - q[..., 0], p[:, None, 1] - q[..., 1])
        dist = np.where(valid, dist, np.inf)
        j = np.argmin(dist, axis=1)
        r = np.arange(len(p))
        jj, lj = J[r, j], ln2[r, j]
        sigma = self.A[jj] + u[r, j] * np.sqrt(lj)
        t = d[r, j] / np.sqrt(lj)[:, None]
        e = t[:, 0] * (p[:, 1] - q[r, j, 1]) - t[:, 1] * (p[:, 0] - q[r, j, 0])
        return sigma, e


class FleetBodies:
    """The :class:`RouteBody` of every vehicle in the network, computed on together.

    :meth:`add` a vehicle's body when it enters and :meth:`remove` it when it leaves; the ragged
    arrays are rebuilt on the next query after a change (a few ms at 1,000 routes), the lanes'
    shapes are kept for the run (a network's lanes are few).
    """

    def __init__(self) -> None:
        self._bodies: dict[str, RouteBody] = {}
        self._lane_id: dict[str, int] = {}
        self._lane_lines: list[tuple[np.ndarray, np.ndarray]] = []
        self._lane_len: list[float] = []
        self._lane_scale: list[float] = []
        self._built = None

    def add(self, vid: str, body: RouteBody) -> None:
        self._bodies[vid] = body
        for k, lane in enumerate(body.lanes):
            if lane not in self._lane_id:
                self._lane_id[lane] = len(self._lane_lines)
                self._lane_lines.append((body.shapes[k], body.arcs[k]))
                self._lane_len.append(float(body.lane_len[k]))
                self._lane_scale.append(float(body.scale[k]))
        self._built = None

    def remove(self, vid: str) -> None:
        if self._bodies.pop(vid, None) is not None:
            self._built = None

    def _arrays(self):
        if self._built is None:
            vids = list(self._bodies)
            bodies = [self._bodies[v] for v in vids]
            routes = _Ragged([(b.poly, b.parc) for b in bodies])
            lanes = _Ragged(self._lane_lines)
            # per route: its lanes (global ids) and the lane behind each (route-local, -1 none);
            # per polyline point: the route-local lane of the segment starting there
            nl = np.array([len(b.lanes) for b in bodies], dtype=np.intp)
            lstart = np.concatenate([[0], np.cumsum(nl)[:-1]]).astype(np.intp) if bodies else nl
            lane_ids = np.array([self._lane_id[x] for b in bodies for x in b.lanes], dtype=np.intp)
            behind = np.concatenate([b.behind for b in bodies]) if bodies else np.zeros(0, np.intp)
            seg_lane = np.concatenate([np.r_[b.seg_lane, b.seg_lane[-1:]] for b in bodies]) if bodies \
                else np.zeros(0, np.intp)
            self._built = dict(row={v: i for i, v in enumerate(vids)}, bodies=bodies, routes=routes, lanes=lanes,
                               lstart=lstart, lane_ids=lane_ids, behind=behind, seg_lane=seg_lane,
                               length=np.array([b.length for b in bodies]), width=np.array([b.width for b in bodies]),
                               lane_len=np.array(self._lane_len), scale=np.array(self._lane_scale))
        return self._built

    def rows(self, ids) -> np.ndarray:
        row = self._arrays()["row"]
        try:
            return np.array([row[v] for v in ids], dtype=np.intp)
        except KeyError as exc:
            raise KeyError(f"FleetBodies: vehicle {exc.args[0]!r} has no body (add it first)") from None

    def project(self, ids, p, around, back: float = 5.0, ahead: float = 30.0):
        """Arc positions and signed offsets of reference points ``p`` (n, 2) on their vehicles'
        routes, searched within ``[around - back, around + ahead]`` (``around`` (n,); NaN: the whole
        route), row by row as :meth:`RouteBody.project`."""
        B = self._arrays()
        row = self.rows(ids)
        p = np.asarray(p, dtype=float).reshape(-1, 2)
        around = np.asarray(around, dtype=float).reshape(-1)
        sigma, e = np.empty(len(row)), np.empty(len(row))
        R = B["routes"]
        win = np.isfinite(around)
        w = np.flatnonzero(win)
        if len(w):
            rw = row[w]
            st, cn = R.start[rw], R.count[rw]
            i0 = st + np.maximum(R.search(rw, around[w] - back, "right") - 1, 0)
            i1 = st + np.minimum(R.search(rw, around[w] + ahead, "left") + 1, cn)
            ok = i1 - i0 >= 2
            g = w[ok]
            sigma[g], e[g] = R.nearest(i0[ok], i1[ok], p[g])
            win[w[~ok]] = False  # too few points in the window: the body's own search (rare)
        for i in np.flatnonzero(~win).tolist():
            b = B["bodies"][row[i]]
            a = None if not np.isfinite(around[i]) else [around[i]]
            s, ee = b.project(p[i:i + 1], a, back, ahead)
            sigma[i], e[i] = s[0], ee[0]
        return sigma, e

    def bodies(self, ids, sigma, e):
        """SUMO's bodies of reference points at arc ``sigma`` (n,) and offset ``e`` (n,) on their
        vehicles' routes: ``front, back`` (n, 2), ``lane`` (n,) (index into each vehicle's
        :attr:`RouteBody.lanes`) and ``corners`` (n, 4, 2), row by row as :meth:`RouteBody.bodies`."""
        return self.bodies_of_rows(self.rows(ids), sigma, e)

    def bodies_of_rows(self, row, sigma, e):
        """:meth:`bodies` of the vehicles at rows ``row`` (n,) of the arrays (:meth:`rows`; a body
        alone, :meth:`RouteBody.bodies`: all 0)."""
        B = self._arrays()
        row = np.asarray(row, dtype=np.intp).reshape(-1)
        R, La = B["routes"], B["lanes"]
        sigma = np.asarray(sigma, dtype=float).reshape(-1)
        e = np.broadcast_to(np.asarray(e, dtype=float), sigma.shape)
        L = B["length"][row]
        q, t, seg = R.at(row, sigma + 0.5 * L)
        front = q + e[:, None] * np.column_stack([-t[:, 1], t[:, 0]])
        kloc = B["seg_lane"][seg]
        ls = B["lstart"][row]
        g = B["lane_ids"][ls + kloc]
        s, lat = La.nearest(La.start[g], La.start[g] + La.count[g], front)
        scale, lane_len = B["scale"], B["lane_len"]
        rem = s / scale[g] - L
        cur = kloc.copy()
        for _ in range(_BEHIND_STEPS):
            prev = B["behind"][ls + cur]
            go = (rem < 0) & (prev >= 0)
            if not go.any():
                break
            cur = np.where(go, prev, cur)
            rem = np.where(go, rem + lane_len[B["lane_ids"][ls + cur]], rem)
        gc = B["lane_ids"][ls + cur]
        pt, tt, _ = La.at(gc, rem * scale[gc])
        back = pt + lat[:, None] * np.column_stack([-tt[:, 1], tt[:, 0]])
        axis = front - back
        n = np.hypot(axis[:, 0], axis[:, 1])
        u = axis / np.where(n > 0, n, 1.0)[:, None]
        side = 0.5 * B["width"][row][:, None] * np.column_stack([-u[:, 1], u[:, 0]])
        corners = np.stack([front - side, front + side, back + side, back - side], axis=1)
        return front, back, kloc, corners
