"""benchmarks/bench_lane.py runs in quick mode (real SUMO on a lane it writes) and writes its table."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[2]
COLUMNS = {"driver", "check", "experiment", "flow_vph", "t20_s", "crossed", "claim_overlaps", "footprint_overlaps",
           "invariant_violations", "collisions", "sim_s", "wall_s"}


def test_lane_benchmark_quick_mode(tmp_path):
    out = tmp_path / "lane.csv"
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_lane.py"), "--quick", "--out", str(out),
                           "--cache-dir", str(tmp_path / "cache")], capture_output=True, text=True, timeout=600,
                          cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "flow" in proc.stdout
    df = pd.read_csv(out)
    assert COLUMNS <= set(df.columns)
    # SUMO and both muvsim checks, for both experiments, in one run
    assert sorted(zip(df["experiment"], df["driver"], df["check"].astype(str))) == sorted(
        [(e, d, c) for e in ("cruise", "queue") for d, c in (("sumo", "-"), ("muvsim", "timed"), ("muvsim", "union"))])
    cruise = df[df["experiment"] == "cruise"]
    assert np.isfinite(cruise["flow_vph"]).all() and (cruise["flow_vph"] > 0).all()
    assert (df["crossed"] > 0).all()
    # the guarantee: no claim overlap, no footprint overlap, no index violation, no SUMO collision
    assert (df[["claim_overlaps", "footprint_overlaps", "invariant_violations", "collisions"]] == 0).all().all()
