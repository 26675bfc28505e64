"""benchmarks/bench_scenarios.py runs SUMO's demo scenarios (quick: cross, square, 20 s) and writes its table."""

import subprocess
import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks" / "bench_scenarios.py"


def test_scenarios_benchmark_quick_mode_writes_its_table(tmp_path):
    out = tmp_path / "scenarios.csv"
    proc = subprocess.run([sys.executable, str(SCRIPT), "--quick", "--controller", "authority", "--out", str(out),
                           "--runs", str(tmp_path / "r")],
                          capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-2000:]
    df = pd.read_csv(out)
    assert sorted(zip(df["scenario"], df["driver"])) == [("cross", "muvsim"), ("cross", "sumo"),
                                                         ("square", "muvsim"), ("square", "sumo")]
    assert df["complete"].all() and (df["collisions_sumo"] == 0).all()
    # the controller asked for; SUMO's drivers have none
    assert set(zip(df["driver"], df["controller"])) == {("muvsim", "authority"), ("sumo", "-")}
    m = df[df["driver"] == "muvsim"].set_index("scenario")
    assert (m["demand"] > 0).all() and (m["invariant_violations"] == 0).all()
    # lights obeyed by default, and the run's red-light counter recorded (cross is signalised)
    assert (m["signals"] == "obey").all() and (m["red_violations"] == 0).all()
    # both drivers of a scenario share one demand (SUMO's expansion in the window)
    assert (df.groupby("scenario")["demand"].nunique() == 1).all()
    # the figures are the runs' own
    import json
    s = json.loads((tmp_path / "r" / "square-muvsim-authority" / "summary.json").read_text())
    assert m.loc["square", "demand"] == s["vehicles_total"] and m.loc["square", "rtf"] == s["rtf"]
    assert (m.loc["square", "stopped_at_end"], m.loc["square", "gridlocked_at_end"]) == (
        s["stopped_at_end"], s["gridlocked_at_end"])
    assert s["options"]["controller"] == "authority"


def test_an_unknown_scenario_is_refused_by_name(tmp_path):
    proc = subprocess.run([sys.executable, str(SCRIPT), "--only", "nosuch", "--out", str(tmp_path / "x.csv")],
                          capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert proc.returncode == 2 and "unknown scenario(s) nosuch" in proc.stderr and "tlsgrid" in proc.stderr
    assert not (tmp_path / "x.csv").exists()
