"""Each vehicle's route intervals through the junction zones' shared guards (movement-authority
mode; :mod:`tm.authority_gate`, module notes: "guard", "entry line", "exit slot").

A route's intervals never change, so they are computed once per vehicle and kept in the forms the
gate asks for them in: as arrays (:meth:`GuardSpans.intervals`), as Python tuples per zone
(:meth:`GuardSpans.span_of`, asked for thousands of times a step), sorted by entry
(:meth:`GuardSpans.entry_runs`, the chained zones) and gathered for many vehicles at once
(:meth:`GuardSpans.gather`).  Pure numpy, no simulator.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from operator import itemgetter

import numpy as np

from tm.authority_reach import AuthorityReach
from tm.boxes import GuardIndex
from tm.junctions import JunctionFleet

__all__ = ["GuardSpans"]


class _FlatIntervals:
    """Every vehicle's guard intervals (:meth:`GuardSpans.intervals`: zone, entry, exit slot) in one
    flat int array, each vehicle's a contiguous run, so that a step's requesters' intervals are
    gathered by index (a list and three concatenations of a few thousand small arrays took ~2 ms a
    step at 1,000 vehicles).  A route's intervals never change; a vehicle's run is added when first
    asked for and the whole is dropped with the other per-vehicle caches (:meth:`GuardSpans.prune`)."""

    def __init__(self):
        self.where: dict[str, tuple[int, int]] = {}  # vehicle id -> (first, count)
        self.table = np.zeros((3, 256), dtype=np.intp)
        self.used = 0

    def gather(self, fleet: JunctionFleet, rows: np.ndarray, intervals) -> tuple[np.ndarray, np.ndarray]:
        """``(count (R,), (zone, entry, exit) (3, sum count))`` of fleet ``rows``, in their order;
        ``intervals(fleet, row)`` gives a vehicle's when first asked."""
        ids, where = fleet.ids, self.where
        rl = rows.tolist()
        for i in rl:
            if ids[i] not in where:
                zs, e, x, _ = intervals(fleet, i)
                m = len(zs)
                if self.used + m > self.table.shape[1]:
                    grown = np.zeros((3, 2 * (self.used + m)), dtype=np.intp)
                    grown[:, :self.used] = self.table[:, :self.used]
                    self.table = grown
                self.table[:, self.used:self.used + m] = (zs, e, x)
                where[ids[i]] = (self.used, m)
                self.used += m
        se = np.array([where[ids[i]] for i in rl], dtype=np.intp).reshape(-1, 2)
        cnt = se[:, 1]
        tot = int(cnt.sum())
        pos = np.repeat(se[:, 0] - (np.cumsum(cnt) - cnt), cnt) + np.arange(tot)
        return cnt, self.table[:, pos]


