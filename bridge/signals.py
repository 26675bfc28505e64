"""Traffic lights in SUMO networks: the stop lines a route crosses, and SUMO's link states.

A signalised connection (``<connection ... tl="T" linkIndex="i">``) has its stop line where
the connection leaves its lane: the end of the incoming lane's shape.  For a route drawn by
:class:`bridge.waypoints.NetGeometry`, :func:`route_stop_lines` finds, junction by junction,
the connection the route uses (its internal ``via`` lane, or its target lane, appears in the
route's polyline) and the position of the line along the route (the end of the last polyline
segment on the incoming lane, or the lane end projected on the polyline, whichever comes
first).  Every ``(tls, linkIndex)`` gets a *slot* (:class:`LinkSlots`); each step
:meth:`LinkSlots.states` reads every light in use once (``getRedYellowGreenState``) and returns
one state byte per slot, for :mod:`tm.signals`.  SUMO keeps running its own signal programs.

:meth:`LinkSlots.time_to_red` reads, per light, its program, phase and next switch, and from the
program's phases (read once per program) the time until each link's state is red (``r``, ``R``,
``u``): the current phase's remaining time, then each later phase's ``minDur`` (its duration in
a static program; an actuated phase lasts at least that long), 0 when red now, ``inf`` when no
phase of the cycle is red for it.  The current phase of an actuated program is taken to last
until ``getNextSwitch`` (SUMO prolongs it from there or not).  A phase with several ``next``
phases ends the look-ahead there: red is assumed to follow (conservative: the rule then only holds
vehicles back).  A program SUMO does not list (a state set over TraCI, ``online``) has no
schedule: ``inf``, the state letter alone decides (the rule before issue 12).
"""

from __future__ import annotations

import numpy as np

from bridge.waypoints import NetGeometry, RouteWaypoints, _arc, project_arc
from tm.signals import StopLines

__all__ = ["LinkSlots", "route_stop_lines", "link_time_to_red"]

_RED = frozenset("rRu")


def link_time_to_red(phases: list, phase: int, remaining: float, link: int) -> float:
    """Time (s) until ``link`` is red in a program ``phases`` (``(state, minDur, next)`` per phase),
    the current phase ``phase`` ending in ``remaining`` s (module notes)."""
    if not 0 <= phase < len(phases):
        return 0.0
    if phases[phase][0][link] in _RED:
        return 0.0
    t, p = max(float(remaining), 0.0), phase
    for _ in range(len(phases)):
        nxt = phases[p][2]
        if len(nxt) > 1:
            return t
        p = nxt[0] if nxt else (p + 1) % len(phases)
        if not 0 <= p < len(phases):
            return t
        state, min_dur, _ = phases[p]
        if state[link] in _RED:
            return t
        t += max(min_dur, 0.0)
    return float("inf")


class LinkSlots:
    """The signalised links in use, numbered, and their states read from SUMO."""

    def __init__(self) -> None:
        self.slot: dict[tuple[str, int], int] = {}
        self.tls_ids: list[str] = []
        self._tls_of: list[int] = []
        self._link: list[int] = []
        self._programs: dict[str, dict] = {}  # tls -> programID -> phases (time_to_red)

    def __len__(self) -> int:
        return len(self.slot)

    def of(self, tls: str, link_index: int) -> int:
        """The slot of a link (a new one the first time)."""
        key = (tls, int(link_index))
        s = self.slot.get(key)
        if s is None:
            if tls not in self.tls_ids:
                self.tls_ids.append(tls)
            s = self.slot[key] = len(self.slot)
            self._tls_of.append(self.tls_ids.index(tls))
            self._link.append(int(link_index))
        return s

    def states(self, adapter) -> np.ndarray:
        """One state letter (uint8) per slot, as SUMO has them now (one call per light)."""
        if not self.slot:
            return np.zeros(0, dtype=np.uint8)
        strings = adapter.tls_states(self.tls_ids)
        lengths = np.array([len(s) for s in strings])
        link = np.asarray(self._link)
        tls_of = np.asarray(self._tls_of)
        bad = np.flatnonzero(link >= lengths[tls_of])
        if len(bad):
            i = int(bad[0])
            raise ValueError(f"traffic light {self.tls_ids[tls_of[i]]!r}: state {strings[tls_of[i]]!r} has no "
                             f"link index {link[i]} (the network's connections name it)")
        buf = np.frombuffer("".join(strings).encode("ascii"), dtype=np.uint8)
        offset = np.concatenate([[0], np.cumsum(lengths)[:-1]])
        return buf[offset[tls_of] + link]

    def time_to_red(self, adapter) -> np.ndarray:
        """Per slot, the time (s) until its link turns red (module notes; programs read once)."""
        if not self.slot:
            return np.zeros(0)
        sched = adapter.tls_schedule(self.tls_ids)
        out = np.empty(len(self._link))
        for s, (ti, link) in enumerate(zip(self._tls_of, self._link)):
            tls = self.tls_ids[ti]
            program, phase, remaining = sched[ti]
            progs = self._programs.get(tls)
            if progs is None or program not in progs:
                progs = self._programs[tls] = adapter.tls_programs(tls)
                progs.setdefault(program, None)  # not listed: no schedule (read once)
            phases = progs.get(program)
            if phases is None or any(link >= len(p[0]) for p in phases):
                out[s] = np.inf if phases is None else max(remaining, 0.0)
                continue
            out[s] = link_time_to_red(phases, phase, remaining, link)
        return out


def route_stop_lines(geo: NetGeometry, route: RouteWaypoints, arc: np.ndarray, slots: LinkSlots) -> StopLines:
    """The signalised stop lines ``route`` crosses, along its polyline.

    Parameters
    ----------
    geo : NetGeometry
    route : RouteWaypoints
    arc : ndarray, shape (K,)
        Positions along ``route.polyline`` of the waypoints the vehicle drives (e.g. a
        trimmed start).
    slots : LinkSlots
        Numbers the links (updated).
    """
    net = geo.sumolib_net
    poly = route.polyline
    parc = _arc(poly)
    lanes = route.segment_lanes
    used = set(lanes)
    s_line, slot = [], []
    cursor = 0
    for k in range(len(route.edges) - 1):
        lane_id, nxt = route.lanes[k], route.edges[k + 1]
        cands = [c for c in net.getLane(lane_id).getOutgoing() if c.getToLane().getEdge().getID() == nxt]
        conn = next((c for c in cands if c.getViaLaneID() and c.getViaLaneID() in used), None) or \
            next((c for c in cands if not c.getViaLaneID() and c.getToLane().getID() in used), None)
        on = [j for j in range(cursor, len(lanes)) if lanes[j] == lane_id]
        if on:
            j_end = on[0]
            while j_end + 1 < len(lanes) and lanes[j_end + 1] == lane_id:
                j_end += 1
            cursor = j_end + 1
        if conn is None or not conn.getTLSID() or conn.getTLLinkIndex() < 0:
            continue
        q = np.asarray(net.getLane(lane_id).getShape()[-1][:2], dtype=float)
        lo = max((on[0] if on else cursor) - 2, 0)
        hi = min((cursor if on else lo + 4) + 2, len(poly) - 1)
        s = project_arc(poly, parc, q, lo, max(hi, lo + 1))
        if on:
            s = min(s, float(parc[cursor]))
        s_line.append(s)
        slot.append(slots.of(conn.getTLSID(), conn.getTLLinkIndex()))
    return StopLines(arc=np.asarray(arc, dtype=float), s_line=np.asarray(s_line, dtype=float),
                     slot=np.asarray(slot, dtype=np.intp))
