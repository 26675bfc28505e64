"""Free-plane scenario layouts: waypoint paths for ``paper10``, ``swap`` and ``crossing``.

Every path is a polyline conditioned like a SUMO route (:func:`subsample`, through
:func:`bridge.waypoints.condition_polyline`): successive waypoints at most the class's
delta apart and, for road-frame classes, corners cut so that no turn exceeds the class's bound.
"""

from __future__ import annotations

import numpy as np

from bridge.cosim import VehicleSpec, Zone
from bridge.waypoints import polyline_waypoints

__all__ = ["subsample", "turn_bound", "paper10", "swap", "crossing"]


#: Free-plane layouts space their waypoints at most this fraction of delta apart (as they always
#: have): a straight piece of exactly k delta gets k + 1 parts, so paper-mode and authority
#: ``crossing``/``paper10``/``swap`` keep the waypoints they had before the shared conditioning.
LAYOUT_SPACING = 0.999


def subsample(points, delta: float, turn_max_deg: float | None = None) -> np.ndarray:
    """Waypoints of the free-plane polyline ``points``, conditioned like a SUMO route.

    One call of :func:`bridge.waypoints.polyline_waypoints` (the shared conditioning of
    :func:`bridge.waypoints.condition_polyline`) with ``corner_deg = 0``: every vertex of
    the layout's polyline is a waypoint, each piece between vertices is divided into equal
    parts <= ``LAYOUT_SPACING x delta``; with ``turn_max_deg`` (road-frame classes) corners sharper than it are
    cut and chords refined until no turn between waypoints exceeds it.
    """
    return polyline_waypoints(points, LAYOUT_SPACING * delta, turn_max_deg=turn_max_deg, corner_deg=0.0)


def turn_bound(model) -> float | None:
    """The turn bound the conditioning needs for a class's model: ``turn_max_deg`` in the road
    frame, None in the world frame (no turn limit)."""
    return float(model.turn_max_deg) if model.frame == "road" else None


def _arc(radius: float, a0: float, a1: float, n: int = 64) -> np.ndarray:
    t = np.linspace(a0, a1, n)
    return radius * np.column_stack([np.cos(t), np.sin(t)])


def swap(n: int, vclass: str, delta: float, radius: float | None = None,
         turn_max_deg: float | None = None) -> list[VehicleSpec]:
    """``n`` vehicles on a circle, each to the diametrically opposite point.

    To avoid head-on meetings (which no traffic manager can resolve without
    replanning) the paths go round a central ring counter-clockwise, like a
    roundabout: in along the start's spoke, half a turn on the ring, out along
    the opposite spoke.  Entry and exit spokes alternate with the vehicles.

    The spokes meet the ring at 90 deg: for road-frame classes pass ``turn_max_deg`` and
    the corners are cut (:func:`subsample`).  Known limit (measured, seed 7, 16 vehicles,
    paper mode, paper-a, disturbance none or random): the paper's TM deadlocks at four
    merges - a ring vehicle and the vehicle on the next spoke stop with each one's next
    claim meeting the other's held claim; adversarial disturbances, or odd vehicles
    departing 2-5 s later, avoid it.
    """
    if n < 2:
        raise ValueError(f"swap: needs at least 2 vehicles, got {n}")
    # ~26 m of ring per vehicle: vehicles meet at the merges (the TM acts) and the ring never
    # fills up (measured: 12-18 m per vehicle deadlocks 20 paper-a vehicles in the ring)
    ring = max(30.0, n * 26.0 / (2 * np.pi))
    radius = radius or ring + 45.0
    specs = []
    for i in range(n):
        th = 2 * np.pi * i / n
        exit_th = th + np.pi
        pts = np.vstack([radius * np.array([[np.cos(th), np.sin(th)]]),
                         _arc(ring, th, exit_th),
                         radius * np.array([[np.cos(exit_th), np.sin(exit_th)]])])
        specs.append(VehicleSpec(id=f"swap{i:02d}", vclass=vclass, waypoints=subsample(pts, delta, turn_max_deg)))
    return specs


def crossing(per_stream: int, vclass: str, delta: float, half: float = 90.0, offset: float = 12.0,
             headway_s: float = 4.0, turn_max_deg: float | None = None) -> tuple[list[VehicleSpec], list[Zone]]:
    """Four streams (E, N, W, S bound) through one square, right-hand traffic ``offset`` m
    from the axes (wide enough that opposite streams' tubes do not meet), and the square
    as a conflict zone."""
    specs = []
    dirs = {"E": (np.array([1.0, 0.0]), np.array([0.0, -offset])),
            "N": (np.array([0.0, 1.0]), np.array([offset, 0.0])),
            "W": (np.array([-1.0, 0.0]), np.array([0.0, offset])),
            "S": (np.array([0.0, -1.0]), np.array([-offset, 0.0]))}
    for name, (d, off) in dirs.items():
        for k in range(per_stream):
            pts = np.array([off - half * d, off + half * d])
            specs.append(VehicleSpec(id=f"{name}{k}", vclass=vclass, waypoints=subsample(pts, delta, turn_max_deg),
                                     depart_s=k * headway_s))
    return specs, [Zone("square", (-offset, -offset), (offset, offset))]


def paper10(deltas: dict[str, float], turn_max_deg: dict[str, float | None] | None = None) -> list[VehicleSpec]:
    """Ten heterogeneous vehicles (3 paper-a, 2 paper-b, 3 paper-c, 2 paper-d) on crossing paths.

    Vehicles start on a circle of radius 70 m and drive straight to a point on
    the far side offset by 100 degrees from diametrically opposite... rotated so
    that paths cross pairwise (not all through one point, and never head-on).
    """
    classes = ["paper-a"] * 3 + ["paper-b"] * 2 + ["paper-c"] * 3 + ["paper-d"] * 2
    order = [0, 5, 2, 7, 1, 8, 3, 6, 4, 9]  # interleave classes around the circle
    specs = []
    for slot, i in enumerate(order):
        c = classes[i]
        th = 2 * np.pi * slot / 10
        goal = th + np.pi * 0.72
        pts = np.array([[70 * np.cos(th), 70 * np.sin(th)], [70 * np.cos(goal), 70 * np.sin(goal)]])
        specs.append(VehicleSpec(id=f"uv{i + 1}", vclass=c, waypoints=subsample(pts, deltas[c], (turn_max_deg or {}).get(c))))
    return specs
