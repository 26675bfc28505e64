"""Single-vehicle free-plane runs: every model type, every disturbance policy, both switching modes."""

import json

import numpy as np
import pytest

from bridge.cli import main
from bridge.freeplane import follow_waypoints, zigzag_waypoints
from controllers.classes import VehicleClass, get_class
from controllers.models import jerk_integrator


@pytest.mark.parametrize("disturbance", ["random", "adversarial", "none"])
@pytest.mark.parametrize("switching", ["terminal", "early"])
@pytest.mark.parametrize("cls", ["paper-c", "bus"])
def test_vehicle_follows_waypoints(cls, disturbance, switching):
    vc = get_class(cls)
    W = zigzag_waypoints(vc.model.delta, count=12, seed=4)
    tr = follow_waypoints(vc, W, disturbance=disturbance, switching=switching, seed=1)
    assert tr.finished and tr.invariant_violations == 0 and tr.constraint_violations == 0
    # it visited every waypoint in order and ends inside T^0 of the last one
    assert list(np.unique(tr.k)) == list(range(len(W)))
    assert np.all(np.diff(tr.k) >= 0) and tr.l[-1] == 0
    # terminal switching only ever switches from T^0 (index 0 on the step before a switch)
    if switching == "terminal":
        switch_steps = np.nonzero(np.diff(tr.k))[0]
        assert np.all(tr.l[switch_steps] == 0)


def test_jerk_model_follows_waypoints():
    vc = VehicleClass("jerk", jerk_integrator(v_max=13.89, a_max=4.0, j_max=40.0, d_max=0.01, delta=1.0),
                      length=5.0, width=1.8, vclass="passenger")
    W = zigzag_waypoints(1.0, count=8, seed=2)
    tr = follow_waypoints(vc, W, disturbance="adversarial", seed=0)
    assert tr.finished and tr.invariant_violations == 0 and tr.constraint_violations == 0


def test_waypoints_too_far_apart_are_rejected():
    vc = get_class("paper-c")
    with pytest.raises(ValueError, match="needs at most delta = 3.22"):
        follow_waypoints(vc, np.array([[0.0, 0.0], [10.0, 0.0]]))


def test_cli_sets_and_run(tmp_path, capsys):
    assert main(["sets", "paper-c", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["class"] == "paper-c" and info["condition8"] is True
    assert len(info["facets"]) == info["N"] + 1
    assert main(["sets", "no-such-class"]) == 2
    assert "valid classes" in capsys.readouterr().err
    out = tmp_path / "run"
    assert main(["run", "single", "--vclass", "paper-c", "--out", str(out), "--disturbance", "adversarial"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["complete"] and summary["finished"] and summary["invariant_violations"] == 0
    assert (out / "steps.csv").stat().st_size > 1000
