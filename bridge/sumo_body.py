"""SUMO's body of a vehicle that muvsim moves along its route, and the pose pushed for it.

SUMO does not judge collisions between rigid bodies.  A vehicle is the box of width ``W``
around the line from its FRONT position (``vehicle.getPosition``) to its BACK position, the
point ``length`` behind the front along SUMO's lanes (the lane it is on, then the lanes behind
it) at the front's lateral offset (``MSVehicle::getBoundingBox`` / ``getBackPosition``; the
passenger shapes cut the box's corners, a subset).  The angle given to ``moveToXY`` only draws.
So on a turn SUMO's body is the chord between two points of the lane, and in muvsim's
lane-change diagonals it stays parallel to the lane.

Measured (``grid``, authority, seed 1, before this module): muvsim pushed the front bumper of a
rigid rectangle centred on the plant state along the heading of the current waypoint's segment,
``moveToXY`` with ``keepRoute=1`` snapped it onto the lane's centre line, and SUMO's body lay up
to 3.7 m (a bus in a right turn) from muvsim's; a truck's front 1.31 m off the lane in a left
turn became a junction collision muvsim's geometry never saw (min separation 0.33 m).

What this module does instead, for a plant position ``p`` (the body's reference point):

* ``sigma, e``: ``p``'s arc position on the route polyline and its signed offset (left +);
* front ``F = path(sigma + L/2) + e n``: pushed with ``keepRoute=3`` (SUMO keeps the exact
  position, lateral offset included, on a lane of the route; measured: to round-off) and the
  lane the front is on as the mapping hint;
* back ``B``: SUMO's, computed as SUMO does from the front's lane, lane position and lateral
  offset (:meth:`RouteBody.bodies`), in SUMO's lane units: a lane position is the shape's arc
  divided by the lane's length-geometry factor (shape length over the net file's ``length``), so
  on a lane whose length is not its shape's the body covers ``length * factor`` metres of road.
  Measured (``grid6``, authority, 180 s, before this was done): ``gneE34_0`` and ``gneE40_0``
  (111.57 m of shape, length 80, factor 1.39) got two SUMO lane collisions (gap -0.13 m and
  -0.00 m in lane units) between cars whose muvsim bodies, 5 m of shape long instead of
  6.97 m, were about 2 m apart; the monitor judged those bodies and saw none.

On a straight lane the body is exactly the rectangle of ``L x W`` centred on ``p`` along the lane.
Elsewhere it differs; :class:`PadTable` bounds how far SUMO's body reaches beyond that rectangle
in the current waypoint's segment frame, for every position the vehicle can still hold (between
where it is and its waypoint), and the reach claims add it to the footprint (tm.reach).
"""

from __future__ import annotations

import sys

import numpy as np

from bridge.body_kernels import path_pad_run, path_pads_many

__all__ = ["RouteBody", "PadTable", "window_starts", "SAMPLE_M", "AHEAD_M", "BACK_M", "KINK_SLOP_M", "OFFSET_MAX_M",
           "LEAN_MAX_RAD"]

#: Arc spacing of the positions :meth:`RouteBody.pads` evaluates (m); the change of the body
#: between neighbouring samples is added to the pads, so a coarser grid only costs room.
SAMPLE_M = 0.1
#: How far past its waypoint (beyond ``T^0``'s along extent) a vehicle's position may be for the
#: pads of that waypoint to hold (m).  The waypoint is its stop point; the loop counts the
#: vehicle-steps beyond it (``body_window_exits``, a safety counter).  At 1.0 m the last waypoint's
#: padding took in fronts clamped at the route's dead end (0.5 m beyond the body's end of route,
#: DEPART_CLEARANCE_M), slowing a queue on a straight road below 10 m/s; 0.3 m keeps them on it.
AHEAD_M = 0.3
#: Largest distance of a reference point from its route polyline for which the padding is computed
#: (m), when the sets allow more (their across extent: 0.95 m car, 1.58 m bus, 1.74 m truck).
#: Measured on ``grid`` (authority, 300 s): 0.74, 0.94, 0.77 m (seeds 1-3, car at most 0.95 by its
#: sets), 1.06 m (seed 2, a bus or truck: the counter fired with a 1.0 m cap).  Counted beyond
#: (``body_window_exits``).
OFFSET_MAX_M = 1.5
#: How far a vehicle's reference point may roll back along its route (below the furthest it
#: reached) for the padding to hold (m); counted otherwise (``body_window_exits``).
BACK_M = 0.5
#: Arc (m), beyond ``e_max tan(turn / 2)``, either side of a kink of the waypoints' chords within
#: which a path-frame table also measures its samples' reach in the other chord's axes
#: (:class:`PadTable`): the route's polyline between two waypoints is not their chord.
KINK_SLOP_M = 0.3


