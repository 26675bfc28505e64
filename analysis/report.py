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
(denied TM requests; muvsim only).  Statistics over each run's own arrived
vehicles favour the run that lands fewer vehicles (the slowest have not
arrived), so two runs are compared like with like (:func:`comparison_table`):
vehicle by vehicle over the vehicles both landed, and over the whole demand
with unfinished vehicles censored at their time so far.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.kpis import baseline_vehicle_table, read_tripinfo, timing_means

__all__ = ["DemandMismatch", "RunData", "load_run", "check_same_demand", "statistics", "report_table",
           "comparison_table", "whole_demand", "arrived_sets_warning", "format_report", "report_path",
           "format_summary"]

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
    total = run.summary.get("vehicles_total", run.summary.get("vehicles"))
    out["vehicles_total.count"] = float(total) if total is not None else (np.nan if run.baseline else float(len(v)))
    out["vehicles_arrived.count"] = float(len(arrived))
    out["throughput_vph.value"] = float(len(arrived)) * 3600.0 / sim_s if sim_s == sim_s and sim_s else np.nan
    s = run.summary
    out["collisions_sumo.pairs"] = float(s.get("collisions_sumo", s.get("collisions_world", np.nan)))
    out["collisions_geometric.pair_steps"] = float(s["collisions_geometric"]) if "collisions_geometric" in s \
        else np.nan
    steps = run.path / "steps.csv"
    if not run.baseline and steps.exists():  # wall milliseconds per step (machine-dependent)
        for c, v in timing_means(pd.read_csv(steps)).items():
            out[f"{c}.mean"] = v
    return pd.Series(out, dtype=float)


def report_table(a: RunData, b: RunData | None = None) -> pd.DataFrame:
    """One run's statistics, or two runs compared.

    Returns
    -------
    DataFrame
        One run: columns ``metric, statistic, run``, each statistic over the run's
        arrived vehicles (:func:`statistics`).  Two runs: :func:`comparison_table`.
    """
    if b is not None:
        return comparison_table(a, b)
    sa = statistics(a)
    return pd.DataFrame({"metric": [k.split(".")[0] for k in sa.index],
                         "statistic": [k.split(".")[1] for k in sa.index], "run": sa.values})


#: Per-vehicle figures compared vehicle by vehicle over the vehicles both runs landed.
PAIRED = ("travel_time_s", "delay_s", "time_halted_s", "halt_episodes")

#: Arrived sets differing by more than this share (of the vehicles either run landed) get a warning.
ARRIVED_DIFFER_SHARE = 0.05


def _stats3(x) -> tuple[float, float, float]:
    x = np.asarray(pd.Series(x).dropna(), dtype=float)
    if not len(x):
        return np.nan, np.nan, np.nan
    return float(x.mean()), float(np.median(x)), float(np.percentile(x, 95))


def whole_demand(a: RunData, b: RunData) -> pd.DataFrame:
    """Every vehicle of the demand with its journey in both runs, unfinished ones censored.

    ``journey_time_s`` is arrival − requested departure (waiting to depart included); a
    vehicle that has not arrived counts with its time so far (end of its run − requested
    departure, 0 if it was not yet due) and is marked in ``censored_run`` / ``censored_vs``.  ``delay_s`` is the
    journey minus free flow (from whichever table has the vehicle's route; a lower bound of
    nothing for a censored vehicle, so the report compares journeys only).  The demand
    is the union of both tables' ids (a baseline's table has finished trips only).
    """
    va, vb = a.vehicles.set_index("id"), b.vehicles.set_index("id")
    ids = sorted(set(va.index) | set(vb.index))
    dep = va["departure_s"].reindex(ids).fillna(vb["departure_s"].reindex(ids))
    free = va["free_flow_s"].reindex(ids).fillna(vb["free_flow_s"].reindex(ids))
    out = pd.DataFrame(index=pd.Index(ids, name="id"))
    for side, v, run in (("run", va, a), ("vs", vb, b)):
        arr = v["arrival_s"].reindex(ids)
        end = float(run.summary.get("simulated_s") or np.nan)
        out[f"censored_{side}"] = arr.isna()
        out[f"journey_time_s_{side}"] = (arr.fillna(end) - dep).clip(lower=0.0)  # not yet departed: 0
        out[f"delay_s_{side}"] = out[f"journey_time_s_{side}"] - free
    return out


