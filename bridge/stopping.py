"""When a SUMO run stops, and why: the one stopping rule of ``muvsim run``.

Without ``--duration`` a run lasts until every vehicle of the demand has
arrived, at most :data:`CAP_FACTOR` times the departure window (the last
requested departure, at least :data:`MIN_WINDOW_S`).  With ``--duration S`` it
stops after S simulated seconds, or earlier when every vehicle has arrived.
:func:`stop_reason` says which of these ended a run, in words for the user.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass

__all__ = ["CAP_FACTOR", "MIN_WINDOW_S", "RunLimit", "run_limit", "stop_reason", "route_file_departures"]

#: A run without ``--duration`` stops at this many departure windows at the latest.
CAP_FACTOR = 3.0

#: Shortest departure window the cap is computed from (s): demands whose vehicles all
#: depart at once still get time to drive.
MIN_WINDOW_S = 60.0


@dataclass(frozen=True)
class RunLimit:
    """How long a run may last.

    Attributes
    ----------
    duration_s : float
        Simulated seconds after which the run stops at the latest.
    capped : bool
        True: the default rule (until every vehicle arrived, at most the cap);
        False: the user's ``--duration``.
    window_s : float
        The departure window the cap was computed from (s).
    """

    duration_s: float
    capped: bool
    window_s: float


def run_limit(departures_s, duration_s: float | None) -> RunLimit:
    """The limit of a run over a demand with requested departures ``departures_s``.

    Parameters
    ----------
    departures_s : iterable of float
        Requested departure of every vehicle of the demand (s).
    duration_s : float or None
        ``--duration``; None for the default rule.

    Raises
    ------
    ValueError
        ``duration_s`` given and not > 0.
    """
    deps = [float(d) for d in departures_s]
    window = max(max(deps, default=0.0), MIN_WINDOW_S)
    if duration_s is not None:
        if not duration_s > 0:
            raise ValueError(f"--duration: must be > 0 simulated seconds, got {duration_s}")
        return RunLimit(float(duration_s), False, window)
    return RunLimit(CAP_FACTOR * window, True, window)


def stop_reason(limit: RunLimit, demand: int, arrived: int, simulated_s: float) -> str:
    """Why a run stopped, for ``summary.json`` (``stop_reason``) and the closing table."""
    left = demand - arrived
    if left <= 0:
        return f"every vehicle of the demand arrived ({arrived} of {demand}) at {simulated_s:.1f} s"
    if limit.capped:
        return (f"cap reached: {limit.duration_s:.1f} s = {CAP_FACTOR:g} x the departure window "
                f"({limit.window_s:.1f} s); {left} of {demand} vehicles still in the network or waiting to "
                f"depart (give --duration S to run longer)")
    return f"--duration {limit.duration_s:g} s reached; {left} of {demand} vehicles still in the network or " \
           f"waiting to depart"


def route_file_departures(route_files) -> list[float]:
    """Requested departures (s) in SUMO route files: ``depart`` of vehicles and trips, ``end`` of flows.

    Used for the cap of a ``--baseline sumo`` run, which reads no demand itself; a
    departure that is not a number (``triggered``) or a file that cannot be read is
    skipped (SUMO reports those when it runs).
    """
    out: list[float] = []
    for f in route_files:
        try:
            root = ET.parse(f).getroot()
        except (OSError, ET.ParseError):
            continue
        for elem in root.iter():
            value = elem.get("end") if elem.tag == "flow" else elem.get("depart") \
                if elem.tag in ("vehicle", "trip") else None
            try:
                out.append(float(value))
            except (TypeError, ValueError):
                continue
    return out
