"""``muvsim report``: statistics of a run, two runs compared, runs of different demand refused."""

import json
import re

import numpy as np
import pandas as pd
import pytest

from analysis.kpis import VEHICLE_COLUMNS
from analysis.report import DemandMismatch, check_same_demand, load_run, report_table
from bridge.cli import main


def _run_dir(path, delays, stops, departures=None, simulated_s=100.0, collisions=0):
    """A muvsim run directory written by hand: every vehicle arrived, free flow 10 s."""
    path.mkdir(parents=True)
    n = len(delays)
    dep = departures if departures is not None else [float(i) for i in range(n)]
    rows = []
    for i in range(n):
        travel = 10.0 + delays[i]
        rows.append({"id": f"v{i}", "vclass": "car", "departure_s": dep[i], "admitted_s": dep[i],
                     "admission_delay_s": 0.0, "arrival_s": dep[i] + travel, "travel_time_s": travel,
                     "route_length_m": 138.9, "free_flow_s": 10.0, "delay_s": delays[i], "sumo_time_loss_s": np.nan,
                     "denials": stops[i], "stop_episodes": stops[i], "time_stopped_s": 0.5 * stops[i],
                     "mean_speed_mps": 5.0, "closest_m": 4.0})
    pd.DataFrame(rows, columns=list(VEHICLE_COLUMNS)).to_csv(path / "vehicles.csv", index=False)
    (path / "summary.json").write_text(json.dumps({"simulated_s": simulated_s, "collisions_geometric": collisions,
                                                   "collisions_world": 0}))
    return path


def test_one_run_statistics(tmp_path):
    a = _run_dir(tmp_path / "a", delays=[1.0, 2.0, 3.0, 4.0], stops=[0, 1, 1, 2])
    assert main(["report", str(a)]) == 0
    df = pd.read_csv(a / "report.csv")
    get = lambda m, s: float(df[(df.metric == m) & (df.statistic == s)]["run"].iloc[0])  # noqa: E731
    assert get("delay_s", "mean") == pytest.approx(2.5)
    assert get("delay_s", "median") == pytest.approx(2.5)
    assert get("delay_s", "p95") == pytest.approx(np.percentile([1, 2, 3, 4], 95))
    assert get("stop_episodes", "mean") == pytest.approx(1.0)
    assert get("time_stopped_s", "mean") == pytest.approx(0.5)
    assert get("travel_time_s", "mean") == pytest.approx(12.5)
    assert get("throughput_vph", "value") == pytest.approx(4 * 36.0)
    assert get("collisions_geometric", "pair_steps") == 0


def _own(df):
    """The 'own arrived' and 'run' rows of a comparison, indexed by (metric, statistic)."""
    return df[df.over.isin(["own arrived", "run"])].set_index(["metric", "statistic"])


def test_report_vs_gives_the_differences_the_tables_imply(tmp_path, capsys):
    a = _run_dir(tmp_path / "a", delays=[1.0, 2.0, 3.0, 4.0], stops=[0, 1, 1, 2])
    b = _run_dir(tmp_path / "b", delays=[2.0, 2.0, 6.0, 6.0], stops=[1, 1, 2, 4], simulated_s=200.0)
    assert main(["report", str(a), "--vs", str(b)]) == 0
    out = capsys.readouterr().out
    assert "difference = run - vs" in out and str(b) in out and "warning" not in out  # same arrivals
    assert not (a / "report.csv").exists()  # --vs writes its own file, never report.csv
    df = _own(pd.read_csv(a / "report_vs_b.csv"))
    assert df.loc[("delay_s", "mean"), "run"] == pytest.approx(2.5)
    assert df.loc[("delay_s", "mean"), "vs"] == pytest.approx(4.0)
    assert df.loc[("delay_s", "mean"), "difference"] == pytest.approx(-1.5)
    assert df.loc[("delay_s", "mean"), "ratio"] == pytest.approx(2.5 / 4.0)
    assert df.loc[("stop_episodes", "median"), "difference"] == pytest.approx(1.0 - 1.5)
    assert df.loc[("time_stopped_s", "mean"), "difference"] == pytest.approx(0.5 - 1.0)
    assert df.loc[("travel_time_s", "mean"), "difference"] == pytest.approx(12.5 - 14.0)
    # same arrivals in half the time: twice the throughput
    assert df.loc[("throughput_vph", "value"), "ratio"] == pytest.approx(2.0)
    assert ("collisions_sumo", "pairs") in df.index and ("collisions_world", "pairs") not in df.index


