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

from collections import Counter

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
        self.steps: Counter[str] = Counter()
        self.episodes: Counter[str] = Counter()
        self._halted: set[str] = set()

    def on_step(self, sim, state, decision, row) -> None:
        """Update the counts from the vehicles' states after the step."""
        now: set[str] = set()
        for g in sim.groups.values():
            if not g.ids:
                continue
            halted = (np.hypot(g.X[:, 2], g.X[:, 3]) <= self.threshold_mps) & ~g.at_last
            now.update(g.ids[i] for i in np.flatnonzero(halted))
        self.steps.update(now)                   # counted in C
        self.episodes.update(now - self._halted)
        self._halted = now
