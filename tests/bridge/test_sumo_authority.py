"""Movement-authority mode in real SUMO: a queue of cars on a straight one-lane road (written here
with ``netgenerate``) -- SUMO reports no collision and the cars cruise near the lane limit."""

import json
import subprocess
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from bridge.sumo_world import run_sumo
from sumo_nets.generate import write_sumocfg
from sumo_nets.sumo_tools import binary

N_CARS = 10
LANE_LIMIT = 13.89  # netgenerate's default lane speed (m/s), = the car's v̄


@pytest.fixture(scope="module")
def road(tmp_path_factory):
    d = tmp_path_factory.mktemp("authority_road")
    net = d / "road.net.xml"
    subprocess.run([str(binary("netgenerate")), "--grid", "--grid.x-number", "2", "--grid.y-number", "1",
                    "--grid.length", "600", "--default.lanenumber", "1", "--default.speed", str(LANE_LIMIT),
                    "--no-internal-links", "true", "--no-turnarounds", "true", "--output-file", str(net)],
                   check=True, capture_output=True)
    vehs = "".join(f'<vehicle id="c{i}" type="car" depart="{i:.1f}"><route edges="A0B0"/></vehicle>'
                   for i in range(N_CARS))
    rou = d / "queue.rou.xml"
    rou.write_text(f'<routes><vType id="car" vClass="passenger" length="5" width="1.8"/>{vehs}</routes>')
    return write_sumocfg(d / "road.sumocfg", net, [rou])


def _opts(controller):
    return SimpleNamespace(seed=1, duration=120.0, tm="optimal", check="timed", switching="early",
                           disturbance="random", solver="exact", baseline=None, gui=False, quiet=True,
                           controller=controller)


def test_queue_on_a_straight_road_authority(road, tmp_path):
    """10 cars departing 1 s apart on a 600 m lane: all arrive, 0 SUMO and geometric collisions,
    every safety counter 0 (tube escapes included), none waits to enter, and their mean speed (route
    length / travel time, start and stop included) at least 9.5 m/s -- the paper mode's cap is 5.4 m/s."""
    s = run_sumo(str(road), tmp_path / "out", _opts("authority"))
    assert s["complete"], s.get("error")
    assert s["collisions_sumo"] == 0 and s["collisions_geometric"] == 0
    assert s["safe"] is True, s.get("safety_violations")
    assert s["tube_escapes"] == 0 and s["claim_violations"] == 0 and s["invariant_violations"] == 0
    assert s["vehicles_arrived"] == N_CARS
    veh = pd.read_csv(tmp_path / "out" / "vehicles.csv")
    # SUMO 1.28 inserts at the lane's speed by default and muvsim starts vehicles as SUMO does
    # (bridge/departure.py): each follower enters on time, 1 s behind its leader, at the fastest free
    # speed of the ladder (half), where from rest it waited for its entry to clear (1.1 s more per place
    # in the queue, not counted in its travel time, which runs from admission): 9.75 m/s measured for
    # the 10th, which arrives 2.8 s earlier than from rest (11.0 m/s then)
    assert veh["mean_speed_mps"].min() >= 9.5
    assert veh["admission_delay_s"].max() < 0.05
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["options"]["controller"] == "authority"


