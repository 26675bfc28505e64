"""Numbers as a reader wants them: rounded to their meaning, never ``None``.

One rule for every table muvsim prints (the closing table of ``muvsim run``,
``muvsim report``): the unit is in the name (``_s`` seconds, ``_m`` metres,
``_ms`` wall milliseconds, ``_vph`` vehicles per hour, ``_mps`` m/s), and the
name decides the rounding -- seconds to 0.1, metres to 0.01, wall
milliseconds to 0.001, vehicles per hour to 1, ratios (``ratio``, ``rtf``) to
0.01, counts as integers.  The files (``summary.json``, ``report.csv``) keep
full precision; only what is printed is rounded.
"""

from __future__ import annotations

import math

__all__ = ["fmt", "decimals_for", "COUNT_STATISTICS"]

#: Statistics whose value is a count when the metric is one (means of counts are not).
COUNT_STATISTICS = ("count", "pairs", "pair_steps", "value_count")

_COUNT_NAMES = ("vehicles", "vehicles_total", "vehicles_arrived", "steps", "collisions_sumo", "collisions_world",
                "collisions_geometric", "invariant_violations", "constraint_violations", "stop_commands",
                "stop_episodes", "halt_episodes", "denials", "seed", "vehicles_censored", "vehicles_paired",
                "demand_seed", "red_violations", "signal_withheld", "pedestrian_conflicts", "pedestrian_withheld",
                "crossing_withheld",
                "persons_arrived", "vehicles_undrivable", "claim_violations", "footprint_overlaps", "zones",
                "zones_ignored", "junction_tokens", "junction_given_back", "junction_withheld",
                "junction_chain_revoked", "junction_ordered", "vehicles_over_limit", "stopped_at_end",
                "gridlocked_at_end", "wait_cycles")


def decimals_for(name: str, statistic: str = "") -> int:
    """Decimals a figure named ``name`` (with ``statistic``, e.g. ``mean``) is printed with."""
    if name.endswith("_ms"):
        return 3
    if name.endswith("_m") or name.endswith("_mps"):
        return 2
    if name.endswith("_s"):
        return 1
    if name.endswith("_vph"):
        return 0
    if name in ("rtf", "ratio") or name.endswith("_ratio") or statistic.startswith("ratio"):
        return 2
    if name in _COUNT_NAMES or name.endswith("_count"):
        return 0 if statistic in ("", "count", "pairs", "pair_steps", "total") else 2
    return 2


def fmt(value, name: str = "", statistic: str = "", missing: str = "-") -> str:
    """``value`` as text for a figure named ``name``; ``missing`` for None / NaN."""
    if value is None:
        return missing
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, str):
        return value
    try:
        v = float(value)
    except (TypeError, ValueError):
        return str(value)
    if math.isnan(v):
        return missing
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    d = decimals_for(name, statistic)
    if d == 0:
        return f"{int(round(v))}"
    return f"{v:.{d}f}"
