"""muvsim sweep: runs over seeds x options as Dask tasks in worker processes, one KPI table."""

import json
from pathlib import Path
from types import SimpleNamespace

import pandas as pd
import pytest

from bridge.cli import main
from bridge.scenarios import default_controller
from bridge.sumo_world import run_sumo
import bridge.sweep
from bridge.sweep import (ROW_COLUMNS, RunSpec, SweepSettings, SweepSettingsError, format_table, plan, run_one,
                          run_plan, runs_from_dirs, spec_from_summary, sweep)
from sumo_nets.generate import write_sumocfg

SMALL = """\
name = "small"
seed = 1
duration_s = 300.0
tm = "optimal"
check = "union"
switching = "early"
disturbance = "random"

[net]
type = "grid"
junctions = 3
spacing_m = 100.0
lanes = 2

[demand]
vehicles = 10
duration_s = 20.0
class_mix = { car = 0.6, bus = 0.2, truck = 0.2 }
"""

#: Figures that do not depend on the machine (not wall time, not rtf).
DETERMINISTIC = ["vehicles_total", "vehicles_arrived", "collisions_sumo", "collisions_geometric",
                 "invariant_violations", "min_separation_m", "mean_travel_time_s", "mean_delay_s", "stop_commands",
                 "halt_episodes", "time_halted_s", "simulated_s"]


@pytest.fixture(scope="module")
def small_toml(tmp_path_factory):
    """A 3 x 3 junction grid with 10 vehicles (mixed classes), as a scenario file."""
    p = tmp_path_factory.mktemp("sweep-scenario") / "small.toml"
    p.write_text(SMALL)
    return p


def _direct(scenario, out, seed, **kw):
    opts = dict(seed=seed, duration=20.0, tm=None, check=None, switching=None, disturbance=None, solver="exact",
                baseline=None, gui=False, quiet=True, log="none", controller=default_controller(str(scenario)))
    opts.update(kw)
    return run_sumo(str(scenario), out, SimpleNamespace(**opts))


def _value(v):
    return None if v is None or (isinstance(v, float) and v != v) or v is pd.NA else float(v)


def test_sweep_on_local_cluster_equals_direct_runs(small_toml, tmp_path):
    """Two seeds through the local Dask cluster give the figures and per-vehicle tables of two runs done
    directly by run_sumo in this process, each row from the run of its own seed."""
    settings = SweepSettings(scenario=str(small_toml), seeds=(1, 2), out=tmp_path / "sweep", duration_s=20.0,
                             workers=2)
    df = sweep(settings)
    assert list(df.columns[:len(ROW_COLUMNS)]) == list(ROW_COLUMNS)
    assert list(df["label"]) == ["seed1", "seed2"] and list(df["seed"]) == [1, 2]
    assert df["complete"].all(), df["error"].tolist()
    assert df["worker"].notna().all()  # ran on Dask workers, not here
    # options not swept are the scenario's, written into every row
    assert set(df["tm"]) == {"optimal"} and set(df["switching"]) == {"early"} and set(df["check"]) == {"union"}
    direct = {s: _direct(small_toml, tmp_path / f"direct{s}", s) for s in (1, 2)}
    # the two seeds differ, so a sweep that ignored (or swapped) seeds would fail below
    assert any(_value(direct[1].get(k)) != _value(direct[2].get(k)) for k in DETERMINISTIC)
    for _, row in df.iterrows():
        d = direct[row["seed"]]
        assert {k: _value(row[k]) for k in DETERMINISTIC} == {k: _value(d.get(k)) for k in DETERMINISTIC}
        a = pd.read_csv(Path(row["run_dir"]) / "vehicles.csv")
        b = pd.read_csv(tmp_path / f"direct{row['seed']}" / "vehicles.csv")
        pd.testing.assert_frame_equal(a, b)
    written = pd.read_csv(tmp_path / "sweep" / "sweep.csv")
    assert list(written["label"]) == ["seed1", "seed2"]
    assert written["stop_commands"].tolist() == df["stop_commands"].tolist()


