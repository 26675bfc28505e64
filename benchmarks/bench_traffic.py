"""City traffic: delay, halts, TM stops and safety per muvsim controller and variant, against SUMO's drivers.

Usage::

    python benchmarks/bench_traffic.py [--scenario grid] [--duration 900] [--seeds 1 2]
                                       [--controller paper authority]
                                       [--paper-variants early/timed/optimal ... | all]
                                       [--authority-check union timed]
                                       [--workers N | --scheduler tcp://host:8786] [--runs DIR]
                                       [--quick] [--out benchmarks/results/traffic.csv]
    python benchmarks/bench_traffic.py --from-runs DIR [--out ...]   # the tables of kept runs, no run

Per seed, one run per muvsim variant plus one ``--baseline sumo`` run (SUMO's own drivers, the same
demand: ``--seed`` draws a generated scenario's demand, so two seeds are two traffic samples):

* ``paper`` (``--controller paper``, the paper's sets, cost and centred claims): the
  ``SWITCHING/CHECK/POLICY`` combinations of ``--paper-variants`` (default ``early/timed/optimal``;
  ``all``: the 8 of terminal, early x union, timed x greedy, optimal);
* ``authority`` (``--controller authority``, movement authority with reach-tightened claims):
  switching early, policy optimal, one run per check of ``--authority-check`` (default union and
  timed).

Every run is given all of its options explicitly (a scenario file's own ``check`` never stands in for
the one asked), and the options each run used, as its ``summary.json`` records them, must be the
ones asked (else the benchmark fails).  Runs go through :func:`bridge.sweep.run_plan` on a local Dask
cluster of ``--workers`` processes (or ``--scheduler``), each run in a fresh Python process
(``fresh_process``): runs are independent and memory does not grow over the benchmark.

Prints and writes one row per combination (``driver``, ``controller``, ``switching``, ``check``,
``policy``): means over the seeds of

* ``arrived`` (of ``demand``) and ``simulated_s`` (a run stops early once its whole demand arrived),
* ``delay_mean_s``, ``delay_p95_s``: mean and 95th percentile of per-vehicle delay,
* ``halts_per_vehicle``, ``time_halted_s``: halt episodes and time halted per vehicle
  (speed <= 0.1 m/s, SUMO's waiting: comparable with the baseline),

all over the arrived vehicles of each run (``analysis.report.statistics`` of its per-vehicle
table), and of ``tm_stops`` (denied switch requests; none for SUMO's drivers),
``collisions_sumo`` (pairs SUMO reported), ``collisions_geometric`` (footprint-overlap pair-steps),
``invariant_violations``, ``throughput_vph``, ``rtf`` and ``wall_s``.  The per-run table goes
next to it (``traffic_runs.csv``).  Statistics over arrived vehicles favour a variant that lands
fewer vehicles: read them with ``arrived``.

``--quick``: the first seed and 20 simulated seconds (the variants as chosen).
``--from-runs DIR``: rebuild both tables from the run directories kept in DIR (``--runs DIR`` of an
earlier run), from each one's ``summary.json`` and per-vehicle table, without running anything.
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

from bridge.sweep import OPTION_CHOICES, RunSpec, SweepSettings, run_plan, runs_from_dirs

#: Per-run column -> column of the table (mean over seeds).
MEANS = {"vehicles_total": "demand", "vehicles_arrived": "arrived", "simulated_s": "simulated_s",
         "delay_s_mean": "delay_mean_s", "delay_s_p95": "delay_p95_s",
         "halt_episodes_mean": "halts_per_vehicle", "time_halted_s_mean": "time_halted_s",
         "stop_commands": "tm_stops", "collisions_sumo": "collisions_sumo",
         "collisions_geometric": "collisions_geometric", "invariant_violations": "invariant_violations",
         "throughput_vph": "throughput_vph", "rtf": "rtf", "wall_s": "wall_s"}
KEYS = ["driver", "controller", "switching", "check", "policy"]
#: Row order of the table: muvsim before SUMO's drivers, then each key's values in this order.
ORDER = {"driver": ("muvsim", "sumo"), "controller": ("paper", "authority"), "switching": ("terminal", "early"),
         "check": ("union", "timed"), "policy": ("greedy", "optimal")}
#: ``--paper-variants`` default: early switching, timed check, optimal policy.
PAPER_DEFAULT = ("early/timed/optimal",)
#: Every paper variant (``--paper-variants all``): switching x check x policy.
PAPER_ALL = tuple(f"{s}/{c}/{p}" for s, c, p in itertools.product(ORDER["switching"], ORDER["check"],
                                                                   ORDER["policy"]))
#: The authority rows' switching and policy (their check is ``--authority-check``).
AUTHORITY_SWITCHING, AUTHORITY_POLICY = "early", "optimal"
QUICK_DURATION_S = 20.0


def combination_table(runs: pd.DataFrame, scenario: str) -> pd.DataFrame:
    """One row per (driver, controller, switching, check, policy): means over seeds of :data:`MEANS`.

    Runs that failed are counted (``seeds`` vs ``complete``) but not averaged.  A run table without a
    ``controller`` column (from before the column) is the paper controller's.  Rows in :data:`ORDER`.
    """
    df = runs.rename(columns={"tm": "policy"}).copy()
    if "controller" not in df:
        df["controller"] = "paper"
    df["controller"] = df["controller"].fillna("paper")
    for k in ("controller", "switching", "check", "policy"):
        df[k] = df[k].where(df["driver"] == "muvsim", "-").fillna("-")
    ok = df[df["complete"].astype(bool)].copy()
    for c in MEANS:  # Int64 counts with missing values (a baseline has no TM stops) -> float NaN
        ok[c] = pd.to_numeric(ok[c], errors="coerce").astype(float) if c in ok else float("nan")
    means = ok.groupby(KEYS, sort=False)[list(MEANS)].mean()
    counts = df.groupby(KEYS, sort=False).agg(seeds=("seed", "size"),
                                              complete=("complete", lambda s: int(s.astype(bool).sum())))
    table = counts.join(means.rename(columns=MEANS)).reset_index()
    rank = lambda k: table[k].map(lambda v: ORDER[k].index(v) if v in ORDER[k] else len(ORDER[k]))  # noqa: E731
    table = table.iloc[pd.DataFrame({k: rank(k) for k in KEYS}).sort_values(KEYS, kind="stable").index]
    table.insert(0, "scenario", scenario)
    return table.reset_index(drop=True).round(3)


def _variant(text: str) -> tuple[str, str, str]:
    parts = tuple(text.split("/"))
    if len(parts) != 3 or any(v not in ORDER[k] for k, v in zip(("switching", "check", "policy"), parts)):
        raise argparse.ArgumentTypeError(
            f"{text!r}: must be SWITCHING/CHECK/POLICY with switching {' or '.join(ORDER['switching'])}, check "
            f"{' or '.join(ORDER['check'])}, policy {' or '.join(ORDER['policy'])} (e.g. early/timed/optimal), "
            f"or all")
    return parts


def paper_variants(values) -> list[tuple[str, str, str]]:
    """``--paper-variants`` as (switching, check, policy) tuples, distinct, in the given order."""
    if list(values) == ["all"]:
        values = PAPER_ALL
    elif "all" in values:
        raise argparse.ArgumentTypeError("'all' stands alone")
    return list(dict.fromkeys(_variant(v) for v in values))


def plan_runs(scenario: str, seeds, duration_s: float, controllers, paper, authority_checks) -> list[RunSpec]:
    """The benchmark's runs, per seed: the paper variants, the authority checks, SUMO's drivers.

    Every option is given (switching, check, policy, controller), so none is the scenario's; labels
    name all of them (``seed1_paper_early_timed_optimal``, ``seed1_authority_early_union_optimal``,
    ``seed1_baseline-sumo``)."""
    settings = SweepSettings(scenario=scenario, seeds=tuple(seeds), out=Path("."), duration_s=duration_s)
    variants = []
    if "paper" in controllers:
        variants += [("paper", s, c, p) for s, c, p in paper]
    if "authority" in controllers:
        variants += [("authority", AUTHORITY_SWITCHING, c, AUTHORITY_POLICY) for c in authority_checks]
    runs = []
    for seed in settings.seeds:
        for ctrl, sw, chk, pol in variants:
            runs.append(RunSpec(label=f"seed{seed}_{ctrl}_{sw}_{chk}_{pol}", scenario=settings.scenario, seed=seed,
                                controller=ctrl, switching=sw, check=chk, tm=pol, duration_s=settings.duration_s))
        runs.append(RunSpec(label=f"seed{seed}_baseline-sumo", scenario=settings.scenario, seed=seed, driver="sumo",
                            duration_s=settings.duration_s))
    return runs


def mismatches(runs: list[RunSpec], table: pd.DataFrame) -> list[str]:
    """Runs whose recorded options (``summary.json``, in the sweep row) differ from the ones asked."""
    rows = table.set_index("label")
    bad = []
    for spec in runs:
        if spec.driver != "muvsim" or spec.label not in rows.index or not bool(rows.loc[spec.label, "complete"]):
            continue
        r = rows.loc[spec.label]
        for name in ("controller", "switching", "check", "tm"):
            if r[name] != getattr(spec, name):
                bad.append(f"{spec.label}: {name} {r[name]!r} ran, {getattr(spec, name)!r} asked")
    return bad


def scenario_of(runs: pd.DataFrame) -> str:
    """The scenario of kept runs (their ``summary.json``): a built-in name, or a file's stem."""
    names = {str(json.loads((Path(d) / "summary.json").read_text()).get("scenario")) for d in runs["run_dir"]}
    if len(names) != 1:
        raise SystemExit(f"bench_traffic.py: --from-runs: runs of several scenarios: {sorted(names)}")
    name = names.pop()
    return Path(name).stem if name.endswith((".toml", ".sumocfg")) else name


