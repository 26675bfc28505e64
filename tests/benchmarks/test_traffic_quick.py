"""benchmarks/bench_traffic.py runs in quick mode (paper and authority controllers, SUMO's drivers) and
writes its table; its per-combination means are right; --from-runs rebuilds the same table."""

import importlib.util
import json
import math
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks" / "bench_traffic.py"
COLUMNS = {"scenario", "driver", "controller", "switching", "check", "policy", "seeds", "complete", "demand",
           "arrived", "simulated_s", "delay_mean_s", "delay_p95_s", "halts_per_vehicle", "time_halted_s", "tm_stops",
           "collisions_sumo", "collisions_geometric", "invariant_violations", "throughput_vph", "rtf", "wall_s"}
#: The quick run's rows (driver, controller, switching, check, policy), in the table's order.
QUICK_ROWS = [("muvsim", "paper", "early", "timed", "optimal"), ("muvsim", "authority", "early", "union", "optimal"),
              ("muvsim", "authority", "early", "timed", "optimal"), ("sumo", "-", "-", "-", "-")]
KEYS = ["driver", "controller", "switching", "check", "policy"]


def test_traffic_benchmark_quick_mode_writes_its_table(tmp_path):
    """Quick mode (seed 1, 20 simulated s): the paper controller's default variant, the authority
    controller with both checks and SUMO's drivers, one complete run each, each run in a process of its
    own; every run's summary.json records the options asked (grid.toml's own check is union, so the
    timed rows show the check reaches the run); --from-runs rebuilds the same tables from the kept runs."""
    out, runs_dir = tmp_path / "result.csv", tmp_path / "runs"
    proc = subprocess.run([sys.executable, str(SCRIPT), "--quick", "--workers", "2", "--runs", str(runs_dir),
                           "--out", str(out)], capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-2000:]
    df = pd.read_csv(out)
    assert COLUMNS <= set(df.columns)
    assert [tuple(r) for r in df[KEYS].itertuples(index=False)] == QUICK_ROWS
    assert (df["seeds"] == 1).all() and (df["complete"] == 1).all()
    assert (df["collisions_sumo"] == 0).all() and (df["demand"] == 150).all()
    assert (df["simulated_s"] <= 20.0 + 1e-9).all()
    runs = pd.read_csv(tmp_path / "result_runs.csv")
    assert len(runs) == 4 and runs["complete"].all() and (runs["seed"] == 1).all()
    for _, r in runs.iterrows():
        s = json.loads((Path(r["run_dir"]) / "summary.json").read_text())
        assert s["seed"] == 1 and s["complete"]
        if r["driver"] == "muvsim":
            o = s["options"]
            assert (o["controller"], o["switching"], o["check"], o["tm"]) == \
                (r["controller"], r["switching"], r["check"], r["tm"])
            assert r["label"] == f"seed1_{o['controller']}_{o['switching']}_{o['check']}_{o['tm']}"
        else:
            assert s["baseline"] == "sumo" and r["label"] == "seed1_baseline-sumo"
    assert proc.stdout.strip()  # it prints its figures too

    again = tmp_path / "again.csv"
    proc = subprocess.run([sys.executable, str(SCRIPT), "--from-runs", str(runs_dir), "--out", str(again)],
                          capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-2000:]
    pd.testing.assert_frame_equal(pd.read_csv(again), df)
    rebuilt = pd.read_csv(tmp_path / "again_runs.csv").set_index("label").sort_index()
    ran = runs.set_index("label").sort_index()
    pd.testing.assert_frame_equal(rebuilt.drop(columns=["worker"]), ran.drop(columns=["worker"]))