def comparison_table(a: RunData, b: RunData) -> pd.DataFrame:
    """Two runs of the same demand compared like with like.

    Returns
    -------
    DataFrame
        Columns ``over, metric, statistic, n, run, vs, difference, ratio``.  ``over`` says
        which vehicles a row is over:

        ``paired``
            the vehicles both runs landed: ``run`` and ``vs`` are the statistic of each
            run over them, ``difference`` and ``ratio`` the statistic (mean, median, p95)
            of the per-vehicle difference (run − vs) and ratio (run / vs, over vehicles with
            a positive ``vs``);
        ``demand (censored)``
            every vehicle of the demand, one not arrived counted with its time so far
            (:func:`whole_demand`); difference and ratio per vehicle as above;
        ``own arrived``
            each run over its own arrived vehicles (differing sets: read with the
            warning of :func:`arrived_sets_warning`); difference and ratio of the statistics;
        ``run``
            counts and rates of each run (``vehicles_total``, ``vehicles_arrived``,
            ``collisions_sumo`` ...), as :func:`statistics` names them.
    """
    check_same_demand(a, b)
    rows = []
    va, vb = a.vehicles.set_index("id"), b.vehicles.set_index("id")
    la = set(va.index[va["arrival_s"].notna()])
    lb = set(vb.index[vb["arrival_s"].notna()])
    both = sorted(la & lb)
    rows.append(dict(over="paired", metric="vehicles_paired", statistic="count", n=len(both),
                     run=float(len(both)), vs=float(len(both)), difference=0.0, ratio=np.nan))

    def add(over, metric, xa, xb):
        xa = pd.Series(np.asarray(xa, dtype=float))
        xb = pd.Series(np.asarray(xb, dtype=float))
        ok = xa.notna() & xb.notna()
        xa, xb = xa[ok], xb[ok]
        diff = xa - xb
        pos = xb > 0
        ratio = xa[pos] / xb[pos]
        for st, ra, rb, d, r in zip(("mean", "median", "p95"), _stats3(xa), _stats3(xb), _stats3(diff),
                                    _stats3(ratio)):
            rows.append(dict(over=over, metric=metric, statistic=st, n=int(ok.sum()), run=ra, vs=rb,
                             difference=d, ratio=r))

    for m in PAIRED:
        if m in va and m in vb:
            add("paired", m, va.loc[both, m], vb.loc[both, m])
    wd = whole_demand(a, b)
    rows.append(dict(over="demand (censored)", metric="vehicles_censored", statistic="count", n=len(wd),
                     run=float(wd["censored_run"].sum()), vs=float(wd["censored_vs"].sum()),
                     difference=float(wd["censored_run"].sum() - wd["censored_vs"].sum()), ratio=np.nan))
    # journey time only: for a censored vehicle it is a lower bound; its delay (journey - free flow)
    # would not be one of anything
    add("demand (censored)", "journey_time_s", wd["journey_time_s_run"], wd["journey_time_s_vs"])
    sa, sb = statistics(a), statistics(b)
    keys = list(sa.index) + [k for k in sb.index if k not in sa.index]
    sa, sb = sa.reindex(keys), sb.reindex(keys)
    for k in keys:
        metric, st = k.split(".")
        over = "own arrived" if metric in DISTRIBUTIONS else "run"
        ra, rb = float(sa[k]), float(sb[k])
        rows.append(dict(over=over, metric=metric, statistic=st,
                         n=int(sa.get("vehicles_arrived.count", 0)) if over == "own arrived" else np.nan,
                         run=ra, vs=rb, difference=ra - rb,
                         ratio=ra / rb if rb == rb and rb != 0 else np.nan))
    df = pd.DataFrame(rows, columns=["over", "metric", "statistic", "n", "run", "vs", "difference", "ratio"])
    return df


