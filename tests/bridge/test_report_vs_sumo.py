"""``muvsim run --vs`` and ``muvsim report --vs`` on real SUMO runs of one demand."""

import json

import pandas as pd

from bridge.cli import main
from sumo_nets.generate import write_sumocfg


def test_run_and_report_compare_with_sumo_drivers(grid_net, grid_routes, tmp_path, capsys):
    cfg = write_sumocfg(tmp_path / "mine.sumocfg", grid_net, [grid_routes])
    base, run = tmp_path / "base", tmp_path / "run"
    assert main(["run", str(cfg), "--baseline", "sumo", "--out", str(base), "--quiet", "--seed", "3"]) == 0
    capsys.readouterr()
    assert main(["run", str(cfg), "--out", str(run), "--quiet", "--seed", "3", "--duration", "30",
                 "--log", "none", "--vs", str(base)]) == 0
    out = capsys.readouterr().out
    s = json.loads((run / "summary.json").read_text())
    b = json.loads((base / "summary.json").read_text())
    assert b["vehicles_total"] == 20 and b["vehicles_arrived"] == 20  # SUMO lands them all (stops when done)
    assert f"vehicles_arrived              {s['vehicles_arrived']} of 20  vs  20 of 20" in out
    assert main(["report", str(run), "--vs", str(base)]) == 0
    df = pd.read_csv(run / "report_vs_base.csv").set_index(["over", "metric", "statistic"])
    landed = pd.read_csv(run / "vehicles.csv")["arrival_s"].notna().sum()
    assert df.loc[("paired", "vehicles_paired", "count"), "run"] == landed == s["vehicles_arrived"]
    assert df.loc[("run", "vehicles_total", "count"), "vs"] == 20
    assert df.loc[("demand (censored)", "vehicles_censored", "count"), "run"] == 20 - landed
    assert df.loc[("demand (censored)", "vehicles_censored", "count"), "vs"] == 0