#: Largest body lean (rad) :meth:`RouteBody.leans` gives a chord off the lanes: a lane change
#: crosses a 3.2 m lane in 20-30 m (6-9 degrees; bridge.waypoints.lane_change_plan), or in half a
#: short edge; a steeper join is a gap in the network's geometry, left without a lean.
LEAN_MAX_RAD = float(np.deg2rad(30.0))

#: Rows per call of the windowed projection in :meth:`RouteBody.project_along` (bounds its arrays).
_PROJECT_CHUNK = 256

#: Samples per block when a path-frame table computes its samples' reach (bounds its arrays).
_REACH_CHUNK = 4096
#: Samples per block when a :class:`PadTable` computes its samples' bodies (three rows each).
#: Measured (20 routes of ``benchmarks/bench_scale.py``'s 1,000-vehicle grid, road frame, best of 3
#: each, two rounds): median 6.8 ms per table at 8192 against 7.2 ms at 4096; 16384 and a whole route
#: at once (tens of thousands of samples) no faster.
_BODY_CHUNK = 8192

#: SUMO's POSITION_EPS (m): the least shape length MSLane's length-geometry factor takes.
_POSITION_EPS = 0.1


def _arc(points: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(points, axis=0).T))])


def _at(points, arc, s):
    """Points (n, 2), unit tangents (n, 2) and segment indices at arc positions ``s`` (clipped)."""
    s = np.clip(np.asarray(s, dtype=float), 0.0, arc[-1])
    i = np.clip(np.searchsorted(arc, s, side="right") - 1, 0, len(points) - 2)
    d = points[i + 1] - points[i]
    n = np.hypot(d[:, 0], d[:, 1])
    t = d / np.where(n > 0, n, 1.0)[:, None]
    return points[i] + t * (s - arc[i])[:, None], t, i


def _project(points, arc, p, lo=0.0, hi=np.inf):
    """Arc positions and signed offsets (left +) of points ``p`` (n, 2) on a polyline, each
    restricted to segments overlapping ``[lo, hi]`` (scalars or (n,))."""
    p = np.asarray(p, dtype=float).reshape(-1, 2)
    if np.ndim(lo) == 0 and np.ndim(hi) == 0 and np.isfinite(hi):  # one window: only its segments
        i0 = max(int(np.searchsorted(arc, lo, side="right")) - 1, 0)
        i1 = min(int(np.searchsorted(arc, hi, side="left")) + 1, len(points))
        if i1 - i0 >= 2:
            return _project(points[i0:i1], arc[i0:i1], p)
    a, b = points[:-1], points[1:]
    d = b - a
    ln2 = np.maximum((d ** 2).sum(axis=1), 1e-18)
    w = p[:, None, :] - a[None]
    u = np.clip((w * d[None]).sum(axis=2) / ln2[None], 0.0, 1.0)
    q = a[None] + u[..., None] * d[None]
    dist = np.hypot(p[:, None, 0] - q[..., 0], p[:, None, 1] - q[..., 1])
    lo = np.broadcast_to(np.asarray(lo, dtype=float), (len(p),))
    hi = np.broadcast_to(np.asarray(hi, dtype=float), (len(p),))
    ok = (arc[1:][None] >= lo[:, None]) & (arc[:-1][None] <= hi[:, None])
    dist = np.where(ok | ~ok.any(axis=1, keepdims=True), dist, np.inf)
    j = np.argmin(dist, axis=1)
    r = np.arange(len(p))
    sigma = arc[j] + u[r, j] * np.sqrt(ln2[j])
    t = d[j] / np.sqrt(ln2[j])[:, None]
    e = t[:, 0] * (p[:, 1] - q[r, j, 1]) - t[:, 1] * (p[:, 0] - q[r, j, 0])
    return sigma, e


