"""SUMO's own demo scenarios, unchanged, driven by muvsim and by SUMO's drivers (``--baseline sumo``).

Usage: python benchmarks/bench_scenarios.py [--quick] [--duration S] [--only NAME ...]
                                            [--controller paper|authority|both]
                                            [--out benchmarks/results/scenarios.csv]

Runs every scenario of ``$SUMO_HOME/tools/game`` that is a road scenario (cross, square, grid6,
corridor, ramp, fkk_in, A10KW, bs3d, fokr_bs_demo) and ``tlsgrid``, a signalised city grid
generated into the runs directory by SUMO's own tools (:func:`sumo_nets.tls_grid.make_tls_grid`:
``netgenerate --grid --grid.number 4 --grid.length 150 --default.lanenumber 2 --tls.guess``,
``randomTrips.py -e 180 -p 2.0 --seed 3 --validate``, a plain .sumocfg), with no option but
``--duration`` and ``--controller`` (default 180 s: the first 180 s of the configuration's window), once per driver,
each in its own process (libsumo runs one simulation per process), and writes one row per
scenario, driver and controller (``--controller``: muvsim's mode, passed to every muvsim run;
default ``both``: paper and authority rows; SUMO's drivers: ``-``): demand
in the window, undrivable vehicles, arrivals, mean delay and travel time of the arrived, halts,
collisions (SUMO's, geometric), invariant violations, the signals mode and red-light
violations (muvsim's ``--signals``, default obey; ``sumo`` for SUMO's drivers), rtf and wall time, or the run's error.
``--quick``: cross and square, 20 s (used by the tests).  One run per row, one machine.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import pandas as pd

GAME = ("cross", "square", "grid6", "corridor", "ramp", "fkk_in", "A10KW", "bs3d", "fokr_bs_demo")
GENERATED = ("tlsgrid",)  # made into the runs directory by sumo_nets.tls_grid
COLUMNS = ["scenario", "driver", "controller", "duration_s", "complete", "demand", "undrivable", "arrived", "stopped_at_end",
           "gridlocked_at_end", "mean_delay_s", "mean_travel_time_s", "halt_episodes", "collisions_sumo", "collisions_geometric",
           "invariant_violations", "signals", "red_violations", "rtf", "wall_s", "error"]


def _row(name: str, driver: str, controller: str, duration: float, out: Path, rc: int, stderr: str) -> dict:
    f = out / "summary.json"
    s = json.loads(f.read_text()) if f.exists() else {}
    demand = s.get("vehicles_total")  # None for SUMO's drivers: the caller fills in muvsim's (the same demand)
    return {"scenario": name, "driver": driver, "controller": controller, "duration_s": duration, "complete": bool(s.get("complete")),
            "demand": demand, "undrivable": s.get("vehicles_undrivable"), "arrived": s.get("vehicles_arrived"),
            "stopped_at_end": s.get("stopped_at_end"), "gridlocked_at_end": s.get("gridlocked_at_end"),
            "mean_delay_s": s.get("mean_delay_s"), "mean_travel_time_s": s.get("mean_travel_time_s"),
            "halt_episodes": s.get("halt_episodes"), "collisions_sumo": s.get("collisions_sumo"),
            "collisions_geometric": s.get("collisions_geometric"),
            "invariant_violations": s.get("invariant_violations"),
            # muvsim: its --signals mode (obey by default); SUMO's drivers always obey their own signals
            "signals": (s.get("options") or {}).get("signals") or ("sumo" if driver == "sumo" else None),
            "red_violations": s.get("red_violations"), "rtf": s.get("rtf"), "wall_s": s.get("wall_s"),
            "error": (s.get("error") or ("" if rc == 0 else stderr.strip()[-300:])).replace("\n", " ")}


def main(argv=None) -> pd.DataFrame:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="cross and square, 20 s (used by the tests)")
    ap.add_argument("--duration", type=float, default=None, help="simulated seconds (default 180; quick 20)")
    ap.add_argument("--only", nargs="+", default=None, metavar="NAME", help="only these scenarios")
    ap.add_argument("--controller", choices=["paper", "authority", "both"], default="both",
                    help="muvsim's --controller (default both: paper and authority rows)")
    ap.add_argument("--out", default="benchmarks/results/scenarios.csv")
    ap.add_argument("--runs", default=None, help="keep the run directories here (default: a temporary one)")
    args = ap.parse_args(argv)
    from sumo_nets.sumo_tools import sumo_home

    game = sumo_home() / "tools" / "game"
    names = args.only or (["cross", "square"] if args.quick else [*GAME, *GENERATED])
    unknown = sorted(set(names) - set(GAME) - set(GENERATED))
    if unknown:
        ap.error(f"--only: unknown scenario(s) {', '.join(unknown)}; valid: {', '.join([*GAME, *GENERATED])}")
    duration = args.duration or (20.0 if args.quick else 180.0)
    controllers = ["paper", "authority"] if args.controller == "both" else [args.controller]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        runs = Path(args.runs) if args.runs else Path(tmp)
        for name in names:
            if name in GENERATED:
                from sumo_nets.tls_grid import make_tls_grid

                cfg = make_tls_grid(runs / f"{name}-scenario")
            else:
                cfg = game / f"{name}.sumocfg"
            demand = None
            for driver, controller in [*(("muvsim", c) for c in controllers), ("sumo", "-")]:
                out = runs / (f"{name}-sumo" if driver == "sumo" else
                              f"{name}-muvsim" + ("" if controller == "paper" else f"-{controller}"))
                cmd = [sys.executable, "-m", "bridge.cli", "run", str(cfg), "--out", str(out),
                       "--duration", f"{duration:g}", "--quiet", "--log", "none"]
                if driver == "sumo":
                    cmd += ["--baseline", "sumo"]
                else:
                    cmd += ["--controller", controller]
                proc = subprocess.run(cmd, capture_output=True, text=True)
                row = _row(name, driver, controller, duration, out, proc.returncode, proc.stderr)
                if driver == "sumo":
                    row["demand"] = demand  # muvsim's: the same demand (SUMO's expansion in the window)
                elif demand is None:
                    demand = row["demand"]
                rows.append(row)
                print(f"{name:<14} {driver:<7} {controller:<9} arrived {row['arrived']}/{row['demand']} "
                      f"collisions_sumo {row['collisions_sumo']} geometric {row['collisions_geometric']} "
                      f"invariant {row['invariant_violations']} red {row['red_violations']} rtf {row['rtf']} "
                      f"{row['error'][:120]}", flush=True)
    df = pd.DataFrame(rows, columns=COLUMNS)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(out, index=False)
    with pd.option_context("display.width", 200, "display.max_columns", 20):
        print(df.drop(columns=["error"]).to_string(index=False))
    print(f"written: {out}")
    return df


if __name__ == "__main__":
    main()
