"""Where on its first lane, and how fast, a vehicle enters: SUMO's ``departPos`` and ``departSpeed``.

SUMO inserts a vehicle with ``departPos="last"`` at the far end of its lane, one with
``departSpeed="max"`` at the lane's speed; muvsim used to start every vehicle at rest with its
back at the lane's start (``departPos="base"``), so on motorway scenarios its vehicles drove
longer routes from rest (SUMO's ``A10KW``: ~1.2 km longer) and a 2,500 veh/h flow could not enter.

A vehicle's :class:`DepartPlan` (built with its spec, :func:`depart_plan`) holds the waypoint SUMO
would start its centre on (on its first edge), the speed it would have there, and the last waypoint
its first stop point may be (its route's last, or its first planned stop).  Admission keeps the
first stop point before whatever the vehicle would have to be let past
(:meth:`bridge.cosim.Cosim._first_stop_limit`): the route's first junction guard
(:meth:`tm.authority_gate.AuthorityGate.entry_limit`), its first signalised stop line and its first
pedestrian crossing, so a vehicle never enters committed to a junction, a light or a crossing it has
not asked for.  Until 2026-12-06 the first stop point also had to leave the front on the first edge:
a vehicle SUMO inserts at the end of a short motorway edge at speed then had to start a braking
distance or more further back, or slower (SUMO's ``A10KW``: 75 of its 601 vehicles arrived in 180 s,
98 without that limit).  Admission (:class:`bridge.cosim.Cosim`)
tries the starts of :func:`start_ladder` in order -- the plan's speed, half of it, at rest; at each,
the plan's position and two thirds and one third of the way back to the lane's start, then the
start itself -- and takes the first whose claims are free (condition (12)): the last is the old
start (at rest, ``base``), so a vehicle enters at least as early as before.  A moving start's
first stop point is the nearest waypoint at least its comfortable braking distance ahead from which
its state lies in the tube (``x0 ∈ T^l(c)``, ``l <= N``): it need not brake at once, and the
traffic manager extends its claims as for any other vehicle.  This is SUMO's own rule for ``departSpeed="max"`` (the
fastest safe speed) and ``departPos="free"``/``"last"`` (a free place on the lane); for a number
SUMO waits instead of starting slower or further back.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["DepartPlan", "DepartLanes", "Start", "depart_plan", "first_edge_end", "start_ladder"]

#: the speeds admission tries, as fractions of the plan's (the last: at rest)
SPEED_STEPS = (1.0, 0.5, 0.0)
#: the positions tried at each speed: fractions of the plan's waypoint index (the last: the lane's start)
POSITION_STEPS = (1.0, 2.0 / 3.0, 1.0 / 3.0, 0.0)


@dataclass(frozen=True)
class DepartPlan:
    """SUMO's start of a vehicle on its waypoints: centre on waypoint ``k`` at ``speed`` (m/s along
    the route; ``inf``: as fast as the class and the lane allow there); its first stop point at
    most waypoint ``stop_max``."""

    k: int
    speed: float
    stop_max: int

    def __post_init__(self) -> None:
        if not (0 <= self.k <= self.stop_max) or not (self.speed >= 0):
            raise ValueError(f"DepartPlan: need 0 <= k <= stop_max and speed >= 0, got k={self.k}, "
                             f"stop_max={self.stop_max}, speed={self.speed}")


@dataclass(frozen=True)
class Start:
    """One start admission tries: centre on waypoint ``k`` at ``speed`` (m/s), the first stop point
    waypoint ``stop`` (``>= k``), the state's membership index ``index`` there."""

    k: int
    speed: float
    stop: int
    index: int


