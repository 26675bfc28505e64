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

from bridge.body_kernels import nearest_on_segments

if TYPE_CHECKING:  # bridge.sumo_body builds its own bodies with this module (RouteBody.bodies)
    from bridge.sumo_body import RouteBody

__all__ = ["FleetBodies"]

#: Gap (m) between consecutive polylines on the shared, shifted arc axis.
_SHIFT_GAP_M = 1.0
#: How many lanes behind its front lane SUMO's back may lie (as :meth:`RouteBody.bodies`).
_BEHIND_STEPS = 8
#: The segment quantities :class:`_Ragged` keeps per point when asked to (``per_segment``).
_SEG_KEYS = ("Tx", "Ty")


def _log2_ceil(k: np.ndarray) -> np.ndarray:
    """``ceil(log2(max(k, 1)))`` of integers ``k``: the bit length of ``max(k, 1) - 1``."""
    return np.frexp((np.maximum(k, 1) - 1).astype(float))[1].astype(np.intp)


class _Ragged:
    """Polylines concatenated: points ``P`` (q, 2), own arc positions ``A`` (q,), shifted arc
    positions ``G`` (increasing over all), and per polyline ``start``, ``count``, ``base``.

    The searches work on x and y arrays (one pass per operation, not (rows, 2) arrays and sums over
    their short last axis) and take each segment's unit tangent (:meth:`_segments`) by the same
    operations as :func:`bridge.sumo_body._at` took it per row, so the same floats (the projection,
    ``_project``'s, is :func:`bridge.body_kernels.nearest_on_segments`).  ``per_segment``: the
    tangents computed once for every segment here
    (polylines queried many times per point: a route's own :class:`bridge.sumo_body.PadTable`, the
    lanes) instead of per row (a fleet's routes, each queried once a step)."""

    def __init__(self, lines: list[tuple[np.ndarray, np.ndarray]], per_segment: bool = False) -> None:
        count = np.array([len(p) for p, _ in lines], dtype=np.intp)
        self.start = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.intp) if len(lines) else count
        self.count = count
        self.P = np.vstack([p for p, _ in lines]) if lines else np.zeros((0, 2))
        self.A = np.concatenate([a for _, a in lines]) if lines else np.zeros(0)
        span = np.array([a[-1] for _, a in lines]) + _SHIFT_GAP_M if lines else np.zeros(0)
        self.base = np.concatenate([[0.0], np.cumsum(span)[:-1]]) if lines else span
        self.G = self.A + np.repeat(self.base, count)
        self.Px, self.Py = np.ascontiguousarray(self.P[:, 0]), np.ascontiguousarray(self.P[:, 1])
        #: per polyline: ceil(log2(its segment count)) (:meth:`nearest_xy`'s groups)
        self.group = _log2_ceil(count - 1)
        self.segs = None
        if per_segment:
            self.segs = dict(zip(_SEG_KEYS, self._segments(np.arange(len(self.A), dtype=np.intp), _SEG_KEYS)))

    def _segments(self, i, keys):
        """Per global point index ``i`` (any shape), quantities ``keys`` of its segment: ``Dx, Dy``
        (to the next point) and :meth:`at`'s unit tangent ``Tx, Ty`` (``d / |d|``, ``d`` where
        ``|d| = 0``); the last point of all: a zero segment, never read.  (:meth:`nearest_xy`'s
        projection takes its own in :func:`bridge.body_kernels.nearest_on_segments`.)"""
        if self.segs is not None and all(k in self.segs for k in keys):
            return [self.segs[k][i] for k in keys]
        j = np.minimum(i + 1, len(self.A) - 1)
        dx, dy = self.Px[j] - self.Px[i], self.Py[j] - self.Py[i]
        got = dict(Dx=dx, Dy=dy)
        if "Tx" in keys:
            n = np.hypot(dx, dy)
            nz = np.where(n > 0, n, 1.0)
            got.update(Tx=dx / nz, Ty=dy / nz)
        return [got[k] for k in keys]

    def search(self, row, s, side: str) -> np.ndarray:
        """Per row: ``np.searchsorted(A_row, s, side)`` on the row's own arc positions (0 .. count)."""
        st, cn = self.start[row], self.count[row]
        i = np.minimum(np.maximum(np.searchsorted(self.G, self.base[row] + s, side=side) - st, 0), cn)
        if len(self.count) == 1:  # one polyline, not shifted (G is A): nothing to correct
            return i
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

    def at_xy(self, row, s, single=None):
        """Points (x, y), unit tangents (x, y) and global segment indices at arc positions ``s``
        (clipped), as :func:`bridge.sumo_body._at` on each row's polyline.  ``single`` (n,) bool, when
        known: the rows whose polyline is one segment (no search: its only segment)."""
        st, cn = self.start[row], self.count[row]
        s = np.clip(np.asarray(s, dtype=float), 0.0, self.A[st + cn - 1])
        if single is None:
            i = st + np.minimum(np.maximum(self.search(row, s, "right") - 1, 0), cn - 2)
        else:
            i = st.copy()
            m = np.flatnonzero(~single)
            if len(m):
                i[m] = st[m] + np.minimum(np.maximum(self.search(row[m], s[m], "right") - 1, 0), cn[m] - 2)
        tx, ty = self._segments(i, ("Tx", "Ty"))
        ds = s - self.A[i]
        return self.Px[i] + tx * ds, self.Py[i] + ty * ds, tx, ty, i

    def at(self, row, s):
        """Points, unit tangents and global segment indices at arc positions ``s`` (clipped), as
        :func:`bridge.sumo_body._at` on each row's polyline."""
        x, y, tx, ty, i = self.at_xy(row, s)
        return np.column_stack([x, y]), np.column_stack([tx, ty]), i

    def nearest(self, i0, i1, p):
        """Arc positions and signed offsets (left +) of points ``p`` (n, 2) on the segments between
        global point indices ``i0`` and ``i1`` (exclusive, at least two points), as
        :func:`bridge.sumo_body._project` without a window."""
        p = np.asarray(p, dtype=float).reshape(-1, 2)
        return self.nearest_xy(i0, i1, p[:, 0].copy(), p[:, 1].copy())

    def nearest_xy(self, i0, i1, px, py, grp=None):
        """:meth:`nearest` of points ``(px, py)``, shape ``(..., n)`` (a row's polyline the same along
        the leading axes).  Rows are taken in groups of like segment counts (1, 2, up to 4, 8, ...;
        ``grp`` (n,), when known: ``ceil(log2(segments))``): a row's arrays are as wide as its group's
        longest polyline, not the longest of all (most lanes are one straight segment, taken for
        every row first; a junction's internal lanes have a few, a curved road's dozens)."""
        nseg = i1 - i0 - 1
        if len(nseg) and (grp is not None or int(nseg.max()) > 1):
            if grp is None:
                grp = _log2_ceil(nseg)
            present = np.flatnonzero(np.bincount(grp))
            if len(present) > 1:
                if present[0] == 0:  # every row as if one segment; the longer ones' rows replaced
                    sigma, e = self._nearest(i0, i1, px, py, np.minimum(nseg, 1))
                    present = present[1:]
                else:
                    sigma, e = np.empty(np.shape(px)), np.empty(np.shape(px))
                for g in present.tolist():
                    r = np.flatnonzero(grp == g)
                    sigma[..., r], e[..., r] = self._nearest(i0[r], i1[r], px[..., r], py[..., r], nseg[r])
                return sigma, e
        return self._nearest(i0, i1, px, py, nseg)

    def _nearest(self, i0, i1, px, py, nseg):
        """The projection of :meth:`nearest_xy` on rows of like segment counts (``nseg``: at most one
        each -- the first only -- or more): :func:`bridge.body_kernels.nearest_on_segments`, the
        same floats as the numpy form it replaced (``tests/bridge/test_body_kernels.py`` keeps it as
        the reference)."""
        shape = np.shape(px)
        n = shape[-1] if len(shape) else 1
        sig, off = nearest_on_segments(self.Px, self.Py, self.A, np.ascontiguousarray(i0, dtype=np.intp),
                                       np.ascontiguousarray(i1, dtype=np.intp),
                                       np.ascontiguousarray(px, dtype=float).reshape(-1, n),
                                       np.ascontiguousarray(py, dtype=float).reshape(-1, n),
                                       int(nseg.max(initial=0)) <= 1)
        return sig.reshape(shape), off.reshape(shape)


