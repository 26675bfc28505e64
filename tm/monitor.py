"""Runtime monitor (design 3g): footprint overlaps, claim invariant, separation.

After every step the monitor is given the vehicles' actual positions (the
state position, i.e. the footprint centre, not SUMO's front bumper),
headings and footprints, and the claims in force.  It counts

* footprint overlaps: pairs of actual rectangles closer than GEOMETRY_TOL
  (broad phase + separating axes);
* claim-invariant violations: pairs of claims that conflict (the TM's
  invariant says there are none);
* tube escapes (reach claims, :meth:`Monitor.escapes`): vehicles whose position ``x(t+1)``
  lies outside the position part of their claim ``S_1(t)``;
* the minimum separation (m) between any two footprints (``inf`` with
  fewer than two vehicles; 0 when two overlap).

Any overlap or violation is a bug; the caller logs it and tests fail on it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from controllers.tolerances import GEOMETRY_TOL
from tm.claims import CHECK_KINDS, Claims, conflicting_pairs
from tm.geometry import aabb, broad_phase, intersect_sat, min_pair_distance, rectangles
from tm.reach import ReachClaims, pairwise_conflicts
from tm.reach_book import tube_escapes

__all__ = ["MonitorStep", "Monitor", "footprint_polygons", "footprint_overlaps"]


@dataclass(frozen=True)
class MonitorStep:
    """What the monitor found at one step.

    Attributes
    ----------
    footprint_overlaps : int
    claim_violations : int
    min_separation : float
        Metres; ``inf`` with fewer than two vehicles.
    overlap_pairs, violation_pairs : tuple of (str, str)
        The offending id pairs.
    closest_pair : tuple of (str, str) or None
    """

    footprint_overlaps: int
    claim_violations: int
    min_separation: float
    overlap_pairs: tuple
    violation_pairs: tuple
    closest_pair: tuple | None

    @property
    def ok(self) -> bool:
        return self.footprint_overlaps == 0 and self.claim_violations == 0


def footprint_polygons(position, heading, length, width) -> np.ndarray:
    """Actual footprint rectangles ``(V, 4, 2)`` centred on the positions ``(V, 2)``."""
    position = np.asarray(position, dtype=float).reshape(-1, 2)
    return rectangles(heading, length, width) + position[:, None, :]


def footprint_overlaps(polygons, tol: float = GEOMETRY_TOL) -> tuple[np.ndarray, np.ndarray]:
    """Pairs ``i < j`` of footprint polygons ``(V, k, 2)`` closer than ``tol``."""
    lo, hi = aabb(polygons)
    i, j = broad_phase(lo, hi, tol)
    hit = intersect_sat(polygons[i], polygons[j], tol)
    return i[hit], j[hit]


class Monitor:
    """Accumulates :class:`MonitorStep` results over a run.

    Parameters
    ----------
    check : {"union", "timed"}
        How claims are compared (use the TM's ``settings.check``).

    Attributes
    ----------
    steps, footprint_overlaps, claim_violations : int
        Totals so far (a pair counts once per step it lasts).
    min_separation : float
        Smallest footprint separation seen so far (m).
    """

    def __init__(self, check: str = "union") -> None:
        if check not in CHECK_KINDS:
            raise ValueError(f"Monitor.check: must be one of {CHECK_KINDS}, got {check!r}")
        self.check = check
        self.steps = 0
        self.footprint_overlaps = 0
        self.claim_violations = 0
        self.tube_escapes = 0
        self.min_separation = np.inf

    def escapes(self, claims: ReachClaims, position, length, width, pad=None, body_heading=None) -> int:
        """Count (and return) the vehicles outside the position part of their ``S_1`` (slot 1 of
        ``claims``: the claims in force after the last decision, rows as ``position``; ``pad``:
        the footprint padding they were built with; ``body_heading``: the bodies' headings where
        they differ from the claims' frames, :func:`tm.reach_book.tube_escapes`)."""
        n = int(tube_escapes(claims, position, length, width, pad=pad, body_heading=body_heading).sum())
        self.tube_escapes += n
        return n

    def step(self, ids: Sequence[str], position, heading, length, width,
             claims: Claims | ReachClaims | None = None, polygons=None) -> MonitorStep:
        """Check one step and add it to the totals.

        Parameters
        ----------
        ids : sequence of str, length V
        position : array_like, shape (V, 2)
            Footprint centres (m).
        heading, length, width : array_like, shape (V,)
        claims : Claims or ReachClaims, optional
            Claims in force, rows as ``ids`` (e.g. ``decision.claims``); not
            checked when omitted.  Reach claims are compared with ``check``
            (``timed``: slot k against slot k).
        polygons : array_like, shape (V, k, 2), optional
            The bodies as the world itself has them (e.g. SUMO's lane-following bodies,
            :meth:`bridge.sumo_world.SumoWorld.bodies`); default the rectangles of ``length`` x
            ``width`` centred on ``position`` along ``heading``.
        """
        ids = tuple(ids)
        polys = footprint_polygons(position, heading, length, width) if polygons is None \
            else np.asarray(polygons, dtype=float)
        if len(polys) != len(ids):
            raise ValueError(f"Monitor.step: {len(ids)} ids but {len(polys)} positions")
        i, j = footprint_overlaps(polys)
        overlap = tuple((ids[a], ids[b]) for a, b in zip(i.tolist(), j.tolist()))
        violation: tuple = ()
        if claims is not None:
            if len(claims) != len(ids):
                raise ValueError(f"Monitor.step: {len(ids)} ids but {len(claims)} claims")
            ci, cj = pairwise_conflicts(claims, self.check) if isinstance(claims, ReachClaims) \
                else conflicting_pairs(claims, self.check)
            violation = tuple((ids[a], ids[b]) for a, b in zip(ci.tolist(), cj.tolist()))
        d, a, b = min_pair_distance(polys)
        result = MonitorStep(footprint_overlaps=len(overlap), claim_violations=len(violation),
                             min_separation=d, overlap_pairs=overlap, violation_pairs=violation,
                             closest_pair=None if a < 0 else (ids[a], ids[b]))
        self.steps += 1
        self.footprint_overlaps += result.footprint_overlaps
        self.claim_violations += result.claim_violations
        self.min_separation = min(self.min_separation, d)
        return result
