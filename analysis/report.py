"""``muvsim report RUN_DIR [--vs OTHER_RUN_DIR]``: KPI statistics of a run, or of two runs side by side.

A run directory is what ``muvsim run --out DIR`` wrote.  For a muvsim run the
per-vehicle table is its ``vehicles.csv``; for a run by SUMO's own drivers
(``--baseline sumo``) it is built from ``tripinfo.xml``
(:func:`analysis.kpis.baseline_vehicle_table`).  Statistics of delay, stops,
time stopped and travel time are taken over the vehicles that arrived.

Two runs are compared only when they ran the same demand: the same vehicle ids
with the same requested departures.  SUMO's tripinfo lists only finished trips,
so against a baseline run the check is that every baseline trip is in the other
run's demand with the same requested departure.

Stops come in two definitions (see :mod:`analysis.kpis`): ``halt_*`` (speed at
most 0.1 m/s, SUMO's waiting; comparable with a baseline) and ``stop_*``
(denied TM requests; muvsim only).  Statistics over arrived vehicles favour the
run that lands fewer vehicles (the slowest have not arrived): read them with
``vehicles_arrived``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.kpis import baseline_vehicle_table, read_tripinfo, timing_means

__all__ = ["DemandMismatch", "RunData", "load_run", "check_same_demand", "statistics", "report_table",
           "format_report"]

#: Per-vehicle columns summarised by mean, median and 95th percentile.
DISTRIBUTIONS = ("delay_s", "halt_episodes", "time_halted_s", "stop_episodes", "time_stopped_s", "travel_time_s",
                 "admission_delay_s")

#: Departures closer than this are the same (tripinfo has 2 decimals).
DEPART_TOL_S = 0.051


class DemandMismatch(ValueError):
    """Two runs that did not run the same demand cannot be compared."""


@dataclass(frozen=True)
class RunData:
    """A run directory loaded for reporting.

    Attributes
    ----------
    path : Path
    summary : dict
        ``summary.json``.
    vehicles : DataFrame
        Per-vehicle table (:data:`analysis.kpis.VEHICLE_COLUMNS`).
    baseline : bool
        Driven by SUMO itself: ``vehicles`` holds finished trips only.
    """

    path: Path
    summary: dict
    vehicles: pd.DataFrame
    baseline: bool

    @property
    def label(self) -> str:
        return f"{self.path.name} ({'sumo' if self.baseline else 'muvsim'})"


def load_run(path) -> RunData:
    """Load a run directory; raise ``FileNotFoundError`` naming what is missing."""
    from controllers.classes import builtin_classes

    path = Path(path)
    sfile = path / "summary.json"
    if not sfile.exists():
        raise FileNotFoundError(f"{path}: no summary.json (not a muvsim run directory)")
    summary = json.loads(sfile.read_text())
    baseline = summary.get("baseline") == "sumo"
    if baseline and (path / "vehicles.csv").exists():  # finished trips only, times from the window's begin
        vehicles = pd.read_csv(path / "vehicles.csv", dtype={"id": str})
    elif baseline:
        ti = path / "tripinfo.xml"
        if not ti.exists():
            raise FileNotFoundError(f"{path}: a --baseline sumo run without tripinfo.xml")
        vehicles = baseline_vehicle_table(read_tripinfo(ti), {c: vc.v_max for c, vc in builtin_classes().items()})
    else:
        vfile = path / "vehicles.csv"
        if not vfile.exists():
            raise FileNotFoundError(f"{path}: no vehicles.csv (a single-vehicle or failed run has none)")
        vehicles = pd.read_csv(vfile, dtype={"id": str})
    return RunData(path, summary, vehicles, baseline)


def check_same_demand(a: RunData, b: RunData) -> None:
    """Raise :class:`DemandMismatch` with a clear message when ``a`` and ``b`` ran different demands."""
    da = a.vehicles.set_index("id")["departure_s"]
    db = b.vehicles.set_index("id")["departure_s"]
    ia, ib = set(da.index), set(db.index)
    problems = []
    if a.baseline and b.baseline:
        extra_a, extra_b = set(), set()
    elif a.baseline:
        extra_a, extra_b = ia - ib, set()
    elif b.baseline:
        extra_a, extra_b = set(), ib - ia
    else:
        extra_a, extra_b = ia - ib, ib - ia
    if extra_a:
        problems.append(f"{len(extra_a)} vehicle(s) only in {a.path} (e.g. {sorted(extra_a)[:3]})")
    if extra_b:
        problems.append(f"{len(extra_b)} vehicle(s) only in {b.path} (e.g. {sorted(extra_b)[:3]})")
    common = sorted(ia & ib)
    if not common and not problems:
        problems.append("no vehicle in common")
    if common:
        diff = (da.loc[common] - db.loc[common]).abs()
        bad = diff[diff > DEPART_TOL_S]
        if len(bad):
            v = bad.index[0]
            problems.append(f"{len(bad)} vehicle(s) with different requested departures "
                            f"(e.g. {v}: {da[v]:.2f} s vs {db[v]:.2f} s)")
    if problems:
        raise DemandMismatch(f"runs differ in demand, refusing to compare {a.path} with {b.path}: "
                             + "; ".join(problems))


def statistics(run: RunData) -> pd.Series:
    """The report's figures of one run, indexed by ``metric.statistic``."""
    v = run.vehicles
    arrived = v[v["arrival_s"].notna()]
    out = {}
    for c in DISTRIBUTIONS:
        x = arrived[c].dropna().astype(float)
        out[f"{c}.mean"] = float(x.mean()) if len(x) else np.nan
        out[f"{c}.median"] = float(x.median()) if len(x) else np.nan
        out[f"{c}.p95"] = float(np.percentile(x, 95)) if len(x) else np.nan
    sim_s = run.summary.get("simulated_s") or np.nan
    out["vehicles_arrived.count"] = float(len(arrived))
    out["throughput_vph.value"] = float(len(arrived)) * 3600.0 / sim_s if sim_s == sim_s and sim_s else np.nan
    s = run.summary
    out["collisions_world.pairs"] = float(s.get("collisions_sumo", s.get("collisions_world", np.nan)))
    out["collisions_geometric.pair_steps"] = float(s["collisions_geometric"]) if "collisions_geometric" in s \
        else np.nan
    steps = run.path / "steps.csv"
    if not run.baseline and steps.exists():  # wall milliseconds per step (machine-dependent)
        for c, v in timing_means(pd.read_csv(steps)).items():
            out[f"{c}.mean"] = v
    return pd.Series(out, dtype=float)


