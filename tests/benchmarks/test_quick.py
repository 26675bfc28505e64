"""Every benchmark script runs in its quick mode and writes its CSV with the expected columns."""

import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[2]

CASES = {
    "bench_controllers.py": {"class", "N", "synthesis_s", "solver", "index_us_per_vehicle", "qp_us_per_vehicle"},
    "bench_tm.py": {"vehicles", "requesting", "policy", "check", "decide_ms", "broad_plus_sat_ms", "stopped",
                    "lp_total_s"},
    "bench_freeplane.py": {"scenario", "check", "switching", "policy", "finished", "time_to_finish_s",
                           "stop_commands", "collisions_geometric", "invariant_violations"},
}


@pytest.mark.parametrize("script", sorted(CASES))
def test_benchmark_quick_mode_writes_its_table(script, tmp_path):
    out = tmp_path / "result.csv"
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), "--quick", "--out", str(out)],
                          capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-2000:]
    df = pd.read_csv(out)
    assert len(df) > 0 and CASES[script] <= set(df.columns)
    assert proc.stdout.strip()  # it prints its figures too
