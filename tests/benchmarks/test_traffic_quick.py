"""benchmarks/bench_traffic.py runs in quick mode and writes its table; its per-combination means are right."""

import importlib.util
import math
import subprocess
import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks" / "bench_traffic.py"
COLUMNS = {"scenario", "driver", "switching", "check", "policy", "seeds", "complete", "arrived", "delay_mean_s",
           "delay_p95_s", "halts_per_vehicle", "time_halted_s", "tm_stops", "collisions_sumo",
           "collisions_geometric", "invariant_violations", "throughput_vph", "rtf", "wall_s"}


def test_traffic_benchmark_quick_mode_writes_its_table(tmp_path):
    out = tmp_path / "result.csv"
    proc = subprocess.run([sys.executable, str(SCRIPT), "--quick", "--out", str(out)],
                          capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-2000:]
    df = pd.read_csv(out)
    assert COLUMNS <= set(df.columns)
    # two muvsim combinations (greedy, optimal) and SUMO's drivers, each from one complete run
    assert sorted(zip(df["driver"], df["policy"])) == [("muvsim", "greedy"), ("muvsim", "optimal"), ("sumo", "-")]
    assert (df["seeds"] == 1).all() and (df["complete"] == 1).all()
    assert (df["collisions_sumo"] == 0).all()
    runs = pd.read_csv(tmp_path / "result_runs.csv")
    assert len(runs) == 3 and runs["complete"].all()
    assert proc.stdout.strip()  # it prints its figures too


def _bench():
    spec = importlib.util.spec_from_file_location("bench_traffic", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_combination_table_means_over_complete_seeds():
    """Means are over the seeds of one combination; a failed run is counted, not averaged; SUMO's
    drivers form their own row whatever options their runs carry."""
    nan = float("nan")
    base = dict(vehicles_arrived=0, delay_s_mean=nan, delay_s_p95=nan, halt_episodes_mean=nan,
                time_halted_s_mean=nan, stop_commands=0, collisions_sumo=0, collisions_geometric=0,
                invariant_violations=0, throughput_vph=0.0, rtf=1.0, wall_s=1.0)

    def run(driver, tm, seed, complete=True, **kw):
        return {**base, "driver": driver, "tm": tm, "check": "union" if driver == "muvsim" else None,
                "switching": "early" if driver == "muvsim" else None, "seed": seed, "complete": complete, **kw}

    runs = pd.DataFrame([
        run("muvsim", "greedy", 1, vehicles_arrived=10, delay_s_mean=20.0, delay_s_p95=40.0, stop_commands=100),
        run("muvsim", "greedy", 2, vehicles_arrived=20, delay_s_mean=30.0, delay_s_p95=60.0, stop_commands=300),
        run("muvsim", "greedy", 3, complete=False, vehicles_arrived=nan, stop_commands=nan),
        run("muvsim", "optimal", 1, vehicles_arrived=5, delay_s_mean=nan, stop_commands=7),
        run("sumo", None, 1, vehicles_arrived=50, delay_s_mean=5.0, halt_episodes_mean=1.5, stop_commands=None),
    ])
    runs["stop_commands"] = runs["stop_commands"].astype("Int64")
    t = _bench().combination_table(runs, "city").set_index(["driver", "policy"])
    g = t.loc[("muvsim", "greedy")]
    assert (g["seeds"], g["complete"]) == (3, 2)
    assert (g["arrived"], g["delay_mean_s"], g["delay_p95_s"], g["tm_stops"]) == (15.0, 25.0, 50.0, 200.0)
    o = t.loc[("muvsim", "optimal")]
    assert o["arrived"] == 5.0 and math.isnan(o["delay_mean_s"]) and o["tm_stops"] == 7.0
    s = t.loc[("sumo", "-")]
    assert s["switching"] == "-" and s["halts_per_vehicle"] == 1.5 and math.isnan(s["tm_stops"])
    assert set(t["scenario"]) == {"city"}
