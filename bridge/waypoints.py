"""SUMO routes as polylines through lane shapes, subsampled into waypoints.

A route (a list of edge ids) becomes a polyline that follows, for every edge,
the centre line of one of its lanes, and between two edges the internal
junction lanes of the connection the vehicle uses (``via`` lanes, possibly a
chain of two for turns with an internal junction), read with
``sumolib.net.readNet(net, withInternal=True)``.

Lane choice.  On every edge but the last the vehicle must leave from a lane
that has a connection to the next edge (right turns leave from lane 0, left
turns from the leftmost lane in SUMO's grids); the connection fixes the lane
it arrives on in the next edge.  The lanes are chosen for the whole route at
once (dynamic programming) to need the fewest lane changes, ties going to the
lower lane index.  Where the arrival lane differs from the lane the vehicle
must leave from, the polyline changes lane along straight diagonals, one per
lane boundary, each in that boundary's own stretch of the edge
(:func:`lane_change_plan`: changes away from lane 0 first, then those towards it,
ending 20 m before the edge's end, so no two routes' changes cross); the points
of a diagonal lie between the two centre lines.

Waypoints.  The polyline is cut at its corners (vertices where the direction
turns by more than ``corner_deg``), and each piece between corners is divided
into the fewest equal arc-length parts of length <= delta.  Waypoints are
therefore ON the polyline (by construction, up to round-off) and consecutive
waypoints are at most delta apart in Euclidean distance (a chord is never
longer than its arc); sharp corners are waypoints themselves.
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

__all__ = [
    "RouteError",
    "project_arc",
    "RouteWaypoints",
    "NetGeometry",
    "load_net",
    "route_waypoints",
    "subsample",
    "ConditionedPath",
    "condition_polyline",
    "polyline_waypoints",
    "point_polyline_distance",
    "drop_slivers",
    "round_corners",
    "refine_turns",
    "LANE_CHANGE_M",
    "LANE_CHANGE_MIN_M",
    "LANE_CHANGE_GAP_M",
    "LANE_CHANGE_END_M",
    "LANE_CHANGE_START_M",
    "lane_change_plan",
    "MIN_SEGMENT_M",
    "CHAMFER_M",
    "REVERSAL_DEG",
]

#: Longitudinal length of a lane change, per lane crossed (m): at most this in
#: :func:`lane_change_plan`'s stretches, exactly this on a short edge's single diagonal (up to
#: half the edge).  With 15 m (12 degrees
#: across a 3.2 m lane) a 12 m bus's turned footprint reached 1.2 m further across, into
#: the claims of the opposite lane, and met an oncoming car head-on: each one's next claim
#: met the other's hold region, for good (measured on ``grid``, 600 s).
LANE_CHANGE_M = 30.0
#: Shortest stretch a lane change across one lane may take when lane changes are laid out in
#: separate stretches (:func:`lane_change_plan`; 9 degrees across a 3.2 m lane); on an edge too
#: short for that, the change is one diagonal in the middle as long as :data:`LANE_CHANGE_M` per
#: lane allows, at most half the edge.
LANE_CHANGE_MIN_M = 20.0
#: Road between two stretches of :func:`lane_change_plan` (m): two routes that meet on a lane share
#: it for at least this long before they part.
LANE_CHANGE_GAP_M = 12.0
#: Road kept free of lane changes before an edge's end (m), where vehicles queue for the next
#: junction side by side (:func:`lane_change_plan`) ...
LANE_CHANGE_END_M = 20.0
#: ... and after its start (m).
LANE_CHANGE_START_M = 5.0

_DUP_TOL = 1e-9  # consecutive polyline points closer than this are merged (m)

#: Polyline segments shorter than this are dropped (their end point merged into the next):
#: where two lane shapes meet, SUMO's geometry has slivers (0.04 m on bs3d, 0.2-0.3 m on fokr)
#: whose direction is noise - read as a 175 deg or 96 deg turn.  Moves the route by < this.
MIN_SEGMENT_M = 0.5
#: A short segment is a sliver only when it turns by more than this from a neighbour (deg).
SLIVER_KINK_DEG = 30.0
#: How far back along each side a corner is cut when it turns more than the class accepts (m):
#: the corner's vertex is replaced by two points this far before and after it, each turning
#: half as much; repeated until every vertex turns within the bound.  Cuts inside the corner
#: by at most this x sin(turn / 2).
CHAMFER_M = 1.0
#: Vertices turning more than this are reversals, never rounded: a vehicle would have to turn
#: on the spot (it is reported undrivable instead).
REVERSAL_DEG = 150.0


class RouteError(ValueError):
    """A route that cannot be drawn: unknown edge or no connection between consecutive edges."""


@dataclass(frozen=True, eq=False)
class RouteWaypoints:
    """Waypoints of one route.

    Attributes
    ----------
    vehicle_id : str or None
        For messages.
    edges : tuple of str
        The route.
    delta : float
        Maximum distance between consecutive waypoints (m).
    waypoints : ndarray, shape (K, 2)
        Points on the polyline, first = start, last = end of the route.
    arc_length : ndarray, shape (K,)
        Cumulative arc length of each waypoint along the polyline (m), from 0.
    lane_ids : tuple of str, length K
        Lane (possibly internal, ``":..."``) each waypoint belongs to.
    on_lane : ndarray of bool, shape (K,)
        True where the waypoint lies on the centre line of ``lane_ids[k]``;
        False inside a lane change (then ``lane_ids[k]`` is the target lane).
    heading : ndarray, shape (K,)
        Direction of travel at each waypoint (rad, mathematical: from +x, counter-clockwise).
    length_m : float
        Route length along the polyline (m).
    polyline : ndarray, shape (P, 2)
        The polyline itself.
    segment_lanes : tuple of str, length P-1
        Lane of each polyline segment.
    segment_on_lane : ndarray of bool, shape (P-1,)
        Whether each segment lies on its lane's centre line.
    lanes : tuple of str
        The lane used on each edge of the route (where the vehicle leaves it).
    """

    vehicle_id: str | None
    edges: tuple[str, ...]
    delta: float
    waypoints: np.ndarray
    arc_length: np.ndarray
    lane_ids: tuple[str, ...]
    on_lane: np.ndarray
    heading: np.ndarray
    length_m: float
    polyline: np.ndarray
    segment_lanes: tuple[str, ...]
    segment_on_lane: np.ndarray
    lanes: tuple[str, ...]

    @property
    def count(self) -> int:
        """Number of waypoints K."""
        return int(self.waypoints.shape[0])

    @property
    def depart_lane_index(self) -> int:
        """Index of the lane the route starts on (for ``vehicle.add(departLane=...)``)."""
        return int(self.segment_lanes[0].rsplit("_", 1)[1])


# --------------------------------------------------------------------------- geometry helpers

def _arc(points: np.ndarray) -> np.ndarray:
    d = np.hypot(*np.diff(points, axis=0).T) if len(points) > 1 else np.zeros(0)
    return np.concatenate([[0.0], np.cumsum(d)])


def project_arc(poly: np.ndarray, parc: np.ndarray, q: np.ndarray, j0: int, j1: int) -> float:
    """Arc length (``parc``: the arcs of ``poly``'s points) of the point of segments ``j0 .. j1 - 1`` of
    ``poly`` closest to ``q``."""
    a, b = poly[j0:j1], poly[j0 + 1:j1 + 1]
    d = b - a
    L2 = np.maximum((d * d).sum(axis=1), 1e-18)
    t = np.clip(((q - a) * d).sum(axis=1) / L2, 0.0, 1.0)
    dist = np.hypot(*(a + t[:, None] * d - q).T)
    i = int(np.argmin(dist))
    return float(parc[j0 + i] + t[i] * np.sqrt(L2[i]))


def _at(points: np.ndarray, arc: np.ndarray, s: float) -> np.ndarray:
    """Point at arc length ``s`` (clamped) of a polyline."""
    s = min(max(s, 0.0), arc[-1])
    i = int(np.clip(np.searchsorted(arc, s, side="right") - 1, 0, len(points) - 2))
    seg = arc[i + 1] - arc[i]
    t = 0.0 if seg <= 0 else (s - arc[i]) / seg
    return points[i] + t * (points[i + 1] - points[i])


def stretch_length(n_lanes: int, length: float) -> float:
    """The length ``lc`` of each of :func:`lane_change_plan`'s ``2 (n - 1)`` stretches on an edge of
    ``n_lanes`` lanes and arc length ``length`` (0 for one lane)."""
    k = 2 * (n_lanes - 1)
    if not k:
        return 0.0
    return min(LANE_CHANGE_M, (length - LANE_CHANGE_END_M - LANE_CHANGE_START_M - (k - 1) * LANE_CHANGE_GAP_M) / k)


def lane_change_plan(n_lanes: int, arrive: int, leave: int, length: float,
                     stepwise: bool = True) -> list[tuple[float, float]]:
    """Where along an edge a route changes from lane ``arrive`` to lane ``leave``: the arc-length
    stretches ``[(s0, s1), ...]``, one per lane boundary crossed, in order.

    Every edge of ``n`` lanes (arc length ``length``) has ``K = 2 (n - 1)`` stretches of equal
    length ``lc = min(LANE_CHANGE_M, (length - LANE_CHANGE_END_M - LANE_CHANGE_START_M
    - (K - 1) LANE_CHANGE_GAP_M) / K)``, :data:`LANE_CHANGE_GAP_M` apart, in one block that ends
    :data:`LANE_CHANGE_END_M` before the edge's end: first those crossing away from lane 0
    (boundary ``0|1`` first), then those crossing towards it (boundary ``n-1|n-2`` first).  A route
    crosses each boundary it must in that boundary's own stretch and drives along the lane between
    two of them.  So two routes on one edge never cross: where one's order across the road changes
    against another's, both drive one lane for at least the gap in between (one follows the
    other).  Measured, each choice (``grid`` seeds 1-5 and bench_scale's 4 x 4 grid with 111
    trips departing in 30 s, ``--controller authority``):

    * one diagonal in the middle for changes both ways (the layout before): the two diagonals
      crossed; two vehicles queued there, each one's stop point short of the crossing, blocked
      each other for good (4 x 4 grid: 18 vehicles, in pairs on adjacent lanes; 93 of 111 arrived);
    * towards lane 0 first: SUMO's body stays parallel to the lane while the route runs
      diagonally, so on a change towards lane 0 (the kerb) the rear swings towards the opposite
      lanes; right after a junction it met the standing box of the car waiting at that junction's
      entry line the other way, and the bus, holding the token, waited for the car, which waited
      for the token (``grid`` seed 1: 138 of 150);
    * the block centred on the edge: the changes towards lane 0 ended 10 m before the edge's end,
      where vehicles queue side by side for the next junction, a leaning body beside a waiter that
      a turning bus's claims reach back over (``grid`` seeds 2, 3: 133 and 136 of 150);
    * this layout: all 150 on seeds 1-5, all 111 on the 4 x 4 grid.

    When ``lc`` would be below :data:`LANE_CHANGE_MIN_M` (a short edge), or ``stepwise`` is False
    (a lane in between the route may not use), the change is one diagonal in the middle of the
    edge, ``min(LANE_CHANGE_M * |leave - arrive|, length / 2)`` long: ``[(s0, s1)]``.
    """
    if arrive == leave:
        return []
    k = 2 * (n_lanes - 1)
    gap = LANE_CHANGE_GAP_M
    lc = stretch_length(n_lanes, length)
    if not stepwise or lc < LANE_CHANGE_MIN_M:
        one = min(LANE_CHANGE_M * abs(leave - arrive), 0.5 * length)
        s_a = 0.5 * (length - one)
        return [(s_a, s_a + one)]
    start = length - LANE_CHANGE_END_M - k * lc - (k - 1) * gap
    if leave > arrive:  # away from lane 0: boundary j|j+1 in stretch j
        slots = list(range(arrive, leave))
    else:               # towards lane 0: boundary j|j-1 in stretch n-1 + (n-1-j)
        slots = [2 * n_lanes - 2 - j for j in range(arrive, leave, -1)]
    return [(start + i * (lc + gap), start + i * (lc + gap) + lc) for i in slots]


def _cut(points: np.ndarray, s0: float, s1: float) -> np.ndarray:
    """The part of a polyline between arc lengths ``s0 <= s1``."""
    arc = _arc(points)
    inner = points[(arc > s0) & (arc < s1)]
    return np.vstack([_at(points, arc, s0), inner, _at(points, arc, s1)])


def point_polyline_distance(p: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Distance of points ``p`` (N,2) to a polyline ``poly`` (M,2), vectorised."""
    p = np.atleast_2d(np.asarray(p, dtype=float))
    a, b = poly[:-1], poly[1:]
    ab = b - a
    den = np.einsum("ij,ij->i", ab, ab)
    den = np.where(den > 0, den, 1.0)
    t = np.clip(np.einsum("nij,ij->ni", p[:, None, :] - a[None], ab) / den, 0.0, 1.0)
    proj = a[None] + t[..., None] * ab[None]
    return np.min(np.hypot(*(p[:, None, :] - proj).transpose(2, 0, 1)), axis=1)


