"""benchmarks/bench_turn.py: its road-frame loop is Cosim's own step, checked step for step.

The benchmark steps one car on a ``_Group`` by hand (requests through ``_Group.request``, as the
co-simulation asks) and compares every state with ``Cosim`` on the same route and seed; the check
stopped the script after the path frame became authority mode's default (``Cosim`` ran the path
frame, the loop the road frame: a state difference of 208).  Run here on one radius and seed."""

import subprocess
import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks" / "bench_turn.py"


def test_bench_turn_reproduces_cosim_and_writes_both_frames(tmp_path):
    out = tmp_path / "turn.csv"
    p = subprocess.run([sys.executable, str(SCRIPT), "--radii", "15", "--seeds", "0", "--out", str(out)],
                       cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    assert "does not reproduce" not in p.stdout + p.stderr
    df = pd.read_csv(out)
    assert sorted(df["frame"]) == ["path", "road"] and (df["index_violations"] == 0).all()
    # the path frame takes the turn near its curve speed, the road frame crawls (README turn table)
    road, path = (df[df["frame"] == f].iloc[0] for f in ("road", "path"))
    assert path["v_min_window_mps"] > 0.9 * path["v_curve_min_mps"] > road["v_min_window_mps"]