class GuardSpans:
    """The route intervals of every vehicle through the zones' shared guards, cached per vehicle.

    Parameters
    ----------
    guards : GuardIndex
        The zones' shared guard boxes (:class:`tm.junctions.JunctionGate`).
    classes : mapping of str to AuthorityReach
        Every class a fleet row may name (its hold box).
    passes : callable
        ``(ids, zones) -> bool array``: whether each vehicle's route passes through the zone
        (:meth:`tm.junctions.JunctionGate.passes`: every zone for a vehicle it has no route of).
    """

    def __init__(self, guards: GuardIndex, classes: Mapping[str, AuthorityReach],
                 passes: Callable[[list, np.ndarray], np.ndarray]):
        self.guards = guards
        self.classes = classes
        self.passes = passes
        self._intervals: dict[str, tuple] = {}  # vehicle id -> :meth:`intervals`
        self._runs: dict[str, list] = {}  # vehicle id -> its intervals as tuples (:meth:`span_of`)
        self._entry_runs: dict[str, list] = {}  # vehicle id -> :meth:`entry_runs`
        self._flat = _FlatIntervals()  # every vehicle's intervals in flat arrays (:meth:`gather`)

    def intervals(self, fleet: JunctionFleet, row: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(zone, entry, exit, exits)``: the runs of waypoints of row ``row``'s route whose hold
        box (``T^0 ⊕ footprint`` at the arriving and leaving headings) meets a zone's shared guard
        (the largest class's: no holder's claims stick out of the zone further, :mod:`tm.authority_gate`).

        ``entry`` is the first waypoint of a run (the stop point may move there only with the
        zone's token), ``exit`` the first after it whose hold box misses the guard (the exit
        slot), or the last waypoint when the route ends inside the guard (``exits`` False).
        Cached per vehicle: they depend on its route only."""
        vid = fleet.ids[row]
        found = self._intervals.get(vid)
        if found is not None:
            return found
        W, H, _ = fleet.route(row)
        i, z = self.guard_hits(W, H, fleet.family[row], vid)
        o = np.lexsort((i, z))
        i, z = i[o], z[o]
        run = np.r_[True, (z[1:] != z[:-1]) | (i[1:] != i[:-1] + 1)] if len(i) else np.zeros(0, dtype=bool)
        starts = np.flatnonzero(run)
        last = i[np.r_[starts[1:], len(i)] - 1] if len(i) else np.zeros(0, dtype=np.intp)
        exits = last + 1 < len(W)
        found = self._intervals[vid] = (z[starts], i[starts], np.where(exits, last + 1, len(W) - 1), exits)
        return found

    def guard_hits(self, W: np.ndarray, H: np.ndarray, vclass: str,
                    vid: str | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(waypoint, zone)`` pairs of a route ``W`` (headings ``H``) whose hold box (``T^0 ⊕
        footprint`` at the arriving and leaving headings) meets a zone's shared guard (the largest
        class's: no holder's claims stick out of the zone further, :mod:`tm.authority_gate`); with vehicle id
        ``vid``, only the zones its route passes through (``passes``)."""
        half = self.classes[vclass].hold_half(H, np.r_[H[1:], H[-1:]])
        i, z = self.guards.pairs(W - half, W + half)
        if vid is not None:
            on = self.passes([vid] * len(z), z)
            i, z = i[on], z[on]
        return i, z

    def entry_limit(self, W: np.ndarray, H: np.ndarray, vclass: str, vid: str | None = None) -> int:
        """The last waypoint of a route ``W`` (headings ``H``: of the segments arriving at each) before
        the first of its guard intervals (:meth:`intervals`) that starts after its first waypoint: the
        furthest stop point a vehicle entering on it may have without a token (bridge/departure.py);
        its last waypoint when there is none.  ``vid``: the vehicle's id (only the zones its route
        passes through count, ``passes``)."""
        W, H = np.asarray(W, dtype=float), np.asarray(H, dtype=float)
        i, _ = self.guard_hits(W, H, vclass, vid)
        inside = np.zeros(len(W), dtype=bool)
        inside[i] = True
        entries = np.flatnonzero(inside[1:] & ~inside[:-1]) + 1  # runs starting after waypoint 0
        return int(entries[0]) - 1 if len(entries) else len(W) - 1

    def span_of(self, fleet: JunctionFleet, row: int, z: int, target: int):
        """``(entry, exit, exits)`` of zone ``z``'s first interval not left before waypoint ``target``
        (the one holding it, or the next one: a chained zone's,
        :meth:`tm.authority_gate.AuthorityGate._wanting`), or None."""
        vid = fleet.ids[row]
        runs = self._runs.get(vid)
        if runs is None:  # the intervals as Python tuples: a few per route, asked for thousands of times a step
            zs, e, x, ex = self.intervals(fleet, row)
            runs = self._runs[vid] = list(zip(zs.tolist(), e.tolist(), x.tolist(), ex.tolist()))
        for zz, en, xx, exits in runs:
            if zz == z and target <= xx:
                return en, xx, bool(exits)
        return None

    def entry_runs(self, fleet: JunctionFleet, row: int) -> list:
        """Row ``row``'s intervals as ``(entry, zone, exit)`` tuples in the route's order (by entry)."""
        vid = fleet.ids[row]
        runs = self._entry_runs.get(vid)
        if runs is None:
            zs, e, x, _ = self.intervals(fleet, row)
            runs = self._entry_runs[vid] = sorted(zip(e.tolist(), zs.tolist(), x.tolist()), key=itemgetter(0))
        return runs

    def gather(self, fleet: JunctionFleet, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(count (R,), (zone, entry, exit) (3, sum count))`` of fleet ``rows``' intervals, in their
        order (:class:`_FlatIntervals`)."""
        return self._flat.gather(fleet, rows, self.intervals)

    def prune(self, ids) -> None:
        """Drop the vehicles not in ``ids`` (the fleet now) once the caches hold many more than it."""
        if len(self._intervals) <= 4 * len(ids) + 1000:
            return
        live = set(ids)
        self._intervals = {v: sp for v, sp in self._intervals.items() if v in live}
        self._runs = {v: sp for v, sp in self._runs.items() if v in live}
        self._entry_runs = {v: sp for v, sp in self._entry_runs.items() if v in live}
        self._flat = _FlatIntervals()
