"""The run's safety verdict: every safety counter of ``summary.json`` and whether any fired.

A run whose counters are all zero is ``safe``; any non-zero counter makes the
summary say ``"safe": false`` and list the counters that fired in
``safety_violations`` (``muvsim run`` then exits with :data:`UNSAFE_EXIT`).
What each counter checks (see ``SAFETY.md``):

``collisions_sumo``
    unique vehicle pairs SUMO itself reported colliding (SUMO runs only).
``collisions_world``
    unique pairs the world adapter reported (SUMO's collisions in a SUMO run).
``collisions_geometric``
    pair-steps of overlapping footprints, summed from ``steps.csv``.
``footprint_overlaps``
    the same pair-steps as totalled by the runtime monitor itself (a cross-check).
``claim_violations``
    pair-steps of conflicting claims after a decision (the TM's invariant).
``invariant_violations``
    vehicle-steps whose membership index did not strictly decrease (nor stay 0),
    plus the claim violations (the tube invariant as a whole).
``constraint_violations``
    vehicle-steps with a state outside the class's state constraints.
``pedestrian_conflicts``
    unique (vehicle, person) pairs whose footprint and body (a disk, ``tm.pedestrians``) met
    after a SUMO step, persons' positions read from SUMO (SUMO runs only).
``tube_escapes``
    vehicle-steps (movement-authority mode) whose position ``x(t+1)`` left the position part
    of its claim ``S_1(t)`` after the decision (reach-tightened claims).
``pose_mismatches``
    vehicle-steps whose front SUMO placed farther than ``POSE_TOL_M`` from the front muvsim
    pushed, or off every lane (SUMO runs only): SUMO then judges a body muvsim did not plan, or
    none (``bridge.sumo_body``).
``body_window_exits``
    vehicle-steps (movement-authority mode) whose position lay beyond the stretch of its
    waypoint's frame for which SUMO's body padding was computed (``bridge.sumo_body.AHEAD_M``).
``red_violations``
    stop lines a front bumper crossed while their link was red (``tm.signals``).  Judged when
    the run obeyed the lights (``options.signals`` not ``ignore``): with ``--signals ignore``
    (the TM-only, AIM-style mode) passing reds is the mode's point, so the counter is reported
    but does not make the run unsafe.
"""

from __future__ import annotations

__all__ = ["SAFETY_COUNTERS", "SIGNAL_COUNTERS", "UNSAFE_EXIT", "verdict"]

#: Every safety counter a summary may hold, in the order reports list them.
SAFETY_COUNTERS = ("collisions_sumo", "collisions_world", "collisions_geometric", "footprint_overlaps",
                   "claim_violations", "invariant_violations", "constraint_violations", "pedestrian_conflicts",
                   "tube_escapes", "pose_mismatches", "body_window_exits", "red_violations")

#: Counters judged only when the run obeyed the traffic lights (``options.signals`` != ``ignore``).
SIGNAL_COUNTERS = ("red_violations",)

#: Exit code of ``muvsim run`` when a complete run's safety counters fired.
UNSAFE_EXIT = 3


def verdict(summary: dict) -> dict:
    """``{"safe": bool, "safety_violations": {counter: count}}`` of a summary's counters.

    Counters missing from ``summary`` (or None) are not judged, nor :data:`SIGNAL_COUNTERS`
    when ``summary["options"]["signals"]`` is ``"ignore"``.
    """
    ignore = (summary.get("options") or {}).get("signals") == "ignore"
    fired = {k: int(summary[k]) for k in SAFETY_COUNTERS
             if summary.get(k) and not (ignore and k in SIGNAL_COUNTERS)}
    return {"safe": not fired, "safety_violations": fired}
