"""``benchmarks/bench_logging.py --quick`` runs and writes its CSV with the expected columns."""

import subprocess
import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[2]
COLUMNS = {"level", "vehicles", "steps", "ms_per_step", "ms_per_step_median", "us_per_vehicle_step",
           "cpu_us_per_vehicle_step", "bytes_per_vehicle_step", "close_ms"}


def test_logging_benchmark_quick_mode_writes_its_table(tmp_path):
    out = tmp_path / "logging.csv"
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_logging.py"), "--quick", "--out", str(out)],
                          capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-2000:]
    df = pd.read_csv(out)
    assert COLUMNS <= set(df.columns)
    assert {(lv, v) for lv, v in zip(df["level"], df["vehicles"])} == {
        (lv, v) for lv in ("summary", "full") for v in (100, 1000)}
    assert (df["us_per_vehicle_step"] > 0).all() and (df["bytes_per_vehicle_step"] > 0).all()
    assert proc.stdout.strip()  # it prints its figures too
