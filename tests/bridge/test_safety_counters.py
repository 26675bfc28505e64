"""Every safety counter of summary.json fires when the fault it exists for is injected.

Each test injects one fault end to end (through :class:`bridge.cosim.Cosim` via
``run_multi``, or a real SUMO run via ``run_sumo``), and asserts that the counter counts it
and that the run ends flagged (``"safe": false``, the counter named in
``safety_violations``), not silently green.  A counter that a mutation silences (the strict
decrease dropped, the monitor called without claims, SUMO's collisions drained but not
reported) fails one of these tests.
"""

import json
from types import SimpleNamespace

import numpy as np
import pytest

import bridge.cosim as cosim_mod
from bridge.cli import main
from bridge.layouts import subsample
from bridge.scenarios import run_multi
from bridge.cosim import VehicleSpec
from controllers.classes import builtin_classes
from controllers.plant import step as real_plant_step
from tm.manager import TrafficManager

CLASSES = builtin_classes()
DELTA = CLASSES["paper-a"].model.delta


def _opts(**kw):
    base = dict(vclass="paper-a", tm="optimal", check="union", switching="early", disturbance="none",
                solver="exact", duration=6.0, vehicles=2, seed=0, log="none")
    base.update(kw)
    return SimpleNamespace(**base)


def _line(vid, a, b, vclass="paper-a"):
    return VehicleSpec(id=vid, vclass=vclass, waypoints=subsample(np.array([a, b], dtype=float), DELTA))


def _flagged(s, counter, complete=True):
    """The run finished (or not), its summary on disk says unsafe and names ``counter``."""
    on_disk = json.loads((s["_out"] / "summary.json").read_text()) if "_out" in s else s
    assert on_disk["complete"] is complete, on_disk.get("error")
    assert on_disk["safe"] is False
    assert on_disk["safety_violations"][counter] == on_disk[counter] > 0


def _run(tmp_path, specs, world=None, **kw):
    s = run_multi("swap", tmp_path, _opts(**kw), world=world, specs=specs)
    s["_out"] = tmp_path
    return s


@pytest.fixture
def admit_all(monkeypatch):
    """A faulty TM whose admission (condition (12)) lets every waiting vehicle in."""
    monkeypatch.setattr(TrafficManager, "admit", lambda self, cur, cand: np.ones(len(cand.ids), dtype=bool))


def test_clean_run_is_safe(tmp_path):
    """The control: the same two parallel vehicles, far apart, no fault: every counter 0, safe."""
    s = _run(tmp_path, [_line("a", (0, 0), (30, 0)), _line("b", (0, 40), (30, 40))])
    assert s["complete"] and s["safe"] is True and s["safety_violations"] == {}
    assert all(s[k] == 0 for k in ("collisions_world", "collisions_geometric", "footprint_overlaps",
                                   "claim_violations", "invariant_violations", "constraint_violations"))


def test_world_collision_counts(tmp_path):
    """A world that reports a collision (as SUMO would): collisions_world counts the pair once."""
    class CollidingWorld(cosim_mod.FreePlaneWorld):
        n = 0

        def step(self):
            self.n += 1
            return [("b", "a")] if self.n in (5, 6) else []  # the same contact twice: one pair

    s = _run(tmp_path, [_line("a", (0, 0), (30, 0)), _line("b", (0, 40), (30, 40))], world=CollidingWorld())
    assert s["collisions_world"] == 1
    _flagged(s, "collisions_world")


def test_footprints_placed_overlapping_count(tmp_path, admit_all):
    """Two vehicles admitted on top of each other (a TM that admits everything): the monitor's
    footprint overlaps and the geometric collisions (steps.csv) both count them, equally."""
    s = _run(tmp_path, [_line("a", (0, 0), (30, 0)), _line("b", (1, 0), (1, 30))])
    assert s["collisions_geometric"] == s["footprint_overlaps"] > 0
    _flagged(s, "collisions_geometric")
    _flagged(s, "footprint_overlaps")


def test_conflicting_claims_count_without_any_overlap(tmp_path, admit_all):
    """Two parallel vehicles 4 m apart side by side: footprints 2.2 m apart (never overlap) but
    claims (P^l ⊕ footprint, P^0 of paper-a is ~1.7 m wide each way) conflict.  Only the claim
    check in the loop can see this: the monitor must be called with the claims."""
    s = _run(tmp_path, [_line("a", (0, 0), (30, 0)), _line("b", (0, 4), (30, 4))])
    assert s["footprint_overlaps"] == 0 and s["collisions_geometric"] == 0
    assert s["claim_violations"] > 0
    assert s["invariant_violations"] >= s["claim_violations"]  # the tube invariant includes the claims
    _flagged(s, "claim_violations")