def test_paired_rows_compare_vehicle_by_vehicle(tmp_path):
    """Paired statistics are statistics of the per-vehicle ratio and difference, over the vehicles
    both runs landed; a vehicle only one run landed is left out of them."""
    a = _run_dir(tmp_path / "a", delays=[1.0, 2.0, 3.0, 4.0], stops=[0, 1, 1, 2])
    b = _run_dir(tmp_path / "b", delays=[2.0, 2.0, 6.0, 6.0], stops=[1, 1, 2, 4])
    v = pd.read_csv(b / "vehicles.csv")
    v.loc[3, ["arrival_s", "travel_time_s", "delay_s"]] = np.nan  # b did not land v3
    v.to_csv(b / "vehicles.csv", index=False)
    df = report_table(load_run(a), load_run(b))
    p = df[df.over == "paired"].set_index(["metric", "statistic"])
    assert p.loc[("vehicles_paired", "count"), "run"] == 3
    ta, tb = np.array([11.0, 12.0, 13.0]), np.array([12.0, 12.0, 16.0])
    # tolerance: float64 arithmetic on a handful of numbers (1e-12 relative)
    for st, f in (("mean", np.mean), ("median", np.median), ("p95", lambda x: np.percentile(x, 95))):
        assert p.loc[("travel_time_s", st), "ratio"] == pytest.approx(f(ta / tb), rel=1e-12)
        assert p.loc[("travel_time_s", st), "difference"] == pytest.approx(f(ta - tb), rel=1e-12)
        assert p.loc[("travel_time_s", st), "run"] == pytest.approx(f(ta), rel=1e-12)
    assert (p.loc[("travel_time_s", "mean"), "n"]) == 3


def test_whole_demand_counts_unfinished_vehicles_with_their_time_so_far(tmp_path, capsys):
    """A vehicle not arrived counts with (end of its run - requested departure), marked censored;
    the arrived sets differing by more than 5 % prints a warning."""
    a = _run_dir(tmp_path / "a", delays=[1.0, 2.0, 3.0, 4.0], stops=[0, 1, 1, 2], simulated_s=100.0)
    b = _run_dir(tmp_path / "b", delays=[2.0, 2.0, 6.0, 6.0], stops=[1, 1, 2, 4], simulated_s=50.0)
    v = pd.read_csv(b / "vehicles.csv")
    v.loc[[2, 3], ["arrival_s", "travel_time_s", "delay_s"]] = np.nan  # b left v2, v3 in the network
    v.to_csv(b / "vehicles.csv", index=False)
    assert main(["report", str(a), "--vs", str(b)]) == 0
    out = capsys.readouterr().out
    assert "warning: the runs landed different vehicles (run 4, vs 2, both 2; 2 of 4 = 50.0 %" in out
    df = pd.read_csv(a / "report_vs_b.csv")
    d = df[df.over == "demand (censored)"].set_index(["metric", "statistic"])
    assert (d.loc[("vehicles_censored", "count"), "run"], d.loc[("vehicles_censored", "count"), "vs"]) == (0, 2)
    journey_a = np.array([11.0, 12.0, 13.0, 14.0])        # arrival - departure, all arrived
    journey_b = np.array([12.0, 12.0, 50.0 - 2.0, 50.0 - 3.0])  # v2, v3 censored at the run's end (50 s)
    assert d.loc[("journey_time_s", "mean"), "run"] == pytest.approx(journey_a.mean())
    assert d.loc[("journey_time_s", "mean"), "vs"] == pytest.approx(journey_b.mean())
    assert d.loc[("journey_time_s", "median"), "ratio"] == pytest.approx(np.median(journey_a / journey_b))


def test_report_without_vs_has_no_comparison_header(tmp_path, capsys):
    a = _run_dir(tmp_path / "a", delays=[1.0, 2.0], stops=[0, 1])
    assert main(["report", str(a)]) == 0
    out = capsys.readouterr().out
    assert "difference" not in out and "ratio" not in out and "None" not in out
    # rounded to meaning: seconds to 0.1, counts whole
    assert re.search(r"\ndelay_s +mean +1\.5\n", out) and re.search(r"\ntravel_time_s +p95 +11\.9\n", out)
    assert re.search(r"\nvehicles_arrived +count +2\n", out) and re.search(r"\nthroughput_vph +value +72\n", out)


