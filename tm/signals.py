"""Traffic lights: which waypoint switches a signal withholds (pure numpy, no simulator).

SUMO keeps running its own signal programs; every step the bridge reads the state
letter of each signalised link in use (``traci.trafficlight.getRedYellowGreenState``)
and hands them here as a vector, one byte per *slot* (a ``(tls, linkIndex)`` pair).
A vehicle's route crosses stop lines at signalised connections; each stop line is a
position ``s_line`` along its waypoints and a slot.

Bound.  The body must stay behind a line while its link is red.  A vehicle at rest at
waypoint ``k`` stays inside its hold region ``P^0`` around it, so its front bumper is at
most ``arc[k] + reach`` along the route, ``reach = max |P^0| + length / 2``
(:func:`stop_bounds`).  ``bound`` is the last waypoint with ``arc[bound] + reach <=
s_line``: the switch ``bound -> bound + 1`` is the one that takes the vehicle past the
line, and it is the only switch the signal acts on.

Rule (:func:`withhold`), for a request ``k -> k + 1`` and every line of the vehicle with
``bound == k``:

* red (``r``) and red-yellow (``u``, "about to turn green"; vehicles may not pass yet):
  withheld;
* yellow (``y``, ``Y``): withheld when the vehicle can still stop before the line with the
  comfortable deceleration ``a_c`` (``v^2 / (2 a_c) <= s_line - front``), granted otherwise
  (it is committed, as a human driver would be);
* green (``G``), minor green (``g``), green arrow that asks for a stop first (``s``), off
  blinking (``o``) and off (``O``): go.  Minor green and the off states mean "yield" in SUMO;
  muvsim does not need SUMO's right-of-way there, because the traffic manager's claims
  already keep every pair of vehicles apart and the junction tokens (:mod:`tm.junctions`)
  order them.

A vehicle whose current waypoint is beyond a line's bound (it was granted past the line)
is never affected by that line.  Withholding a request is always safe (the traffic manager
keeps the invariant under "deny every request"): signals only cost liveness.

``ignore`` mode (the TM-only, AIM-style intersection management) withholds nothing;
crossings on red are still counted (:func:`red_crossings`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

__all__ = ["SignalSettings", "SignalSettingsError", "StopLines", "SIGNAL_MODES", "STATE_LETTERS",
           "SignalBook", "stop_bounds", "along_position", "withhold", "red_crossings", "is_red", "is_yellow"]

#: Valid values of :attr:`SignalSettings.mode`.
SIGNAL_MODES = ("obey", "ignore")
#: SUMO's link state letters (sumo.dlr.de/docs/Simulation/Traffic_Lights.html#signal_state_definitions).
STATE_LETTERS = "rRyYgGsuoO"
_RED = np.frombuffer(b"rRu", dtype=np.uint8)
_YELLOW = np.frombuffer(b"yY", dtype=np.uint8)


class SignalSettingsError(ValueError):
    """Invalid signal setting; the message names the field and the valid values."""


@dataclass(frozen=True)
class SignalSettings:
    """How vehicles treat SUMO's traffic lights.

    Parameters
    ----------
    mode : {"obey", "ignore"}
        ``obey`` (default): no grant takes a vehicle past a stop line whose link is red, or
        yellow with room to stop.  ``ignore``: the traffic manager alone (AIM-style).
    comfort_decel : float
        ``a_c`` (m/s^2) of the yellow rule: design.md §7's comfortable deceleration.
    """

    mode: Literal["obey", "ignore"] = "obey"
    comfort_decel: float = 2.5

    def __post_init__(self) -> None:
        if self.mode not in SIGNAL_MODES:
            raise SignalSettingsError(f"SignalSettings.mode: must be one of {SIGNAL_MODES}, got {self.mode!r}")
        if (not isinstance(self.comfort_decel, (int, float)) or isinstance(self.comfort_decel, bool)
                or not np.isfinite(self.comfort_decel) or not self.comfort_decel > 0):
            raise SignalSettingsError("SignalSettings.comfort_decel: must be a number > 0 (m/s^2), "
                                      f"got {self.comfort_decel!r}")


@dataclass(frozen=True, eq=False)
class StopLines:
    """The signalised stop lines one route crosses, in route order.

    Parameters
    ----------
    arc : ndarray, shape (K,)
        Position of each waypoint along the route (m, increasing).
    s_line : ndarray, shape (M,)
        Position of each stop line along the same route (m).
    slot : ndarray of int, shape (M,)
        Index of each line's link into the link-state vector.
    """

    arc: np.ndarray
    s_line: np.ndarray
    slot: np.ndarray

    def __post_init__(self) -> None:
        arc, s, slot = (np.asarray(a) for a in (self.arc, self.s_line, self.slot))
        if arc.ndim != 1 or len(arc) < 1 or not np.all(np.isfinite(arc)) or np.any(np.diff(arc) < 0):
            raise ValueError(f"StopLines.arc: must be finite and non-decreasing, shape (K >= 1,), got {arc!r}")
        if s.ndim != 1 or s.shape != slot.shape or not np.all(np.isfinite(s)):
            raise ValueError(f"StopLines.s_line and slot: finite, one slot per line, got shapes {s.shape} "
                             f"and {slot.shape}")
        if len(slot) and slot.min() < 0:
            raise ValueError(f"StopLines.slot: must be >= 0, got {slot!r}")

    def __len__(self) -> int:
        return len(self.s_line)


def stop_bounds(arc: np.ndarray, s_line: np.ndarray, reach: float) -> np.ndarray:
    """Per line, the last waypoint index ``k`` with ``arc[k] + reach <= s_line``.

    ``reach`` (m): how far the front bumper can be ahead of the waypoint the vehicle rests
    at (``max |P^0| + length / 2``).  ``-1`` when even the first waypoint is too close (the
    vehicle starts at or past the line: never affected)."""
    arc = np.asarray(arc, dtype=float)
    return np.searchsorted(arc + float(reach), np.asarray(s_line, dtype=float), side="right") - 1


def along_position(arc_k: np.ndarray, centre: np.ndarray, heading: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """A vehicle's position along its route: its current waypoint's ``arc_k`` plus the
    offset of ``pos`` from the waypoint ``centre`` along the route's ``heading`` there (the
    road frame's along coordinate)."""
    d = np.asarray(pos, dtype=float) - np.asarray(centre, dtype=float)
    return np.asarray(arc_k, dtype=float) + d[:, 0] * np.cos(heading) + d[:, 1] * np.sin(heading)