def _turn_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Heading change between directions ``a`` and ``b`` (deg, 0..180)."""
    return math.degrees(abs(math.atan2(a[0] * b[1] - a[1] * b[0], a[0] * b[0] + a[1] * b[1])))


def drop_slivers(poly: np.ndarray, lanes: list, on: list, min_seg: float = MIN_SEGMENT_M,
                 kink_deg: float = SLIVER_KINK_DEG) -> tuple[np.ndarray, list, list]:
    """Drop the end points of slivers: segments shorter than ``min_seg`` that turn by more
    than ``kink_deg`` from the segment before or after them (ends kept exactly).

    Short segments of a smooth curve turn little and are kept.  ``lanes[i]``/``on[i]``
    describe segment ``i`` (point ``i`` to ``i + 1``); a merged segment takes the lane of
    its last part and is on no centre line.
    """
    n = len(poly)
    if n <= 2:
        return poly, lanes, on
    keep, kl, ko = [0], [], []
    merged = False
    for j in range(1, n):
        d = poly[j] - poly[keep[-1]]
        if np.hypot(*d) < min_seg:
            before = poly[keep[-1]] - poly[keep[-2]] if len(keep) > 1 else None
            after = poly[j + 1] - poly[j] if j + 1 < n else None
            kinked = (before is not None and _turn_deg(before, d) > kink_deg) or (
                after is not None and _turn_deg(d, after) > kink_deg)
            if kinked:
                if j == n - 1 and len(keep) > 1:  # the end stays exact: drop the previous instead
                    keep[-1] = j
                    kl[-1], ko[-1] = lanes[j - 1], False
                else:
                    merged = True
                continue
        keep.append(j)
        kl.append(lanes[j - 1])
        ko.append(on[j - 1] and not merged)
        merged = False
    if len(keep) < 2:  # the whole route is one sliver: keep its ends
        return poly[[0, -1]], [lanes[-1]], [False]
    return poly[keep], kl, ko


def _turns(poly: np.ndarray) -> np.ndarray:
    d = np.diff(poly, axis=0)
    h = np.arctan2(d[:, 1], d[:, 0])
    return np.degrees(np.abs((np.diff(h) + np.pi) % (2 * np.pi) - np.pi))


def round_corners(poly: np.ndarray, lanes: list, on: list, max_turn_deg: float, chamfer: float = CHAMFER_M,
                  reversal_deg: float = REVERSAL_DEG, passes: int = 8) -> tuple[np.ndarray, list, list]:
    """Cut every corner turning more than ``max_turn_deg`` (and at most ``reversal_deg``).

    Each such vertex P between unit directions u1, u2 becomes ``P - c u1`` and ``P + c u2``
    (``c = min(chamfer, 0.45 x` the adjacent segments)``), each turning half as much; the
    pass repeats up to ``passes`` times.  The new middle segment is on no centre line.
    """
    poly = np.asarray(poly, dtype=float)
    lanes, on = list(lanes), list(on)
    for _ in range(passes):
        if len(poly) < 3:
            break
        t = _turns(poly)
        bad = np.flatnonzero((t > max_turn_deg + 1e-9) & (t <= reversal_deg))
        if not len(bad):
            break
        seg = np.diff(poly, axis=0)
        seg_len = np.hypot(seg[:, 0], seg[:, 1])
        pts, nl, no = [poly[0]], [], []
        bad_set = set((bad + 1).tolist())  # vertex indices
        for j in range(1, len(poly)):
            if j in bad_set:
                u1, u2 = seg[j - 1] / seg_len[j - 1], seg[j] / seg_len[j]
                c = min(chamfer, 0.45 * seg_len[j - 1], 0.45 * seg_len[j])
                pts += [poly[j] - c * u1, poly[j] + c * u2]
                nl += [lanes[j - 1], lanes[j]]
                no += [on[j - 1], False]
            else:
                pts.append(poly[j])
                nl.append(lanes[j - 1])
                no.append(on[j - 1])
        poly, lanes, on = np.asarray(pts), nl, no
    return poly, lanes, on


def refine_turns(poly: np.ndarray, wps: np.ndarray, arc: np.ndarray, max_turn_deg: float, passes: int = 8
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Denser waypoints where the chords between them turn more than ``max_turn_deg``.

    A chord across a curve turns by about its length over the curve's radius (3 m chords on
    a 3.8 m turnaround: 45 deg), even when no polyline vertex turns that much.  At every
    waypoint whose two chords turn more than the bound, the arc midpoints of both chords
    become waypoints (halving the turn on an arc); repeated up to ``passes`` times.  A
    vertex that itself turns more stays as it is (and is reported by the caller).
    """
    parc = _arc(poly)
    for _ in range(passes):
        if len(wps) < 3:
            break
        t = _turns(wps)
        bad = np.flatnonzero(t > max_turn_deg + 1e-9) + 1  # waypoint indices
        if not len(bad):
            break
        mids = np.concatenate([0.5 * (arc[bad - 1] + arc[bad]), 0.5 * (arc[bad] + arc[bad + 1])])
        arc = np.union1d(arc, mids)
        wps = np.column_stack([np.interp(arc, parc, poly[:, 0]), np.interp(arc, parc, poly[:, 1])])
    return wps, arc


def subsample(polyline: np.ndarray, delta: float, corner_deg: float = 30.0) -> tuple[np.ndarray, np.ndarray]:
    """Waypoints on ``polyline`` at most ``delta`` apart, corners kept.

    Parameters
    ----------
    polyline : ndarray, shape (P, 2)
        Without repeated points.
    delta : float
        Maximum Euclidean (and arc-length) distance between consecutive waypoints (m).
    corner_deg : float
        Vertices where the direction turns by more than this are waypoints.

    Returns
    -------
    points : ndarray, shape (K, 2)
    arc : ndarray, shape (K,)
        Arc length of each waypoint along the polyline.
    """
    if not (delta > 0 and math.isfinite(delta)):
        raise ValueError(f"delta: must be a finite number > 0 m, got {delta!r}")
    poly = np.asarray(polyline, dtype=float)
    arc = _arc(poly)
    anchors = [0]
    if len(poly) > 2:
        d = np.diff(poly, axis=0)
        ang = np.arctan2(d[:, 1], d[:, 0])
        turn = np.abs((np.diff(ang) + np.pi) % (2 * np.pi) - np.pi)
        anchors += [int(i) + 1 for i in np.nonzero(turn > math.radians(corner_deg))[0]]
    anchors.append(len(poly) - 1)
    s_out = [0.0]
    for i0, i1 in zip(anchors[:-1], anchors[1:]):
        a0, a1 = arc[i0], arc[i1]
        n = max(1, math.ceil((a1 - a0) / delta - 1e-12))
        s_out += list(a0 + (a1 - a0) * np.arange(1, n + 1) / n)
    s = np.asarray(s_out)
    s[-1] = arc[-1]
    idx = np.clip(np.searchsorted(arc, s, side="right") - 1, 0, len(poly) - 2)
    seg = arc[idx + 1] - arc[idx]
    t = np.where(seg > 0, (s - arc[idx]) / np.where(seg > 0, seg, 1.0), 0.0)
    pts = poly[idx] + t[:, None] * (poly[idx + 1] - poly[idx])
    # anchors exactly on their vertex (no interpolation round-off at corners and ends)
    for i in anchors:
        k = int(np.argmin(np.abs(s - arc[i])))
        if abs(s[k] - arc[i]) <= 1e-9 * max(1.0, arc[-1]):
            pts[k] = poly[i]
    return pts, s


# --------------------------------------------------------------------------- conditioning

@dataclass(frozen=True, eq=False)
class ConditionedPath:
    """A polyline conditioned for a vehicle class, and its waypoints (:func:`condition_polyline`).

    Attributes
    ----------
    polyline : ndarray, shape (P, 2)
        Slivers dropped, corners sharper than the class's bound cut.
    waypoints : ndarray, shape (K, 2)
        On ``polyline``, consecutive ones at most delta apart.
    arc_length : ndarray, shape (K,)
        Arc length of each waypoint along ``polyline`` (m).
    segment_lanes : tuple, length P-1
        The caller's label of each segment (lane id; None from :func:`polyline_waypoints`).
    segment_on : tuple of bool, length P-1
        Whether each segment is an unmodified part of the input (on its lane's centre line).
    """

    polyline: np.ndarray
    waypoints: np.ndarray
    arc_length: np.ndarray
    segment_lanes: tuple
    segment_on: tuple


def condition_polyline(polyline: np.ndarray, delta: float, *, turn_max_deg: float | None = None,
                       corner_deg: float = 30.0, lanes: Sequence | None = None,
                       on: Sequence[bool] | None = None) -> ConditionedPath:
    """The route-geometry conditioning every path gets, SUMO route or free-plane layout.

    :func:`drop_slivers`, then (with ``turn_max_deg``) :func:`round_corners`, then
    :func:`subsample` with ``corner_deg`` (at most ``turn_max_deg / 2``), then (with
    ``turn_max_deg``) :func:`refine_turns`.

    Parameters
    ----------
    polyline : ndarray, shape (P, 2)
        Without repeated consecutive points.
    delta : float
        Maximum waypoint spacing (m).
    turn_max_deg : float, optional
        The class's largest accepted turn between segments (road-frame classes); None
        (world-frame classes) leaves corners as they are.
    corner_deg : float
        Vertices turning more than this are waypoints (see :func:`subsample`).
    lanes, on : sequence, optional
        Per-segment labels carried through (default None and True).
    """
    poly = np.asarray(polyline, dtype=float)
    n_seg = len(poly) - 1
    lanes = list(lanes) if lanes is not None else [None] * n_seg
    on = list(on) if on is not None else [True] * n_seg
    poly, lanes, on = drop_slivers(poly, lanes, on)
    if turn_max_deg is not None:
        poly, lanes, on = round_corners(poly, lanes, on, turn_max_deg)
        corner_deg = min(corner_deg, 0.5 * turn_max_deg)
    wps, arc = subsample(poly, delta, corner_deg)
    if turn_max_deg is not None:
        wps, arc = refine_turns(poly, wps, arc, turn_max_deg)
    return ConditionedPath(poly, wps, arc, tuple(lanes), tuple(bool(x) for x in on))


def polyline_waypoints(points, delta: float, *, turn_max_deg: float | None = None,
                       corner_deg: float = 30.0) -> np.ndarray:
    """Lane-free entry to :func:`condition_polyline`: waypoints (K, 2) of a free-plane path.

    Repeated consecutive points are merged first.

    Raises
    ------
    ValueError
        Fewer than two distinct points, or a bad ``delta``.
    """
    P = np.asarray(points, dtype=float)
    if P.ndim != 2 or P.shape[1] != 2:
        raise ValueError(f"points: must be (P, 2), got shape {P.shape}")
    keep = np.concatenate([[True], np.hypot(*np.diff(P, axis=0).T) > _DUP_TOL]) if len(P) else np.zeros(0, bool)
    P = P[keep]
    if len(P) < 2:
        raise ValueError("points: a path needs at least two distinct points")
    return condition_polyline(P, delta, turn_max_deg=turn_max_deg, corner_deg=corner_deg).waypoints


# --------------------------------------------------------------------------- the network

@dataclass(frozen=True)
class _Conn:
    from_lane: int
    to_lane: int
    via: tuple[str, ...]  # internal lanes in order
    straight: bool = False  # SUMO's direction "s" (netconvert limits only turning connections' speed)


class NetGeometry:
    """A SUMO network read once (with internal lanes), and the routes drawn on it.

    Parameters
    ----------
    net_path : path
        The ``.net.xml`` file.

    Notes
    -----
    Use :func:`load_net` to share one instance per file.  Routes are memoised
    per (edges, depart lane, vClass, delta, corner) in the instance.
    """

    def __init__(self, net_path: str | os.PathLike) -> None:
        import sumolib  # only bridge/ talks to SUMO's libraries

        self.path = Path(net_path).resolve()
        if not self.path.is_file():
            raise FileNotFoundError(f"SUMO network {self.path} does not exist")
        self._net = sumolib.net.readNet(str(self.path), withInternal=True)
        self._shapes: dict[str, np.ndarray] = {}
        self._conns: dict[tuple[str, str, str | None], list[_Conn]] = {}
        self._memo: dict[tuple, RouteWaypoints] = {}

    # -- lanes and connections
    def lane_shape(self, lane_id: str) -> np.ndarray:
        """Centre line of a lane (P, 2), repeated points removed."""
        shp = self._shapes.get(lane_id)
        if shp is None:
            raw = np.asarray(self._net.getLane(lane_id).getShape(), dtype=float)[:, :2]
            keep = np.concatenate([[True], np.hypot(*np.diff(raw, axis=0).T) > _DUP_TOL])
            shp = raw[keep]
            shp.setflags(write=False)
            self._shapes[lane_id] = shp
        return shp

    def lane_length(self, lane_id: str) -> float:
        """A lane's length as SUMO counts lane positions (m): the ``length`` of the net file, which
        may differ from its shape's length (netconvert gives every lane of an edge the edge's
        length; SUMO maps a lane position ``pos`` to the shape's arc ``pos * shape / length``)."""
        return float(self._net.getLane(lane_id).getLength())

    def lane_allows(self, edge_id: str, index: int, vclass: str | None) -> bool:
        """Whether lane ``index`` of an edge admits the SUMO vClass ``vclass`` (None: any)."""
        return vclass is None or self._net.getEdge(edge_id).getLane(index).allows(vclass)

    @property
    def sumolib_net(self):
        """The ``sumolib`` network (read with internal lanes), for queries this class does not wrap."""
        return self._net

    def has_edge(self, edge_id: str) -> bool:
        """Whether the network has this (non-internal) edge."""
        return self._net.hasEdge(edge_id)

    def lane_speed(self, lane_id: str) -> float:
        """A lane's speed limit (m/s), internal lanes included."""
        return float(self._net.getLane(lane_id).getSpeed())

    @functools.cached_property
    def max_lane_speed(self) -> float:
        """The highest speed limit of any lane of the network (m/s; 0 without lanes)."""
        return max((float(lane.getSpeed()) for e in self._net.getEdges() for lane in e.getLanes()), default=0.0)

    def speed_limits(self, route: "RouteWaypoints") -> np.ndarray:
        """The speed limit of the lane under each waypoint of ``route`` (m/s, (K,))."""
        return np.array([self.lane_speed(lane) for lane in route.lane_ids], dtype=float)

    def straight_through(self, route: "RouteWaypoints") -> np.ndarray:
        """Which waypoints of ``route`` lie on the internal lanes of a straight connection (SUMO's
        direction ``s``), bool (K,): where SUMO's drivers keep the lane's speed (netconvert lowers
        only turning connections' internal lane speeds), whatever the lane shape does there -- e.g.
        the S-bend of a node where a road's lane count changes (SUMO's ``cross`` demo: 2.6 m
        sideways over 8.4 m)."""
        straight = set()
        for a, b in zip(route.edges[:-1], route.edges[1:]):
            for c in self.connections(a, b):
                if c.straight:
                    straight.update(c.via)
        return np.array([lane in straight for lane in route.lane_ids], dtype=bool)

    def route_arc_at(self, route: "RouteWaypoints", lane_id: str, pos: float | None) -> float | None:
        """Arc position along ``route.polyline`` of position ``pos`` on lane ``lane_id`` (SUMO's lane
        coordinate, m; negative: from the lane's end; None: its end), projected onto the route's
        segments on that lane -- or on that lane's edge, where the route takes another of its
        lanes; None when the route does not use the edge."""
        edge = lane_id.rsplit("_", 1)[0]
        segs = [j for j, ln in enumerate(route.segment_lanes) if ln == lane_id] or \
            [j for j, ln in enumerate(route.segment_lanes) if ln.rsplit("_", 1)[0] == edge]
        if not segs or not self._net.hasEdge(edge):
            return None
        L = self.lane_length(lane_id)
        p = L if pos is None else (pos + L if pos < 0 else pos)
        shape = self.lane_shape(lane_id)
        sarc = _arc(shape)
        q = _at(shape, sarc, min(max(p, 0.0), L) * sarc[-1] / max(L, 1e-9))
        return project_arc(route.polyline, _arc(route.polyline), q, min(segs), max(segs) + 1)

    def ends_at_boundary(self, edge_id: str) -> bool:
        """Whether edge ``edge_id`` is the only edge entering the junction it ends at (a dead end at
        the network's boundary, or a fringe node whose other edges only leave it): no other stream
        arrives there, so a vehicle whose route ends there may run on past the end."""
        try:
            node = self._net.getEdge(edge_id).getToNode()
        except KeyError:
            raise RouteError(f"unknown edge {edge_id!r}") from None
        return [e.getID() for e in node.getIncoming() if e.getFunction() != "internal"] == [edge_id]

    def route_junctions(self, edges: Sequence[str]) -> frozenset[str]:
        """The ids of the junctions a route over ``edges`` passes through: where its first edge starts
        and where each of its edges ends (the junction zones it needs tokens of,
        :class:`tm.junctions.JunctionGate`'s ``through``; a junction beside the route, e.g. an on-ramp
        merge on the opposite carriageway, is not one of them)."""
        try:
            got = [self._net.getEdge(edges[0]).getFromNode().getID()] if len(edges) else []
            got += [self._net.getEdge(e).getToNode().getID() for e in edges]
        except KeyError as exc:
            raise RouteError(f"unknown edge {exc.args[0]!r}") from None
        return frozenset(got)

    def lane_count(self, edge_id: str) -> int:
        """Number of lanes of an edge."""
        return self._net.getEdge(edge_id).getLaneNumber()

    def successors(self, edge_id: str) -> list[str]:
        """Edges reachable from ``edge_id`` through one connection, sorted."""
        return sorted(e.getID() for e in self._net.getEdge(edge_id).getOutgoing())

    def connections(self, from_edge: str, to_edge: str, vclass: str | None = None) -> list[_Conn]:
        """Lane connections from one edge to the next, with their chains of internal lanes."""
        key = (from_edge, to_edge, vclass)
        if key in self._conns:
            return self._conns[key]
        src, dst = self._net.getEdge(from_edge), self._net.getEdge(to_edge)
        out = []
        for c in src.getOutgoing().get(dst, []):
            if vclass is not None and not (c.getFromLane().allows(vclass) and c.getToLane().allows(vclass)):
                continue
            via, lane_id = [], c.getViaLaneID()
            while lane_id:
                via.append(lane_id)
                nxt = [cc for cc in self._net.getLane(lane_id).getOutgoing()
                       if cc.getToLane().getEdge().getID() == to_edge]
                lane_id = nxt[0].getViaLaneID() if nxt else ""
                if len(via) > 8:  # a cycle would be a broken network
                    raise RouteError(f"{self.path.name}: internal lanes of {from_edge} -> {to_edge} do not end")
            out.append(_Conn(c.getFromLane().getIndex(), c.getToLane().getIndex(), tuple(via),
                             c.getDirection() == "s"))
        out.sort(key=lambda c: (c.from_lane, c.to_lane))
        self._conns[key] = out
        return out

    # -- routes
    def _check_route(self, edges: Sequence[str], who: str, vclass: str | None) -> list[list[_Conn]]:
        if len(edges) == 0:
            raise RouteError(f"{who}: empty route")
        for e in edges:
            if not self._net.hasEdge(e) or self._net.getEdge(e).getFunction() == "internal":
                raise RouteError(f"{who}: edge {e!r} of route [{' '.join(edges)}] is not in {self.path.name}")
        conns = []
        for a, b in zip(edges[:-1], edges[1:]):
            cs = self.connections(a, b, vclass)
            if not cs:
                extra = f" for vClass {vclass!r}" if vclass else ""
                raise RouteError(f"{who}: route [{' '.join(edges)}] is unreachable: no connection from edge "
                                 f"{a!r} to edge {b!r}{extra} in {self.path.name}")
            conns.append(cs)
        return conns

    def _lane_plan(self, edges: Sequence[str], conns: list[list[_Conn]]) -> tuple[list[dict], list[dict]]:
        """``(best, choice)``: ``best[k][a]``, the cost ``(lane changes, changes on short edges)`` from
        edge ``k`` on arriving on its lane ``a``, and ``choice[k][a]``, the connection taken from there
        (dynamic programming, costs compared in that order).

        Among plans with the fewest changes, those that change lanes on edges too short for
        :func:`lane_change_plan`'s stretches (:meth:`_short_for_changes`: one diagonal in the middle)
        come last; then a change is made on the edge it arrives on (the latest).  SUMO's ``ramp``
        (``--controller authority``, 180 s): the highway's route changed from lane 0 to lane 1 on the
        53 m ``offramp`` edge just before the exit splits off, not on the 381 m edge before it; there
        lane 1's traffic, at 33 m/s, never left the diagonal free, and the exit's vehicles queued
        behind (offramp: 2 of 25 entered vehicles arrived)."""
        best = [dict.fromkeys(range(self.lane_count(edges[-1])), (0, 0))]
        choice: list[dict[int, _Conn]] = []
        for k in range(len(edges) - 2, -1, -1):
            nxt = best[0]
            short = int(self._short_for_changes(edges[k]))
            cost_k, choice_k = {}, {}
            for a in range(self.lane_count(edges[k])):
                def cost(c, a=a):
                    n = abs(a - c.from_lane)
                    return (n + nxt[c.to_lane][0], short * n + nxt[c.to_lane][1])
                cands = sorted(conns[k], key=lambda c: (cost(c), abs(a - c.from_lane), c.from_lane, c.to_lane))
                cost_k[a] = cost(cands[0])
                choice_k[a] = cands[0]
            best.insert(0, cost_k)
            choice.insert(0, choice_k)
        return best, choice

    def _short_for_changes(self, edge_id: str) -> bool:
        """Whether lane changes on edge ``edge_id`` are one diagonal in its middle (its stretches of
        :func:`lane_change_plan` would be shorter than :data:`LANE_CHANGE_MIN_M`)."""
        n = self.lane_count(edge_id)
        if n < 2:
            return False
        length = min(_arc(self.lane_shape(f"{edge_id}_{j}"))[-1] for j in range(n))  # as route() takes it
        return stretch_length(n, length) < LANE_CHANGE_MIN_M

    def start_lanes(self, edges: Sequence[str], vclass: str | None = None) -> dict[int, int]:
        """The lanes of a route's first edge that ``vclass`` may use, each with the lane changes the
        route needs from there (raises :class:`RouteError` on a route that cannot be drawn)."""
        edges = tuple(edges)
        best, _ = self._lane_plan(edges, self._check_route(edges, "route", vclass))
        return {a: c[0] for a, c in best[0].items() if self.lane_allows(edges[0], a, vclass)}

    def _choose(self, edges: Sequence[str], conns: list[list[_Conn]], depart_lane: int | None,
                vclass: str | None = None) -> tuple[int, list[_Conn]]:
        """Fewest lane changes over the route: (arrival lane on the first edge, connection per junction)."""
        m = len(edges)
        n_last = self.lane_count(edges[-1])
        best, choice = self._lane_plan(edges, conns)
        if depart_lane is None:
            # free start: the lane of the cheapest first connection (no change needed on edge 0)
            if m == 1:  # the lowest lane the vClass may use (lane 0 is often a sidewalk)
                a0 = next((i for i in range(n_last) if self.lane_allows(edges[0], i, vclass)), 0)
            else:
                a0 = min(conns[0], key=lambda c: (best[1][c.to_lane], c.from_lane, c.to_lane)).from_lane
        else:
            a0 = depart_lane
        path, a = [], a0
        for k in range(m - 1):
            c = choice[k][a]
            path.append(c)
            a = c.to_lane
        return a0, path

    def route(self, edges: Sequence[str], delta: float, *, depart_lane: int | None = None,
              vclass: str | None = None, vehicle_id: str | None = None, corner_deg: float = 30.0,
              turn_max_deg: float | None = None) -> RouteWaypoints:
        """Polyline and waypoints of a route; see the module notes.

        Parameters
        ----------
        edges : sequence of str
            Edge ids, consecutive ones connected.
        delta : float
            Maximum waypoint spacing (m).
        depart_lane : int, optional
            Lane the vehicle starts on; None lets the route choose.
        vclass : str, optional
            Use only lanes this SUMO vClass may use.
        vehicle_id : str, optional
            For error messages.
        corner_deg : float
            See :func:`subsample`.
        turn_max_deg : float, optional
            The class's largest accepted turn between segments: sharper corners (up to
            :data:`REVERSAL_DEG`) are cut (:func:`round_corners`) and vertices turning more
            than ``turn_max_deg / 2`` become waypoints.  Slivers shorter than
            :data:`MIN_SEGMENT_M` are always dropped (:func:`drop_slivers`).

        Raises
        ------
        RouteError
            Unknown edge, or consecutive edges without a connection (naming the
            vehicle and both edges), or a depart lane the first edge lacks.
        """
        edges = tuple(edges)
        key = (edges, depart_lane, vclass, float(delta), float(corner_deg), turn_max_deg)
        if key in self._memo:
            hit = self._memo[key]
            if hit.vehicle_id == vehicle_id:
                return hit
            return RouteWaypoints(**{**hit.__dict__, "vehicle_id": vehicle_id})
        who = f"vehicle {vehicle_id!r}" if vehicle_id is not None else "route"
        conns = self._check_route(edges, who, vclass)
        if depart_lane is not None and not 0 <= depart_lane < self.lane_count(edges[0]):
            raise RouteError(f"{who}: depart lane {depart_lane} does not exist on edge {edges[0]!r} "
                             f"(lanes 0..{self.lane_count(edges[0]) - 1})")
        if depart_lane is not None and not self.lane_allows(edges[0], depart_lane, vclass):
            ok = [i for i in range(self.lane_count(edges[0])) if self.lane_allows(edges[0], i, vclass)]
            raise RouteError(f"{who}: depart lane {depart_lane} of edge {edges[0]!r} does not admit vClass "
                             f"{vclass!r} (lanes it may use: {ok})")
        arrive, path = self._choose(edges, conns, depart_lane, vclass)

        pieces: list[tuple[np.ndarray, str, bool]] = []  # (points, lane id, on its centre line)
        lanes_used = []
        for k, e in enumerate(edges):
            leave = path[k].from_lane if k < len(path) else arrive
            lane_in, lane_out = f"{e}_{arrive}", f"{e}_{leave}"
            lanes_used.append(lane_out)
            if leave == arrive:
                pieces.append((self.lane_shape(lane_in), lane_in, True))
            else:
                step = 1 if leave > arrive else -1
                lanes = [f"{e}_{j}" for j in range(arrive, leave + step, step)]
                shapes = [self.lane_shape(ln) for ln in lanes]
                length = min(_arc(sh)[-1] for sh in shapes)
                between = all(self.lane_allows(e, j, vclass) for j in range(arrive + step, leave, step))
                plan = lane_change_plan(self.lane_count(e), arrive, leave, length, stepwise=between)
                if len(plan) == 1:  # one diagonal, from the arrival lane to the leaving one
                    lanes, shapes = [lanes[0], lanes[-1]], [shapes[0], shapes[-1]]
                s_from = 0.0
                for (s0, s1), ln, sh in zip(plan, lanes, shapes):
                    pieces.append((_cut(sh, s_from, s0), ln, True))
                    s_from = s1
                pieces.append((_cut(shapes[-1], s_from, _arc(shapes[-1])[-1]), lanes[-1], True))
            if k < len(path):
                for via in path[k].via:
                    pieces.append((self.lane_shape(via), via, True))
                arrive = path[k].to_lane

        pts, seg_lane, seg_on = [pieces[0][0][0]], [], []
        for shape, lane, on in pieces:
            for j, q in enumerate(shape):
                if np.hypot(*(q - pts[-1])) <= _DUP_TOL:
                    continue
                pts.append(q)
                seg_lane.append(lane)
                # j == 0: a segment joining the previous piece to this one (the diagonal of a lane
                # change, or a gap in the network's geometry): on no centre line
                seg_on.append(on and j > 0)
        poly = np.asarray(pts, dtype=float)
        if len(poly) < 2:
            raise RouteError(f"{who}: route [{' '.join(edges)}] has zero length")
        cond = condition_polyline(poly, delta, turn_max_deg=turn_max_deg, corner_deg=corner_deg,
                                  lanes=seg_lane, on=seg_on)
        poly, seg_lane, seg_on = cond.polyline, list(cond.segment_lanes), list(cond.segment_on)
        wps, arc = cond.waypoints, cond.arc_length
        parc = _arc(poly)
        seg = np.clip(np.searchsorted(parc, arc, side="right") - 1, 0, len(poly) - 2)
        d = np.diff(poly, axis=0)
        seg_heading = np.arctan2(d[:, 1], d[:, 0])
        seg_on_arr = np.asarray(seg_on, dtype=bool)
        out = RouteWaypoints(
            vehicle_id=vehicle_id, edges=edges, delta=float(delta), waypoints=wps, arc_length=arc,
            lane_ids=tuple(seg_lane[i] for i in seg), on_lane=seg_on_arr[seg], heading=seg_heading[seg],
            length_m=float(parc[-1]), polyline=poly, segment_lanes=tuple(seg_lane),
            segment_on_lane=seg_on_arr, lanes=tuple(lanes_used))
        for a in (wps, arc, out.on_lane, out.heading, poly, seg_on_arr):
            a.setflags(write=False)
        self._memo[key] = out
        return out


@functools.lru_cache(maxsize=8)
def _load_net_cached(path: str, mtime_ns: int, size: int) -> NetGeometry:
    return NetGeometry(path)


def load_net(net_path: str | os.PathLike) -> NetGeometry:
    """A :class:`NetGeometry` shared per file (re-read when the file changes)."""
    p = Path(net_path).resolve()
    try:
        st = p.stat()
    except OSError as exc:
        raise FileNotFoundError(f"SUMO network {p} cannot be read: {exc.strerror or exc}") from None
    return _load_net_cached(str(p), st.st_mtime_ns, st.st_size)


def trim_start_index(route: "RouteWaypoints", s0: float) -> np.ndarray:
    """Indices into ``route.waypoints`` of the points :func:`trim_start` returns (its first
    point, inside the segment ending at the first kept waypoint, takes that segment's start)."""
    s0 = float(min(max(s0, 0.0), 0.5 * route.length_m))
    keep = np.flatnonzero(route.arc_length > s0 + 1e-6)
    return np.concatenate([[max(int(keep[0]) - 1, 0) if len(keep) else route.count - 1], keep])


def trim_start(route: "RouteWaypoints", s0: float) -> np.ndarray:
    """The route's waypoints from arc length ``s0`` on: the point at ``s0`` on the
    polyline, then every waypoint beyond it (consecutive gaps stay at most ``delta``:
    the new first gap is part of an old one).

    Used for departures: SUMO inserts a vehicle with its back at the start of its
    first lane (``departPos="base"``), so muvsim starts its centre half a length in.
    ``s0`` is clamped to half the route.
    """
    s0 = float(min(max(s0, 0.0), 0.5 * route.length_m))
    keep = route.arc_length > s0 + 1e-6
    start = _at(route.polyline, _arc(route.polyline), s0)
    return np.vstack([start[None], route.waypoints[keep]])


def route_waypoints(net: str | os.PathLike | NetGeometry, edges: Sequence[str], delta: float, *,
                    depart_lane: int | None = None, vclass: str | None = None, vehicle_id: str | None = None,
                    corner_deg: float = 30.0) -> RouteWaypoints:
    """Waypoints of a route on a network file or :class:`NetGeometry`; see :meth:`NetGeometry.route`."""
    geom = net if isinstance(net, NetGeometry) else load_net(net)
    return geom.route(edges, delta, depart_lane=depart_lane, vclass=vclass, vehicle_id=vehicle_id,
                      corner_deg=corner_deg)
