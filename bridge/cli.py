"""The ``muvsim`` command line.

``muvsim sets CLASS [--json]``
    Synthesise (or load from cache) a class's sets and print N, facet counts,
    synthesis seconds and whether condition (8) holds.
``muvsim run [SCENARIO] --out DIR ...``
    Run a scenario and write ``DIR/summary.json`` plus per-step CSV.
``muvsim report RUN_DIR [--vs OTHER_RUN_DIR] [--plots]``
    KPI statistics of a run (or two, compared) into ``RUN_DIR/report.csv``.
``muvsim sweep SCENARIO --out DIR --seeds S [S ...] [--tm ...] ...``
    Runs over seeds x options in parallel (Dask), one KPI table ``DIR/sweep.csv``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

from bridge.interrupt import InterruptGuard

__all__ = ["main"]


def _cmd_sets(args) -> int:
    from controllers.classes import ClassError, get_class
    from controllers.settings import SynthesisSettings
    from controllers.synthesis import SynthesisError, synthesize

    try:
        vclass = get_class(args.vclass)
    except ClassError as exc:
        print(f"muvsim sets: {exc}", file=sys.stderr)
        return 2
    settings = SynthesisSettings(cache=not args.no_cache)
    t0 = time.perf_counter()
    try:
        fam = synthesize(vclass.model, settings)
    except SynthesisError as exc:
        print(f"muvsim sets: class {args.vclass!r}: {exc}", file=sys.stderr)
        return 1
    wall = time.perf_counter() - t0
    info = {"class": vclass.name, **fam.summary(), "wall_s": round(wall, 4),
            "delta_m": vclass.model.delta, "Ts_s": vclass.model.Ts,
            "footprint_m": [vclass.length, vclass.width]}
    if args.json:
        print(json.dumps(info))
    else:
        print(f"class {vclass.name}: N = {fam.N}, condition (8) holds: {fam.condition8}")
        print(f"  synthesis {fam.seconds:.3f} s ({'loaded from cache' if fam.from_cache else 'computed'}; "
              f"this call {wall:.3f} s)")
        print("  facets of T^0..T^N: " + " ".join(str(c) for c in fam.facet_counts()))
    return 0


FREE_PLANE = ("single", "paper10", "swap", "crossing")


def _make_out(out: Path, option: str = "--out") -> str | None:
    """Create the output directory; a message naming the option and the path when it cannot be."""
    if out.exists() and not out.is_dir():
        return f"{option} {out}: is a file, not a directory; give a directory (created if missing)"
    for parent in out.parents:
        if parent.exists() and not parent.is_dir():
            return f"{option} {out}: cannot create it: {parent} is a file, not a directory"
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        return f"{option} {out}: cannot create the directory: {exc.strerror or exc}"
    if not os.access(out, os.W_OK | os.X_OK):
        return f"{option} {out}: the directory is not writable"
    return None


#: Fewest vehicles ``--vehicles`` may ask of each free-plane scenario that takes it.
MIN_VEHICLES = {"swap": 2, "crossing": 1}


def scenario_problem(name: str) -> str | None:
    """Why ``name`` is not a scenario ``muvsim run`` can run (listing every valid one), or None.

    Checked before anything is written, so a wrong name creates no output folder.
    """
    from sumo_nets.scenario import builtin_scenarios

    if name in FREE_PLANE:
        return None
    path = Path(name).expanduser()
    if name.endswith((".toml", ".sumocfg")):
        return None if path.is_file() else f"scenario file {path} does not exist"
    if name in builtin_scenarios() or path.is_file():
        return None
    return (f"unknown scenario {name!r}; valid: {', '.join(builtin_scenarios())} (SUMO, built in), "
            f"{', '.join(FREE_PLANE)} (free plane), or the path of a scenario .toml or a SUMO .sumocfg file")


def _cmd_run(args) -> int:
    from bridge.scenarios import ScenarioRunError, default_controller, default_vclass, run_scenario

    problem = scenario_problem(args.scenario)
    if problem:
        print(f"muvsim run: {problem}", file=sys.stderr)
        return 2
    out = Path(args.out)
    if args.scenario in MIN_VEHICLES and args.vehicles < MIN_VEHICLES[args.scenario]:
        print(f"muvsim run: --vehicles: {args.scenario} needs at least {MIN_VEHICLES[args.scenario]} "
              f"vehicle(s), got {args.vehicles}", file=sys.stderr)
        return 2
    problem = _make_out(out)
    if problem:
        print(f"muvsim run: {problem}", file=sys.stderr)
        return 2
    if getattr(args, "controller", "paper") is None:
        args.controller = default_controller(args.scenario)
    if getattr(args, "vclass", "paper-a") is None:
        args.vclass = default_vclass(getattr(args, "controller", "paper"))
    if args.scenario in FREE_PLANE:
        from tm.settings import default_check

        for name, default in (("tm", "optimal"), ("check", default_check(getattr(args, "controller", "paper"))),
                              ("switching", "early"), ("disturbance", "random")):
            if getattr(args, name) is None:
                setattr(args, name, default)
        args.seed = 0 if args.seed is None else args.seed
        if args.baseline:
            print("muvsim run: --baseline sumo needs a SUMO scenario (grid, grid-large, a .toml or a "
                  ".sumocfg)", file=sys.stderr)
            return 2
        try:
            with InterruptGuard() as guard:
                summary = run_scenario(args.scenario, out, args, observers_extra=[guard])
        except ScenarioRunError as exc:
            print(f"muvsim run: {exc}", file=sys.stderr)
            return 2
    else:
        from bridge.sumo_world import run_sumo

        with InterruptGuard() as guard:
            summary = run_sumo(args.scenario, out, args, observers_extra=[guard])
    if "error" in summary:
        if getattr(args, "debug", False) and summary.get("traceback"):
            print(summary["traceback"], file=sys.stderr)
        print(f"muvsim run: {summary['error']}", file=sys.stderr)
    from analysis.report import SUMMARY_ROWS, format_summary

    print(format_summary(summary))
    width = max(len(k) for k in SUMMARY_ROWS)
    if (out / "steps.csv").exists() and not summary.get("baseline") == "sumo":
        import pandas as pd

        from analysis.kpis import timing_means

        ms = timing_means(pd.read_csv(out / "steps.csv"))
        print("wall ms per step".ljust(width) + "  " + ", ".join(f"{k[:-3]} {v:.3f}" for k, v in ms.items()))
    if getattr(args, "vs", None) and (out / "summary.json").exists():
        _print_vs(out, Path(args.vs))
    print(f"written: {out / 'summary.json'}")
    if args.plots and (out / "summary.json").exists():
        _write_plots(out)
    if not summary.get("complete", True):
        return 1
    if summary.get("safe") is False:
        from analysis.safety import UNSAFE_EXIT

        fired = ", ".join(f"{k} {v}" for k, v in summary.get("safety_violations", {}).items())
        print(f"muvsim run: UNSAFE: safety counters fired: {fired} (see {out / 'summary.json'})", file=sys.stderr)
        return UNSAFE_EXIT
    return 0


def _print_vs(out: Path, base: Path) -> None:
    """The closing comparison of ``muvsim run --vs BASE`` (a message, never an exception)."""
    from analysis.report import DemandMismatch, format_brief_comparison, load_run

    try:
        print(format_brief_comparison(load_run(out), load_run(base)))
    except (FileNotFoundError, DemandMismatch) as exc:
        print(f"muvsim run: no comparison with {base}: {exc}", file=sys.stderr)


def _cmd_report(args) -> int:
    from analysis.report import DemandMismatch, format_report, load_run, report_path, report_table

    try:
        a = load_run(args.run)
        b = load_run(args.vs) if args.vs else None
        df = report_table(a, b)
    except (FileNotFoundError, DemandMismatch) as exc:
        print(f"muvsim report: {exc}", file=sys.stderr)
        return 2
    print(format_report(df, a, b))
    dest = report_path(a, b)
    df.to_csv(dest, index=False)
    print(f"written: {dest}")
    if args.plots:
        _write_plots(Path(args.run), Path(args.vs) if args.vs else None)
    return 0


def _cmd_sweep(args) -> int:
    from bridge.sweep import SweepSettings, SweepSettingsError, format_table, sweep

    problem = scenario_problem(args.scenario)
    if problem:
        print(f"muvsim sweep: {problem}", file=sys.stderr)
        return 2
    try:
        settings = SweepSettings(
            scenario=args.scenario, seeds=tuple(args.seeds), out=Path(args.out),
            controller=tuple(args.controller or ()), tm=tuple(args.tm or ()),
            check=tuple(args.check or ()), switching=tuple(args.switching or ()),
            disturbance=tuple(args.disturbance or ()), solver=tuple(args.solver or ()),
            signals=tuple(args.signals or ()), pedestrians=tuple(args.pedestrians or ()), duration_s=args.duration,
            baseline=args.baseline, log=args.log, workers=args.workers, scheduler=args.scheduler,
            vclass=args.vclass, vehicles=args.vehicles)
        df = sweep(settings, quiet=args.quiet)
    except SweepSettingsError as exc:
        print(f"muvsim sweep: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # e.g. no scheduler at the address given
        print(f"muvsim sweep: cannot run on Dask: {exc}", file=sys.stderr)
        return 2
    print(format_table(df))
    print(f"written: {settings.out / 'sweep.csv'}")
    return 0 if bool(df["complete"].all()) else 1


def _write_plots(run: Path, vs: Path | None = None) -> None:
    from analysis.plots import write_plots

    try:
        written = write_plots(run, vs)
    except FileNotFoundError as exc:
        print(f"muvsim: no plots: {exc}", file=sys.stderr)
        return
    for kind, path in written.items():
        print(f"plot {kind}: {path}")
    from analysis.report import DemandMismatch
    from analysis.report_html import write_html_report

    try:
        print(f"report: {write_html_report(run, vs, written)}")
    except (FileNotFoundError, DemandMismatch) as exc:
        print(f"muvsim: no report.html: {exc}", file=sys.stderr)


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("muvsim")
    except PackageNotFoundError:  # pragma: no cover - run from a tree that was never installed
        return "unknown (not installed)"


def _duration(text: str) -> float:
    """``--duration``: simulated seconds, a finite number > 0."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be simulated seconds (a number > 0), got {text!r}") from None
    if not (v > 0 and v != float("inf")):
        raise argparse.ArgumentTypeError(f"must be > 0 simulated seconds, got {text!r} (leave --duration out "
                                         "to run until every vehicle has arrived)")
    return v