def write(runs: pd.DataFrame, scenario: str, out: Path) -> pd.DataFrame:
    table = combination_table(runs, scenario)
    out.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(out, index=False)
    runs.to_csv(out.with_name(out.stem + "_runs.csv"), index=False)
    return table


def main(argv=None) -> pd.DataFrame:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="grid", help="a SUMO scenario: grid (default), grid-large, a .toml")
    ap.add_argument("--duration", type=float, default=900.0,
                    help="at most this many simulated seconds per run (default 900); a run ends earlier once "
                         "its whole demand has arrived")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2], help="seeds (default 1 2)")
    ap.add_argument("--controller", nargs="+", choices=OPTION_CHOICES["controller"],
                    default=list(OPTION_CHOICES["controller"]), help="muvsim controllers (default: both)")
    ap.add_argument("--paper-variants", nargs="+", default=list(PAPER_DEFAULT), metavar="SWITCHING/CHECK/POLICY",
                    help="the paper controller's variants (default early/timed/optimal; all: the 8 of "
                         "terminal, early x union, timed x greedy, optimal)")
    ap.add_argument("--authority-check", nargs="+", choices=ORDER["check"], default=list(ORDER["check"]),
                    help="the authority controller's checks (default: union and timed); switching early, "
                         "policy optimal")
    ap.add_argument("--workers", type=int, default=None, help="local worker processes (default: CPUs)")
    ap.add_argument("--scheduler", default=None, help="an existing Dask scheduler instead of a local cluster")
    ap.add_argument("--runs", default=None, help="keep the run directories here (default: a temporary directory)")
    ap.add_argument("--from-runs", default=None, metavar="DIR",
                    help="rebuild the tables from the run directories kept in DIR; runs nothing")
    ap.add_argument("--quick", action="store_true", help=f"the first seed, {QUICK_DURATION_S:g} simulated s")
    ap.add_argument("--out", default="benchmarks/results/traffic.csv")
    args = ap.parse_args(argv)
    out = Path(args.out)
    if args.from_runs:
        runs = runs_from_dirs(args.from_runs)
        scenario = scenario_of(runs)
        print(f"{len(runs)} kept runs of {scenario} from {args.from_runs}")
    else:
        try:
            paper = paper_variants(args.paper_variants)
        except argparse.ArgumentTypeError as exc:
            ap.error(f"--paper-variants: {exc}")
        seeds = args.seeds[:1] if args.quick else args.seeds
        duration = QUICK_DURATION_S if args.quick else args.duration
        specs = plan_runs(args.scenario, seeds, duration, list(dict.fromkeys(args.controller)), paper,
                          list(dict.fromkeys(args.authority_check)))
        scenario = args.scenario
        with tempfile.TemporaryDirectory(prefix="bench-traffic-") as tmp:
            t0 = time.perf_counter()
            runs = run_plan(specs, Path(args.runs or tmp), workers=args.workers, scheduler=args.scheduler,
                            quiet=False, stream=sys.stdout, fresh_process=True)
            wall = time.perf_counter() - t0
        print(f"{len(runs)} runs ({scenario}, at most {duration:g} s simulated, seeds {list(seeds)}) "
              f"in {wall:.1f} s wall")
        bad = mismatches(specs, runs)
        if bad:
            write(runs, scenario, out.with_name(out.stem + "_MISMATCH" + out.suffix))
            raise SystemExit("bench_traffic.py: runs used options other than the ones asked:\n" + "\n".join(bad))
    table = write(runs, scenario, out)
    print(table.to_string(index=False))
    for _, r in runs[~runs["complete"].astype(bool)].iterrows():
        print(f"FAILED {r['label']}: {r['error']}")
    print(f"written: {out}")
    return table


if __name__ == "__main__":
    main()