def is_red(state: np.ndarray) -> np.ndarray:
    """Whether each state byte means "do not pass" (``r``, ``R``, ``u``)."""
    return np.isin(np.asarray(state, dtype=np.uint8), _RED)


def is_yellow(state: np.ndarray) -> np.ndarray:
    """Whether each state byte is yellow (``y``, ``Y``)."""
    return np.isin(np.asarray(state, dtype=np.uint8), _YELLOW)


def withhold(settings: SignalSettings, requesting: np.ndarray, k: np.ndarray, line_row: np.ndarray,
             line_bound: np.ndarray, line_state: np.ndarray, line_gap: np.ndarray,
             speed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The requests that stay, and which vehicles a signal holds.

    Parameters
    ----------
    settings : SignalSettings
    requesting : ndarray of bool, shape (n,)
        Which fleet rows ask to switch ``k -> k + 1``.
    k : ndarray of int, shape (n,)
        Each row's current waypoint index.
    line_row, line_bound : ndarray of int, shape (m,)
        For every stop line of the fleet's routes: its vehicle's row and its bound
        (:func:`stop_bounds`).
    line_state : ndarray of uint8, shape (m,)
        The line's link state letter now.
    line_gap : ndarray, shape (m,)
        Distance from the vehicle's front bumper to the line (m; negative: past it).
    speed : ndarray, shape (n,)
        Each row's speed (m/s).

    Returns
    -------
    requesting : ndarray of bool, shape (n,)
    held : ndarray of bool, shape (n,)
        Rows whose request a signal withheld.
    """
    req = np.array(requesting, dtype=bool)
    held = np.zeros(len(req), dtype=bool)
    if settings.mode == "ignore" or not len(line_row):
        return req, held
    row = np.asarray(line_row, dtype=np.intp)
    at = (np.asarray(line_bound) == np.asarray(k)[row]) & req[row]  # this switch crosses the line
    state = np.asarray(line_state, dtype=np.uint8)
    v = np.asarray(speed, dtype=float)[row]
    room = v * v <= 2.0 * settings.comfort_decel * np.asarray(line_gap, dtype=float)
    stop = at & (is_red(state) | (is_yellow(state) & room))
    held[row[stop]] = True
    req &= ~held
    return req, held


def red_crossings(front_before: np.ndarray, front_after: np.ndarray, s_line: np.ndarray,
                  state: np.ndarray) -> np.ndarray:
    """Which lines a front bumper crossed in one step while their link was red
    (``front_before < s_line <= front_after``, state ``r``/``R``/``u``)."""
    s = np.asarray(s_line, dtype=float)
    return (np.asarray(front_before) < s) & (np.asarray(front_after) >= s) & is_red(state)


class SignalBook:
    """The stop lines of the vehicles in the network, and their front bumpers' last positions.

    Parameters
    ----------
    settings : SignalSettings
    """

    def __init__(self, settings: SignalSettings):
        self.settings = settings
        self._lines: dict[str, tuple[StopLines, np.ndarray]] = {}
        self._front: dict[str, float] = {}
        #: crossings of a stop line while its link was red (front bumper, one per line crossed)
        self.red_violations = 0
        #: requests a signal withheld
        self.withheld = 0

    def __len__(self) -> int:
        return len(self._lines)

    def add(self, vid: str, lines: StopLines, reach: float) -> None:
        """Register a vehicle's lines; ``reach``: its front bumper's largest lead over the waypoint
        it rests at (``max |P^0| + length / 2``, m)."""
        if len(lines):
            self._lines[vid] = (lines, stop_bounds(lines.arc, lines.s_line, reach))

    def remove(self, vid: str) -> None:
        self._lines.pop(vid, None)
        self._front.pop(vid, None)

    def bounds(self, vid: str) -> np.ndarray:
        """The bound of each of the vehicle's lines (empty for a vehicle without lines)."""
        got = self._lines.get(vid)
        return got[1] if got is not None else np.zeros(0, dtype=np.intp)

    def gather(self, ids, k: np.ndarray, centre: np.ndarray, heading: np.ndarray, pos: np.ndarray,
               half_length: np.ndarray):
        """Flat line arrays of the fleet rows ``ids``: ``(line_row, bound, s_line, slot, front)``, and
        each row's front-bumper position along its route (NaN for rows without lines)."""
        rows = [i for i, v in enumerate(ids) if v in self._lines]
        front = np.full(len(ids), np.nan)
        if not rows:
            e = np.zeros(0, dtype=np.intp)
            return e, e, np.zeros(0), e, front
        r = np.array(rows, dtype=np.intp)
        got = [self._lines[ids[i]] for i in rows]
        arc_k = np.array([g[0].arc[min(int(k[i]), len(g[0].arc) - 1)] for g, i in zip(got, rows)])
        front[r] = along_position(arc_k, centre[r], heading[r], pos[r]) + half_length[r]
        n = np.array([len(g[0]) for g in got])
        line_row = np.repeat(r, n)
        bound = np.concatenate([g[1] for g in got])
        s_line = np.concatenate([g[0].s_line for g in got])
        slot = np.concatenate([g[0].slot for g in got]).astype(np.intp)
        return line_row, bound, s_line, slot, front

    def count_crossings(self, ids, front: np.ndarray, line_row, s_line, line_state) -> int:
        """Count the lines crossed on red since the last call (fronts of ``ids`` now; the states
        the step ran with) and remember the fronts."""
        before = np.array([self._front.get(ids[i], np.nan) for i in line_row], dtype=float)
        hit = red_crossings(before, front[line_row], s_line, line_state) if len(line_row) else np.zeros(0, bool)
        n = int(np.count_nonzero(hit))
        self.red_violations += n
        for i in np.unique(line_row).tolist():
            self._front[ids[i]] = float(front[i])
        return n
