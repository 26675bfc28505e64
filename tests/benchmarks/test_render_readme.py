"""The README's benchmark tables are the benchmarks' CSV files, rendered: one source per figure."""

import importlib.util
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[2]


def _mod():
    spec = importlib.util.spec_from_file_location("render_readme", ROOT / "benchmarks" / "render_readme.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_readme_tables_match_the_results_csv():
    """Fails when a README table is edited by hand or a CSV re-measured without re-rendering."""
    assert _mod().main(["--check"]) == 0


def test_a_changed_csv_changes_the_table_and_the_check_catches_it(tmp_path):
    m = _mod()
    df = pd.read_csv(ROOT / "benchmarks" / "results" / "traffic.csv")
    df.loc[0, "arrived"] = 77.0
    df.loc[0, "delay_mean_s"] = 123.456
    csv = tmp_path / "traffic.csv"
    df.to_csv(csv, index=False)
    table = m.traffic_table(csv)
    assert "| 77 | 123.5 / " in table.splitlines()[2]
    readme = tmp_path / "README.md"
    readme.write_text((ROOT / "README.md").read_text(encoding="utf-8").replace("| 14 | 344.6 /", "| 4 | 306 /", 1))
    assert m.main(["--check", "--readme", str(readme)]) == 1  # a hand-edited figure is caught
    assert m.main(["--readme", str(readme)]) == 0 and m.main(["--check", "--readme", str(readme)]) == 0
