"""The claims' body padding of a group's vehicles, looked up once per step (authority mode in SUMO).

:meth:`bridge.sumo_world.SumoWorld.claim_pads` gives the padding ``(n, 4)`` of vehicles for
waypoints ``k``; it depends on the vehicles, their waypoints and the windows of positions still
ahead of them, which move only when the world places its bodies (``world.pads_version`` counts
those moves).  A step asks for the same padding several times (current claims, requested ones,
the tube-escape check, admissions, the monitor's claims); :class:`PadMemo` keeps the last answer
per (group, waypoint offset) and asks the world again only for the rows whose waypoint changed
(a grant), or for all rows after the windows moved or the group's vehicles changed.  A world that
also tells, per row, the run of window starts the row holds for (``claim_pad_runs``) and each
vehicle's window start (``pad_windows``) is asked, after the windows moved, only for the rows whose
window start left its run: most rows of a step (a row is a maximum over the positions ahead, the
same while the one that sets it stays ahead).
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
        same = ver is not None and last is not None and last[1] is ids and len(last[2]) == n
        runs = None
        if same and last[0] == ver:
            diff = np.flatnonzero(last[2] != k)
        elif same and last[4] is not None:  # the windows moved: the rows whose start left its run
            j0 = self.world.pad_windows(ids)
            diff = np.flatnonzero((last[2] != k) | (j0 < last[4][0]) | (j0 > last[4][1]))
        else:
            diff = None
        if diff is None:
            pads, runs = self._ask(ids, k)
            self.asked += n
        elif not len(diff):  # every row still holds: the same (read-only) arrays
            self.served += n
            if last[0] == ver:
                return last[3]
            pads, runs = last[3], last[4]
        else:
            got, got_runs = self._ask([ids[i] for i in diff.tolist()], k[diff])
            pads = last[3].copy()
            pads[diff] = got
            if last[4] is not None and got_runs is not None:
                runs = (last[4][0].copy(), last[4][1].copy())
                runs[0][diff], runs[1][diff] = got_runs
            self.asked += len(diff)
            self.served += n - len(diff)
        if ver is not None:
            pads.setflags(write=False)  # handed out again: nobody may change it
            self._last[(key, offset)] = (ver, ids, k.copy(), pads, runs)
        return pads

    def _ask(self, ids, k) -> tuple[np.ndarray, tuple | None]:
        """``(pads (n, 4), runs)``: ``runs`` the rows' ``(j_lo, j_hi)`` when the world tells them."""
        if hasattr(self.world, "claim_pad_runs") and hasattr(self.world, "pad_windows"):
            got = self.world.claim_pad_runs(ids, k)
            if got is not None:
                return np.asarray(got[0], dtype=float).reshape(len(ids), 4), (got[1], got[2])
        got = self.world.claim_pads(ids, k)
        return (np.zeros((len(ids), 4)) if got is None
                else np.asarray(got, dtype=float).reshape(len(ids), 4)), None
