"""Typed, validated settings of the traffic manager."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

__all__ = ["TMSettings", "TMSettingsError", "POLICIES", "CHECKS", "default_check"]

#: Valid values of :attr:`TMSettings.policy`.
POLICIES = ("greedy", "optimal")
#: Valid values of :attr:`TMSettings.check`.
CHECKS = ("union", "timed")


def default_check(controller: str) -> str:
    """The tube check a run uses when none is given: ``timed`` with the movement-authority controller
    (its reach-tightened claims are compared step k against step k, design.md §7), ``union`` with the
    paper's (condition (9); with its nested centred sets both checks decide alike)."""
    return "timed" if controller == "authority" else "union"


class TMSettingsError(ValueError):
    """Invalid traffic-manager setting; the message names the field and the valid values."""


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


@dataclass(frozen=True)
class TMSettings:
    """Settings of the :class:`~tm.manager.TrafficManager`.

    Parameters
    ----------
    policy : {"optimal", "greedy"}
        How the set of stopped requesters is chosen.  ``optimal`` maximises
        the total weight of granted requests exactly (weights grow with the
        time a request has waited, see ``starvation_horizon``); ``greedy`` is
        the paper's (P1)-(P3) rule extended to hold regions (design 3b).
    check : {"union", "timed"}
        Tube comparison.  ``union``: the paper's condition (9), one polygon
        per claim.  ``timed``: design 3d, claims compared at the same future
        step ``k`` only.
    seed : int
        Seed of the random generator that breaks ties (``greedy``: equal
        degrees; ``optimal``: equal weights).  Same seed and same inputs give
        the same decisions.
    starvation_horizon : int
        ``H`` in the weight ``w_i = 1 + waited_i / H`` of a request denied
        ``waited_i`` consecutive steps (``optimal`` only).  Among requests
        with equal waits the fewest stops are chosen; a request in conflict
        with ``m`` others that keep being granted outweighs them after about
        ``(m - 1) H`` denied steps.
    exhaustive_max : int
        Components of the requester constraint graph with at most this many
        free requesters are solved by exhaustive enumeration (``2^n`` rows,
        vectorised); larger ones by a MILP (HiGHS).  1 <= value <= 16.
    milp_time_limit : float
        Time limit (s) of one MILP; on timeout the best feasible point found
        is used, or the ``greedy`` rule on that component if none is found.
    verify : bool
        After every decision check independently that the resulting claims
        are pairwise disjoint and raise :class:`~tm.manager.InvariantError`
        otherwise (debug; costs an all-pairs broad phase per decision).
    """

    policy: Literal["greedy", "optimal"] = "optimal"
    check: Literal["union", "timed"] = "union"
    seed: int = 0
    starvation_horizon: int = 50
    exhaustive_max: int = 14
    milp_time_limit: float = 1.0
    verify: bool = False

    def __post_init__(self) -> None:
        if self.policy not in POLICIES:
            raise TMSettingsError(f"TMSettings.policy: must be one of {POLICIES}, got {self.policy!r}")
        if self.check not in CHECKS:
            raise TMSettingsError(f"TMSettings.check: must be one of {CHECKS}, got {self.check!r}")
        if not _is_int(self.seed) or self.seed < 0:
            raise TMSettingsError(f"TMSettings.seed: must be an integer >= 0, got {self.seed!r}")
        if not _is_int(self.starvation_horizon) or self.starvation_horizon < 1:
            raise TMSettingsError("TMSettings.starvation_horizon: must be an integer >= 1 (steps), "
                                  f"got {self.starvation_horizon!r}")
        if not _is_int(self.exhaustive_max) or not 1 <= self.exhaustive_max <= 16:
            raise TMSettingsError("TMSettings.exhaustive_max: must be an integer in [1, 16], "
                                  f"got {self.exhaustive_max!r}")
        if (not isinstance(self.milp_time_limit, (int, float)) or isinstance(self.milp_time_limit, bool)
                or not self.milp_time_limit > 0):
            raise TMSettingsError("TMSettings.milp_time_limit: must be a number > 0 (s), "
                                  f"got {self.milp_time_limit!r}")
        if not isinstance(self.verify, bool):
            raise TMSettingsError(f"TMSettings.verify: must be True or False, got {self.verify!r}")
