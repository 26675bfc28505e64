"""SUMO's own demo scenarios, unchanged, driven by muvsim and by SUMO's drivers (``--baseline sumo``).

Usage: python benchmarks/bench_scenarios.py [--quick] [--duration S] [--only NAME ...]
                                            [--out benchmarks/results/scenarios.csv]

Runs every scenario of ``$SUMO_HOME/tools/game`` that is a road scenario (cross, square, grid6,
corridor, ramp, fkk_in, A10KW, bs3d, fokr_bs_demo) with no option but ``--duration`` (default
180 s: the first 180 s of the configuration's window), once per driver, each in its own process
(libsumo runs one simulation per process), and writes one row per scenario and driver: demand
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
COLUMNS = ["scenario", "driver", "duration_s", "complete", "demand", "undrivable", "arrived", "mean_delay_s",
           "mean_travel_time_s", "halt_episodes", "collisions_sumo", "collisions_geometric",
           "invariant_violations", "signals", "red_violations", "rtf", "wall_s", "error"]


def _row(name: str, driver: str, duration: float, out: Path, rc: int, stderr: str) -> dict:
    f = out / "summary.json"
    s = json.loads(f.read_text()) if f.exists() else {}
    demand = s.get("vehicles_total")  # None for SUMO's drivers: the caller fills in muvsim's (the same demand)
    return {"scenario": name, "driver": driver, "duration_s": duration, "complete": bool(s.get("complete")),
            "demand": demand, "undrivable": s.get("vehicles_undrivable"), "arrived": s.get("vehicles_arrived"),
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
    ap.add_argument("--out", default="benchmarks/results/scenarios.csv")
    ap.add_argument("--runs", default=None, help="keep the run directories here (default: a temporary one)")
    args = ap.parse_args(argv)
    from sumo_nets.sumo_tools import sumo_home

    game = sumo_home() / "tools" / "game"
    names = args.only or (["cross", "square"] if args.quick else list(GAME))
    duration = args.duration or (20.0 if args.quick else 180.0)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        runs = Path(args.runs) if args.runs else Path(tmp)
        for name in names:
            for driver in ("muvsim", "sumo"):
                out = runs / f"{name}-{driver}"
                cmd = [sys.executable, "-m", "bridge.cli", "run", str(game / f"{name}.sumocfg"), "--out", str(out),
                       "--duration", f"{duration:g}", "--quiet", "--log", "none"]
                if driver == "sumo":
                    cmd += ["--baseline", "sumo"]
                proc = subprocess.run(cmd, capture_output=True, text=True)
                row = _row(name, driver, duration, out, proc.returncode, proc.stderr)
                if driver == "sumo":
                    row["demand"] = rows[-1]["demand"] if rows and rows[-1]["scenario"] == name else None
                rows.append(row)
                print(f"{name:<14} {driver:<7} arrived {row['arrived']}/{row['demand']} collisions_sumo "
                      f"{row['collisions_sumo']} rtf {row['rtf']} {row['error'][:120]}", flush=True)
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
