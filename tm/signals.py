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
is never affected by that line -- unless the rule is given a :class:`LineTiming` (authority
mode), see below.

Time to red (:class:`LineTiming`, movement-authority mode, issue 12).  A cruising vehicle asks
for the crossing switch a braking distance ahead of the line (~50 m, 3.6 s at 13.9 m/s), and a
grant is never revisited: checking only the letter now lets it enter on red (yellow lasts 3 s).
With the time until each link turns red (read from SUMO's program by the bridge), the
switches of the *crossing chain* ``bound <= k < commit`` are withheld, while the front has not
reached the line, also when the front would not reach the line before red (less
``red_margin_s``) under the speed profile the cost tracks when nothing further is granted but
the chain (:func:`time_to_line`).  ``commit`` is the first waypoint whose nominal rest front
(the cost stops the centre ``s0`` short of the stop point: front ``arc + L/2 - s0``) is past
the line; usually ``commit = bound + 1``.  What is counted, here and by SUMO, is the front
bumper entering over the stop line while the link is red (SUMO: the light drops out of
``vehicle.getNextTLS`` when the front enters the junction); a rear still in the junction at red
is not a red crossing (the junction's claims and tokens keep foes apart).  Withholding a request is always safe (the traffic manager
keeps the invariant under "deny every request"): signals only cost liveness.

``ignore`` mode (the TM-only, AIM-style intersection management) withholds nothing;
crossings on red are still counted (:func:`red_crossings`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

__all__ = ["SignalSettings", "SignalSettingsError", "StopLines", "SIGNAL_MODES", "STATE_LETTERS", "LineTiming",
           "SignalBook", "stop_bounds", "commit_points", "along_position", "time_to_line", "withhold",
           "red_crossings", "is_red", "is_yellow"]

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
    accel_floor : float
        Time-to-red rule (:func:`time_to_line`): the acceleration (m/s^2) a vehicle below its
        speed cap is assumed to reach at least; small is conservative (a longer time to the line).
    red_margin_s : float
        Time-to-red rule: the front must reach the line this long (s) before red.  It covers the
        step the state is sampled at (Ts = 0.1 s), the cost's tracking lag and disturbances.
    """

    mode: Literal["obey", "ignore"] = "obey"
    comfort_decel: float = 2.5
    accel_floor: float = 1.0
    red_margin_s: float = 0.5

    def __post_init__(self) -> None:
        if self.mode not in SIGNAL_MODES:
            raise SignalSettingsError(f"SignalSettings.mode: must be one of {SIGNAL_MODES}, got {self.mode!r}")
        for name, unit in (("comfort_decel", "m/s^2"), ("accel_floor", "m/s^2"), ("red_margin_s", "s")):
            v = getattr(self, name)
            if (not isinstance(v, (int, float)) or isinstance(v, bool) or not np.isfinite(v)
                    or not (v >= 0 if name == "red_margin_s" else v > 0)):
                bound = ">= 0" if name == "red_margin_s" else "> 0"
                raise SignalSettingsError(f"SignalSettings.{name}: must be a number {bound} ({unit}), got {v!r}")


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


def commit_points(arc: np.ndarray, s_line: np.ndarray, rest_lead: float) -> np.ndarray:
    """Per line, the first waypoint index ``j`` with ``arc[j] + rest_lead > s_line``: the first stop
    point at which the cost's nominal rest front (``rest_lead = L/2 - s0``) lies past the line
    (``len(arc)`` when none does)."""
    arc = np.asarray(arc, dtype=float)
    return np.searchsorted(arc + float(rest_lead), np.asarray(s_line, dtype=float), side="right")


def time_to_line(gap: np.ndarray, rest: np.ndarray, speed: np.ndarray, v_cap: np.ndarray, accel: np.ndarray,
                 decel: np.ndarray) -> np.ndarray:
    """Time (s) for a front bumper to cover ``gap`` (m) under the profile the movement-authority
    cost tracks when nothing further is granted: speed ``min(sqrt(v0^2 + 2 a s), V, sqrt(2 a_c
    (rest - s)))`` at distance ``s``, with ``v0 = min(speed, V)``, ``V = v_cap``, ``a = accel``
    (a floor on the acceleration below the cap), ``a_c = decel`` (the cost's braking to rest at
    ``rest`` m ahead: its stop point less ``s0``).  Closed form, piece by piece (accelerate,
    cruise, brake); ``inf`` when the profile stops at or before the line (``gap >= rest``), 0 for
    ``gap <= 0``.  Every argument broadcasts; shapes (m,)."""
    gap, rest, v0, V, a, b = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in
                                                   (gap, rest, speed, v_cap, accel, decel)))
    V = np.maximum(V, 0.0)
    v0 = np.clip(v0, 0.0, V)
    R = np.maximum(rest, 0.0)
    v0 = np.minimum(v0, np.sqrt(2.0 * b * R))
    g = np.clip(gap, 0.0, R)
    s_av = (V * V - v0 * v0) / (2.0 * a)                  # the acceleration curve meets the cap
    s_dv = R - V * V / (2.0 * b)                          # the braking curve drops below it
    s_ad = (2.0 * b * R - v0 * v0) / (2.0 * (a + b))      # the two curves meet (no cruise)
    cruise = s_av <= s_dv
    s1 = np.clip(np.where(cruise, s_av, s_ad), 0.0, R)   # end of the acceleration piece
    s2 = np.clip(np.where(cruise, s_dv, s_ad), s1, R)    # start of the braking piece
    with np.errstate(divide="ignore", invalid="ignore"):
        e1 = np.minimum(g, s1)
        t = (np.sqrt(v0 * v0 + 2.0 * a * e1) - v0) / a
        e2 = np.clip(g, s1, s2)
        t = t + np.where(e2 > s1, (e2 - s1) / np.where(V > 0, V, 1.0), 0.0)
        e3 = np.clip(g, s2, R)
        t = t + (np.sqrt(2.0 * b * (R - s2)) - np.sqrt(2.0 * b * (R - e3))) / b
    t = np.where((V <= 0) & (g > 0), np.inf, t)
    t = np.where(gap >= R, np.inf, t)
    return np.where(gap <= 0, 0.0, t)


@dataclass(frozen=True, eq=False)
class LineTiming:
    """What the time-to-red rule needs (module notes), per stop line (shape (m,)) and per fleet
    row (shape (n,)).

    Parameters
    ----------
    commit : ndarray of int, shape (m,)
        First waypoint whose nominal rest front is past the line (:func:`commit_points`).
    rest_past : ndarray, shape (m,)
        How far past the line that nominal rest front lies (m, > 0; ``inf``: no such waypoint).
    time_to_red : ndarray, shape (m,)
        Time (s) until the line's link turns red (0: red now; ``inf``: not within a cycle).
    v_cap, decel : ndarray, shape (n,)
        Each row's speed cap (m/s) and its cost's braking ``a_c`` (m/s^2).
    """

    commit: np.ndarray
    rest_past: np.ndarray
    time_to_red: np.ndarray
    v_cap: np.ndarray
    decel: np.ndarray


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
             speed: np.ndarray, timing: LineTiming | None = None) -> tuple[np.ndarray, np.ndarray]:
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
    timing : LineTiming, optional
        The time-to-red rule (module notes): the crossing chain ``bound <= k < commit`` is
        withheld, while the front is behind the line, on red, on yellow with room to stop, and
        when the front would not reach the line ``red_margin_s`` before red.  Without it, only the
        switch ``k == bound`` is judged, by the state letter alone.

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
    kr = np.asarray(k)[row]
    bound = np.asarray(line_bound)
    gap = np.asarray(line_gap, dtype=float)
    at = (bound == kr) & req[row]  # this switch crosses the line
    state = np.asarray(line_state, dtype=np.uint8)
    v = np.asarray(speed, dtype=float)[row]
    room = v * v <= 2.0 * settings.comfort_decel * gap
    late = np.zeros(len(row), dtype=bool)
    if timing is not None:
        at |= (bound <= kr) & (kr < np.asarray(timing.commit)) & (gap > 0) & req[row]  # the crossing chain
        t_line = time_to_line(gap, gap + np.asarray(timing.rest_past, dtype=float), v,
                              np.asarray(timing.v_cap, dtype=float)[row], settings.accel_floor,
                              np.asarray(timing.decel, dtype=float)[row])
        late = t_line + settings.red_margin_s > np.asarray(timing.time_to_red, dtype=float)
    stop = at & (is_red(state) | (is_yellow(state) & room) | late)
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
        self._commit: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self._front: dict[str, float] = {}
        #: crossings of a stop line while its link was red (front bumper, one per line crossed)
        self.red_violations = 0
        #: requests a signal withheld
        self.withheld = 0

    def __len__(self) -> int:
        return len(self._lines)

    def add(self, vid: str, lines: StopLines, reach: float, rest_lead: float | None = None) -> None:
        """Register a vehicle's lines; ``reach``: its front bumper's largest lead over the waypoint
        it rests at (``max |P^0| + length / 2``, m); ``rest_lead``: the cost's nominal one
        (``length / 2 - s0``, m; movement-authority mode, for :meth:`timing_of`)."""
        if len(lines):
            self._lines[vid] = (lines, stop_bounds(lines.arc, lines.s_line, reach))
            if rest_lead is not None:
                arc = np.asarray(lines.arc, dtype=float)
                commit = commit_points(arc, lines.s_line, rest_lead)
                past = np.where(commit < len(arc), arc[np.minimum(commit, len(arc) - 1)] + rest_lead
                                - np.asarray(lines.s_line, dtype=float), np.inf)
                self._commit[vid] = (commit, past)

    def remove(self, vid: str) -> None:
        self._lines.pop(vid, None)
        self._commit.pop(vid, None)
        self._front.pop(vid, None)

    def timing_of(self, ids) -> tuple[np.ndarray, np.ndarray] | None:
        """``(commit, rest_past)`` of the lines of ``ids`` in :meth:`gather`'s order, or None when
        a vehicle with lines was registered without ``rest_lead``."""
        got = [self._commit.get(v) for v in ids if v in self._lines]
        if any(g is None for g in got):
            return None
        if not got:
            return np.zeros(0, dtype=np.intp), np.zeros(0)
        return (np.concatenate([g[0] for g in got]).astype(np.intp), np.concatenate([g[1] for g in got]))

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