def _bench():
    spec = importlib.util.spec_from_file_location("bench_traffic", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_combination_table_means_over_complete_seeds():
    """Means are over the seeds of one combination; a failed run is counted, not averaged; the two
    controllers are separate rows; SUMO's drivers form their own row, last, whatever options their
    runs carry."""
    nan = float("nan")
    base = dict(vehicles_total=150, vehicles_arrived=0, simulated_s=900.0, delay_s_mean=nan, delay_s_p95=nan,
                halt_episodes_mean=nan, time_halted_s_mean=nan, stop_commands=0, collisions_sumo=0,
                collisions_geometric=0, invariant_violations=0, throughput_vph=0.0, rtf=1.0, wall_s=1.0)

    def run(driver, tm, seed, complete=True, controller="paper", **kw):
        mu = driver == "muvsim"
        return {**base, "driver": driver, "controller": controller if mu else None, "tm": tm,
                "check": "union" if mu else None, "switching": "early" if mu else None, "seed": seed,
                "complete": complete, **kw}

    runs = pd.DataFrame([
        run("sumo", None, 1, vehicles_arrived=50, delay_s_mean=5.0, halt_episodes_mean=1.5, stop_commands=None,
            simulated_s=380.0),
        run("muvsim", "optimal", 1, controller="authority", vehicles_arrived=150, simulated_s=500.0),
        run("muvsim", "optimal", 2, controller="authority", vehicles_arrived=140),
        run("muvsim", "greedy", 1, vehicles_arrived=10, delay_s_mean=20.0, delay_s_p95=40.0, stop_commands=100),
        run("muvsim", "greedy", 2, vehicles_arrived=20, delay_s_mean=30.0, delay_s_p95=60.0, stop_commands=300),
        run("muvsim", "greedy", 3, complete=False, vehicles_arrived=nan, stop_commands=nan),
        run("muvsim", "optimal", 1, vehicles_arrived=5, delay_s_mean=nan, stop_commands=7),
    ])
    runs["stop_commands"] = runs["stop_commands"].astype("Int64")
    table = _bench().combination_table(runs, "city")
    assert [tuple(r) for r in table[["driver", "controller", "policy"]].itertuples(index=False)] == [
        ("muvsim", "paper", "greedy"), ("muvsim", "paper", "optimal"), ("muvsim", "authority", "optimal"),
        ("sumo", "-", "-")]
    t = table.set_index(["driver", "controller", "policy"])
    g = t.loc[("muvsim", "paper", "greedy")]
    assert (g["seeds"], g["complete"]) == (3, 2)
    assert (g["arrived"], g["delay_mean_s"], g["delay_p95_s"], g["tm_stops"]) == (15.0, 25.0, 50.0, 200.0)
    o = t.loc[("muvsim", "paper", "optimal")]
    assert o["arrived"] == 5.0 and math.isnan(o["delay_mean_s"]) and o["tm_stops"] == 7.0
    a = t.loc[("muvsim", "authority", "optimal")]
    assert (a["seeds"], a["arrived"], a["simulated_s"], a["demand"]) == (2, 145.0, 700.0, 150.0)
    s = t.loc[("sumo", "-", "-")]
    assert s["switching"] == "-" and s["halts_per_vehicle"] == 1.5 and math.isnan(s["tm_stops"])
    assert s["simulated_s"] == 380.0
    assert set(t["scenario"]) == {"city"}
    # a run table from before the controller column: the paper controller's
    old = _bench().combination_table(runs[runs["controller"] != "authority"].drop(columns=["controller"]), "city")
    assert list(old["controller"]) == ["paper", "paper", "-"]


def test_plan_gives_every_run_all_its_options_and_names_them():
    """Paper variants as asked (default early/timed/optimal, `all` the 8), authority one run per check
    (switching early, policy optimal), SUMO's drivers once per seed; every muvsim option explicit."""
    b = _bench()
    runs = b.plan_runs("grid", [1, 2], 900.0, ["paper", "authority"], b.paper_variants(b.PAPER_DEFAULT),
                       ["union", "timed"])
    assert [r.label for r in runs] == [
        "seed1_paper_early_timed_optimal", "seed1_authority_early_union_optimal",
        "seed1_authority_early_timed_optimal", "seed1_baseline-sumo",
        "seed2_paper_early_timed_optimal", "seed2_authority_early_union_optimal",
        "seed2_authority_early_timed_optimal", "seed2_baseline-sumo"]
    for r in runs:
        assert r.duration_s == 900.0
        if r.driver == "muvsim":
            assert None not in (r.controller, r.switching, r.check, r.tm)
            assert vars(r.options())["check"] == r.check and vars(r.options())["controller"] == r.controller
        else:
            assert r.controller is None and r.check is None
    assert len(b.paper_variants(["all"])) == 8 == len(set(b.paper_variants(["all"])))
    only = b.plan_runs("grid", [3], 20.0, ["authority"], [], ["timed"])
    assert [r.label for r in only] == ["seed3_authority_early_timed_optimal", "seed3_baseline-sumo"]
    with pytest.raises(Exception, match="SWITCHING/CHECK/POLICY"):
        b.paper_variants(["early/fast/optimal"])