def test_report_says_no_vehicle_arrived_instead_of_nan(tmp_path, capsys):
    a = _run_dir(tmp_path / "a", delays=[1.0, 2.0], stops=[0, 1])
    v = pd.read_csv(a / "vehicles.csv")
    v[["arrival_s", "travel_time_s", "delay_s"]] = np.nan
    v.to_csv(a / "vehicles.csv", index=False)
    assert main(["report", str(a)]) == 0
    out = capsys.readouterr().out
    assert "no vehicle arrived" in out and "nan" not in out.lower() and "None" not in out


def test_runs_of_different_demand_are_refused(tmp_path, capsys):
    a = _run_dir(tmp_path / "a", delays=[1.0, 2.0], stops=[0, 1])
    b = _run_dir(tmp_path / "b", delays=[1.0, 2.0, 3.0], stops=[0, 1, 1])
    c = _run_dir(tmp_path / "c", delays=[1.0, 2.0], stops=[0, 1], departures=[0.0, 5.0])
    assert main(["report", str(a), "--vs", str(b)]) == 2
    assert "runs differ in demand" in capsys.readouterr().err
    with pytest.raises(DemandMismatch, match=r"different requested departures \(e.g. v1: 1.00 s vs 5.00 s\)"):
        check_same_demand(load_run(a), load_run(c))
    assert not (a / "report.csv").exists()


def test_baseline_run_is_read_from_tripinfo(tmp_path):
    """A --baseline sumo run: its trips (a subset of the demand, SUMO lists finished trips only) are
    compared with the muvsim run's; a trip with another requested departure is refused."""
    a = _run_dir(tmp_path / "a", delays=[1.0, 2.0, 3.0], stops=[0, 1, 1])
    base = tmp_path / "base"
    base.mkdir()
    (base / "summary.json").write_text(json.dumps({"baseline": "sumo", "simulated_s": 100.0, "collisions_sumo": 0}))
    trips = "".join(
        f'<tripinfo id="v{i}" depart="{i + 0.5:.2f}" departDelay="0.50" arrival="{i + 12.5:.2f}" duration="12.00" '
        f'routeLength="138.90" timeLoss="2.00" waitingTime="1.00" waitingCount="1" vType="DEFAULT_VEHTYPE"/>'
        for i in range(2))
    (base / "tripinfo.xml").write_text(f"<tripinfos>{trips}</tripinfos>")
    df = _own(report_table(load_run(a), load_run(base)))
    assert df.loc[("travel_time_s", "mean"), "vs"] == pytest.approx(12.0)
    assert df.loc[("delay_s", "mean"), "vs"] == pytest.approx(12.0 - 138.9 / 13.89)
    assert df.loc[("halt_episodes", "mean"), "vs"] == pytest.approx(1.0)
    assert df.loc[("time_halted_s", "mean"), "vs"] == pytest.approx(1.0)
    assert np.isnan(df.loc[("stop_episodes", "mean"), "vs"])  # TM stops: muvsim only
    assert df.loc[("vehicles_arrived", "count"), "difference"] == 1
    moved = trips.replace('departDelay="0.50"', 'departDelay="0.00"', 1)
    (base / "tripinfo.xml").write_text(f"<tripinfos>{moved}</tripinfos>")
    with pytest.raises(DemandMismatch, match="different requested departures"):
        report_table(load_run(a), load_run(base))


def test_closing_table_prints_every_safety_and_rule_counter_as_an_integer():
    """Counters are counts: 0, 7, never 0.00 or 7.00 (a float that equals an int included)."""
    from analysis.readable import fmt

    for name in ("red_violations", "signal_withheld", "pedestrian_conflicts", "pedestrian_withheld",
                 "persons_arrived", "vehicles_undrivable", "claim_violations", "footprint_overlaps",
                 "collisions_sumo", "invariant_violations"):
        assert fmt(7.0, name) == "7", name
        assert fmt(0, name) == "0", name
    assert fmt(0.5, "min_separation_m") == "0.50"  # a length keeps its decimals
