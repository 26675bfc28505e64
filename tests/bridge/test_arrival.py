"""Arrival at speed (``VehicleSpec.arrive_k``): a route with a run-out past its arrival waypoint is
left at speed, as SUMO's vehicles leave their route's end; without one the vehicle comes to rest on
its last waypoint (as before).  Free plane here; on SUMO networks (dead-end route ends) in
tests/bridge/test_sumo_authority.py."""

import numpy as np
import pytest

from bridge.cosim import Cosim, CosimSettings, VehicleSpec
from bridge.layouts import subsample
from bridge.sumo_world import run_out
from controllers.classes import builtin_classes

CLASSES = builtin_classes()


def _drive(spec: VehicleSpec, vclass: str = "car", disturbance: str = "random", seed: int = 0):
    """Step a lone vehicle until it arrives: (arrival time s, speed at its last step s, last position,
    the simulation)."""
    sim = Cosim(CLASSES, [spec], CosimSettings(controller="authority", disturbance=disturbance, seed=seed))
    sim._admit(0.0)
    g = sim.groups[vclass]
    v, x = np.nan, None
    while not sim.done and sim.t < 5000:
        if g.ids:
            v, x = float(np.linalg.norm(sim.world_states(g)[0, 2:4])), sim.world_states(g)[0, :2].copy()
        sim.step()
    assert sim.done
    return sim.records[spec.id].arrived_s, v, x, sim


@pytest.mark.parametrize("vclass", ["car", "bus", "truck"])
def test_a_run_out_is_left_at_speed_and_earlier(vclass):
    """300 m straight: with a run-out the vehicle passes its arrival waypoint near its top speed
    (at least 90 % of v̄: it never brakes for the end) and arrives at least 2 s earlier than the same
    route without one, where it comes to rest (below 0.5 m/s at its last step); no invariant
    violation either way; its last position is within one step's travel past the arrival waypoint."""
    vc = CLASSES[vclass]
    W = subsample([[0.0, 0.0], [300.0, 0.0]], vc.model.delta)
    ext, lim, k = run_out(W, np.full(len(W), 13.89), vc)
    t_stop, v_stop, _, s1 = _drive(VehicleSpec("v", vclass, W), vclass)
    t_pass, v_pass, x, s2 = _drive(VehicleSpec("v", vclass, ext, speed_limits=lim, arrive_k=k), vclass)
    top = min(float(vc.v_max), 13.89)
    assert v_stop < 0.5 and v_pass >= 0.9 * top, (v_stop, v_pass)
    assert t_pass <= t_stop - 2.0, (t_pass, t_stop)
    assert s1.invariant_violations == s2.invariant_violations == 0
    assert 300.0 - 2 * top * 0.1 <= x[0] <= 300.0  # before its last step: within two steps' travel
    # the run-out is long enough to stop from the top speed (the vehicle never sees its end)
    assert np.hypot(*(ext[-1] - ext[k])) >= top ** 2 / (2 * vc.comfort_decel)


def test_record_figures_stop_at_the_arrival_waypoint():
    """Route length and free-flow time count the driven part only (the run-out is never driven), so
    delays compare with SUMO's on the same route."""
    vc = CLASSES["car"]
    W = subsample([[0.0, 0.0], [300.0, 0.0]], vc.model.delta)
    ext, lim, k = run_out(W, np.full(len(W), 13.89), vc)
    a, b = VehicleSpec("a", "car", W, speed_limits=np.full(len(W), 13.89)), \
        VehicleSpec("b", "car", ext, speed_limits=lim, arrive_k=k)
    assert b.route_length_m == pytest.approx(a.route_length_m, abs=1e-9) == pytest.approx(300.0)
    sim = Cosim(CLASSES, [a, b], CosimSettings(controller="authority"))
    assert sim.records["b"].free_flow_s == pytest.approx(sim.records["a"].free_flow_s, abs=1e-9)


def test_run_out_following_vehicles_stay_safe():
    """Eight cars one after another on a 200 m road with a run-out, random disturbances: all arrive,
    each at speed; 0 footprint overlaps and claim violations by the monitor, 0 invariant violations,
    0 tube escapes."""
    vc = CLASSES["car"]
    W = subsample([[0.0, 0.0], [200.0, 0.0]], vc.model.delta)
    ext, lim, k = run_out(W, np.full(len(W), 13.89), vc)
    specs = [VehicleSpec(f"c{i}", "car", ext, depart_s=1.5 * i, speed_limits=lim, arrive_k=k) for i in range(8)]
    sim = Cosim(CLASSES, specs, CosimSettings(controller="authority", seed=3))
    sim.run(6000)
    assert sim.done and all(r.arrived_s is not None for r in sim.records.values())
    rows = sim.step_rows
    assert sum(r.get("footprint_overlaps", 0) for r in rows) == 0
    assert sum(r.get("claim_violations", 0) for r in rows) == 0
    assert sim.invariant_violations == 0 and sim.monitor.tube_escapes == 0


@pytest.mark.parametrize("bad", [0, 5.0, "3", -1, 10 ** 6])
def test_arrive_k_must_be_a_waypoint_before_the_last(bad):
    W = subsample([[0.0, 0.0], [60.0, 0.0]], 3.0)
    with pytest.raises(ValueError, match="vehicle v: arrive_k must be an int"):
        Cosim(CLASSES, [VehicleSpec("v", "car", W, arrive_k=bad)], CosimSettings(controller="authority"))