class FleetBodies:
    """The :class:`RouteBody` of every vehicle in the network, computed on together.

    :meth:`add` a vehicle's body when it enters and :meth:`remove` it when it leaves; the ragged
    arrays are rebuilt on the next query after a change (a few ms at 1,000 routes), the lanes'
    shapes are kept for the run (a network's lanes are few).  ``route_segments``: keep the routes'
    segment quantities for all their segments (:class:`_Ragged`; a route asked about many more
    positions than it has points, as a :class:`bridge.sumo_body.PadTable` asks its own) instead of
    computing them for the rows asked about (a fleet, once a step per vehicle).
    """

    def __init__(self, route_segments: bool = False) -> None:
        self._route_segments = bool(route_segments)
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
            routes = _Ragged([(b.poly, b.parc) for b in bodies], self._route_segments)
            lanes = _Ragged(self._lane_lines, True)
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
                               lane_len=np.array(self._lane_len), scale=np.array(self._lane_scale),
                               lane_single=lanes.count == 2)
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
        row = np.asarray(row, dtype=np.intp).reshape(-1)
        sigma = np.asarray(sigma, dtype=float).reshape(-1)
        e = np.broadcast_to(np.asarray(e, dtype=float), sigma.shape)
        qx, qy, tx, ty, kloc = self._fronts(row, sigma)
        fx, fy = qx + e * -ty, qy + e * tx
        bx, by = self._backs(row, kloc, fx, fy)
        corners = np.empty((len(sigma), 4, 2))
        for c, (cx, cy) in enumerate(self._corners(row, fx, fy, bx, by)):
            corners[:, c, 0], corners[:, c, 1] = cx, cy
        return np.column_stack([fx, fy]), np.column_stack([bx, by]), kloc, corners

    def corners_at_offsets(self, row, sigma, offsets):
        """The corners of :meth:`bodies_of_rows` for every row at each offset of ``offsets`` (k,): four
        ``(x, y)``, each of shape (k, n), counter-clockwise from the front right one.  The fronts'
        positions on the routes are found once for all offsets, and what depends on a row's lane
        only once for all its offsets (a :class:`bridge.sumo_body.PadTable` asks for three at every
        sample)."""
        row = np.asarray(row, dtype=np.intp).reshape(-1)
        sigma = np.asarray(sigma, dtype=float).reshape(-1)
        qx, qy, tx, ty, kloc = self._fronts(row, sigma)
        ev = np.asarray(offsets, dtype=float).reshape(-1, 1)
        fx, fy = qx + ev * -ty, qy + ev * tx  # (k, n)
        bx, by = self._backs(row, kloc, fx, fy)
        return self._corners(row, fx, fy, bx, by)

    def route_at(self, row, sigma):
        """Points ``x, y`` and unit tangents ``tx, ty`` of the vehicles' routes at arc positions
        ``sigma`` (clipped): :func:`bridge.sumo_body._at` on each route."""
        return self._arrays()["routes"].at_xy(row, sigma)[:4]

    def _fronts(self, row, sigma):
        """Where the fronts of reference points at arc ``sigma`` lie on their routes (offset 0): ``x,
        y``, the route's unit tangent there ``tx, ty`` and the route-local lane of its segment."""
        B = self._arrays()
        qx, qy, tx, ty, seg = B["routes"].at_xy(row, sigma + 0.5 * B["length"][row])
        return qx, qy, tx, ty, B["seg_lane"][seg]

    def _backs(self, row, kloc, fx, fy):
        """SUMO's back points (x, y) of fronts ``(fx, fy)``, shape ``(..., n)``, of rows ``row`` on their
        route-local lanes ``kloc`` (n,): the front's lane position and lateral offset on its lane,
        ``length`` lane units back along it and the lanes behind it (each row only while its back is
        not found), at the same offset."""
        B = self._arrays()
        La, lane_ids, scale = B["lanes"], B["lane_ids"], B["scale"]
        ls = B["lstart"][row]
        g = lane_ids[ls + kloc]
        s, lat = La.nearest_xy(La.start[g], La.start[g] + La.count[g], fx, fy, La.group[g])
        rem = (s / scale[g] - B["length"][row]).reshape(-1)
        n = len(row)
        cur = np.empty(s.shape, dtype=np.intp)
        cur[...] = kloc
        cur = cur.reshape(-1)
        act = np.flatnonzero(rem < 0)
        for _ in range(_BEHIND_STEPS):  # rows whose back lies on a lane behind: walk back
            if not len(act):
                break
            prev = B["behind"][ls[act % n] + cur[act]]
            act = act[prev >= 0]
            if not len(act):
                break
            cur[act] = prev[prev >= 0]
            rem[act] = rem[act] + B["lane_len"][lane_ids[ls[act % n] + cur[act]]]
            act = act[rem[act] < 0]
        gc = lane_ids[(ls + cur.reshape(s.shape)).reshape(-1)]
        px, py, tx, ty, _ = La.at_xy(gc, rem * scale[gc], B["lane_single"][gc])
        lat = lat.reshape(-1)
        return (px + lat * -ty).reshape(s.shape), (py + lat * tx).reshape(s.shape)

    def _corners(self, row, fx, fy, bx, by):
        """The box of width ``W`` around ``back -> front``: its corners ``(x, y)`` counter-clockwise
        from the front right one."""
        ax, ay = fx - bx, fy - by
        n = np.hypot(ax, ay)
        nz = np.where(n > 0, n, 1.0)
        hw = 0.5 * self._arrays()["width"][row]
        sx, sy = hw * -(ay / nz), hw * (ax / nz)
        return [(fx - sx, fy - sy), (fx + sx, fy + sy), (bx + sx, by + sy), (bx - sx, by - sy)]
