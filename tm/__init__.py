"""muvsim traffic manager: Go/Stop decisions that keep all vehicles' tubes disjoint.

Modules: :mod:`tm.settings` (TMSettings), :mod:`tm.geometry` (vectorised
convex-polygon geometry), :mod:`tm.families` (position-set families),
:mod:`tm.claims` (claims and their conflict test), :mod:`tm.selection`
(greedy and optimal Go/Stop selection), :mod:`tm.manager` (TrafficManager,
FleetState, Decision, paper_decision), :mod:`tm.monitor` (runtime monitor),
:mod:`tm.junctions` (the liveness layer: Zone, JunctionGate; junction tokens,
corridors, exit slots) over the box joins of :mod:`tm.boxes`.
"""

from tm.claims import Claims, claim_conflicts, conflicting_pairs
from tm.families import FamilyError, FamilyTable, build_family_table
from tm.junctions import ClassReach, JunctionFleet, JunctionGate, Zone
from tm.manager import Decision, FleetState, InvariantError, Timings, TrafficManager, paper_decision
from tm.monitor import Monitor, MonitorStep
from tm.settings import TMSettings, TMSettingsError

__all__ = [
    "TMSettings", "TMSettingsError", "TrafficManager", "FleetState", "Decision", "Timings",
    "InvariantError", "paper_decision", "Claims", "claim_conflicts", "conflicting_pairs",
    "FamilyTable", "FamilyError", "build_family_table", "Monitor", "MonitorStep",
    "Zone", "ClassReach", "JunctionFleet", "JunctionGate",
]
