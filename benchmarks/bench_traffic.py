"""City traffic: delay, halts, TM stops and safety per traffic-manager option, against SUMO's drivers.

Usage::

    python benchmarks/bench_traffic.py [--scenario grid] [--duration 300] [--seeds 1 2 3]
                                       [--workers N | --scheduler tcp://host:8786] [--runs DIR]
                                       [--quick] [--out benchmarks/results/traffic.csv]

Runs one :mod:`bridge.sweep` over every combination of switching (terminal, early) x check
(union, timed) x policy (greedy, optimal) for each seed, plus one ``--baseline sumo`` run
(SUMO's own drivers, same demand) per seed, on a local Dask cluster (or ``--scheduler``).
Prints and writes one row per combination: means over the seeds of

* ``delay_mean_s``, ``delay_p95_s``: mean and 95th percentile of per-vehicle delay,
* ``halts_per_vehicle``, ``time_halted_s``: halt episodes and time halted per vehicle
  (speed <= 0.1 m/s, SUMO's waiting: comparable with the baseline),

all over the arrived vehicles of each run (``analysis.report.statistics`` of its per-vehicle
table), and of ``tm_stops`` (denied switch requests; none for SUMO's drivers), ``arrived``,
``collisions_sumo`` (pairs SUMO reported), ``collisions_geometric`` (footprint-overlap pair-steps),
``invariant_violations``, ``throughput_vph``, ``rtf`` and ``wall_s``.  The per-run table goes
next to it (``traffic_runs.csv``).  Statistics over arrived vehicles favour an option that lands
fewer vehicles: read them with ``arrived``.

``--quick``: the first seed, two combinations (early switching, union check, greedy and
optimal) and the baseline, 20 simulated seconds.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

from bridge.sweep import SweepSettings, sweep

#: Per-run column -> column of the table (mean over seeds).
MEANS = {"vehicles_arrived": "arrived", "delay_s_mean": "delay_mean_s", "delay_s_p95": "delay_p95_s",
         "halt_episodes_mean": "halts_per_vehicle", "time_halted_s_mean": "time_halted_s",
         "stop_commands": "tm_stops", "collisions_sumo": "collisions_sumo",
         "collisions_geometric": "collisions_geometric", "invariant_violations": "invariant_violations",
         "throughput_vph": "throughput_vph", "rtf": "rtf", "wall_s": "wall_s"}
KEYS = ["driver", "switching", "check", "policy"]


def combination_table(runs: pd.DataFrame, scenario: str) -> pd.DataFrame:
    """One row per (driver, switching, check, policy): means over seeds of :data:`MEANS`.

    Runs that failed are counted (``seeds`` vs ``complete``) but not averaged.
    """
    df = runs.rename(columns={"tm": "policy"}).copy()
    for k in ("switching", "check", "policy"):
        df[k] = df[k].where(df["driver"] == "muvsim", "-").fillna("-")
    ok = df[df["complete"].astype(bool)].copy()
    for c in MEANS:  # Int64 counts with missing values (a baseline has no TM stops) -> float NaN
        ok[c] = pd.to_numeric(ok[c], errors="coerce").astype(float)
    means = ok.groupby(KEYS, sort=False)[list(MEANS)].mean()
    counts = df.groupby(KEYS, sort=False).agg(seeds=("seed", "size"),
                                              complete=("complete", lambda s: int(s.astype(bool).sum())))
    table = counts.join(means.rename(columns=MEANS)).reset_index()
    table.insert(0, "scenario", scenario)
    return table.round(3)


def main(argv=None) -> pd.DataFrame:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="grid", help="a SUMO scenario: grid (default), grid-large, a .toml")
    ap.add_argument("--duration", type=float, default=300.0, help="simulated seconds per run (default 300)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3], help="seeds (default 1 2 3)")
    ap.add_argument("--workers", type=int, default=None, help="local worker processes (default: CPUs)")
    ap.add_argument("--scheduler", default=None, help="an existing Dask scheduler instead of a local cluster")
    ap.add_argument("--runs", default=None, help="keep the run directories here (default: a temporary directory)")
    ap.add_argument("--quick", action="store_true", help="1 seed, 2 combinations + baseline, 20 s")
    ap.add_argument("--out", default="benchmarks/results/traffic.csv")
    args = ap.parse_args(argv)
    seeds = tuple(args.seeds[:1]) if args.quick else tuple(args.seeds)
    options = dict(tm=("greedy", "optimal"), check=("union",), switching=("early",)) if args.quick else \
        dict(tm=("greedy", "optimal"), check=("union", "timed"), switching=("terminal", "early"))
    duration = 20.0 if args.quick else args.duration
    with tempfile.TemporaryDirectory(prefix="bench-traffic-") as tmp:
        settings = SweepSettings(scenario=args.scenario, seeds=seeds, out=Path(args.runs or tmp),
                                 duration_s=duration, baseline=True, workers=args.workers,
                                 scheduler=args.scheduler, **options)
        t0 = time.perf_counter()
        runs = sweep(settings, quiet=False, stream=sys.stdout)
        wall = time.perf_counter() - t0
    table = combination_table(runs, args.scenario)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(out, index=False)
    runs.to_csv(out.with_name(out.stem + "_runs.csv"), index=False)
    print(f"{len(runs)} runs ({args.scenario}, {duration:g} s simulated, seeds {list(seeds)}) in {wall:.1f} s wall")
    print(table.to_string(index=False))
    for _, r in runs[~runs["complete"].astype(bool)].iterrows():
        print(f"FAILED {r['label']}: {r['error']}")
    print(f"written: {out}")
    return table


if __name__ == "__main__":
    main()