def test_arrival_pass_leaves_the_road_at_speed(road, tmp_path):
    """``--arrival pass`` on the same straight road (its end a dead end: a run-out past it): all 10
    arrive, SUMO reports no collision, every safety counter 0, and each car's travel time is at
    least 2 s shorter than with ``--arrival stop`` (it no longer brakes to rest at the end: 13.89 m/s
    takes 5.3 s to shed at the car's 2.6 m/s^2; measured 2.7-8.3 s shorter, mean 5.6 s); the route length and
    free-flow time are the same (the run-out is never driven)."""
    got = {}
    for mode in ("stop", "pass"):
        opts = _opts("authority")
        opts.arrival = mode
        s = run_sumo(str(road), tmp_path / mode, opts)
        assert s["complete"], s.get("error")
        assert s["collisions_sumo"] == 0 and s["safe"] is True, s.get("safety_violations")
        assert s["vehicles_arrived"] == N_CARS and s["options"]["arrival"] == mode
        got[mode] = pd.read_csv(tmp_path / mode / "vehicles.csv").set_index("id").sort_index()
    stop, run = got["stop"], got["pass"]
    np.testing.assert_allclose(run["route_length_m"], stop["route_length_m"], atol=1e-9)
    np.testing.assert_allclose(run["free_flow_s"], stop["free_flow_s"], atol=1e-9)
    assert (run["travel_time_s"] <= stop["travel_time_s"] - 2.0).all(), (run["travel_time_s"] - stop["travel_time_s"])


def test_grid_junctions_authority(grid_cfg, tmp_path):
    """Movement authority on the shared 3 x 3 grid (20 vehicles: cars, buses, trucks; 2 lanes,
    internal junction lanes) with the junction liveness layer on: its 9 zones are used (tokens
    handed out, requests withheld, none ignored), SUMO and the geometric monitor report no
    collision, every safety counter 0."""
    opts = _opts("authority")
    opts.duration = 60.0
    s = run_sumo(str(grid_cfg), tmp_path / "out", opts)
    assert s["complete"], s.get("error")
    assert s["zones"] == 9 and s["zones_ignored"] == 0
    assert s["junction_tokens"] > 0 and s["junction_withheld"] > 0
    assert s["collisions_sumo"] == 0 and s["collisions_geometric"] == 0
    assert s["safe"] is True, s.get("safety_violations")
    assert s["tube_escapes"] == 0 and s["claim_violations"] == 0 and s["invariant_violations"] == 0
    assert s["vehicles_arrived"] > 0


def test_admission_on_the_near_vehicles_decides_as_on_all(grid_cfg, tmp_path, monkeypatch):
    """Admission (condition (12)) computes the claims now of only the vehicles whose claims in force
    after the step's decision come near the entry claims (``FleetClaims.near_rows``: the fresh claims lie in
    those).  On the shared grid with real SUMO, at every admission the decision is the one taken
    against every vehicle's fresh claims; the rule is exercised (vehicles left out, candidates
    admitted and refused)."""
    from bridge import cosim as cosim_mod
    from bridge.fleet_claims import FleetClaims
    from tm.reach import ReachClaims

    seen = {"steps": 0, "left_out": 0, "admitted": 0, "refused": 0}
    sims = []
    real_admit, real_near = cosim_mod.admit_reach, FleetClaims.near_rows

    def near(self, t, ids, centre, entry):
        sims[:] = [self]
        got = real_near(self, t, ids, centre, entry)
        if got is not None:
            seen["left_out"] += int((~got).sum())
        return got

    def admit(current, candidates, check):
        ok = real_admit(current, candidates, check)
        claims = sims[0] if sims else None  # the run's FleetClaims
        n = sum(len(g.ids) for g in claims.groups.values()) if claims is not None else 0
        if n:  # the footprints are the last n rows: with every vehicle's fresh claims before them
            foot = current.take(np.arange(len(current) - n, len(current)))
            full = real_admit(ReachClaims.concat(claims.reach_claims(), foot), candidates, check)
            np.testing.assert_array_equal(ok, full)
            seen["steps"] += 1
        seen["admitted"] += int(ok.sum())
        seen["refused"] += int((~ok).sum())
        return ok

    monkeypatch.setattr(cosim_mod, "admit_reach", admit)
    monkeypatch.setattr(FleetClaims, "near_rows", near)
    opts = _opts("authority")
    opts.duration = 60.0
    s = run_sumo(str(grid_cfg), tmp_path / "out", opts)
    assert s["complete"], s.get("error")
    assert seen["steps"] > 0 and seen["left_out"] > 0 and seen["admitted"] > 0 and seen["refused"] > 0, seen
