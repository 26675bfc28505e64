"""What the junction liveness layer needs of a movement-authority class: :class:`AuthorityReach`,
its extents (metres) and the world boxes of its hold and claim boxes at waypoints
(:mod:`tm.authority_gate`, :mod:`tm.keep_out`, :mod:`tm.crossing_gate`).

Pure numpy, no simulator.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.authority import AuthorityTables

__all__ = ["AuthorityReach"]


def _world_box(a: float, b: float, pad: np.ndarray, *headings: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Offsets ``(lo, hi)`` (n, 2) from the waypoints of the world bounding box of a segment-frame
    box ``±a`` along, ``±b`` across, padded one-sided by ``pad`` (n, 4: back, front, right, left;
    the frame's ``y`` points left), hulled over the given headings."""
    pad = np.asarray(pad, dtype=float)
    cx, cy = 0.5 * (pad[:, 1] - pad[:, 0]), 0.5 * (pad[:, 3] - pad[:, 2])
    ea, eb = a + 0.5 * (pad[:, 0] + pad[:, 1]), b + 0.5 * (pad[:, 2] + pad[:, 3])
    lo = hi = None
    for h in headings:
        c, s = np.cos(h), np.sin(h)
        mid = np.stack([c * cx - s * cy, s * cx + c * cy], axis=1)
        e = np.stack([np.abs(c) * ea + np.abs(s) * eb, np.abs(s) * ea + np.abs(c) * eb], axis=1)
        lo = mid - e if lo is None else np.minimum(lo, mid - e)
        hi = mid + e if hi is None else np.maximum(hi, mid + e)
    return lo, hi


def _world_half(a: float, b: float, *headings: np.ndarray) -> np.ndarray:
    """Half extents (n, 2) of the world bounding box of a segment-frame box ``±a`` along, ``±b``
    across, hulled over the given headings (a waypoint's arriving and leaving segments)."""
    out = None
    for h in headings:
        c, s = np.abs(np.cos(h))[:, None], np.abs(np.sin(h))[:, None]
        e = np.hstack([c * a + s * b, s * a + c * b])
        out = e if out is None else np.maximum(out, e)
    return out


def _polygons(a: float, b: float, W: np.ndarray, pad: np.ndarray, *headings: np.ndarray) -> np.ndarray:
    """Segment-frame boxes ``±a`` along, ``±b`` across around waypoints ``W`` (n, 2), padded one-sided
    by ``pad`` (n, 4: back, front, right, left), one per waypoint and heading: corners (h n, 4, 2),
    counter-clockwise."""
    pad = np.asarray(pad, dtype=float).reshape(-1, 4)
    xs = np.stack([a + pad[:, 1], a + pad[:, 1], -a - pad[:, 0], -a - pad[:, 0]], axis=1)  # (n, 4)
    ys = np.stack([-b - pad[:, 2], b + pad[:, 3], b + pad[:, 3], -b - pad[:, 2]], axis=1)
    out = []
    for h in headings:
        c, s = np.cos(h)[:, None], np.sin(h)[:, None]
        out.append(np.asarray(W, dtype=float)[:, None, :] + np.stack([c * xs - s * ys, s * xs + c * ys], axis=-1))
    return np.concatenate(out)