def first_edge_end(route) -> float:
    """Arc length (m, along ``route.polyline``) where a :class:`bridge.waypoints.RouteWaypoints`
    leaves its first edge (its length when it has one edge)."""
    first = route.edges[0]
    lanes = route.segment_lanes
    n = 0
    while n < len(lanes) and lanes[n].rsplit("_", 1)[0] == first:
        n += 1
    P = np.asarray(route.polyline, dtype=float)
    if n >= len(lanes):
        return float(route.length_m)
    return float(np.sum(np.hypot(*np.diff(P[:n + 1], axis=0).T)))


def depart_plan(arc: np.ndarray, length: float, edge_end: float, pos_m: float | None,
                speed: float | None, first_lane_m: float | None = None) -> DepartPlan | None:
    """The plan of a vehicle whose waypoints lie at route arcs ``arc`` (K,) (the first: its old start,
    back at the lane's start), ``length`` m long, on a route leaving its first edge at ``edge_end``.

    ``pos_m``: SUMO's ``departPos`` (the front along the first lane, at most its end; negative: from
    its end, which needs ``first_lane_m``, the lane's length); ``speed``: ``departSpeed`` (m/s,
    ``inf``: as fast as allowed).  Its first stop point may be as far as the route's last waypoint
    (admission limits it further: module notes).  None when the vehicle starts as before (at rest on
    its first waypoint)."""
    arc = np.asarray(arc, dtype=float)
    v = 0.0 if speed is None or not speed > 0 else float(speed)
    stop_max = len(arc) - 1
    on_edge = int(np.searchsorted(arc, edge_end - 0.5 * length, side="right")) - 1
    k = 0
    if pos_m is not None:
        front = float(pos_m)
        if front < 0 and first_lane_m is not None:
            front += float(first_lane_m)
        centre = min(front - 0.5 * length, edge_end - 0.5 * length)
        k = min(max(int(np.searchsorted(arc, centre, side="right")) - 1, 0), max(on_edge, 0))
    if k == 0 and v == 0.0:
        return None
    return DepartPlan(k, v, stop_max)


def start_ladder(plan: DepartPlan, v_top: float) -> list[tuple[int, float]]:
    """``(k, speed)`` in the order admission tries them (module notes): the plan's speed (at most
    ``v_top``), half of it, at rest; at each the plan's waypoint, two thirds and one third of it, and
    the first.  Repeats dropped; the last is always ``(0, 0.0)``."""
    v = min(plan.speed, float(v_top))
    v = v if math.isfinite(v) and v > 0 else 0.0
    out = []
    for fs in SPEED_STEPS:
        for fk in POSITION_STEPS:
            key = (int(math.floor(fk * plan.k)), fs * v)
            if key not in out:
                out.append(key)
    return out


class DepartLanes:
    """The start lane of each vehicle whose ``departLane`` is one of SUMO's keywords, as SUMO picks it
    among the first edge's lanes the vehicle may use (``costs``: each lane's lane changes to the
    route's end, :meth:`bridge.waypoints.NetGeometry.start_lanes`):

    * ``first``: the rightmost;
    * ``best``: among those needing the fewest lane changes, ``free``/``allowed``: among all, the
      least occupied -- in turn, per first edge and candidate set, in departure order (SUMO picks
      the least occupied lane when the vehicle is inserted; on a busy road that spreads them);
    * ``random``/``random_free``: drawn (seeded).

    A number is used as it is; no ``departLane``: the route's own choice (None)."""

    def __init__(self, seed: int = 0) -> None:
        self._rng = np.random.default_rng(seed)
        self._turn: dict[tuple, int] = {}

    def pick(self, first_edge: str, rule: str | None, costs: dict[int, int]) -> int | None:
        if rule is None or not costs:
            return None
        lanes = sorted(costs)
        if rule == "first":
            return lanes[0]
        if rule == "best":
            low = min(costs.values())
            lanes = [a for a in lanes if costs[a] == low]
        if rule in ("random", "random_free"):
            return int(self._rng.choice(lanes))
        key = (first_edge, tuple(lanes))
        n = self._turn.get(key, 0)
        self._turn[key] = n + 1
        return lanes[n % len(lanes)]
