"""What a run writes next to ``summary.json``: the KPI tables as CSV.

``steps.csv`` (one row per step), ``steps_1s.csv`` (the same aggregated per
simulated second, for long runs) and ``vehicles.csv`` (one row per vehicle); see
:mod:`analysis.kpis` for the columns.
"""

from __future__ import annotations

from pathlib import Path

from analysis.kpis import per_second, run_tables

__all__ = ["write_run_tables", "close_observers"]


def write_run_tables(out, sim, tripinfo=None) -> dict:
    """Write the KPI tables of ``sim`` into ``out``; return the summary figures computed from them.

    Parameters
    ----------
    out : path-like
        The run's output directory.
    sim : bridge.cosim.Cosim
        A finished or partial run.
    tripinfo : path-like, optional
        SUMO's tripinfo of the run (for ``sumo_time_loss_s``), if any.

    Returns
    -------
    dict
        :func:`analysis.kpis.run_tables`'s figures.
    """
    out = Path(out)
    figures, steps, vehicles = run_tables(sim, tripinfo)
    steps.to_csv(out / "steps.csv", index=False)
    per_second(steps).to_csv(out / "steps_1s.csv", index=False)
    vehicles.to_csv(out / "vehicles.csv", index=False)
    return figures


def close_observers(observers) -> list[str]:
    """Close every observer that can be closed; return the errors' messages (never raises)."""
    errors = []
    for obs in observers:
        close = getattr(obs, "close", None)
        if close is None:
            continue
        try:
            close()
        except Exception as exc:  # a log that cannot be finished must not lose the run's tables
            errors.append(f"{type(obs).__name__}: {type(exc).__name__}: {exc}")
    return errors