def report_table(a: RunData, b: RunData | None = None) -> pd.DataFrame:
    """One run's statistics, or two runs' with ``difference`` (a − b) and ``ratio`` (a / b).

    Returns
    -------
    DataFrame
        Columns ``metric, statistic, run`` (+ ``vs, difference, ratio``).
    """
    sa = statistics(a)
    if b is not None:
        check_same_demand(a, b)
        sb = statistics(b)
        keys = list(sa.index) + [k for k in sb.index if k not in sa.index]
        sa, sb = sa.reindex(keys), sb.reindex(keys)
    df = pd.DataFrame({"metric": [k.split(".")[0] for k in sa.index],
                       "statistic": [k.split(".")[1] for k in sa.index], "run": sa.values})
    if b is not None:
        df["vs"] = sb.values
        df["difference"] = df["run"] - df["vs"]
        with np.errstate(divide="ignore", invalid="ignore"):
            df["ratio"] = np.where(df["vs"] != 0, df["run"] / df["vs"].where(df["vs"] != 0), np.nan)
    return df


def format_report(df: pd.DataFrame, a: RunData, b: RunData | None = None) -> str:
    """The table as text for the terminal."""
    head = f"run: {a.path}  [{a.label}]"
    if b is not None:
        head += f"\nvs:  {b.path}  [{b.label}]"
    note = ("statistics over arrived vehicles; halt = speed <= 0.1 m/s (as SUMO's waiting), stop = denied TM "
            "request;\ndifference = run - vs, ratio = run / vs")
    return f"{head}\n{note}\n{df.to_string(index=False, float_format=lambda x: f'{x:.3f}')}"