def test_index_that_does_not_drop_counts(tmp_path, monkeypatch):
    """A plant that does not move (x(t+1) = x(t)): after the switch to the next waypoint the
    index stays at l > 0 instead of strictly decreasing; every such vehicle-step counts."""
    monkeypatch.setattr(cosim_mod, "plant_step", lambda m, X, U, c, pol, rng, heading=None: (X.copy(), 0 * X))
    s = _run(tmp_path, [_line("a", (0, 0), (30, 0))], duration=3.0)
    assert s["claim_violations"] == 0
    # 30 steps; the first (l = 0 at the first waypoint, then the switch) may be fine, the rest not
    assert s["invariant_violations"] >= 25
    _flagged(s, "invariant_violations")


def test_state_constraint_violation_counts(tmp_path, monkeypatch):
    """A plant pushed far outside D once (a 40 m/s kick at the last step, beyond paper-a's
    20 m/s bound): constraint_violations counts it.  A state outside the constraints is outside
    every T^l too, so the run then stops with an error naming the vehicle's index; the summary
    keeps the counter and says unsafe."""
    last = int(round(3.0 / 0.1))
    calls = {"n": 0}

    def kicked(m, X, U, c, pol, rng, heading=None):
        Xn, D = real_plant_step(m, X, U, c, pol, rng, heading=heading)
        calls["n"] += 1
        if calls["n"] == last:
            Xn = Xn.copy()
            Xn[:, 2] += 40.0
        return Xn, D

    monkeypatch.setattr(cosim_mod, "plant_step", kicked)
    s = _run(tmp_path, [_line("a", (0, 0), (60, 0))], duration=3.0)
    assert s["constraint_violations"] == 1
    assert "vehicle 'a'" in s["error"] and "outside" in s["error"]
    _flagged(s, "constraint_violations", complete=False)


def test_cli_exits_unsafe_and_says_so(tmp_path, monkeypatch, capsys):
    """The command line does not end green on a run whose counters fired: exit code 3 and a
    line naming the counters."""
    monkeypatch.setattr(cosim_mod, "plant_step", lambda m, X, U, c, pol, rng, heading=None: (X.copy(), 0 * X))
    rc = main(["run", "single", "--out", str(tmp_path / "ok"), "--duration", "2", "--quiet", "--log", "none"])
    assert rc == 0  # single does not use the loop's plant: untouched, safe
    rc = main(["run", "swap", "--vehicles", "2", "--out", str(tmp_path / "o"), "--duration", "3", "--quiet",
               "--log", "none"])
    assert rc == 3
    err = capsys.readouterr().err
    assert "UNSAFE" in err and "invariant_violations" in err
    assert json.loads((tmp_path / "o" / "summary.json").read_text())["safe"] is False


def test_sumo_collision_counts_in_a_real_sumo_run(grid_net, grid_routes, tmp_path, monkeypatch):
    """A world fault in a real SUMO run: after every push, the second vehicle in the network is
    put (moveToXY, any lane) exactly onto the first one's pose.  SUMO itself reports the
    collision; collisions_sumo counts it (a SumoWorld that drains SUMO's collisions without
    reporting them fails here) and the summary says unsafe."""
    from bridge.pose import front_bumper, sumo_angle
    from bridge.sumo_world import SumoWorld, run_sumo
    from sumo_nets.generate import write_sumocfg

    push = SumoWorld.push
    fault = {}

    def faulty_push(self, ids, centre, heading):
        c, h = np.asarray(centre, dtype=float), np.asarray(heading, dtype=float)
        b = fault.get("b")
        keep = [i for i, v in enumerate(ids) if v != b]
        push(self, [ids[i] for i in keep], c[keep], h[keep])
        move = self.adapter._api.vehicle.moveToXY  # keepRoute=2: any lane, off its route if need be
        if b is None and len(ids) >= 2:  # the fault, once: the second vehicle onto the first
            a, fault["b"] = ids[0], ids[1]
            front = front_bumper(c[:1], h[:1], [self.lengths[a]])[0]
            move(ids[1], "", -1, float(front[0]), float(front[1]), float(sumo_angle(h[0])), 2)
        elif b in ids:  # afterwards: that vehicle where the loop has it, off its SUMO route
            i = list(ids).index(b)
            front = front_bumper(c[i:i + 1], h[i:i + 1], [self.lengths[b]])[0]
            move(b, "", -1, float(front[0]), float(front[1]), float(sumo_angle(h[i])), 2)

    monkeypatch.setattr(SumoWorld, "push", faulty_push)
    cfg = write_sumocfg(tmp_path / "mine.sumocfg", grid_net, [grid_routes])
    opts = SimpleNamespace(seed=3, duration=15.0, tm="optimal", check="union", switching="early",
                           disturbance="none", solver="exact", baseline=None, gui=False, quiet=True, log="none")
    s = run_sumo(str(cfg), tmp_path / "out", opts)
    s["_out"] = tmp_path / "out"
    assert s["collisions_sumo"] >= 1
    assert s["collisions_geometric"] == 0  # muvsim's own vehicles never met: only SUMO saw it
    _flagged(s, "collisions_sumo")