def arrived_sets_warning(a: RunData, b: RunData) -> str | None:
    """A warning when the two runs' arrived vehicles differ by more than :data:`ARRIVED_DIFFER_SHARE`."""
    va, vb = a.vehicles, b.vehicles
    la = set(va.loc[va["arrival_s"].notna(), "id"])
    lb = set(vb.loc[vb["arrival_s"].notna(), "id"])
    either = la | lb
    if not either:
        return "warning: neither run landed a vehicle; only the censored whole-demand rows compare them"
    only = len(la ^ lb)
    if only / len(either) <= ARRIVED_DIFFER_SHARE:
        return None
    return (f"warning: the runs landed different vehicles (run {len(la)}, vs {len(lb)}, both {len(la & lb)}; "
            f"{only} of {len(either)} = {100.0 * only / len(either):.1f} % arrived in one run only): the "
            f"'own arrived' rows compare different vehicles; read the 'paired' and 'demand (censored)' rows")


def frame_cells(df: pd.DataFrame, landed: dict | None = None) -> list[list[str]]:
    """The cells of ``df`` as text, every number rounded by its metric's meaning (:mod:`analysis.readable`).

    ``landed`` maps a value column (``run``, ``vs``) to whether that run landed a vehicle:
    where it did not, a statistic over arrived vehicles reads "no vehicle arrived" (else "-")."""
    from analysis.readable import fmt

    landed = landed or {}
    body = []
    for _, r in df.iterrows():
        line = []
        for c in df.columns:
            v = r[c]
            if c in ("run", "vs", "difference"):
                none = "no vehicle arrived" if (c in landed and not landed[c] and r["metric"] in DISTRIBUTIONS
                                                and r.get("over", "own arrived") != "demand (censored)") else "-"
                line.append(fmt(v, r["metric"], r["statistic"], missing=none))
            elif c == "ratio":
                line.append(fmt(v, "ratio"))
            elif c == "n":
                line.append(fmt(v, "vehicles"))
            else:
                line.append(str(v))
        body.append(line)
    return body


def _print_frame(df: pd.DataFrame, landed: dict | None = None) -> str:
    """``df`` as aligned text, cells as :func:`frame_cells` writes them."""
    cols = list(df.columns)
    body = frame_cells(df, landed)
    widths = [max([len(c)] + [len(b[i]) for b in body]) for i, c in enumerate(cols)]
    text = lambda cells: "  ".join(  # noqa: E731
        (x.ljust(w) if i < (3 if "over" in cols else 2) else x.rjust(w)) for i, (x, w) in enumerate(zip(cells, widths)))
    return "\n".join([text(cols)] + [text(b) for b in body])


def format_report(df: pd.DataFrame, a: RunData, b: RunData | None = None) -> str:
    """The table as text for the terminal (numbers rounded: seconds 0.1, counts whole, ratios 0.01)."""
    head = f"run: {a.path}  [{a.label}]"
    if b is None:
        note = ("statistics over the run's arrived vehicles; halt = speed <= 0.1 m/s (as SUMO's waiting), "
                "stop = denied TM request")
        return f"{head}\n{note}\n{_print_frame(df, {'run': a.vehicles['arrival_s'].notna().any()})}"
    head += f"\nvs:  {b.path}  [{b.label}]"
    note = ("paired: the vehicles both runs landed; demand (censored): every vehicle, one not arrived counted "
            "with its time so far;\nown arrived: each run over its own arrived vehicles. difference = run - vs, "
            "ratio = run / vs (per vehicle in paired and demand rows; statistic of the per-vehicle values)")
    warn = arrived_sets_warning(a, b)
    landed = {"run": a.vehicles["arrival_s"].notna().any(), "vs": b.vehicles["arrival_s"].notna().any()}
    return "\n".join([head, note] + ([warn] if warn else []) + [_print_frame(df, landed)])


def report_path(a: RunData, b: RunData | None = None) -> Path:
    """Where ``muvsim report`` writes: ``report.csv``, or ``report_vs_<OTHER>.csv`` with ``--vs``."""
    return a.path / ("report.csv" if b is None else f"report_vs_{b.path.name}.csv")


