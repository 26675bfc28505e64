"""SUMO's pose conventions and muvsim's.

muvsim's plant works with the vehicle's centre ``(x, y)`` and a mathematical
heading ``theta`` (rad, counter-clockwise from +x).  SUMO places a vehicle by
its FRONT BUMPER and an angle in degrees clockwise from north (+y).  So

* ``front = centre + (length / 2) * (cos theta, sin theta)``,
* ``angle = 90 - degrees(theta)`` (taken modulo 360 into ``[0, 360)``).

All functions are vectorised over vehicles.
"""

from __future__ import annotations

import numpy as np

__all__ = ["front_bumper", "centre_from_front", "sumo_angle", "heading_from_sumo_angle"]


def front_bumper(centre, heading, length) -> np.ndarray:
    """Front-bumper positions (V, 2) from centres (V, 2), headings (V,) in rad and lengths (V,) in m."""
    c = np.asarray(centre, dtype=float)
    th = np.asarray(heading, dtype=float)
    half = 0.5 * np.asarray(length, dtype=float)
    return c + np.stack([half * np.cos(th), half * np.sin(th)], axis=-1)


def centre_from_front(front, heading, length) -> np.ndarray:
    """Inverse of :func:`front_bumper`."""
    f = np.asarray(front, dtype=float)
    th = np.asarray(heading, dtype=float)
    half = 0.5 * np.asarray(length, dtype=float)
    return f - np.stack([half * np.cos(th), half * np.sin(th)], axis=-1)


def sumo_angle(heading) -> np.ndarray:
    """SUMO angle (deg, clockwise from north, in [0, 360)) of mathematical headings (rad)."""
    return np.mod(90.0 - np.degrees(np.asarray(heading, dtype=float)), 360.0)


def heading_from_sumo_angle(angle_deg) -> np.ndarray:
    """Mathematical heading (rad, in (-pi, pi]) of SUMO angles (deg)."""
    th = np.radians(90.0 - np.asarray(angle_deg, dtype=float))
    return np.arctan2(np.sin(th), np.cos(th))
