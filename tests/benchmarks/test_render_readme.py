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
    assert "| 77 / " in table.splitlines()[2] and "| 123.5 / " in table.splitlines()[2]
    # the README's own traffic table is the rendered one: a hand-edited figure is caught, re-rendering fixes it
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    ours = m.traffic_table().splitlines()[2]
    assert ours in text
    cells = ours.split(" | ")
    cells[6] = "1" + cells[6]  # arrived / demand
    readme = tmp_path / "README.md"
    readme.write_text(text.replace(ours, " | ".join(cells), 1), encoding="utf-8")
    assert m.main(["--check", "--readme", str(readme)]) == 1  # a hand-edited figure is caught
    assert m.main(["--readme", str(readme)]) == 0 and m.main(["--check", "--readme", str(readme)]) == 0


def test_the_scenario_table_is_scenarios_csv_and_the_check_catches_a_hand_edit(tmp_path):
    m = _mod()
    df = pd.read_csv(ROOT / "benchmarks" / "results" / "scenarios.csv")
    for col in ("signals", "error", "red_violations"):  # empty in the CSV (read as float) or absent
        df[col] = df[col].astype(object) if col in df else None
    first = df["scenario"].iloc[0]
    mu = (df["scenario"] == first) & (df["driver"] == "muvsim")
    su = (df["scenario"] == first) & (df["driver"] == "sumo")
    df.loc[mu, "arrived"], df.loc[su, "arrived"] = 71, 83
    df.loc[mu, "mean_delay_s"], df.loc[su, "mean_delay_s"] = 123.456, 7.04
    df.loc[mu, "red_violations"], df.loc[mu, "signals"] = 5, "ignore"
    df.loc[mu, "stopped_at_end"], df.loc[mu, "gridlocked_at_end"] = 12, 9
    df.loc[su, "error"] = "SumoError: boom"
    csv = tmp_path / "scenarios.csv"
    df.to_csv(csv, index=False)
    row = next(line for line in m.scenarios_table(csv).splitlines() if line.startswith(f"| {first} |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[4] == "9 of 12"  # muvsim's gridlocked of its vehicles at rest at the end
    assert cells[3] == "71 / 83" and cells[5] == "123.5 / 7.0"  # delays to 0.1 s
    assert cells[9] == "ignore, 5" and cells[11] == "sumo: SumoError: boom"
    # the README's own scenario table is the rendered one: a hand-edited figure is caught, re-rendering fixes it
    readme = tmp_path / "README.md"
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    ours = next(line for line in m.scenarios_table().splitlines() if line.startswith(f"| {first} |"))
    assert ours in text
    readme.write_text(text.replace(ours, ours.replace(f"| {first} |", f"| {first} | 1", 1), 1), encoding="utf-8")
    assert m.main(["--check", "--readme", str(readme)]) == 1
    assert m.main(["--readme", str(readme)]) == 0 and m.main(["--check", "--readme", str(readme)]) == 0


def test_traffic_rows_name_driver_and_controller_and_older_csvs_render(tmp_path):
    """A row per driver and controller: SUMO's drivers have no controller or variant; arrivals are of the
    demand; a CSV from before the controller, demand and simulated columns renders them as paper and "-"."""
    m = _mod()
    csv = tmp_path / "traffic.csv"
    base = dict(scenario="grid", switching="early", check="timed", policy="optimal", seeds=2, complete=2,
                demand=150.0, arrived=149.5, simulated_s=712.25, delay_mean_s=61.04, delay_p95_s=150.0,
                halts_per_vehicle=3.0, time_halted_s=40.0, tm_stops=1234.5, collisions_sumo=0.0,
                collisions_geometric=0.0)
    pd.DataFrame([{**base, "driver": "muvsim", "controller": "authority"},
                  {**base, "driver": "sumo", "controller": "-", "switching": "-", "check": "-", "policy": "-",
                   "arrived": 150.0, "simulated_s": 380.0, "tm_stops": float("nan"),
                   "collisions_geometric": float("nan")}]).to_csv(csv, index=False)
    rows = [[c.strip() for c in r.strip("|").split("|")] for r in m.traffic_table(csv).splitlines()[2:]]
    assert rows[0] == ["muvsim", "authority", "early", "timed", "optimal", "2", "149.5 / 150", "61.0 / 150.0",
                       "3.0", "40.0", "1234.5", "0 / 0", "712.2"]
    assert rows[1][:7] == ["SUMO's drivers", "-", "-", "-", "-", "2", "150 / 150"]
    assert rows[1][10:] == ["-", "0 / -", "380"]
    pd.read_csv(csv).drop(columns=["controller", "demand", "simulated_s"]).to_csv(csv, index=False)
    rows = [[c.strip() for c in r.strip("|").split("|")] for r in m.traffic_table(csv).splitlines()[2:]]
    assert [r[1] for r in rows] == ["paper", "-"] and rows[0][6] == "149.5 / -" and rows[0][12] == "-"


def test_a_scenario_with_only_one_driver_renders_dashes_not_a_crash(tmp_path):
    m = _mod()
    csv = tmp_path / "scenarios.csv"
    pd.DataFrame([{"scenario": "cross", "driver": "muvsim", "duration_s": 20.0, "demand": 9, "arrived": 2,
                   "mean_delay_s": float("nan"), "collisions_sumo": 0, "rtf": 1.5, "error": ""}]).to_csv(csv, index=False)
    row = m.scenarios_table(csv).splitlines()[2]
    assert row.startswith("| cross | 20 | 9 | 2 / - | - | - / - | 0 / - |") and row.endswith("| 1.50 / - | - |")


def test_authority_rows_render_after_the_paper_row_beside_the_same_sumo_figures(tmp_path):
    """bench_scenarios.py --controller both: a scenario's paper row keeps its name, the authority
    row follows as ``NAME (authority)``, both beside the one SUMO row."""
    m = _mod()
    csv = tmp_path / "scenarios.csv"
    base = {"scenario": "tlsgrid", "duration_s": 180.0, "demand": 90, "collisions_sumo": 0, "error": ""}
    pd.DataFrame([{**base, "driver": "muvsim", "controller": "authority", "arrived": 7, "rtf": 0.5},
                  {**base, "driver": "muvsim", "controller": "paper", "arrived": 5, "rtf": 1.0},
                  {**base, "driver": "sumo", "controller": "-", "arrived": 45, "rtf": 300.0}]).to_csv(csv, index=False)
    rows = m.scenarios_table(csv).splitlines()[2:]
    cells = [[c.strip() for c in r.strip("|").split("|")] for r in rows]
    assert [c[0] for c in cells] == ["tlsgrid", "tlsgrid (authority)"]
    assert cells[0][3] == "5 / 45" and cells[1][3] == "7 / 45"
    assert cells[0][10] == "1.00 / 300.00" and cells[1][10] == "0.50 / 300.00"
