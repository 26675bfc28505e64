"""benchmarks/bench_scale.py runs in quick mode and writes its table; its sizing and window figures are right."""

import importlib.util
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks" / "bench_scale.py"
COLUMNS = {"target", "junctions", "demand", "active_max", "active_mean", "sumo_s_per_sim_s",
           "sumo_move_s_per_sim_s", "sumo_step_s_per_sim_s", "sumo_insert_s_per_sim_s", "controllers_s_per_sim_s",
           "tm_s_per_sim_s", "monitor_s_per_sim_s", "logging_s_per_sim_s", "other_s_per_sim_s", "total_s_per_sim_s",
           "rtf_window", "rtf", "wall_s", "controller_us_per_vehicle_step", "tm_ms_per_decision", "peak_rss_mb",
           "sumo_wall_s", "sumo_rtf", "sumo_peak_rss_mb", "wall_ratio", "simulated_s", "sumo_simulated_s",
           "machine", "cpus", "command", "complete"}
PARTS = ["sumo", "controllers", "tm", "monitor", "logging", "other"]


def _bench():
    spec = importlib.util.spec_from_file_location("bench_scale", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["bench_scale"] = mod  # dataclasses look their module up
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("controller", ["paper", "authority"])
def test_scale_benchmark_quick_mode_writes_its_table(tmp_path, controller):
    out = tmp_path / "result.csv"
    proc = subprocess.run([sys.executable, str(SCRIPT), "--quick", "--controller", controller, "--out", str(out),
                           "--runs", str(tmp_path / "runs")], capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-2000:] + proc.stdout[-2000:]
    df = pd.read_csv(out)
    assert COLUMNS <= set(df.columns)
    assert len(df) == 1
    r = df.iloc[0]
    assert r["complete"] and (r["target"], r["junctions"]) == (30, 3)
    # the muvsim run was driven by the controller asked for, and the row says which
    import json
    (summary,) = (tmp_path / "runs").glob("*/muvsim/summary.json")
    options = json.loads(summary.read_text())["options"]
    assert r["controller"] == controller == options["controller"]
    # with the controller's own tube check (the scenario pins none): timed for authority, union for paper
    assert options["check"] == {"paper": "union", "authority": "timed"}[controller]
    assert 0 < r["active_mean"] <= r["active_max"] <= r["demand"]
    assert r["simulated_s"] == r["sumo_simulated_s"] == 20.0
    # the components, other included, add up to the measured total; all but "other" are >= 0
    parts = sum(r[f"{k}_s_per_sim_s"] for k in PARTS)
    assert parts == pytest.approx(r["total_s_per_sim_s"], rel=1e-9)
    assert all(r[f"{k}_s_per_sim_s"] >= 0 for k in PARTS[:-1]) and r["logging_s_per_sim_s"] > 0
    assert r["sumo_s_per_sim_s"] == pytest.approx(
        r["sumo_move_s_per_sim_s"] + r["sumo_step_s_per_sim_s"] + r["sumo_insert_s_per_sim_s"])
    assert r["rtf_window"] == pytest.approx(1 / r["total_s_per_sim_s"])
    assert r["peak_rss_mb"] > 50 and r["sumo_peak_rss_mb"] > 50
    assert r["wall_ratio"] == pytest.approx(r["wall_s"] / r["sumo_wall_s"])
    assert r["cpus"] >= 1 and "bench_scale.py --quick" in r["command"]
    assert proc.stdout.strip() and "command:" in proc.stdout  # it prints its figures and how they were made


def test_sizing_gives_room_for_the_target_and_a_valid_scenario(tmp_path):
    from sumo_nets.scenario import load_scenario

    b = _bench()
    assert [b.junctions_for(n) for n in (30, 100, 300, 1000, 3000)] == [3, 4, 6, 11, 19]
    for n in (30, 100, 300, 1000, 3000):
        j = b.junctions_for(n)
        assert b.directed_edges(j) * b.VEHICLES_PER_EDGE >= n
        assert j == b.MIN_JUNCTIONS or b.directed_edges(j - 1) * b.VEHICLES_PER_EDGE < n
    case = b.case_for(300, window_s=120.0, warmup_s=30.0, seed=4)
    path = tmp_path / "s.toml"
    path.write_text(b.scenario_toml(case))
    sc = load_scenario(path)  # the schema validates it
    assert (sc.net.junctions, sc.demand.vehicles, sc.duration_s, sc.seed) == (6, 330, 150.0, 4)
    assert sc.check is None  # each controller runs with its own default check (tm.settings.default_check)
    assert sc.demand.duration_s == 30.0 and sc.demand.fringe_factor == 1.0
    assert tomllib.loads(path.read_text())["demand"]["class_mix"] == b.CLASS_MIX
    with pytest.raises(ValueError, match="size"):
        b.case_for(0, 120.0, 30.0)


def test_window_figures_split_the_step_time():
    """Synthetic steps: known per-step times give known per-simulated-second figures."""
    b = _bench()
    n = 21  # t = 0.0 .. 2.0 s; the first step has no measured start and the window starts at 1.0 s
    steps = pd.DataFrame({"t_s": np.arange(n) * 0.1, "active": np.r_[np.arange(10), np.full(11, 10)],
                          "requests": 4, "grants": 2, "tm_ms": 2.0, "tm_decide_ms": np.r_[np.zeros(15), np.ones(6)],
                          "controller_ms": 3.0, "world_ms": 5.0, "logging_ms": 1.0})
    timed = pd.DataFrame({"wall_ms": np.r_[np.nan, np.full(n - 1, 20.0)], "sumo_move_ms": 1.5,
                          "sumo_step_ms": 2.5, "sumo_insert_ms": 0.5})
    f = b.window_figures(steps, timed, warmup_s=1.0, Ts=0.1)
    assert f["window_steps"] == 11 and f["window_sim_s"] == pytest.approx(1.1)
    assert (f["active_max"], f["active_mean"]) == (10, 10.0)
    # per step: total 20, SUMO 1.5 + 2.5 + 0.5 = 4.5, monitor 5 - 4 = 1, other 20 - 4.5 - 3 - 2 - 1 - 1 = 8.5
    expect = {"sumo": 4.5, "controllers": 3.0, "tm": 2.0, "monitor": 1.0, "logging": 1.0, "other": 8.5}
    for k, ms in expect.items():
        assert f[f"{k}_s_per_sim_s"] == pytest.approx(ms / 100), k  # ms per 0.1 s step -> s per s
        assert f[f"{k}_share"] == pytest.approx(ms / 20.0), k
    assert f["total_s_per_sim_s"] == pytest.approx(0.2) and f["rtf_window"] == pytest.approx(5.0)
    assert f["controller_us_per_vehicle_step"] == pytest.approx(300.0)
    assert f["decisions"] == 6 and f["tm_decide_ms_per_decision"] == 1.0 and f["tm_ms_per_decision"] == 2.0
    assert f["controller_us_per_vehicle_step_median"] == pytest.approx(300.0)
    assert f["tm_decide_ms_median"] == 1.0
    # request indices (timed inside tm_ms) move from the TM to the controllers
    f2 = b.window_figures(steps.assign(request_ms=0.5, gate_ms=0.25), timed, warmup_s=1.0, Ts=0.1)
    assert f2["controllers_s_per_sim_s"] == pytest.approx(3.5 / 100)
    assert f2["tm_s_per_sim_s"] == pytest.approx(1.5 / 100)
    assert f2["other_s_per_sim_s"] == pytest.approx(f["other_s_per_sim_s"])
    assert f2["controller_us_per_vehicle_step"] == pytest.approx(350.0)
    assert f2["tm_ms_per_decision"] == 1.5 and f2["tm_gate_ms_per_decision"] == 0.25
    assert f2["request_ms_per_decision"] == 0.5
    with pytest.raises(ValueError, match="rows"):
        b.window_figures(steps, timed.iloc[:-1], warmup_s=1.0, Ts=0.1)
    with pytest.raises(ValueError, match="window"):
        b.window_figures(steps, timed, warmup_s=5.0, Ts=0.1)