@dataclass(frozen=True, eq=False)
class AuthorityReach:
    """What the junction layer needs of a movement-authority class (metres).

    Parameters
    ----------
    hold, hold_y : float
        Half extents of ``T^0``'s position along and across the road (the vehicle at rest at its
        stop point lies in ``T^0``).
    across : float
        The claims' across half-width: ``max |y|`` over every level's across range (a claim lies
        inside ``T^m``, so inside it).
    length, width : float
        Footprint.
    delta : float
        Largest gap between consecutive waypoints.
    """

    hold: float
    hold_y: float
    across: float
    length: float
    width: float
    delta: float

    def __post_init__(self) -> None:
        vals = dict(hold=self.hold, hold_y=self.hold_y, across=self.across, length=self.length,
                    width=self.width, delta=self.delta)
        bad = {k: v for k, v in vals.items() if not (np.isfinite(v) and v >= 0)}
        if bad or not (self.length > 0 and self.width > 0 and self.delta > 0):
            raise ValueError(f"AuthorityReach: extents must be finite and >= 0 m, length, width and delta > 0; "
                             f"got {vals}")

    @staticmethod
    def of(tables: AuthorityTables, length: float, width: float, delta: float) -> AuthorityReach:
        """From a movement-authority family's tables (:func:`controllers.authority.build_tables`)."""
        return AuthorityReach(hold=float(max(-tables.p_lo[0], tables.p_hi[0])),
                              hold_y=float(max(-tables.y_lo[0], tables.y_hi[0])),
                              across=float(max(-tables.y_lo.min(), tables.y_hi.max())),
                              length=float(length), width=float(width), delta=float(delta))

    @property
    def guard_reach(self) -> float:
        """How far this class's claims stick out of a zone its route crosses: the across
        half-width plus half the footprint's diagonal (the body turns inside the junction)."""
        return self.across + 0.5 * float(np.hypot(self.length, self.width))

    def hold_half(self, *headings: np.ndarray) -> np.ndarray:
        """World half extents (n, 2) of the hold box ``T^0 ⊕ footprint`` at the headings."""
        return _world_half(self.hold + 0.5 * self.length, self.hold_y + 0.5 * self.width, *headings)

    def claim_half(self, *headings: np.ndarray) -> np.ndarray:
        """World half extents (n, 2) of what a claim with its stop point at a waypoint covers there:
        ``T^0`` along plus ``L/2``, the claims' across half-width plus ``W/2`` across."""
        return _world_half(self.hold + 0.5 * self.length, self.across + 0.5 * self.width, *headings)

    def claim_box(self, pad: np.ndarray, *headings: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`claim_half` padded one-sided by ``pad`` (n, 4: back, front, right, left): offsets
        ``(lo, hi)`` (n, 2) from the waypoints of what a claim with its stop point there covers."""
        return _world_box(self.hold + 0.5 * self.length, self.across + 0.5 * self.width, pad, *headings)

    def hold_box(self, pad: np.ndarray, *headings: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`hold_half` padded one-sided by ``pad``: offsets ``(lo, hi)`` (n, 2) of the box of a
        vehicle at rest at its stop point (its standing claim)."""
        return _world_box(self.hold + 0.5 * self.length, self.hold_y + 0.5 * self.width, pad, *headings)

    def corridor_polygons(self, W: np.ndarray, pad: np.ndarray, *headings: np.ndarray) -> np.ndarray:
        """The corridor boxes of :meth:`half_extent` around waypoints ``W`` (n, 2) as oriented boxes,
        one per waypoint and heading (not hulled into world boxes), each padded one-sided by ``pad``
        (n, 4: back, front, right, left; SUMO's body reach there): corners (h n, 4, 2),
        counter-clockwise."""
        return _polygons(0.5 * self.delta + self.hold + 0.5 * self.length, self.hold_y + 0.5 * self.width,
                         W, pad, *headings)

    def hold_polygons(self, W: np.ndarray, pad: np.ndarray, *headings: np.ndarray) -> np.ndarray:
        """:meth:`hold_box` around waypoints ``W`` as oriented boxes (as :meth:`corridor_polygons`)."""
        return _polygons(self.hold + 0.5 * self.length, self.hold_y + 0.5 * self.width, W, pad, *headings)

    def half_extent(self, *headings: np.ndarray) -> np.ndarray:
        """World half extents (n, 2) of a corridor box around a waypoint at the headings: the hold
        box ``T^0 ⊕ footprint`` of every stop point within ``δ/2`` of it (module notes)."""
        return _world_half(0.5 * self.delta + self.hold + 0.5 * self.length, self.hold_y + 0.5 * self.width,
                           *headings)
