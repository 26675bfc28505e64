"""benchmarks/bench_pads.py runs on a few routes of the built-in grid and writes its table: a row per
size and frame, the total, and the fleet row (the only benchmark script that had no test)."""

import subprocess
import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "benchmarks" / "bench_pads.py"


def test_bench_pads_quick_writes_every_row(tmp_path):
    out = tmp_path / "pads.csv"
    p = subprocess.run([sys.executable, str(SCRIPT), "--routes", "3", "--repeat", "1", "--fleet", "20",
                        "--steps", "3", "--out", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    df = pd.read_csv(out)
    rows = set(zip(df["size"], df["frame"]))
    assert rows == {("car", "road"), ("car", "path"), ("bus", "road"), ("bus", "path"), ("all", "all"),
                    ("fleet", "step")}, rows
    per = df[~df["size"].isin(["all", "fleet"])]
    assert (per["tables"] == 3).all() and (per["ms_median"] > 0).all() and (per["route_m_median"] > 0).all()
    assert int(df.loc[df["size"] == "all", "tables"].iloc[0]) == 12
    assert int(df.loc[df["size"] == "fleet", "tables"].iloc[0]) == 20
