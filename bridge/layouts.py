"""Free-plane scenario layouts: waypoint paths for ``paper10``, ``swap`` and ``crossing``.

Every path is a polyline subsampled so that successive waypoints are at most
the class's delta apart (:func:`subsample`).
"""

from __future__ import annotations

import numpy as np

from bridge.cosim import VehicleSpec, Zone

__all__ = ["subsample", "paper10", "swap", "crossing"]


def subsample(points, delta: float) -> np.ndarray:
    """Waypoints on the polyline ``points``, every vertex kept, consecutive ones <= delta apart."""
    P = np.asarray(points, dtype=float)
    out = [P[0]]
    for a, b in zip(P[:-1], P[1:]):
        n = max(int(np.ceil(np.linalg.norm(b - a) / (0.999 * delta))), 1)
        for s in np.arange(1, n + 1) / n:
            out.append(a + s * (b - a))
    return np.array(out)


def _arc(radius: float, a0: float, a1: float, n: int = 64) -> np.ndarray:
    t = np.linspace(a0, a1, n)
    return radius * np.column_stack([np.cos(t), np.sin(t)])


def swap(n: int, vclass: str, delta: float, radius: float | None = None) -> list[VehicleSpec]:
    """``n`` vehicles on a circle, each to the diametrically opposite point.

    To avoid head-on meetings (which no traffic manager can resolve without
    replanning) the paths go round a central ring counter-clockwise, like a
    roundabout: in along the start's spoke, half a turn on the ring, out along
    the opposite spoke.  Entry and exit spokes alternate with the vehicles.
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
        specs.append(VehicleSpec(id=f"swap{i:02d}", vclass=vclass, waypoints=subsample(pts, delta)))
    return specs


def crossing(per_stream: int, vclass: str, delta: float, half: float = 90.0, offset: float = 12.0,
             headway_s: float = 4.0) -> tuple[list[VehicleSpec], list[Zone]]:
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
            specs.append(VehicleSpec(id=f"{name}{k}", vclass=vclass, waypoints=subsample(pts, delta),
                                     depart_s=k * headway_s))
    return specs, [Zone("square", (-offset, -offset), (offset, offset))]


def paper10(deltas: dict[str, float]) -> list[VehicleSpec]:
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
        specs.append(VehicleSpec(id=f"uv{i + 1}", vclass=c, waypoints=subsample(pts, deltas[c])))
    return specs
