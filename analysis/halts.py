"""Halts measured like SUMO's ``waitingTime`` / ``waitingCount``: speed at most 0.1 m/s.

The traffic manager's stops (denied requests, :mod:`analysis.kpis`) miss the
vehicles held back by a zone token (their requests are withheld, not denied)
and have no counterpart for SUMO's own drivers.  :class:`HaltCounter` is a
co-simulation observer that counts, per vehicle, the steps after which its
speed is at most ``threshold_mps`` and the episodes of such steps -- the
definition of SUMO's tripinfo, so muvsim and ``--baseline sumo`` compare.
Standing still at the last waypoint (a vehicle arrives once its index is 0
there) is not a halt: SUMO's vehicles do not stop at the end of their route.
"""

from __future__ import annotations

import numpy as np

__all__ = ["HaltCounter", "SUMO_HALT_MPS"]

#: SUMO's waiting threshold (m/s).
SUMO_HALT_MPS = 0.1


class HaltCounter:
    """Observer counting halts per vehicle.

    Parameters
    ----------
    threshold_mps : float
        A vehicle halts in a step after which its speed is at most this.

    Attributes
    ----------
    steps, episodes : dict of str to int
        Halted steps and halt episodes per vehicle id (absent: never halted).
    """

    def __init__(self, threshold_mps: float = SUMO_HALT_MPS):
        self.threshold_mps = float(threshold_mps)
        self.steps: dict[str, int] = {}
        self.episodes: dict[str, int] = {}
        self._halted: set[str] = set()

    def on_step(self, sim, state, decision, row) -> None:
        """Update the counts from the vehicles' states after the step."""
        now = set()
        for g in sim.groups.values():
            if not g.ids:
                continue
            speed = np.linalg.norm(g.X[:, 2:4], axis=1)
            last = g.at_last
            for vid in np.asarray(g.ids, dtype=object)[(speed <= self.threshold_mps) & ~last]:
                now.add(vid)
                self.steps[vid] = self.steps.get(vid, 0) + 1
                if vid not in self._halted:
                    self.episodes[vid] = self.episodes.get(vid, 0) + 1
        self._halted = now
