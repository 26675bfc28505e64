"""Vehicles' planned stops (SUMO's ``<stop>``: bus stops, parking, a lane position and a dwell).

A stop becomes a waypoint of the route, the one whose centre lies last before ``endPos - L/2``
(SUMO halts a vehicle with its front at the stop's end position), and a rule on the vehicle's
requests: while that waypoint is its stop point (its movement authority, or the paper's current
waypoint) it may not ask for the next one until it has stood there for the stop's duration and
the stop's ``until`` time has come (:class:`StopBook`).  Withholding requests is always safe (the
traffic manager's claims only shrink without a grant), so a stop needs nothing of the guarantee;
the controller brakes to rest at its stop point as it does at a red light.

The dwell a vehicle serves is time SUMO's ``timeLoss`` leaves out, so :mod:`analysis.kpis` counts
it in the vehicle's free-flow time (its delay is what traffic cost it, as SUMO's drivers' is).
Pure numpy: the stops' waypoints come from :func:`plan_stops`, which the SUMO bridge calls with
the route's geometry.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

__all__ = ["PlannedStop", "StopBook", "plan_stops", "AT_REST_MPS"]

#: A vehicle at its stop point counts as halted there below this speed (m/s) with index 0.
AT_REST_MPS = 0.1


@dataclass(frozen=True)
class PlannedStop:
    """A stop on a vehicle's waypoints.

    Attributes
    ----------
    k : int
        The waypoint it halts at (index into the vehicle's waypoints).
    duration_s : float
        Dwell once halted (s, >= 0).
    until_s : float or None
        Earliest departure in the run's time (s from its start); None: none.
    place : str
        What it stops at (a stopping place's id or the lane), for messages.
    """

    k: int
    duration_s: float
    until_s: float | None
    place: str


def plan_stops(vid: str, arc: np.ndarray, fronts: Sequence[float | None], stops, length: float,
               t0_s: float = 0.0) -> tuple[tuple[PlannedStop, ...], list[str]]:
    """The waypoints of a vehicle's stops.

    Parameters
    ----------
    vid : str
        The vehicle (messages).
    arc : ndarray, shape (K,)
        Arc positions of its waypoints along its route (m, increasing).
    fronts : sequence of float or None
        Per stop, the arc position along the route where SUMO would halt its front (None: the stop's
        lane is not on the route).
    stops : sequence of bridge.demand.VehicleStop
    length : float
        The vehicle's length (m).
    t0_s : float
        The run's start in simulation time (``until`` is simulation time).

    Returns
    -------
    (tuple of PlannedStop, list of str)
        The stops, in route order, and why any was left out (a stop off the route, behind the
        start or behind an earlier stop: SUMO would not serve it either).
    """
    arc = np.asarray(arc, dtype=float)
    out, skipped, last_k = [], [], 0
    for st, front in zip(stops, fronts):
        if front is None:
            skipped.append(f"vehicle {vid!r}: stop at {st.place!r} (lane {st.lane!r}) is not on its route")
            continue
        centre = float(front) - 0.5 * float(length)
        k = int(np.searchsorted(arc, centre + 1e-9, side="right")) - 1
        if k < 1 or k <= last_k and out:
            skipped.append(f"vehicle {vid!r}: stop at {st.place!r} lies behind its start or its previous stop")
            continue
        until = None if st.until_s is None else float(st.until_s) - t0_s
        out.append(PlannedStop(k, float(st.duration_s), until, st.place))
        last_k = k
    return tuple(out), skipped


class StopBook:
    """Which vehicles may not ask past their stop point yet (their stops' dwell), and the dwell each
    has served.

    Parameters
    ----------
    plans : mapping of str to sequence of PlannedStop
        Each vehicle's stops in route order (vehicles without any need no entry).
    """

    def __init__(self, plans) -> None:
        self._plans = {v: tuple(p) for v, p in dict(plans).items() if p}
        self._next: dict[str, int] = {}        # vehicle -> index of its next stop
        self._since: dict[str, float] = {}     # vehicle -> when it halted at that stop
        self.withheld = 0                      # requests withheld at stops (steps)
        self.served = 0                        # stops served
        self.passed = 0                        # stops a vehicle was past before halting there
        self.dwell_s: dict[str, float] = {}    # vehicle -> dwell served so far (s)

    def __len__(self) -> int:
        return len(self._plans)

    def pending(self, vid: str) -> PlannedStop | None:
        """The next stop of vehicle ``vid`` (None: none left)."""
        plan = self._plans.get(vid)
        i = self._next.get(vid, 0)
        return plan[i] if plan is not None and i < len(plan) else None

    def withhold(self, t_s: float, ids: Sequence[str], k: np.ndarray, index: np.ndarray, speed: np.ndarray,
                 requesting: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(requesting, held)``: the requests that stay, and which vehicles are held at a stop.

        A vehicle whose current waypoint ``k`` is its next stop's waypoint is held until it has been
        halted there (index 0, speed below :data:`AT_REST_MPS`) for the stop's duration and the
        stop's ``until`` time has come; then the stop is served and its requests go on.  A vehicle
        already past its stop's waypoint (it entered past it) skips it (:attr:`passed`)."""
        req = np.asarray(requesting, dtype=bool).copy()
        held = np.zeros(len(req), dtype=bool)
        if not self._plans:
            return req, held
        for i, vid in enumerate(ids):
            st = self.pending(vid)
            while st is not None and int(k[i]) > st.k:  # past it (admitted beyond): not served
                self._advance(vid, served=False)
                st = self.pending(vid)
            if st is None or int(k[i]) < st.k:
                continue
            if vid not in self._since:
                if int(index[i]) != 0 or float(speed[i]) >= AT_REST_MPS:
                    held[i] = True  # still coming to rest at its stop point
                    continue
                self._since[vid] = t_s
            done = t_s - self._since[vid] >= st.duration_s - 1e-9 and (st.until_s is None or t_s >= st.until_s - 1e-9)
            if done:
                self.dwell_s[vid] = self.dwell_s.get(vid, 0.0) + (t_s - self._since.pop(vid))
                self._advance(vid, served=True)
            else:
                held[i] = True
        self.withheld += int((held & req).sum())
        req &= ~held
        return req, held

    def _advance(self, vid: str, served: bool) -> None:
        self._next[vid] = self._next.get(vid, 0) + 1
        if served:
            self.served += 1
        else:
            self.passed += 1

    def finish(self, vid: str) -> float:
        """Forget vehicle ``vid``, which left; returns the dwell it served at its stops (s)."""
        self._plans.pop(vid, None)
        self._next.pop(vid, None)
        self._since.pop(vid, None)
        return self.dwell_s.pop(vid, 0.0)
