"""The movement-authority junction gate's oriented boxes: corridors, exit slots and corridors ahead.

World (axis-aligned) boxes of two lanes side by side overlap on a road that does not run along an
axis; where the gate's world boxes meet, :class:`tm.authority_gate.AuthorityGate` asks the oriented
boxes, padded by SUMO's body reach, whether they really do (its notes say where each rule needs
them).  :class:`GateBoxes` keeps them, per route key ``(vehicle, zone, waypoint[, cut])`` of
:meth:`tm.authority_gate.AuthorityGate.route_through`:

* a corridor's boxes (:meth:`AuthorityReach.corridor_polygons`, one per waypoint and heading), for
  through movements only (headings within the gate's ``oriented_turn_max_deg``), cut with the corridor
  (:meth:`cut`), and whether two corridors meet (:meth:`corridors_meet`, cached per pair);
* an exit slot's padded hold box (:meth:`slot_free`);
* a corridor without the box at its current waypoint (:meth:`ahead`).

Each cache starts over past a size bound (stale keys): what it forgot is taken as world boxes
(corridors, slots) or computed again (the corridor ahead).  Pure numpy, no simulator.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from tm.authority_reach import AuthorityReach
from tm.boxes import polygon_sets_meet, polygons_meet
from tm.junctions import JunctionFleet

__all__ = ["GateBoxes"]

#: Entries a cache holds before it starts over.
_MAX_KEYS = 100_000


class GateBoxes:
    """Oriented boxes of the gate's corridors and exit slots (module notes).

    Parameters
    ----------
    classes : mapping of str to AuthorityReach
    """

    def __init__(self, classes: Mapping[str, AuthorityReach]):
        self.classes = classes
        #: route key -> the corridor's oriented boxes, or None for a turn
        self.corridor: dict = {}
        self._meet: dict = {}    # (key, key) -> whether the oriented boxes meet
        #: route key -> the exit slot's padded hold box as oriented boxes
        self.slot: dict = {}
        self._ahead: dict = {}   # route key -> its corridor ahead as oriented boxes
        #: over the run: exit slots whose world box met another vehicle's claims but whose oriented box did
        #: not (:meth:`slot_free`)
        self.slots_freed = 0

    def note_route(self, key, cls: AuthorityReach, W: np.ndarray, H: np.ndarray, idx: np.ndarray, nxt: np.ndarray,
                   pad: np.ndarray, exits: bool, turn_max_deg: float) -> None:
        """Keep route ``key``'s corridor boxes at waypoints ``idx`` (headings ``H[idx]``, ``H[nxt]``,
        padding ``pad`` (len(idx), 4)) if it goes through (its headings spread over at most
        ``turn_max_deg``; a turn keeps none), and its exit slot's at ``idx[-1]`` if it ``exits`` the
        guard."""
        if exits:
            last, n1 = int(idx[-1]), int(nxt[-1])
            if len(self.slot) > _MAX_KEYS:
                self.slot.clear()
            self.slot[key] = cls.hold_polygons(W[last:last + 1], pad[-1:], H[last:last + 1], H[n1:n1 + 1])
        turn = np.angle(np.exp(1j * (np.r_[H[idx], H[nxt]] - H[idx[0]])))
        if len(self.corridor) > _MAX_KEYS:
            self.corridor.clear()
        self.corridor[key] = (cls.corridor_polygons(W[idx], pad, H[idx], H[nxt])
                              if np.ptp(turn) <= np.deg2rad(turn_max_deg) else None)

    def cut(self, key, cut_key, i0: int, m: int) -> None:
        """Corridor ``key`` (``m`` waypoints) cut to its boxes from waypoint ``i0`` on, kept as
        ``cut_key`` (boxes come per heading: ``[0, m)`` arriving, ``[m, 2m)`` leaving)."""
        polys = self.corridor.get(key)
        if polys is not None:
            self.corridor[cut_key] = np.concatenate([polys[i0:m], polys[m + i0:]])

    def corridors_meet(self, key_a, key_b) -> bool:
        """Whether two corridors' oriented boxes meet (separating axes, touching counts), cached per
        pair; True when either keeps none (a turn, or dropped with the cache): its world boxes stand."""
        pa, pb = self.corridor.get(key_a), self.corridor.get(key_b)
        if pa is None or pb is None:
            return True
        pair = (key_a, key_b)
        hit = self._meet.get(pair)
        if hit is None:
            if len(self._meet) > 2 * _MAX_KEYS:
                self._meet.clear()
            hit = self._meet[pair] = polygons_meet(pa, pb)
        return hit

    def slot_free(self, fleet: JunctionFleet, keys: list, rows: np.ndarray) -> np.ndarray:
        """Of exit slots ``keys[i]`` whose world box meets row ``rows[i]``'s claims, those whose padded hold
        box misses that vehicle's claims as oriented boxes (:attr:`JunctionFleet.claim_polygons`), all
        pairs at once; False where either is unknown."""
        out = np.zeros(len(rows), dtype=bool)
        if fleet.claim_polygons is None or not len(rows):
            return out
        mine = [self.slot.get(key) for key in keys]
        pairs = np.flatnonzero([m is not None for m in mine])
        if not len(pairs):
            return out
        P = np.concatenate([mine[t] for t in pairs.tolist()])
        p_count = np.array([len(mine[t]) for t in pairs.tolist()], dtype=np.intp)
        uniq, inv = np.unique(rows[pairs], return_inverse=True)
        Q, q_owner = fleet.claim_polygons(uniq)          # each other vehicle's boxes once
        cnt = np.bincount(q_owner, minlength=len(uniq))
        free = ~polygon_sets_meet(P, np.cumsum(p_count) - p_count, p_count, Q, (np.cumsum(cnt) - cnt)[inv], cnt[inv])
        out[pairs[free]] = True
        self.slots_freed += int(free.sum())
        return out

    def ahead(self, fleet: JunctionFleet, row: int, key, n: int) -> np.ndarray:
        """Row ``row``'s corridor (route key ``key``, ``n`` waypoints from its current one) without the
        box at its current waypoint where more follow, as oriented boxes padded by SUMO's body reach
        (cached per key)."""
        found = self._ahead.get(key)
        if found is None:
            W, H, k = fleet.route(row)
            idx = np.arange(k + (n > 1), k + n)
            nxt = np.minimum(idx + 1, len(H) - 1)
            if len(self._ahead) > _MAX_KEYS:
                self._ahead.clear()
            found = self._ahead[key] = self.classes[fleet.family[row]].corridor_polygons(
                W[idx], fleet.pad(row, idx), H[idx], H[nxt])
        return found
