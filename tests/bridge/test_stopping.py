"""The stopping rule of ``muvsim run``: until every vehicle arrived, at most 3 x the departure window."""

import json

import pytest

from bridge import stopping
from bridge.cli import main
from bridge.stopping import CAP_FACTOR, MIN_WINDOW_S, route_file_departures, run_limit, stop_reason
from sumo_nets.generate import write_sumocfg


def test_default_limit_is_three_departure_windows():
    lim = run_limit([0.0, 12.5, 300.0, 7.0], None)
    assert lim.capped and lim.window_s == 300.0 and lim.duration_s == CAP_FACTOR * 300.0 == 900.0


def test_short_window_still_gets_time_to_drive():
    lim = run_limit([0.0, 0.0], None)
    assert lim.window_s == MIN_WINDOW_S and lim.duration_s == CAP_FACTOR * MIN_WINDOW_S


def test_duration_given_is_the_limit_and_must_be_positive():
    lim = run_limit([0.0, 300.0], 42.0)
    assert not lim.capped and lim.duration_s == 42.0
    for bad in (0.0, -1.0):
        with pytest.raises(ValueError, match="--duration: must be > 0"):
            run_limit([0.0], bad)


def test_reasons_say_how_many_are_left_and_why():
    cap = run_limit([0.0, 300.0], None)
    assert stop_reason(cap, 150, 150, 812.3).startswith("every vehicle of the demand arrived (150 of 150) at 812.3")
    r = stop_reason(cap, 150, 34, 900.0)
    assert "cap reached: 900.0 s = 3 x the departure window (300.0 s)" in r and "116 of 150" in r
    assert "--duration 300 s reached; 116 of 150" in stop_reason(run_limit([0.0], 300.0), 150, 34, 300.0)


def test_route_file_departures(tmp_path):
    f = tmp_path / "r.rou.xml"
    f.write_text('<routes><vehicle id="a" depart="3.5"/><trip id="b" depart="triggered"/>'
                 '<flow id="f" begin="0" end="120" number="4"/><trip id="c" depart="9"/></routes>')
    assert sorted(route_file_departures([f, tmp_path / "missing.xml"])) == [3.5, 9.0, 120.0]


@pytest.mark.parametrize("bad", ["0", "-5", "nan", "inf", "soon"])
def test_cli_refuses_a_duration_that_is_not_positive(bad, tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        main(["run", "grid", "--duration", bad, "--out", str(tmp_path / "o")])
    assert e.value.code == 2 and "--duration" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_run_without_duration_stops_when_every_vehicle_arrived(grid_net, tmp_path, capsys, monkeypatch):
    """Real SUMO, 4 vehicles departing within 20 s, no --duration: the run ends at the step the
    last vehicle arrives (not at a fixed time), and the closing table says so as arrived of demand.
    The minimum window is raised to 150 s (cap 450 s) so slow junction waits cannot reach the cap."""
    from sumo_nets.generate import make_demand

    monkeypatch.setattr(stopping, "MIN_WINDOW_S", 150.0)
    routes = make_demand(grid_net, tmp_path, seed=9, vehicles=4, duration_s=20.0,
                         class_mix={"car": 0.5, "bus": 0.25, "truck": 0.25})
    cfg = write_sumocfg(tmp_path / "small.sumocfg", grid_net, [routes])
    assert main(["run", str(cfg), "--out", str(tmp_path / "out"), "--quiet", "--log", "none", "--seed", "3"]) == 0
    out = capsys.readouterr().out
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert s["vehicles_arrived"] == s["vehicles_total"] == 4 and s["finished"]
    assert s["collisions_sumo"] == 0 and s["invariant_violations"] == 0
    import pandas as pd

    arrivals = pd.read_csv(tmp_path / "out" / "vehicles.csv")["arrival_s"]
    # stopped at the last arrival: within one step (0.1 s) of it, below the cap of 450 s
    assert s["simulated_s"] == pytest.approx(arrivals.max() + 0.1, abs=0.1 + 1e-9)
    assert s["simulated_s"] < CAP_FACTOR * 150.0
    assert "every vehicle of the demand arrived (4 of 4)" in s["stop_reason"]
    assert "vehicles_arrived" in out and "4 of 4 (vehicles_total; 100.0 %)" in out
    assert "None" not in out


def test_run_at_the_cap_says_how_many_are_left(grid_net, grid_routes, tmp_path, monkeypatch, capsys):
    """Real SUMO; the cap shrunk (0.25 x a 60 s window = 15 s, too short for any 20-vehicle trip to
    end): the run stops there and says the cap ended it and how many vehicles are still out."""
    monkeypatch.setattr(stopping, "CAP_FACTOR", 0.25)
    cfg = write_sumocfg(tmp_path / "mine.sumocfg", grid_net, [grid_routes])
    assert main(["run", str(cfg), "--out", str(tmp_path / "out"), "--quiet", "--log", "none", "--seed", "3"]) == 0
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert s["steps"] == 150 and s["simulated_s"] == pytest.approx(15.0)  # 150 steps of 0.1 s
    left = 20 - s["vehicles_arrived"]
    assert left > 0 and s["stop_reason"].startswith("cap reached: 15.0 s")
    assert f"{left} of 20 vehicles still in the network" in s["stop_reason"]
    assert f"{left} of 20 vehicles still in the network" in capsys.readouterr().out


def test_baseline_without_duration_runs_until_done_and_counts_the_demand(grid_net, grid_routes, tmp_path):
    cfg = write_sumocfg(tmp_path / "mine.sumocfg", grid_net, [grid_routes])
    assert main(["run", str(cfg), "--baseline", "sumo", "--out", str(tmp_path / "b"), "--quiet", "--seed", "3"]) == 0
    s = json.loads((tmp_path / "b" / "summary.json").read_text())
    assert s["vehicles_total"] == 20 and s["vehicles_arrived"] == 20
    assert s["stop_reason"].startswith("every vehicle of the demand arrived (20 of 20)")