def test_failed_runs_are_rows_and_the_others_complete(small_toml, tmp_path):
    """A run whose SUMO net is missing and a run that raises before starting are rows with complete False
    and their error; the muvsim and baseline runs of the same sweep complete."""
    good = plan(SweepSettings(scenario=str(small_toml), seeds=(3,), out=tmp_path, tm=("greedy",),
                              duration_s=20.0, baseline=True))
    routes = tmp_path / "some.rou.xml"
    routes.write_text("<routes/>")
    broken = write_sumocfg(tmp_path / "broken.sumocfg", tmp_path / "missing.net.xml", [routes])
    runs = good + (RunSpec(label="broken", scenario=str(broken), seed=3, tm="optimal", check="union",
                           switching="early", disturbance="random", duration_s=20.0),
                   RunSpec(label="bad-class", scenario="single", seed=0, vclass="no-such-class", duration_s=5.0))
    df = run_plan(runs, tmp_path / "out", workers=2).set_index("label")
    assert list(df.index) == ["seed3", "seed3_baseline-sumo", "broken", "bad-class"]
    assert df.loc["seed3", "complete"] and df.loc["seed3", "tm"] == "greedy"
    assert df.loc["seed3_baseline-sumo", "complete"] and df.loc["seed3_baseline-sumo", "driver"] == "sumo"
    assert df.loc["seed3_baseline-sumo", "collisions_sumo"] == 0
    assert not df.loc["broken", "complete"] and "missing.net.xml" in df.loc["broken", "error"]
    assert not df.loc["bad-class", "complete"] and "no-such-class" in df.loc["bad-class", "error"]
    # the failed SUMO run still left its summary saying why
    s = json.loads((tmp_path / "out" / "broken" / "summary.json").read_text())
    assert s["complete"] is False and "missing.net.xml" in s["error"]
    assert len(pd.read_csv(tmp_path / "out" / "sweep.csv")) == 4


def test_cli_sweep_over_controllers_takes_each_ones_class_and_check(tmp_path, capsys):
    """`muvsim sweep single --controller paper authority`: one run per controller, each with muvsim run's
    class and check for it (paper-a and union; car and timed), both complete."""
    out = tmp_path / "sc"
    rc = main(["sweep", "single", "--out", str(out), "--seeds", "0", "--controller", "paper", "authority",
               "--duration", "5", "--workers", "1", "--quiet"])
    assert rc == 0, capsys.readouterr().out
    df = pd.read_csv(out / "sweep.csv").set_index("label")
    assert df["complete"].all(), df["error"].tolist()
    assert dict(df["controller"]) == {"seed0_controller-paper": "paper", "seed0_controller-authority": "authority"}
    assert dict(df["check"]) == {"seed0_controller-paper": "union", "seed0_controller-authority": "timed"}
    got = {label: json.loads((out / label / "summary.json").read_text())["options"]["vclass"] for label in df.index}
    assert got == {"seed0_controller-paper": "paper-a", "seed0_controller-authority": "car"}


def test_cli_sweep_free_plane_over_seeds_and_options(tmp_path, capsys):
    """`muvsim sweep single` runs seeds x solvers (no SUMO), prints the table and writes sweep.csv."""
    out = tmp_path / "sw"
    rc = main(["sweep", "single", "--out", str(out), "--seeds", "0", "1", "--solver", "exact", "daqp",
               "--duration", "5", "--workers", "2", "--quiet"])
    printed = capsys.readouterr().out
    assert rc == 0, printed
    df = pd.read_csv(out / "sweep.csv")
    assert sorted(df["label"]) == ["seed0_solver-daqp", "seed0_solver-exact", "seed1_solver-daqp",
                                   "seed1_solver-exact"]
    assert df["complete"].all() and (df["vehicles_total"] == 1).all()
    assert set(df["tm"]) == {"optimal"} and set(df["switching"]) == {"early"}  # muvsim run's defaults
    assert "seed1_solver-daqp" in printed and "written:" in printed
    for label in df["label"]:
        assert json.loads((out / label / "summary.json").read_text())["complete"]


def test_cli_sweep_bad_settings_exit_2_naming_the_field(tmp_path, capsys):
    assert main(["sweep", "paper10", "--out", str(tmp_path), "--seeds", "1", "--baseline"]) == 2
    assert "baseline" in capsys.readouterr().err
    assert main(["sweep", "grid", "--out", str(tmp_path), "--seeds", "1", "1"]) == 2
    assert "seeds" in capsys.readouterr().err