def _lat_accel(text: str) -> float | str:
    """``--lat-accel``: m/s^2 (a number >= 0; 0 turns curve speeds off), or ``net``."""
    if text.strip().lower() == "net":
        return "net"
    try:
        v = float(text)
    except ValueError:
        v = float("nan")
    if not 0 <= v <= 10:
        raise argparse.ArgumentTypeError(f"must be a lateral acceleration in [0, 10] m/s^2 (0: no curve speeds) "
                                         f"or 'net' (the network's own limitTurnSpeed), got {text!r}")
    return v


DURATION_HELP = ("stop after S simulated seconds, or earlier once every vehicle of the demand has arrived. "
                 "Default: until every vehicle has arrived, at most 3 x the departure window (the last "
                 "requested departure, at least 60 s; 900 s for grid); the closing table says why the run "
                 "stopped and how many vehicles are still in the network")


SEED_HELP = ("seed of the run: draws a generated scenario's demand (randomTrips' seed and the class "
             "assignment) as well as SUMO's seed, the disturbances and the TM's tie-breaks; a .sumocfg's demand "
             "is its own and does not change. Default: the scenario's seed (0 for free-plane scenarios)")


SIGNALS_HELP = "SUMO's traffic lights: obey (default) or ignore (the TM alone, AIM-style)"
PEDESTRIANS_HELP = ("guard (default): no claim over a crossing or walking area a pedestrian can reach in time; "
                    "ignore: vehicles disregard pedestrians (comparison only)")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="muvsim", description="muvsim: collision-free co-simulation of automated vehicles (set-theoretic "
                                   "MPC and a traffic manager) in SUMO city traffic.",
        epilog="muvsim COMMAND --help describes a command's options.")
    p.add_argument("--version", action="version", version=f"muvsim {_version()}")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--debug", action="store_true", help="show the Python traceback of an error")
    sub = p.add_subparsers(dest="command", required=True)
    s = sub.add_parser("sets", parents=[common],
                       help="synthesise a vehicle class's ST-MPC sets and describe them")
    s.add_argument("vclass", metavar="CLASS")
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.add_argument("--no-cache", action="store_true", help="ignore and do not write the set cache")
    s.set_defaults(func=_cmd_sets)
    r = sub.add_parser("run", parents=[common], help="run a scenario")
    r.add_argument("scenario", nargs="?", default="grid",
                   help="grid (default), grid-large, a scenario .toml, a .sumocfg, or a free-plane "
                        "scenario: single, paper10, swap, crossing")
    r.add_argument("--out", default="runs/latest", help="output directory (default runs/latest)")
    r.add_argument("--seed", type=int, default=None, help=SEED_HELP)
    r.add_argument("--vclass", default=None,
                   help="vehicle class for single/swap/crossing (default paper-a; car with --controller authority)")
    r.add_argument("--controller", choices=["paper", "authority"], default=None,
                   help="authority (default for SUMO scenarios): movement-authority sets and cost with "
                        "reach-tightened claims (design.md §7; car, bus, truck; single: a 600 m straight); "
                        "paper (default for the free-plane scenarios): the paper's sets, cost and centred claims")
    r.add_argument("--tm", choices=["greedy", "optimal"], default=None, help="default: the scenario's")
    r.add_argument("--claim-cache", choices=["on", "off"], default="on",
                   help="authority mode: on (default): current claims reused between steps where sound "
                        "(tm.reach_cache); off: fresh claims every step (the reference)")
    r.add_argument("--frame", choices=["auto", "path", "road"], default="auto",
                   help="the plant's frame: path (authority default): stepped along its route, turns at the "
                        "curve speed; road (paper default): errors in the waypoint segment's frame")
    r.add_argument("--arrival", choices=["stop", "pass"], default="stop",
                   help="authority mode on SUMO networks: stop (default): a vehicle comes to rest at its "
                        "route's end; pass: a route ending where no other edge enters (the network's "
                        "boundary) is left at speed, as SUMO's vehicles leave it (its stop point runs out "
                        "past the end)")
    r.add_argument("--speed-limits", choices=["obey", "ignore"], default="obey",
                   help="obey (default): lanes' speed limits bound the vehicles' speed (with look-ahead); "
                        "ignore: only the class bound (the KPI speed_limit_excess_max still measures them)")
    r.add_argument("--lat-accel", type=_lat_accel, default=None, metavar="A",
                   help="authority mode: curve speed sqrt(A / curvature), A in m/s^2 (default 2.0; 0: off); "
                        "'net': the network's limitTurnSpeed, the lateral acceleration netconvert built its "
                        "turn speeds with (5.5 unless set otherwise; 2.0 where the network records none)")
    r.add_argument("--check", choices=["union", "timed"], default=None)
    r.add_argument("--switching", choices=["terminal", "early"], default=None)
    r.add_argument("--disturbance", choices=["random", "adversarial", "none"], default=None)
    r.add_argument("--baseline", choices=["sumo"], default=None,
                   help="drive the same demand by SUMO itself (no muvsim control)")
    r.add_argument("--pedestrians", choices=["guard", "ignore"], default="guard", help=PEDESTRIANS_HELP)
    r.add_argument("--gui", action="store_true", help="sumo-gui (needs a display)")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.add_argument("--solver", choices=["exact", "daqp", "proxsuite"], default="exact")
    r.add_argument("--signals", choices=["obey", "ignore"], default=None, help=SIGNALS_HELP)
    r.add_argument("--duration", type=_duration, default=None, metavar="S", help=DURATION_HELP)
    r.add_argument("--vehicles", type=int, default=8, help="vehicles in swap")
    r.add_argument("--log", choices=["none", "summary", "full"], default="summary",
                   help="run.mcap for Foxglove: none, summary (states, decisions; default) or full "
                        "(+ claim polygons)")
    r.add_argument("--plots", action="store_true", help="write plots into DIR/plots after the run")
    r.add_argument("--vs", metavar="BASE_DIR", default=None,
                   help="after the run, compare with this run of the same demand (e.g. a --baseline sumo run): "
                        "arrivals, per-vehicle ratios over the vehicles both landed, the whole demand censored")
    r.set_defaults(func=_cmd_run)
    q = sub.add_parser("report", parents=[common],
                       help="KPI statistics of a run, or two runs compared (report.csv)")
    q.add_argument("run", metavar="RUN_DIR")
    q.add_argument("--vs", metavar="OTHER_RUN_DIR", default=None,
                   help="compare with this run (same demand): difference and ratio")
    q.add_argument("--plots", action="store_true", help="also write plots into RUN_DIR/plots")
    q.set_defaults(func=_cmd_report)
    w = sub.add_parser("sweep", parents=[common],
                       help="run a scenario over seeds and options in parallel (Dask): one KPI table")
    w.add_argument("scenario", help="grid, grid-large, a scenario .toml, a .sumocfg, or a free-plane scenario: "
                                    "single, paper10, swap, crossing")
    w.add_argument("--out", default="runs/sweep",
                   help="output directory: DIR/<run label>/ per run and DIR/sweep.csv (default runs/sweep)")
    w.add_argument("--seeds", type=int, nargs="+", required=True, metavar="SEED",
                   help="seeds to run, each as muvsim run --seed: a generated scenario's demand is drawn anew "
                        "per seed, so means over seeds are means over traffic (a .sumocfg's demand is fixed)")
    w.add_argument("--tm", choices=["greedy", "optimal"], nargs="+", default=None,
                   help="policies to sweep (default: the scenario's)")
    w.add_argument("--controller", choices=["authority", "paper"], nargs="+", default=None,
                   help="default: muvsim run's (authority for SUMO scenarios, paper for free-plane ones)")
    w.add_argument("--check", choices=["union", "timed"], nargs="+", default=None)
    w.add_argument("--switching", choices=["terminal", "early"], nargs="+", default=None)
    w.add_argument("--disturbance", choices=["random", "adversarial", "none"], nargs="+", default=None)
    w.add_argument("--solver", choices=["exact", "daqp", "proxsuite"], nargs="+", default=None,
                   help="default exact")
    w.add_argument("--signals", choices=["obey", "ignore"], nargs="+", default=None,
                   help="as muvsim run --signals, one or more values to sweep: " + SIGNALS_HELP
                        + "; SUMO scenarios only")
    w.add_argument("--pedestrians", choices=["guard", "ignore"], nargs="+", default=None,
                   help="as muvsim run --pedestrians, one or more values to sweep: " + PEDESTRIANS_HELP
                        + "; SUMO scenarios only")
    w.add_argument("--duration", type=_duration, default=None, metavar="S",
                   help="each run's --duration (as muvsim run: " + DURATION_HELP.split(". ", 1)[0] + "; default: "
                        "until every vehicle has arrived, at most 3 x the departure window)")
    w.add_argument("--baseline", action="store_true", help="add one --baseline sumo run per seed")
    w.add_argument("--log", choices=["none", "summary", "full"], default="none",
                   help="run.mcap of each run (default none)")
    w.add_argument("--workers", type=int, default=None,
                   help="worker processes of the local cluster (default: CPUs, at most one per run)")
    w.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="use an existing Dask cluster, e.g. tcp://host:8786 (DIR must be shared with its workers)")
    w.add_argument("--vclass", default=None,
                   help="vehicle class for single/swap/crossing (default paper-a; car with --controller authority)")
    w.add_argument("--vehicles", type=int, default=8, help="vehicles in swap/crossing")
    w.add_argument("--quiet", action="store_true", help="no progress line per finished run")
    w.set_defaults(func=_cmd_sweep)
    return p


#: Exit code of a run ended by Ctrl-C (128 + SIGINT, as a shell reports it).
INTERRUPTED_EXIT = 130


def _interrupted(args) -> int:
    """The one line a Ctrl-C ends with: where the run stopped and where its outputs are."""
    out = getattr(args, "out", None)
    where = f"; outputs kept in {out}" if out else ""
    t = None
    if out and (Path(out) / "summary.json").exists():
        try:
            t = json.loads((Path(out) / "summary.json").read_text()).get("simulated_s")
        except (OSError, ValueError):
            t = None
    print(f"interrupted at t = {t:g} s{where}" if t is not None else f"interrupted{where}", file=sys.stderr)
    return INTERRUPTED_EXIT


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except KeyboardInterrupt:
        return _interrupted(args)
    except Exception as exc:  # never a raw traceback for the user; --debug shows it
        if getattr(args, "debug", False):
            raise
        print(f"muvsim {args.command}: {type(exc).__name__}: {exc} (run with --debug for the traceback)",
              file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