def window_starts(grids: np.ndarray, sigma_lo: np.ndarray) -> np.ndarray:
    """:meth:`PadTable.window_start` of many tables at once: ``grids`` (n, 3) their
    :attr:`PadTable.grid` rows, ``sigma_lo`` (n,).  The samples are a linspace (``sig[j] = j *
    step``): an index from the quotient, corrected against the samples themselves, which is what
    ``searchsorted(sig, sigma_lo, "right") - 1`` (clipped at 0) gives, float for float."""
    g = np.asarray(grids, dtype=float).reshape(-1, 3)
    s = np.asarray(sigma_lo, dtype=float).reshape(-1)
    step, last, end = g[:, 0], g[:, 1].astype(np.intp), g[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        q = np.where(step > 0, s / np.where(step > 0, step, 1.0), 0.0)
    nan = np.isnan(q)
    j = np.clip(np.where(nan, 0.0, q), 0.0, last).astype(np.intp)

    def sig(i):  # the samples, as numpy's linspace makes them
        return np.where(i >= last, end, i * step)

    while True:
        up = ~nan & (j < last) & (sig(j + 1) <= s)
        if not up.any():
            break
        j = j + up
    while True:
        down = ~nan & (j > 0) & (sig(j) > s)
        if not down.any():
            break
        j = j - down
    return np.where(nan, last, j)  # NaN sorts last


def _rowmax(a: np.ndarray) -> np.ndarray:
    """``a.max(axis=1)`` of an (m, k) array, column by column (k passes over m; numpy's reduction over
    a short last axis runs an inner loop per row, several times slower)."""
    out = a[:, 0].copy()
    for i in range(1, a.shape[1]):
        np.maximum(out, a[:, i], out=out)
    return out


def _max_norm(d: np.ndarray) -> np.ndarray:
    """``np.hypot(d[..., 0], d[..., 1]).max(axis=1)`` of an (m, k, 2) array, the same floats; a row
    whose vectors are all zero is 0 without ``hypot`` (``hypot(+-0, +-0) = +0``): most rows of a
    :class:`PadTable`'s changes between samples, where a straight lane's body keeps its offsets
    exactly, and ``hypot`` costs ten times a product."""
    x, y = d[..., 0], d[..., 1]
    out = np.zeros(len(d))
    rows = np.flatnonzero(_rowmax((x != 0) | (y != 0)))  # NaN != 0 too
    if len(rows):
        out[rows] = _rowmax(np.hypot(x[rows], y[rows]))
    return out


def _sample_reach(rel: np.ndarray, heading: np.ndarray, step: np.ndarray) -> np.ndarray:
    """How far bodies reach from their positions (back, front, right, left; (4, m)) in frames at
    ``heading`` (m,): ``rel`` (m, 3, 4, 2) the corners relative to the positions, ``step`` (m,) added.
    The corners are taken as (12, m) arrays (each maximum over a sample's 12 corners then runs along
    the samples); a reach behind or to the right is minus the least coordinate (the largest of
    minus them: the same float, ``+ step`` making any zero +0)."""
    m, k = len(rel), rel.shape[1] * rel.shape[2]
    x, y = rel[..., 0].reshape(m, k).T, rel[..., 1].reshape(m, k).T  # (12, m) views
    c, s = np.cos(heading), np.sin(heading)
    ra, ry, t = np.empty(x.shape), np.empty(x.shape), np.empty(x.shape)
    np.multiply(c, x, out=ra)  # corners relative to the position, along the frame: c x + s y
    np.multiply(s, y, out=t)
    ra += t
    np.multiply(-s, x, out=ry)  # and across (left +): -s x + c y
    np.multiply(c, y, out=t)
    ry += t
    out = np.empty((4, m))  # back, front, right, left
    np.negative(ra.min(axis=0), out=out[0])
    ra.max(axis=0, out=out[1])
    np.negative(ry.min(axis=0), out=out[2])
    ry.max(axis=0, out=out[3])
    out += step
    return out


class RouteBody:
    """SUMO's body along one route (see the module notes).

    Parameters
    ----------
    route : bridge.waypoints.RouteWaypoints
        The route's polyline and the lane of each of its segments.
    net : bridge.waypoints.NetGeometry
        For the lanes' shapes (SUMO's geometry).
    length, width : float
        SUMO's vType length and width (m).
    """

    def __init__(self, route, net, length: float, width: float) -> None:
        self.length, self.width = float(length), float(width)
        self.poly = np.asarray(route.polyline, dtype=float)
        self.parc = _arc(self.poly)
        #: whether each polyline segment lies on a lane's centre line (False: a lane change's
        #: diagonal, or a join across a gap in the network's geometry)
        self.seg_on = np.asarray(route.segment_on_lane, dtype=bool)
        # the route's lanes in order, each once; a polyline segment's lane is one of them
        order: list[str] = []
        for lane in route.segment_lanes:
            if not order or order[-1] != lane:
                order.append(lane)
        self.lanes = order
        self.seg_lane = np.array([0] * len(route.segment_lanes), dtype=np.intp)
        k = 0
        for s, lane in enumerate(route.segment_lanes):
            while order[k] != lane:
                k += 1
            self.seg_lane[s] = k
        self.shapes = [np.asarray(net.lane_shape(lane), dtype=float) for lane in order]
        self.arcs = [_arc(s) for s in self.shapes]
        # SUMO counts lane positions in the net file's lane length, not the shape's: a lane
        # position ``pos`` lies at the shape's arc ``pos * scale`` (MSLane's length-geometry factor,
        # shape length (at least POSITION_EPS) over length).  netconvert gives every lane of an edge
        # the edge's length, so on a curved or re-shaped edge the factor is not 1 (grid6's gneE34_0:
        # 111.57 m of shape, length 80, factor 1.39): there SUMO's body, ``length`` lane units from
        # its front, covers ``length * scale`` metres of road.
        self.lane_len = np.array([float(net.lane_length(lane)) for lane in order])
        if np.any(self.lane_len <= 0):
            bad = [lane for lane, ln in zip(order, self.lane_len) if ln <= 0]
            raise ValueError(f"RouteBody: lane(s) {bad} have a non-positive length in the network")
        self.scale = np.array([max(a[-1], _POSITION_EPS) for a in self.arcs]) / self.lane_len
        self.edge = [lane.rsplit("_", 1)[0] for lane in order]
        self.index = [int(lane.rsplit("_", 1)[1]) for lane in order]
        # the lane SUMO continues the back on behind lane k: the last earlier lane of another edge
        self.behind = np.full(len(order), -1, dtype=np.intp)
        for k in range(len(order)):
            j = k - 1
            while j >= 0 and self.edge[j] == self.edge[k]:
                j -= 1
            self.behind[k] = j

    @property
    def route_length(self) -> float:
        return float(self.parc[-1])

    def project(self, p, around=None, back: float = 5.0, ahead: float = 30.0):
        """Arc positions and signed offsets (left +) of positions ``p`` (n, 2) on the route,
        searched within ``[around - back, around + ahead]`` when ``around`` (n,) is given."""
        if around is None:
            return _project(self.poly, self.parc, p)
        around = np.asarray(around, dtype=float)
        if around.size == 1:
            a = float(around.reshape(-1)[0])
            return _project(self.poly, self.parc, p, a - back, a + ahead)
        return _project(self.poly, self.parc, p, around - back, around + ahead)

    def bodies(self, sigma, e):
        """SUMO's body for reference points at arc ``sigma`` (n,) and offset ``e`` (n,).

        Returns
        -------
        front, back : ndarray, shape (n, 2)
        lane : ndarray of int, shape (n,)
            Index into :attr:`lanes` of the lane the front is on.
        corners : ndarray, shape (n, 4, 2)
            The box of width ``W`` around ``back -> front``, counter-clockwise from the front
            right corner (as :func:`tm.geometry.rectangles`).
        """
        sigma = np.asarray(sigma, dtype=float).reshape(-1)
        return self._alone().bodies_of_rows(np.zeros(len(sigma), dtype=np.intp), sigma, e)

    def _alone(self):
        """This body as a fleet of one (:class:`bridge.body_fleet.FleetBodies`, built on first use):
        its lanes as one ragged array, so :meth:`bodies` takes every row at once instead of a few
        numpy calls per lane (a route's :class:`PadTable` asks for three bodies per 0.1 m sample)."""
        f = self.__dict__.get("_fleet")
        if f is None:
            from bridge.body_fleet import FleetBodies  # it imports this module (for its types only)

            f = self._fleet = FleetBodies(route_segments=True)
            f.add("", self)
        return f

    def project_along(self, P, hint=None, back: float = 1.0, ahead: float = 10.0) -> np.ndarray:
        """Arc positions of points ``P`` (m, 2) met in order along the route (waypoints, their chords'
        middles): each searched within ``[s - back, s + ahead]`` of the one before (the first on the
        whole route), so a route that passes near itself is not confused.  With ``hint`` (m,), each
        point's approximate arc position (within ``back`` above and ``ahead`` below the true one), all are
        searched at once within ``[hint - back, hint + ahead]``."""
        P = np.asarray(P, dtype=float).reshape(-1, 2)
        if hint is None:
            out, s = np.empty(len(P)), None
            for j in range(len(P)):
                out[j] = float(self.project(P[j:j + 1], None if s is None else [s], back, ahead)[0][0])
                s = out[j]
            return out
        h = np.asarray(hint, dtype=float).reshape(-1)
        out = np.empty(len(P))
        for a in range(0, len(P), _PROJECT_CHUNK):  # (rows x segments) arrays: in chunks
            b = min(a + _PROJECT_CHUNK, len(P))
            out[a:b] = _project(self.poly, self.parc, P[a:b], h[a:b] - back, h[a:b] + ahead)[0]
        return out

    def leans(self, W, arcs=None) -> np.ndarray:
        """Body lean (rad) of each chord ``W[j] -> W[j + 1]`` of the route's waypoints ``W`` (P, 2),
        for :class:`controllers.path.PathFrame`: where the chord's middle lies on a polyline segment
        off the lanes (a lane change's diagonal), the angle from the chord to SUMO's body there
        (front minus back at offset 0: the lane's direction); 0 elsewhere, and where that angle
        exceeds :data:`LEAN_MAX_RAD` (a gap join, not a lane change).  ``arcs`` (P,): the waypoints'
        arc positions on the route (:meth:`project_along`), when known."""
        W = np.asarray(W, dtype=float)
        out = np.zeros(max(len(W) - 1, 0))
        if len(W) < 2 or self.seg_on.all():
            return out
        d = np.diff(W, axis=0)
        mid = W[:-1] + 0.5 * d
        hint = None if arcs is None else 0.5 * (np.asarray(arcs, dtype=float)[:-1] + np.asarray(arcs, dtype=float)[1:])
        sig = self.project_along(mid, hint)
        seg = np.clip(np.searchsorted(self.parc, sig, side="right") - 1, 0, len(self.seg_on) - 1)
        off = np.flatnonzero(~self.seg_on[seg] & (np.hypot(d[:, 0], d[:, 1]) > 0))
        if len(off):
            front, back, _, _ = self.bodies(sig[off], np.zeros(len(off)))
            axis = front - back
            lean = np.angle(np.exp(1j * (np.arctan2(axis[:, 1], axis[:, 0]) - np.arctan2(d[off, 1], d[off, 0]))))
            out[off] = np.where(np.abs(lean) <= LEAN_MAX_RAD, lean, 0.0)
        return out

    def pad_table(self, arc_k, W, H, box_lo, box_hi, frame: str = "road") -> "PadTable":
        """The :class:`PadTable` of this route for waypoints ``W`` (arcs ``arc_k``, headings ``H``)."""
        return PadTable(self, arc_k, W, H, box_lo, box_hi, frame)


class PadTable:
    """How far SUMO's body reaches beyond the rectangle ``L x W`` centred on the plant position,
    in a waypoint's segment frame, for the positions a vehicle can hold (:meth:`pads`).

    The positions taken are the reference points ``path(sigma) + e n`` with ``sigma`` on a
    :data:`SAMPLE_M` grid and ``e`` in ``{-e_max, 0, e_max}`` (``e_max``: the across extent of the
    box, at most :data:`OFFSET_MAX_M`) that lie in ``[box_lo, box_hi]`` of the waypoint's frame and
    at ``sigma`` no lower than the vehicle's window start (it does not roll back more than
    :data:`BACK_M`).  A position between two samples is covered by adding the change of the body
    between them, its smooth part where the body jumps.

    Parameters
    ----------
    body : RouteBody
    arc_k : ndarray, shape (K,)
        Arc positions of the waypoints on the route polyline.
    W, H : ndarray, shapes (K, 2) and (K,)
        The waypoints and their segment headings.
    box_lo, box_hi : (2,) float
        Along and across bounds, in a waypoint's frame, of every position a vehicle can hold
        while that waypoint is its current one (its sets' widest projection; the along upper
        bound includes :data:`AHEAD_M`).
    frame : {"road", "path"}
        ``road``: the rectangle lies along the waypoint's segment and the positions are in its
        frame (a road-frame plant).  ``path``: a path-frame plant (:mod:`bridge.path_fleet`): the
        positions are path coordinates (``box_lo, box_hi`` bound the arc from the waypoint and
        the offset), the rectangle at a position lies along the route's segment there, and the
        pads are in the rectangle's own axes (as :func:`tm.path_claims.path_reach_claims` adds
        them).  A sample takes the heading of the segment it lies on (right-continuous, as
        :meth:`controllers.path.PathFrame.to_world`); the pose at a vertex with the arriving
        segment's heading, which the claims cover too, is the limit of the poses before it: the
        sample before the vertex and the step term hold it.  A plant position near a vertex lies
        on one segment but projects onto the route on either side of it, so the samples within
        ``e_max tan(turn / 2) +`` :data:`KINK_SLOP_M` of a kink count in both chords' axes
        (:meth:`_kink_reach`).
    """

    def __init__(self, body: RouteBody, arc_k, W, H, box_lo, box_hi, frame: str = "road") -> None:
        if frame not in ("road", "path"):
            raise ValueError(f"PadTable: frame must be 'road' or 'path', got {frame!r}")
        self.frame = frame
        self.length, self.width = body.length, body.width
        self._half = 0.5 * np.array([self.length, self.length, self.width, self.width])  # (back, front, right, left)
        self.arc_k = np.asarray(arc_k, dtype=float)
        self.W = np.asarray(W, dtype=float)
        self.H = np.asarray(H, dtype=float)
        self.box_lo = (float(box_lo[0]), float(box_lo[1]))
        self.box_hi = (float(box_hi[0]), float(box_hi[1]))
        e_max = min(max(abs(self.box_lo[1]), abs(self.box_hi[1])), OFFSET_MAX_M)
        self.offset_max = e_max
        n = int(np.ceil(body.route_length / SAMPLE_M)) + 1
        self.sig = np.linspace(0.0, body.route_length, n)
        self._step = float(self.sig[1]) if n > 1 else 0.0
        self._grid = (self._step, n - 1, float(self.sig[-1]))
        # the three bodies of every sample, block by block (arrays of a few thousand rows: a whole
        # route's at once, tens of thousands, cost more in fresh memory than in arithmetic)
        fleet = body._alone()
        offsets = (-e_max, 0.0, e_max)
        ev = np.array(offsets)[:, None]
        self.rel = np.empty((n, 3, 4, 2))  # corners relative to the positions
        self.ref = np.empty((n, 3, 2))     # the positions
        #: k -> (j_base, (n + 1, 4) suffix maxima of the per-sample pads from j_base on, a zero row last)
        self._suffix: dict[int, tuple[int, np.ndarray, np.ndarray]] = {}
        self.step = np.zeros(n)
        dd = np.empty(max(n - 1, 0))
        chord = np.float64(np.inf)  # shortest front-back distance (e = 0)
        zeros = np.zeros(min(n, _BODY_CHUNK), dtype=np.intp)
        for a in range(0, n, _BODY_CHUNK):
            b = min(a + _BODY_CHUNK, n)
            m = b - a
            # the positions: path(sig) + e n (sumo_body._at's floats) and the corners of
            # body.bodies(sig, e) at the three offsets, (m, 3, 4) x and y
            qx, qy, tx, ty = fleet.route_at(zeros[:m], self.sig[a:b])
            px, py = qx + ev * -ty, qy + ev * tx  # (3, m)
            rel, ref = self.rel[a:b], self.ref[a:b]
            ref[..., 0], ref[..., 1] = px.T, py.T
            for c, (cx, cy) in enumerate(fleet.corners_at_offsets(zeros[:m], self.sig[a:b], offsets)):
                rel[:, :, c, 0] = (cx - px).T
                rel[:, :, c, 1] = (cy - py).T
            r1 = rel[:, 1]
            ax = 0.5 * (r1[:, 0, 0] + r1[:, 1, 0] - r1[:, 2, 0] - r1[:, 3, 0])
            ay = 0.5 * (r1[:, 0, 1] + r1[:, 1, 1] - r1[:, 2, 1] - r1[:, 3, 1])
            chord = np.minimum(chord, np.hypot(ax, ay).min())
            # the largest change of a corner from each sample to the next (np.diff's floats)
            if a > 0:  # from the block before's last sample to this block's first
                dd[a - 1] = _max_norm((rel[0] - self.rel[a - 1]).reshape(1, 12, 2))[0]
            if m > 1:
                dd[a:b - 1] = _max_norm((rel[1:] - rel[:-1]).reshape(m - 1, 12, 2))
        if n > 1:
            # where the body jumps (the front's lane changes under a lateral offset, a polyline
            # vertex turns the offset's normal) a position between two samples has the body of one
            # side or the other: only the smooth part of the change needs room, at most
            # (1 + e_max kappa)(1 + W / |F - B|) per metre (corners of a box on a moving axis), times
            # how much faster than the front the back can move (lanes of different factors)
            d = np.diff(body.poly, axis=0)
            seg = np.hypot(d[:, 0], d[:, 1])
            turn = np.abs(np.angle(np.exp(1j * np.diff(np.arctan2(d[:, 1], d[:, 0])))))
            kappa = float((turn / np.maximum(np.minimum(seg[:-1], seg[1:]), SAMPLE_M)).max(initial=0.0))
            # the back moves up to (largest / smallest lane factor) times as far as the front
            ratio = float(body.scale.max() / body.scale.min())
            lip = ratio * (1.0 + e_max * kappa) * (1.0 + self.width / max(float(chord), 1e-6)) * SAMPLE_M
            dd = np.minimum(dd, lip)
            self.step[:-1] = np.maximum(self.step[:-1], dd)
            self.step[1:] = np.maximum(self.step[1:], dd)
        if frame == "path":
            # a sample's reach in the path frame does not depend on the waypoint (the rectangle lies
            # along the route's segment at the sample): computed once, (n, 4); the corners are then
            # not needed (a tenth of the memory: 24 floats a sample down to 4)
            seg = np.searchsorted(self.arc_k, self.sig, side="right")
            h = self.H[np.clip(seg, 1, len(self.H) - 1)]
            # stored (4, n + 1) (``_path_reach`` is the (n, 4) view of its first n columns): pads_many
            # reduces along the samples, and its ranges may end at n (the last column, zeros)
            self._reach_T = np.zeros((4, n + 1))
            self._path_reach = self._reach_T[:, :n].T
            for a in range(0, n, _REACH_CHUNK):
                b = min(a + _REACH_CHUNK, n)
                self._path_reach[a:b] = _sample_reach(self.rel[a:b], h[a:b], self.step[a:b]).T
            self._kink_reach(e_max)
            del self.rel, self.ref  # the positions too: the path frame's box is an arc range

    def _kink_reach(self, e_max: float) -> None:
        """Path frame: near each kink of the waypoints' chords, the samples' reach in both chords'
        axes.  A plant position ``(s, n)`` near a vertex lies on one segment (its rectangle in that
        segment's axes) and projects onto the route up to ``|n| tan(turn / 2)`` past the vertex (on
        the inside of the turn), or before it, where the samples take the other chord's heading.
        Measured before (``tests/bridge/test_sumo_body.py``, the test grid's turns, car, bus and
        truck, every 0.05 m and 5 offsets, a window from the position's own arc): SUMO's body lay up
        to 0.26 m outside the padded rectangle at 46 of 138,600 positions."""
        K = len(self.arc_k)
        if K < 3:
            return
        turn = np.angle(np.exp(1j * np.diff(self.H[1:])))  # at arc_k[c], from chord c to c + 1 (c = 1 .. K - 2)
        kinks = np.flatnonzero(np.abs(turn) > 0.0) + 1
        if not len(kinks):
            return
        slop = e_max * np.tan(0.5 * np.minimum(np.abs(turn[kinks - 1]), 0.5 * np.pi)) + KINK_SLOP_M
        lo = np.searchsorted(self.sig, self.arc_k[kinks] - slop, side="left")
        hi = np.searchsorted(self.sig, self.arc_k[kinks] + slop, side="right")
        cnt = hi - lo
        j = np.repeat(lo, cnt) + (np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt))
        c = np.repeat(kinks, cnt)
        for hh in (self.H[c], self.H[c + 1]):
            for a in range(0, len(j), _REACH_CHUNK):
                b = min(a + _REACH_CHUNK, len(j))
                jj = j[a:b]
                np.maximum.at(self._path_reach, jj, _sample_reach(self.rel[jj], hh[a:b], self.step[jj]).T)

    def pads(self, k: int, sigma_lo: float) -> np.ndarray:
        """``(back, front, right, left) >= 0``: the padding of waypoint ``k``'s claims for a vehicle
        whose reference point stays at arc ``>= sigma_lo``, one-sided: how far SUMO's body reaches
        beyond each side of the rectangle in the waypoint's frame (non-increasing in ``sigma_lo``;
        :func:`tm.reach.split_pad`).  One-sided because the body of a turn lies off-centre (the
        chord between front and back cuts the inside of the curve): symmetric pads claimed the
        larger side on both and on ``grid`` locked junctions (issue 12)."""
        return self.pads_at(k, self.window_start(sigma_lo))

    def pads_at(self, k: int, j0: int) -> np.ndarray:
        """:meth:`pads` for the window starting at sample ``j0`` (:meth:`window_start`,
        :func:`window_starts`)."""
        return self.pads_run(k, j0)[0]

    def pads_run(self, k: int, j0: int) -> tuple[np.ndarray, int]:
        """:meth:`pads_at` and the last window start ``j1 >= j0`` with the same padding: the
        padding is a suffix maximum, constant over long runs of window starts, so a caller may keep
        the row while its window starts in ``[j0, j1]`` (:meth:`bridge.sumo_world.SumoWorld.claim_pads`).
        ``j1`` is ``sys.maxsize`` where the padding is zero from there on.  A road-frame table keeps a
        table of suffix maxima per waypoint; a path-frame one takes the maximum over the samples
        directly (:meth:`_path_run`)."""
        k = int(min(max(k, 0), len(self.W) - 1))
        if self.frame == "path":
            return self._path_run(k, j0)
        tab = self._suffix.get(k)
        if tab is None or j0 < tab[0]:  # a window start before the table's (rolled back): built anew from it
            tab = self._suffix[k] = self._table(k, j0)
            if len(self._suffix) > 64:  # waypoints left behind (a vehicle's k only grows)
                for old in sorted(self._suffix)[:32]:
                    del self._suffix[old]
        base, S, last = tab
        i = min(j0 - base, len(S) - 1)
        return S[i], (sys.maxsize if i == len(S) - 1 else base + int(last[i]))

    def _path_run(self, k: int, j0: int) -> tuple[np.ndarray, int]:
        """:meth:`pads_run` of a path-frame table: the maxima of ``reach - half`` over the samples of
        waypoint ``k``'s box from ``j0`` on (the very values :meth:`_table` takes, so the same
        floats), and the run's end: the last sample, over the sides whose padding is positive, that
        still reaches that side's maximum (past it, that side's padding drops).  The box's samples
        ``[lo, hi)``: ``box_lo <= sig[j] - arc_k[k] <= box_hi`` (a run: the rounded difference does not
        decrease along ``sig``; :meth:`_table`'s own bound, ``box_hi + 2 L``, lies past it), found by
        bisection on ``arc + bound`` and the rounding's +-1 settled on the very comparison
        :meth:`_reach` makes (the two roundings differ by an ulp or so, the samples lie 0.1 m apart:
        one index at most); :func:`bridge.body_kernels.path_pad_run`."""
        pads, j1 = path_pad_run(self.sig, float(self.arc_k[k]), self.box_lo[0], self.box_hi[0], self._reach_T,
                                self._half, int(j0))
        return pads, (sys.maxsize if j1 < 0 else int(j1))

    def pads_many(self, ks, j0: int) -> np.ndarray:
        """:meth:`pads_at` ``(k, j0)`` for every ``k`` of ``ks`` (m,), one window start, as ``(m, 4)``:
        the same floats.  A path-frame table takes them in one compiled loop (a waypoint's pads are
        a maximum of the reach over one contiguous run of samples, :func:`bridge.body_kernels.path_pads_many`),
        builds no suffix table and keeps nothing; a road-frame one asks :meth:`pads_run` per waypoint."""
        ks = np.clip(np.asarray(ks, dtype=np.intp).reshape(-1), 0, len(self.W) - 1)
        if self.frame != "path":
            return np.array([self.pads_run(k, j0)[0] for k in ks.tolist()]).reshape(len(ks), 4)
        return path_pads_many(self.sig, self.arc_k, ks, self.box_lo[0], self.box_hi[0], self._reach_T, self._half,
                              int(j0))

    def window_start(self, sigma_lo: float) -> int:
        """The first sample a window starting at arc ``sigma_lo`` counts: the last one at or before
        it.  A position between two samples has the body of one or the other where the body jumps
        (the step term covers only the smooth part): the first sample past ``sigma_lo`` alone missed
        the body of the one before (a truck at the window start before a left turn, 1.5 m off the
        route: 0.11 m outside its padded rectangle, ``tests/bridge/test_sumo_body.py``)."""
        return int(window_starts([self._grid], [sigma_lo])[0])

    @property
    def grid(self) -> tuple[float, int, float]:
        """The samples as ``(step, last, end)``: ``sig[j] = j * step`` for ``j < last``, ``sig[last] = end``
        (a linspace from 0)."""
        return self._grid

    def _table(self, k: int, j_base: int) -> tuple[int, np.ndarray, np.ndarray]:
        """Pads of waypoint ``k`` for every window start ``j0 >= j_base``: row ``j0 - j_base`` is
        :meth:`_pads` ``(k, j0)`` (the same maxima of the same sample values, so the same floats);
        past the samples that count, the zero row.  Also, per row, the last row of its run of
        equal rows."""
        j1 = int(np.searchsorted(self.sig, self.arc_k[k] + self.box_hi[0] + 2.0 * self.length, side="right"))
        if j1 <= j_base:
            return j_base, np.zeros((1, 4)), np.zeros(1, dtype=np.int32)
        per = self._per_sample(k, j_base, j1)  # (j1 - j_base, 4), -inf where no position counts
        suf = np.maximum.accumulate(per[::-1], axis=0)[::-1]
        out = np.zeros((len(suf) + 1, 4))
        out[:-1] = np.maximum(suf, 0.0)
        # last[i]: the last row of row i's run of equal rows (pads_run)
        ends = np.append(np.flatnonzero(np.any(out[1:] != out[:-1], axis=1)), len(out) - 1)
        last = ends[np.searchsorted(ends, np.arange(len(out)))].astype(np.int32)  # 4 bytes beside each row's 32
        return j_base, out, last

    def _per_sample(self, k: int, j0: int, j1: int) -> np.ndarray:
        """Per sample ``j0 <= j < j1``: how far SUMO's body reaches beyond the rectangle (back,
        front, right, left) in waypoint ``k``'s frame, ``-inf`` where no position of the sample
        lies in the box."""
        out = np.full((j1 - j0, 4), -np.inf)
        inside, reach = self._reach(k, j0, j1)
        if inside.any():
            out[inside] = reach.T - self._half
        return out

    def _reach(self, k: int, j0: int, j1: int) -> tuple[np.ndarray, np.ndarray]:
        """Which samples ``j0 <= j < j1`` hold a position of waypoint ``k``'s box, and for those how
        far SUMO's body reaches from the position (back, front, right, left; (4, m)), in waypoint
        ``k``'s frame (road) or the route segment's at the sample (path), step term included."""
        if self.frame == "road":
            c, s = np.cos(self.H[k]), np.sin(self.H[k])
            d = self.ref[j0:j1] - self.W[k]
            a = c * d[..., 0] + s * d[..., 1]
            y = -s * d[..., 0] + c * d[..., 1]
            inside = ((a >= self.box_lo[0]) & (a <= self.box_hi[0]) &
                      (y >= self.box_lo[1]) & (y <= self.box_hi[1])).any(axis=1)
            hs = [np.full(int(inside.sum()), self.H[k])]
        else:  # arc from the waypoint; every sampled offset lies within the box's (e_max)
            a = self.sig[j0:j1] - self.arc_k[k]
            inside = (a >= self.box_lo[0]) & (a <= self.box_hi[0])
            if not inside.any():
                return inside, np.zeros((4, 0))
            return inside, self._path_reach[j0:j1][inside].T
        if not inside.any():
            return inside, np.zeros((4, 0))
        reach = None
        for h in hs:
            got = _sample_reach(self.rel[j0:j1][inside], h, self.step[j0:j1][inside])
            reach = got if reach is None else np.maximum(reach, got)
        return inside, reach

    def _pads(self, k: int, j0: int) -> np.ndarray:
        """The reference computation of :meth:`pads` (one window start; tests compare the tables with it)."""
        j1 = int(np.searchsorted(self.sig, self.arc_k[k] + self.box_hi[0] + 2.0 * self.length, side="right"))
        if j1 <= j0:
            return np.zeros(4)
        inside, reach = self._reach(k, j0, j1)
        if not inside.any():
            return np.zeros(4)
        return np.maximum(reach.max(axis=1) - self._half, 0.0)