@pytest.mark.parametrize("change, field", [
    (dict(seeds=()), "seeds"),
    (dict(seeds=(1, 1)), "seeds"),
    (dict(seeds=(-1,)), r"seeds\[0\]"),
    (dict(seeds=(1.5,)), r"seeds\[0\]"),
    (dict(seeds=5), "seeds"),
    (dict(tm=("fastest",)), "tm"),
    (dict(check="union"), "check"),
    (dict(switching=("early", "early")), "switching"),
    (dict(disturbance=("gusty",)), "disturbance"),
    (dict(solver=("gurobi",)), "solver"),
    (dict(duration_s=0.0), "duration_s"),
    (dict(duration_s=float("nan")), "duration_s"),
    (dict(log="verbose"), "log"),
    (dict(workers=0), "workers"),
    (dict(workers=2, scheduler="tcp://10.0.0.5:8786"), "workers"),
    (dict(scheduler="http://10.0.0.5:8786"), "scheduler"),
    (dict(scheduler="localhost"), "scheduler"),
    (dict(scheduler="tcp://host:99999"), "scheduler"),
    (dict(scenario="no-such-scenario"), "scenario"),
    (dict(scenario="/nonexistent/city.toml"), "scenario"),
    (dict(scenario=""), "scenario"),
    (dict(scenario="swap", baseline=True), "baseline"),
    (dict(baseline="yes"), "baseline"),
    (dict(vehicles=0), "vehicles"),
    (dict(signals=("red",)), "signals"),
    (dict(signals="ignore"), "signals"),
    (dict(signals=("obey", "obey")), "signals"),
    (dict(scenario="swap", signals=("ignore",)), "signals"),
    (dict(pedestrians=("off",)), "pedestrians"),
    (dict(scenario="single", pedestrians=("guard",)), "pedestrians"),
    (dict(controller=("mpc",)), "controller"),
    (dict(controller="authority"), "controller"),
    (dict(controller=("paper", "paper")), "controller"),
    (dict(fresh_process="yes"), "fresh_process"),
])
def test_settings_are_validated_with_the_field_named(change, field, tmp_path):
    kw = dict(scenario="grid", seeds=(1, 2), out=tmp_path)
    kw.update(change)
    with pytest.raises(SweepSettingsError, match=rf"^{field}: "):
        SweepSettings(**kw)


def test_settings_accept_lists_and_plan_labels_the_varied_options(tmp_path):
    s = SweepSettings(scenario="grid", seeds=[4, 2], out=tmp_path / "x", tm=["greedy", "optimal"],
                      check=["timed"], baseline=True, scheduler=" tcp://10.0.0.5:8786 ")
    assert s.seeds == (4, 2) and s.tm == ("greedy", "optimal") and s.scheduler == "tcp://10.0.0.5:8786"
    runs = plan(s)
    assert [r.label for r in runs] == ["seed4_tm-greedy", "seed4_tm-optimal", "seed4_baseline-sumo",
                                       "seed2_tm-greedy", "seed2_tm-optimal", "seed2_baseline-sumo"]
    assert {r.check for r in runs if r.driver == "muvsim"} == {"timed"}
    assert {r.switching for r in runs if r.driver == "muvsim"} == {"early"}  # grid.toml's
    with pytest.raises(SweepSettingsError, match="^label: "):
        RunSpec(label="seed1:sumo", scenario="grid", seed=1)  # SUMO reads host:port in such a path
    with pytest.raises(SweepSettingsError, match="labels must be distinct"):
        run_plan([RunSpec(label="a", scenario="single", seed=0)] * 2, tmp_path)


def test_signals_and_pedestrians_are_run_options_of_sumo_runs_only(tmp_path):
    """Default: muvsim run's (obey, guard) in every muvsim row of a SUMO scenario, none for SUMO's
    drivers or a free-plane scenario; swept values label the runs; RunSpec refuses them where they
    mean nothing, naming the field."""
    runs = plan(SweepSettings(scenario="grid", seeds=(1,), out=tmp_path, baseline=True))
    assert [(r.label, r.signals, r.pedestrians) for r in runs] == [("seed1", "obey", "guard"),
                                                                   ("seed1_baseline-sumo", None, None)]
    assert vars(runs[0].options())["signals"] == "obey" and vars(runs[0].options())["pedestrians"] == "guard"
    runs = plan(SweepSettings(scenario="grid", seeds=(1,), out=tmp_path, signals=["obey", "ignore"],
                              pedestrians=["ignore"]))
    assert [(r.label, r.signals, r.pedestrians) for r in runs] == [("seed1_signals-obey", "obey", "ignore"),
                                                                   ("seed1_signals-ignore", "ignore", "ignore")]
    assert [(r.signals, r.pedestrians) for r in plan(SweepSettings(scenario="swap", seeds=(1,), out=tmp_path))] \
        == [(None, None)]
    for kw, field in ((dict(scenario="single", signals="ignore"), "signals"),
                      (dict(scenario="grid", driver="sumo", pedestrians="guard"), "pedestrians"),
                      (dict(scenario="grid", signals="amber"), "signals")):
        with pytest.raises(SweepSettingsError, match=rf"^{field}: "):
            RunSpec(label="a", seed=1, **kw)


