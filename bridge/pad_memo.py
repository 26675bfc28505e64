"""The claims' body padding of a group's vehicles, looked up once per step (authority mode in SUMO).

:meth:`bridge.sumo_world.SumoWorld.claim_pads` gives the padding ``(n, 4)`` of vehicles for
waypoints ``k``; it depends on the vehicles, their waypoints and the windows of positions still
ahead of them, which move only when the world places its bodies (``world.pads_version`` counts
those moves).  A step asks for the same padding several times (current claims, requested ones,
the tube-escape check, admissions, the monitor's claims); :class:`PadMemo` keeps the last answer
per (group, waypoint offset) and asks the world again only for the rows whose waypoint changed
(a grant), or for all rows after the windows moved or the group's vehicles changed.
"""

from __future__ import annotations

import numpy as np

__all__ = ["PadMemo"]


class PadMemo:
    """Last padding per ``(key, offset)``: ``(version, ids, k, pads)``; see the module docstring.

    Parameters
    ----------
    world
        Has ``claim_pads(ids, k) -> (n, 4) | None``; with ``pads_version`` (an int that changes
        whenever an answer of ``claim_pads`` may change for the same ids and ``k``) answers are
        kept, without it every lookup asks the world.
    """

    def __init__(self, world):
        self.world = world
        self._last: dict = {}
        #: rows asked of the world / rows served from the memo, over the run
        self.asked = 0
        self.served = 0

    def pads(self, key, ids: list, k: np.ndarray, offset: int = 0) -> np.ndarray:
        """Padding ``(len(ids), 4)`` of vehicles ``ids`` (a group's id list, the same object while
        the group's vehicles do not change) for waypoints ``k`` (``(n,)``; already offset and
        clipped by the caller); zeros where the world has none."""
        k = np.asarray(k, dtype=np.intp)
        n = len(ids)
        ver = getattr(self.world, "pads_version", None)
        last = self._last.get((key, offset))
        if ver is not None and last is not None and last[0] == ver and last[1] is ids and len(last[2]) == n:
            diff = np.flatnonzero(last[2] != k)
            if not len(diff):
                self.served += n
                return last[3]
            got = self._ask([ids[i] for i in diff.tolist()], k[diff])
            pads = last[3].copy()
            pads[diff] = got
            self.asked += len(diff)
            self.served += n - len(diff)
        else:
            pads = self._ask(ids, k)
            self.asked += n
        if ver is not None:
            pads.setflags(write=False)  # handed out again: nobody may change it
            self._last[(key, offset)] = (ver, ids, k.copy(), pads)
        return pads

    def _ask(self, ids, k) -> np.ndarray:
        got = self.world.claim_pads(ids, k)
        return np.zeros((len(ids), 4)) if got is None else np.asarray(got, dtype=float).reshape(len(ids), 4)
