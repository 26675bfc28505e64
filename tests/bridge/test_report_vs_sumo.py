"""``muvsim run --vs`` and ``muvsim report --vs`` on real SUMO runs of one demand."""

import json

import pandas as pd

from bridge.cli import main
from sumo_nets.generate import write_sumocfg


def test_run_and_report_compare_with_sumo_drivers(grid_net, grid_routes, tmp_path, capsys):
    cfg = write_sumocfg(tmp_path / "mine.sumocfg", grid_net, [grid_routes])
    base, run = tmp_path / "base", tmp_path / "run"
    # one window for both (issue 11: the demand is what departs inside begin .. begin + duration)
    assert main(["run", str(cfg), "--baseline", "sumo", "--out", str(base), "--quiet", "--seed", "3",
                 "--duration", "100"]) == 0
    capsys.readouterr()
    assert main(["run", str(cfg), "--out", str(run), "--quiet", "--seed", "3", "--duration", "100",
                 "--log", "none", "--vs", str(base)]) == 0
    out = capsys.readouterr().out
    s = json.loads((run / "summary.json").read_text())
    b = json.loads((base / "summary.json").read_text())
    n = s["vehicles_total"]
    assert 0 < n <= 20 and b["vehicles_total"] == n  # the window's demand, the same on both sides
    b_arr = b["vehicles_arrived"]
    assert f"vehicles_arrived              {s['vehicles_arrived']} of {n}  vs  {b_arr} of {n}" in out
    assert main(["report", str(run), "--vs", str(base)]) == 0
    df = pd.read_csv(run / "report_vs_base.csv").set_index(["over", "metric", "statistic"])
    rv = pd.read_csv(run / "vehicles.csv", dtype={"id": str})
    bv = pd.read_csv(base / "vehicles.csv", dtype={"id": str})
    landed = rv["arrival_s"].notna().sum()
    both = set(rv.loc[rv["arrival_s"].notna(), "id"]) & set(bv.loc[bv["arrival_s"].notna(), "id"])
    assert len(both) > 0 and df.loc[("paired", "vehicles_paired", "count"), "run"] == len(both)
    assert landed == s["vehicles_arrived"]
    assert df.loc[("run", "vehicles_total", "count"), "vs"] == n
    assert df.loc[("demand (censored)", "vehicles_censored", "count"), "run"] == n - landed
    assert df.loc[("demand (censored)", "vehicles_censored", "count"), "vs"] == n - b_arr