def test_cli_sweep_signals_reach_the_runs(tls_cfg, tmp_path, capsys):
    """`muvsim sweep CFG --signals obey ignore --pedestrians ignore` on a signalised network (real SUMO):
    two runs, each run with the values given (its summary.json), the obey run withholding requests at
    the light and passing no red, the ignore run withholding none."""
    out = tmp_path / "sw"
    rc = main(["sweep", str(tls_cfg), "--out", str(out), "--seeds", "1", "--signals", "obey", "ignore",
               "--pedestrians", "ignore", "--duration", "40", "--workers", "1", "--quiet"])
    printed = capsys.readouterr().out
    assert rc == 0, printed
    df = pd.read_csv(out / "sweep.csv").set_index("label")
    assert list(df.index) == ["seed1_signals-obey", "seed1_signals-ignore"] and df["complete"].all()
    assert df["signals"].tolist() == ["obey", "ignore"] and set(df["pedestrians"]) == {"ignore"}
    obey, ignore = (json.loads((out / lb / "summary.json").read_text()) for lb in df.index)
    assert (obey["options"]["signals"], ignore["options"]["signals"]) == ("obey", "ignore")
    assert obey["options"]["pedestrians"] == ignore["options"]["pedestrians"] == "ignore"
    assert obey["signal_withheld"] > 0 and obey["red_violations"] == 0
    assert ignore["signal_withheld"] == 0


def test_printed_table_is_rounded_as_muvsim_run_prints_figures():
    """analysis/readable.py's rule: seconds (also a mean or p95 of delay_s) to 0.1, ratios (rtf) and
    means of counts to 0.01, counts as integers, missing as '-'; the failed run's error below."""
    df = pd.DataFrame(dict(
        label=["a", "b"], complete=[True, False], vehicles_arrived=pd.array([3, None], dtype="Int64"),
        vehicles_total=pd.array([10, 10], dtype="Int64"), mean_travel_time_s=[60.5172, float("nan")],
        delay_s_mean=[2.66482, float("nan")], delay_s_p95=[7.1234, float("nan")],
        halt_episodes_mean=[1.33333, float("nan")], rtf=[16.327, float("nan")], wall_s=[11.025, 0.31],
        error=[None, "boom"]))
    lines = format_table(df).splitlines()
    assert lines[0].split() == ["label", "complete", "vehicles_arrived", "vehicles_total", "mean_travel_time_s",
                                "delay_s_mean", "delay_s_p95", "halt_episodes_mean", "rtf", "wall_s"]
    assert lines[1].split() == ["a", "yes", "3", "10", "60.5", "2.7", "7.1", "1.33", "16.33", "11.0"]
    assert lines[2].split() == ["b", "no", "-", "10", "-", "-", "-", "-", "-", "0.3"]
    assert lines[3] == "b: boom"


def test_controller_is_a_run_option_authority_by_default_for_sumo(tmp_path):
    """Every muvsim run names its controller (muvsim run's default when not swept: authority for a SUMO
    scenario, paper for a free-plane one) and hands it to the run; swept controllers label the runs;
    SUMO's drivers have none; RunSpec refuses a bad one."""
    runs = plan(SweepSettings(scenario="grid", seeds=(1,), out=tmp_path, baseline=True))
    assert [(r.label, r.controller) for r in runs] == [("seed1", "authority"), ("seed1_baseline-sumo", None)]
    assert vars(runs[0].options())["controller"] == "authority"
    runs = plan(SweepSettings(scenario="grid", seeds=(1,), out=tmp_path, controller=["paper", "authority"],
                              check=["timed"]))
    assert [(r.label, r.controller, r.check) for r in runs] == [("seed1_controller-paper", "paper", "timed"),
                                                                ("seed1_controller-authority", "authority", "timed")]
    assert vars(runs[1].options())["controller"] == "authority"
    assert vars(RunSpec(label="a", scenario="grid", seed=1).options())["controller"] == "authority"
    assert vars(RunSpec(label="a", scenario="single", seed=1).options())["controller"] == "paper"
    assert [r.controller for r in plan(SweepSettings(scenario="single", seeds=(1,), out=tmp_path))] == ["paper"]
    for kw in (dict(controller="mpc"), dict(driver="sumo", controller="paper")):
        with pytest.raises(SweepSettingsError, match="^controller: "):
            RunSpec(label="a", scenario="grid", seed=1, **kw)