#: Rows of the closing table of ``muvsim run`` (names as in ``summary.json``).
SUMMARY_ROWS = ("scenario", "baseline", "seed", "vehicles_arrived", "stop_reason", "gridlocked_at_end", "simulated_s",
                "steps",
                "collisions_sumo", "collisions_geometric", "invariant_violations", "constraint_violations",
                "min_separation_m", "stop_commands", "mean_travel_time_s", "mean_delay_s", "throughput_vph",
                "speed_limit_excess_max", "vehicles_over_limit", "red_violations", "rtf", "wall_s", "error")


def format_summary(summary: dict) -> str:
    """The closing table of ``muvsim run``: the figures of ``summary.json``, named as there, rounded.

    ``vehicles_arrived`` reads "A of N (P %)" with N the demand (``vehicles_total``, or
    ``vehicles`` for a free-plane run); means over arrived vehicles say "no vehicle
    arrived" when none did; ``min_separation_m`` says so when no two vehicles were in
    the world at once.
    """
    from analysis.readable import fmt

    s = summary
    total = s.get("vehicles_total", s.get("vehicles"))
    rows = []
    for k in SUMMARY_ROWS:
        if k not in s and k != "vehicles_arrived":
            continue
        v = s.get(k)
        if k == "vehicles_arrived":
            if v is None:
                continue
            text = f"{int(v)}"
            if total:
                text += f" of {int(total)} (vehicles_total; {100.0 * v / total:.1f} %)"
        elif k in ("mean_travel_time_s", "mean_delay_s"):
            text = fmt(v, k, missing="no vehicle arrived") + ("" if v is None else "  (over arrived vehicles)")
        elif k == "min_separation_m":
            text = fmt(v, k) if v is not None and v != float("inf") else "never two vehicles at once"
        elif k == "rtf":
            text = fmt(v, k) + "  (simulated s per wall s)" if v is not None else "-"
        elif k == "gridlocked_at_end" and v is not None:
            n = int(s.get("stopped_at_end", 0))
            text = ("no vehicle at rest" if not n else
                    f"{int(v)} of the {n} vehicles at rest wait on a circle of waits "
                    f"({int(s.get('wait_cycles', 0))} cycle(s); waits.csv says who waits for whom)")
        else:
            text = fmt(v, k)
        rows.append((k, text))
    width = max(len(k) for k, _ in rows) if rows else 0
    return "\n".join(f"{k:<{width}}  {t}" for k, t in rows)


def format_brief_comparison(a: RunData, b: RunData) -> str:
    """A few lines for the end of ``muvsim run --vs BASE``: arrivals and the like-with-like rows."""
    from analysis.readable import fmt

    df = comparison_table(a, b).set_index(["over", "metric", "statistic"])
    sa, sb = a.summary, b.summary
    ta, tb = sa.get("vehicles_total", sa.get("vehicles")), sb.get("vehicles_total", sb.get("vehicles"))
    lines = [f"compared with {b.path} [{b.label}] (muvsim report {a.path} --vs {b.path} for every row):",
             f"  vehicles_arrived              {fmt(sa.get('vehicles_arrived'), 'vehicles')} of {fmt(ta, 'vehicles')}"
             f"  vs  {fmt(sb.get('vehicles_arrived'), 'vehicles')} of {fmt(tb, 'vehicles')}"]
    n = int(df.loc[("paired", "vehicles_paired", "count"), "run"])
    for over, metric, label in (("paired", "travel_time_s", f"paired ({n} both landed)"),
                                ("paired", "delay_s", f"paired ({n} both landed)"),
                                ("demand (censored)", "journey_time_s", "whole demand, unfinished censored")):
        if (over, metric, "mean") not in df.index:
            continue
        r, m = df.loc[(over, metric, "mean")], df.loc[(over, metric, "median")]
        if not int(r["n"]):
            lines.append(f"  {metric:<14} no vehicle landed by both runs")
            continue
        lines.append(f"  {metric:<14} mean {fmt(r['run'], metric)} vs {fmt(r['vs'], metric)}; per-vehicle ratio "
                     f"median {fmt(m['ratio'], 'ratio')}  [{label}]")
    warn = arrived_sets_warning(a, b)
    return "\n".join(lines + ([warn] if warn else []))
