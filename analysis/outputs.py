"""What a run writes next to ``summary.json``: the KPI tables as CSV, streamed as the run goes.

``steps.csv`` (one row per step), ``steps_1s.csv`` (the same aggregated per
simulated second, for long runs) and ``vehicles.csv`` (one row per vehicle); see
:mod:`analysis.kpis` for the columns.  At the end, ``waits.csv``: every vehicle at rest and why
(:mod:`analysis.waits`).

Nothing is lost on a crash: :class:`StreamingOutputs`, an observer of the loop,
appends every step's row to ``steps.csv`` and the row of every vehicle that
arrived to ``vehicles.csv``, flushing both to the operating system every
simulated second, and rewrites ``summary.json`` (``"complete": false``) every
simulated minute.  A process killed outright (SIGKILL) leaves those files as
they were at the last flush.  At the end of a run :func:`write_run_tables`
replaces them with the complete tables (every vehicle, every column).
"""

from __future__ import annotations

import csv
import json
import os
from pathlib import Path

from analysis.kpis import STEP_COLUMNS, VEHICLE_COLUMNS, per_second, run_tables, vehicle_table
from analysis.waits import waits_at_end

__all__ = ["write_run_tables", "close_observers", "write_summary", "StreamingOutputs", "STREAM_STEP_COLUMNS"]

#: Columns of the streamed ``steps.csv`` (the loop's step row; empty where a step has none).
STREAM_STEP_COLUMNS = STEP_COLUMNS + ("footprint_overlaps", "claim_violations", "min_separation_m")


def write_summary(out, summary: dict) -> None:
    """Write ``out/summary.json`` atomically (a temporary file renamed over it)."""
    out = Path(out)
    tmp = out / "summary.json.tmp"
    tmp.write_text(json.dumps(summary, indent=2, default=float))
    tmp.replace(out / "summary.json")


def _replace_csv(df, path: Path) -> None:
    tmp = path.with_name(path.name + ".tmp")
    df.to_csv(tmp, index=False)
    tmp.replace(path)


def write_run_tables(out, sim, tripinfo=None) -> dict:
    """Write the KPI tables of ``sim`` into ``out``; return the summary figures computed from them.

    Each file is written to a temporary name and renamed over the streamed one, so a crash
    while writing leaves the streamed file.

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
    waits = waits_at_end(sim)  # once: for the figures and the file
    figures, steps, vehicles = run_tables(sim, tripinfo, waits)
    _replace_csv(steps, out / "steps.csv")
    _replace_csv(per_second(steps), out / "steps_1s.csv")
    _replace_csv(vehicles, out / "vehicles.csv")
    _replace_csv(waits, out / "waits.csv")
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


class StreamingOutputs:
    """Observer of :class:`bridge.cosim.Cosim` streaming ``steps.csv``, ``vehicles.csv`` and a
    periodic ``summary.json`` while the run goes.

    Attach it after every observer that adds to the step row (e.g. the MCAP logger's
    ``logging_ms``).

    Parameters
    ----------
    out : path-like
        The run's output directory (exists).
    summary : dict
        The run's summary so far (scenario, seed, options); the periodic summary is this dict
        updated with the figures of the run so far and ``"complete": false``.
    flush_s : float
        Simulated seconds between flushes of the CSV files (at most 1 s).
    summary_s : float
        Simulated seconds between rewrites of ``summary.json``.
    """

    def __init__(self, out, summary: dict, flush_s: float = 1.0, summary_s: float = 60.0):
        if not 0 < flush_s <= 1.0:
            raise ValueError(f"StreamingOutputs.flush_s: must be in (0, 1] s, got {flush_s}")
        if not summary_s > 0:
            raise ValueError(f"StreamingOutputs.summary_s: must be > 0 s, got {summary_s}")
        self.out = Path(out)
        self.summary = summary
        self.flush_s, self.summary_s = float(flush_s), float(summary_s)
        self._steps_fh = open(self.out / "steps.csv", "w", newline="")
        self._steps = csv.DictWriter(self._steps_fh, fieldnames=list(STREAM_STEP_COLUMNS), restval="",
                                     extrasaction="ignore")
        self._steps.writeheader()
        self._veh_fh = open(self.out / "vehicles.csv", "w", newline="")
        self._veh_fh.write(",".join(VEHICLE_COLUMNS) + "\n")
        self._written: set[str] = set()
        self._next_flush = self.flush_s
        self._next_summary = self.summary_s
        self.closed = False

    def on_step(self, sim, state, decision, row) -> None:
        """Append the step's row; every ``flush_s`` the arrived vehicles' rows and a flush,
        every ``summary_s`` the summary."""
        self._steps.writerow({"edges": 0, **row})
        t_end = float(row["t_s"]) + float(sim.settings.Ts)
        if t_end + 1e-9 >= self._next_flush:
            self._next_flush += self.flush_s
            self._write_arrived(sim)
            self._steps_fh.flush()
            self._veh_fh.flush()
        if t_end + 1e-9 >= self._next_summary:
            self._next_summary += self.summary_s
            figures = run_tables(sim)[0]
            write_summary(self.out, {**self.summary, **figures, "complete": False,
                                     "written_at_s": round(t_end, 3)})

    def _write_arrived(self, sim) -> None:
        new = [r for v, r in sim.records.items() if r.arrived_s is not None and v not in self._written]
        if not new:
            return
        from analysis.halts import HaltCounter
        from controllers.classes import builtin_classes

        classes = dict(builtin_classes())
        classes.update(getattr(sim, "classes", {}))
        halts = next((o for o in getattr(sim, "observers", []) if isinstance(o, HaltCounter)), None)
        df = vehicle_table(new, {c: vc.v_max for c, vc in classes.items()}, float(sim.settings.Ts), None, halts)
        df.to_csv(self._veh_fh, index=False, header=False)
        self._written.update(r.id for r in new)

    def close(self) -> None:
        """Flush and close both files; idempotent."""
        if self.closed:
            return
        self.closed = True
        for fh in (self._steps_fh, self._veh_fh):
            fh.flush()
            os.fsync(fh.fileno())
            fh.close()