def test_fresh_process_runs_equal_runs_here_and_rebuild_from_their_directories(small_toml, tmp_path,
                                                                               monkeypatch):
    """fresh_process: both controllers and SUMO's drivers, each run in a new Python process, give the
    figures and per-vehicle tables of the same runs done here; each summary.json records the controller
    and check asked (timed, not the scenario's union); runs_from_dirs rebuilds the table from the run
    directories alone.  run_one with fresh_process runs in a new process (a run in this one would fail:
    _execute is broken here)."""
    settings = SweepSettings(scenario=str(small_toml), seeds=(1,), out=tmp_path / "sweep", duration_s=20.0,
                             controller=("paper", "authority"), check=("timed",), baseline=True, workers=2,
                             fresh_process=True)
    specs = plan(settings)

    def broken(spec, run_dir):
        raise RuntimeError("ran in the sweep's own process")

    here = {}
    for spec in specs:  # the reference: the same specs run in this process
        here[spec.label] = run_one(spec, tmp_path / "here")
    df = sweep(settings)
    assert list(df["label"]) == ["seed1_controller-paper", "seed1_controller-authority", "seed1_baseline-sumo"]
    assert df["complete"].all(), df["error"].tolist()
    assert df["worker"].notna().all()
    for _, row in df.iterrows():
        ref = here[row["label"]]
        assert ref["complete"]
        assert {k: _value(row[k]) for k in DETERMINISTIC} == {k: _value(ref[k]) for k in DETERMINISTIC}
        pd.testing.assert_frame_equal(pd.read_csv(Path(row["run_dir"]) / "vehicles.csv"),
                                      pd.read_csv(tmp_path / "here" / row["label"] / "vehicles.csv"))
        summary = json.loads((Path(row["run_dir"]) / "summary.json").read_text())
        if row["driver"] == "muvsim":
            assert (summary["options"]["controller"], summary["options"]["check"]) == (row["controller"], "timed")
        else:
            assert summary["baseline"] == "sumo" and pd.isna(row["controller"])
    assert df.loc[df["driver"] == "muvsim", "controller"].tolist() == ["paper", "authority"]
    rebuilt = runs_from_dirs(tmp_path / "sweep").set_index("label")
    ran = df.set_index("label").loc[rebuilt.index]
    pd.testing.assert_frame_equal(rebuilt.drop(columns=["worker"]), ran.drop(columns=["worker"]))
    monkeypatch.setattr(bridge.sweep, "_execute", broken)
    assert run_one(specs[0], tmp_path / "here", fresh_process=False)["error"] == \
        "RuntimeError: ran in the sweep's own process"
    row = run_one(specs[1], tmp_path / "direct", fresh_process=True)
    assert row["complete"] and row["controller"] == "authority" and row["worker"] is None
    assert {k: _value(row[k]) for k in DETERMINISTIC} == {k: _value(here[specs[1].label][k]) for k in DETERMINISTIC}
    with pytest.raises(SweepSettingsError, match="no run directory"):
        runs_from_dirs(tmp_path / "nothing")
    with pytest.raises(SweepSettingsError, match="no scenario or seed"):
        spec_from_summary("x", {"options": {}})


def test_a_fresh_run_process_that_dies_is_a_failed_row(tmp_path, monkeypatch):
    """The process of a fresh run exiting without a row (a crash, a signal) makes a failed row naming its
    exit code and the end of its error output."""
    monkeypatch.setattr(bridge.sweep, "_CHILD_CODE", "import sys; sys.stderr.write('boom'); sys.exit(3)")
    row = run_one(RunSpec(label="dead", scenario="single", seed=0, duration_s=5.0), tmp_path, fresh_process=True)
    assert row["complete"] is False and row["error"] == "run process exited with code 3: boom"
    assert row["label"] == "dead" and row["controller"] == "paper"
