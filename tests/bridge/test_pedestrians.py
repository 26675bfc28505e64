"""Pedestrians in the loop: the rule at the request step, the pedestrian_conflicts counter, and
real SUMO (a generated 4-arm junction with crossings, walking areas and personFlows)."""

import json
import subprocess
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from bridge.cosim import Cosim, CosimSettings, FreePlaneWorld, VehicleSpec
from bridge.layouts import subsample
from controllers.classes import builtin_classes
from sumo_nets.sumo_tools import binary
from tm.pedestrians import PedestrianRule, PedestrianSettings

CLASSES = builtin_classes()
#: A crossing 4 m wide over a road along x, at x = 30.
CROSSING = np.array([[28.0, -6.0], [32.0, -6.0], [32.0, 6.0], [28.0, 6.0]])


class StandingPedestrian(FreePlaneWorld):
    """The free plane plus one pedestrian standing on the crossing until ``leave_s``."""

    def __init__(self, leave_s: float, Ts: float = 0.1):
        self.t, self.leave_s, self.Ts = 0, leave_s, Ts

    def step(self):
        self.t += 1
        return []

    def pedestrians(self):
        if self.t * self.Ts < self.leave_s:
            return ["p"], np.array([[30.0, 0.0]])
        return [], np.zeros((0, 2))


def _run(enabled: bool, leave_s: float, controller: str = "paper"):
    vc = CLASSES["car"]
    spec = VehicleSpec(id="car", vclass="car", waypoints=subsample(np.array([[0.0, 0.0], [60.0, 0.0]]),
                                                                  vc.model.delta))
    s = CosimSettings(disturbance="none", controller=controller)
    rule = PedestrianRule(PedestrianSettings(enabled=enabled), [CROSSING], s.Ts)
    sim = Cosim(CLASSES, [spec], s, world=StandingPedestrian(leave_s), pedestrians=rule)
    sim.run(600)
    return sim


@pytest.mark.parametrize("controller", ["paper", "authority"])
def test_counter_fires_when_the_rule_is_off(controller):
    sim = _run(enabled=False, leave_s=1e9, controller=controller)
    assert sim.pedestrian_conflicts == {("car", "p")}
    assert sim.pedestrian_withheld == 0


@pytest.mark.parametrize("controller", ["paper", "authority"])
def test_rule_on_the_car_waits_for_the_pedestrian_and_then_goes(controller):
    sim = _run(enabled=True, leave_s=20.0, controller=controller)
    assert sim.pedestrian_conflicts == set()
    assert sim.pedestrian_withheld > 0
    rec = sim.records["car"]
    assert rec.arrived_s is not None and rec.arrived_s > 20.0   # after the pedestrian left
    # it stopped short of the crossing (x in [28, 32]): its footprint never reached it while p stood there
    if controller == "authority":
        assert rec.arrived_s < 20.0 + 15.0                          # and then went (60 m route)


# ------------------------------------------------------------------ real SUMO
NODES = """<nodes>
  <node id="W" x="-100" y="0" type="priority"/> <node id="C" x="0" y="0" type="priority"/>
  <node id="E" x="100" y="0" type="priority"/> <node id="N" x="0" y="30" type="priority"/>
  <node id="S" x="0" y="-30" type="priority"/>
</nodes>"""
ROUTES = """<routes>
  <vType id="car" vClass="passenger" length="5" width="1.8"/>
  <flow id="we" type="car" from="WC" to="CE" begin="0" end="50" period="6"/>
  <personFlow id="pn" begin="0" end="20" period="8"><walk from="NC" to="CS"/></personFlow>
  <personFlow id="ps" begin="4" end="20" period="8"><walk from="SC" to="CN"/></personFlow>
  <flow id="ew" type="car" from="EC" to="CW" begin="3" end="50" period="6"/>
</routes>"""


@pytest.fixture(scope="module")
def ped_cfg(tmp_path_factory):
    d = tmp_path_factory.mktemp("peds")
    (d / "n.nod.xml").write_text(NODES)
    arms = [("W", "C"), ("C", "W"), ("C", "E"), ("E", "C"), ("N", "C"), ("C", "N"), ("S", "C"), ("C", "S")]
    (d / "n.edg.xml").write_text("<edges>" + "".join(
        f'<edge id="{a}{b}" from="{a}" to="{b}" numLanes="1" speed="13.89" sidewalkWidth="2"/>' for a, b in arms)
        + "</edges>")
    subprocess.run([str(binary("netconvert")), "-n", str(d / "n.nod.xml"), "-e", str(d / "n.edg.xml"), "--crossings.guess",
                    "--walkingareas", "-o", str(d / "n.net.xml")], check=True, capture_output=True)
    (d / "r.rou.xml").write_text(ROUTES)
    cfg = d / "p.sumocfg"
    cfg.write_text('<configuration><input><net-file value="n.net.xml"/><route-files value="r.rou.xml"/></input>'
                   '<time><begin value="0"/><end value="120"/></time></configuration>')
    return cfg


def test_walk_regions_cover_sumo_pedestrians_and_their_speed_bound_holds(ped_cfg):
    """Every position SUMO gives a person on a crossing or walking area lies in a region (grown by
    WALK_MARGIN_M: without it SUMO's paths leave the walking areas' outlines by up to 0.22 m here);
    over every window of k = 1..60 steps of 0.1 s no person moves more than v_max k Ts + jump_m
    (the bound the rule assumes; single steps jump beyond v_max Ts, so the allowance is needed)."""
    import libsumo

    from bridge.sumo_pedestrians import read_persons, walk_regions
    from tm.pedestrians import SUMO_PED_SPEED_BOUND, point_polygon_distance

    regions = walk_regions(ped_cfg.parent / "n.net.xml")
    assert len(regions) >= 8   # 4 crossings and the walking areas' triangles
    libsumo.start(["sumo", "-c", str(ped_cfg), "--step-length", "0.1", "--no-step-log", "true",
                   "--no-warnings", "true"])
    try:
        track, on_walk, max_out = {}, 0, 0.0
        for _ in range(600):
            libsumo.simulationStep()
            ids, xy = read_persons(libsumo)
            for p, q in zip(ids, xy):
                track.setdefault(p, []).append(q)
                lane = libsumo.person.getLaneID(p)
                if "_c" in lane or "_w" in lane:   # SUMO names crossings :C_c<i>, walking areas :C_w<i>
                    on_walk += 1
                    d = point_polygon_distance(np.stack([_pad(r) for r in regions]),
                                               np.repeat(q[None], len(regions), axis=0)).min()
                    max_out = max(max_out, float(d))
    finally:
        libsumo.close()
    assert on_walk > 100
    assert max_out <= 1e-6       # 1e-6 m: round-off of coordinates of O(100) m
    # without the margin some positions are outside: the margin is needed
    bare = walk_regions(ped_cfg.parent / "n.net.xml", margin_m=0.0)
    assert len(bare) == len(regions)
    s = PedestrianSettings()
    excess_1 = -np.inf
    for a in map(np.array, track.values()):
        for k in range(1, 61):
            if len(a) > k:
                d = np.hypot(*(a[k:] - a[:-k]).T)
                assert d.max() <= SUMO_PED_SPEED_BOUND * k * 0.1 + s.jump_m, k
                if k == 1:
                    excess_1 = max(excess_1, float(d.max() - SUMO_PED_SPEED_BOUND * 0.1))
    assert excess_1 > 0   # a one-step jump beyond the speed bound: the allowance is used


def _pad(r, k=16):
    from tm.geometry import convex_hull
    h = convex_hull(r)
    return np.vstack([h, np.repeat(h[-1:], k - len(h), axis=0)])


class GrantWatch:
    """Observer: at each decision, the granted claims against persons on crossings (positions read
    after the previous step, which the rule saw)."""

    def __init__(self, crossings):
        self.crossings, self.peds, self.checked, self.inside = crossings, np.zeros((0, 2)), 0, 0

    def on_step(self, sim, state, decision, row):
        from tm.pedestrians import point_polygon_distance
        if decision is not None and decision.go.any() and len(self.peds):
            on = np.array([point_polygon_distance(self.crossings, np.repeat(p[None], len(self.crossings), 0)).min()
                           <= 1e-9 for p in self.peds])
            P = self.peds[on]
            g = np.flatnonzero(decision.go)
            polys = decision.claims.polygons(g)          # the granted (union) claims
            for poly in polys:
                self.checked += 1
                d = point_polygon_distance(np.repeat(poly[None], len(P), 0), P) if len(P) else np.zeros(0)
                self.inside += int((d <= 0.3).sum())     # within a body radius
        self.peds = sim.filters.peds()[1].copy()

    def close(self):
        pass


def _opts(**kw):
    base = dict(baseline=None, gui=False, seed=None, duration=120.0, tm=None, check=None, switching=None,
                disturbance=None, solver="exact", log="none", quiet=True, pedestrians="guard")
    base.update(kw)
    return SimpleNamespace(**base)


@pytest.mark.parametrize("mode", ["guard", "ignore"])
def test_no_granted_claim_contains_a_pedestrian_on_a_crossing(ped_cfg, tmp_path, monkeypatch, mode):
    import bridge.sumo_world as sw
    from bridge.sumo_pedestrians import _segment_boxes, _shape
    from bridge.sumo_inputs import parse_xml

    crossings = [b for e in parse_xml(ped_cfg.parent / "n.net.xml").getroot().iter("edge")
                 if e.get("function") == "crossing" for ln in e.iter("lane")
                 for b in _segment_boxes(_shape(ln.get("shape")), float(ln.get("width")))]
    watch = GrantWatch(np.stack(crossings))
    real = sw.observers_for
    monkeypatch.setattr(sw, "observers_for", lambda *a, **k: real(*a, **k) + [watch])
    s = sw.run_sumo(str(ped_cfg), tmp_path, _opts(pedestrians=mode))
    assert s["complete"] and s["collisions_sumo"] == 0
    assert s["vehicles_arrived"] > 0
    assert watch.checked > 100
    if mode == "guard":
        # with the rule persons get across; ignoring them, cars entering at the lane's speed (as SUMO
        # inserts them, bridge/departure.py) leave SUMO's yielding pedestrians no gap in 120 s
        assert s["persons_arrived"] > 0
        assert watch.inside == 0 and s["pedestrian_conflicts"] == 0 and s["pedestrian_withheld"] > 0
        assert s["safe"]
    else:  # without the rule grants do go over pedestrians on crossings: the check above is not vacuous
        assert watch.inside > 0 and s["pedestrian_withheld"] == 0
    persons = __import__("pandas").read_csv(tmp_path / "persons.csv")
    assert len(persons) == s["persons_arrived"]
    assert s["mean_person_delay_s"] == pytest.approx(persons["walk_time_loss_s"].mean())
    assert json.loads((tmp_path / "summary.json").read_text())["options"]["pedestrians"] == mode


def test_baseline_reports_pedestrians_delay(ped_cfg, tmp_path):
    import bridge.sumo_world as sw

    s = sw.run_sumo(str(ped_cfg), tmp_path, _opts(baseline="sumo"))
    assert s["persons_arrived"] == 5 and s["mean_person_delay_s"] >= 0
    assert (tmp_path / "persons.csv").exists()


def test_a_faster_pedestrian_vtype_raises_the_speed_bound(ped_cfg, tmp_path):
    """A runner (vType maxSpeed = desiredMaxSpeed = 5 m/s, speed factor 1): the bound becomes its
    walking speed times the striping factor sqrt(1.16), above the 3.0 m/s default."""
    import bridge.sumo_world as sw
    from tm.pedestrians import STRIPING_SPEED_FACTOR

    d = tmp_path / "in"
    d.mkdir()
    (d / "n.net.xml").write_bytes((ped_cfg.parent / "n.net.xml").read_bytes())
    (d / "r.rou.xml").write_text(
        '<routes><vType id="runner" vClass="pedestrian" maxSpeed="5" desiredMaxSpeed="5" speedFactor="1"/>'
        '<vType id="car" vClass="passenger" length="5" width="1.8"/>'
        '<person id="r" type="runner" depart="0"><walk from="NC" to="CS"/></person>'
        '<vehicle id="c" type="car" depart="0"><route edges="WC CE"/></vehicle></routes>')
    cfg = d / "p.sumocfg"
    cfg.write_text(ped_cfg.read_text())
    s = sw.run_sumo(str(cfg), tmp_path / "out", _opts(duration=5.0))
    assert s["complete"], s.get("error")
    assert s["pedestrian_speed_bound_mps"] == pytest.approx(5.0 * STRIPING_SPEED_FACTOR, rel=1e-3)


class ReachGrantWatch(GrantWatch):
    """GrantWatch for authority mode: at each decision, every granted reach claim's boxes S_k
    (k = 1 .. max(l, 1): the steps the rule checks) against persons on crossings (positions the
    rule saw); box corners built here, distances by tm.pedestrians.point_polygon_distance."""

    def on_step(self, sim, state, decision, row):
        from tm.pedestrians import point_polygon_distance
        if decision is not None and decision.go.any() and len(self.peds):
            on = np.array([point_polygon_distance(self.crossings, np.repeat(p[None], len(self.crossings), 0)).min()
                           <= 1e-9 for p in self.peds], dtype=bool)
            P = self.peds[on]
            c = decision.claims                           # in force after the decision: granted rows are new
            for i in np.flatnonzero(decision.go):
                for k in range(1, min(max(int(state.req_index[i]), 1), c.lo.shape[1]) + 1):
                    lo, hi = c.lo[i, k - 1], c.hi[i, k - 1]
                    if np.any(lo > hi):
                        continue
                    self.checked += 1
                    C = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
                    th = c.heading[i]
                    box = C @ np.array([[np.cos(th), np.sin(th)], [-np.sin(th), np.cos(th)]]) + c.centre[i]
                    if len(P):
                        d = point_polygon_distance(np.repeat(box[None], len(P), 0), P)
                        self.inside += int((d <= 0.3).sum())     # within a body radius
        self.peds = sim.filters.peds()[1].copy()


@pytest.mark.parametrize("mode", ["guard", "ignore"])
def test_authority_mode_no_granted_reach_claim_contains_a_pedestrian_on_a_crossing(ped_cfg, tmp_path,
                                                                                    monkeypatch, mode):
    """--controller authority on the 4-arm junction with personFlows (real SUMO): with the rule no
    granted S_k (k <= max(l, 1)) comes within a body radius of a person on a crossing, 0 SUMO
    collisions, 0 pedestrian_conflicts, requests withheld for pedestrians and still cars and persons
    arrive; without it grants do cover persons (the check is not vacuous) and cars arrive."""
    import bridge.sumo_world as sw
    from bridge.sumo_inputs import parse_xml
    from bridge.sumo_pedestrians import _segment_boxes, _shape

    crossings = [b for e in parse_xml(ped_cfg.parent / "n.net.xml").getroot().iter("edge")
                 if e.get("function") == "crossing" for ln in e.iter("lane")
                 for b in _segment_boxes(_shape(ln.get("shape")), float(ln.get("width")))]
    watch = ReachGrantWatch(np.stack(crossings))
    real = sw.observers_for
    monkeypatch.setattr(sw, "observers_for", lambda *a, **k: real(*a, **k) + [watch])
    s = sw.run_sumo(str(ped_cfg), tmp_path, _opts(controller="authority", pedestrians=mode))
    assert s["complete"], s.get("error")
    assert s["collisions_sumo"] == 0
    assert s["vehicles_arrived"] > 0
    assert watch.checked > 100
    if mode == "guard":
        # with the rule persons get across; ignoring them, cars entering at the lane's speed (as SUMO
        # inserts them, bridge/departure.py) leave SUMO's yielding pedestrians no gap in 120 s
        assert s["persons_arrived"] > 0
        assert watch.inside == 0 and s["pedestrian_conflicts"] == 0 and s["pedestrian_withheld"] > 0
        assert s["safe"]
    else:
        assert watch.inside > 0 and s["pedestrian_withheld"] == 0


# ------------------------------------------------------------------ one claim computation per step
def _counting(obj, name, calls):
    real = getattr(obj, name)

    def wrapped(*a, **k):
        calls.append(a)
        return real(*a, **k)
    setattr(obj, name, wrapped)


def test_paper_mode_the_junction_gate_and_the_pedestrian_rule_share_the_steps_claims():
    """Requests' claims are built once per step: the zone gate and the pedestrian rule both read them
    (each built its own before), and the rule still withholds."""
    from tm.junctions import Zone

    vc = CLASSES["car"]
    spec = VehicleSpec(id="car", vclass="car", waypoints=subsample(np.array([[0.0, 0.0], [60.0, 0.0]]),
                                                                  vc.model.delta))
    s = CosimSettings(disturbance="none")
    rule = PedestrianRule(PedestrianSettings(), [CROSSING], s.Ts)
    sim = Cosim(CLASSES, [spec], s, world=StandingPedestrian(1e9), pedestrians=rule,
                zones=[Zone("z", (26.0, -6.0), (34.0, 6.0))])
    calls, inside = [], []
    _counting(sim.tm, "claims", calls)
    real = sim._requests

    def requests():                                   # tm.claims calls made while the requests are filtered
        n0, w0 = len(calls), sim.pedestrian_withheld
        state = real()
        inside.append((len(calls) - n0, sim.pedestrian_withheld - w0))
        return state
    sim._requests = requests
    sim.run(300)
    assert max(n for n, _ in inside) == 1              # the gate and the rule: one computation
    assert sum(w for _, w in inside) > 10 and sim.pedestrian_conflicts == set()


def test_authority_mode_the_pedestrian_rule_and_the_tm_share_the_requests_reach_claims():
    vc = CLASSES["car"]
    spec = VehicleSpec(id="car", vclass="car", waypoints=subsample(np.array([[0.0, 0.0], [60.0, 0.0]]),
                                                                  vc.model.delta))
    s = CosimSettings(disturbance="none", controller="authority")
    rule = PedestrianRule(PedestrianSettings(), [CROSSING], s.Ts)
    sim = Cosim(CLASSES, [spec], s, world=StandingPedestrian(10.0), pedestrians=rule)
    calls = []
    _counting(sim.claims, "reach_claims", calls)
    sim.run(1)
    per_step = []
    for _ in range(300):
        calls.clear()
        sim.step()
        per_step.append(sum(1 for a in calls if a))      # calls for requests (with a FleetState argument)
    assert max(per_step) == 1 and sum(per_step) > 50
    assert sim.pedestrian_withheld > 0 and sim.records["car"].arrived_s is not None


def test_a_person_riding_a_vehicle_is_no_pedestrian(ped_cfg, tmp_path):
    """SUMO gives a rider its vehicle's position: read_persons leaves riders out (they met their own
    vehicle's footprint: pedestrian_conflicts fired on tools/game/rail), walkers stay in."""
    import libsumo

    from bridge.sumo_pedestrians import read_persons

    (tmp_path / "r.rou.xml").write_text(
        '<routes><vType id="car" vClass="passenger" length="5" width="1.8"/>'
        '<vehicle id="c" type="car" depart="triggered"><route edges="WC CE"/></vehicle>'
        '<person id="rider" depart="0"><ride from="WC" to="CE" lines="c"/></person>'
        '<person id="walker" depart="0"><walk from="NC" to="CS"/></person></routes>')
    libsumo.start(["sumo", "-n", str(ped_cfg.parent / "n.net.xml"), "-r", str(tmp_path / "r.rou.xml"),
                   "--step-length", "0.1", "--no-step-log", "true", "--no-warnings", "true"])
    try:
        riding = 0
        for _ in range(100):
            libsumo.simulationStep()
            ids, xy = read_persons(libsumo)
            assert "rider" not in ids or not libsumo.person.getVehicle("rider")
            assert "walker" in ids and xy.shape == (len(ids), 2)
            if "rider" in libsumo.person.getIDList() and libsumo.person.getVehicle("rider") == "c":
                riding += 1
                assert np.allclose(libsumo.person.getPosition("rider"), libsumo.vehicle.getPosition("c"), atol=5.0)
    finally:
        libsumo.close()
    assert riding > 50           # the rider was in the car for most of the window: the filter was needed


@pytest.mark.parametrize("controller", ["paper", "authority"])
@pytest.mark.parametrize("enabled", [True, False])
def test_admission_waits_while_a_pedestrian_stands_where_the_car_would_appear(controller, enabled):
    """A car whose first waypoint is 2 m before the crossing (its footprint reaches x = 28.5, the
    crossing starts at x = 28) is not admitted while the pedestrian stands on it (until 5 s), with
    either controller; with the rule off it appears at once and meets the pedestrian."""
    vc = CLASSES["car"]
    spec = VehicleSpec(id="car", vclass="car", waypoints=subsample(np.array([[26.0, 0.0], [60.0, 0.0]]),
                                                                  vc.model.delta))
    s = CosimSettings(disturbance="none", controller=controller)
    rule = PedestrianRule(PedestrianSettings(enabled=enabled), [CROSSING], s.Ts)
    sim = Cosim(CLASSES, [spec], s, world=StandingPedestrian(5.0), pedestrians=rule)
    sim.run(400)
    rec = sim.records["car"]
    if enabled:
        assert rec.admitted_s is not None and rec.admitted_s >= 5.0
        assert sim.pedestrian_withheld > 0 and sim.pedestrian_conflicts == set()
        assert rec.arrived_s is not None
    else:
        assert rec.admitted_s == 0.0 and sim.pedestrian_conflicts == {("car", "p")}


class StandingWatch:
    """Observer: vehicle-steps with a vehicle at rest (speed below 0.05 m/s) whose footprint meets a
    crossing (the crossings' own rectangles, not grown)."""

    def __init__(self, crossings):
        self.crossings, self.standing, self.steps = crossings, 0, 0

    def on_step(self, sim, state, decision, row):
        from tm.geometry import intersect_sat, rectangles
        for g in sim.groups.values():
            if not g.ids:
                continue
            self.steps += len(g.ids)
            still = np.flatnonzero(np.linalg.norm(g.X[:, 2:4], axis=1) < 0.05)
            if not len(still):
                continue
            _, hd, _ = g.centres()
            rect = rectangles(hd[still], g.vclass.length, g.vclass.width) + g.X[still, None, :2]
            vi, ci = np.repeat(np.arange(len(still)), len(self.crossings)), np.tile(np.arange(len(self.crossings)),
                                                                                       len(still))
            hit = intersect_sat(rect[vi], self.crossings[ci], 0.0)
            self.standing += len(np.unique(vi[hit]))

    def close(self):
        pass


def test_authority_mode_every_vehicle_and_person_arrives_and_no_vehicle_stands_on_a_crossing(ped_cfg, tmp_path,
                                                                                           monkeypatch):
    """Issue 12's pedestrian deadlock, real SUMO, --controller authority on the 4-arm junction: before the
    crossing gate (tm.crossing_gate) a car stood on the west crossing with its stop point there, SUMO's
    persons waited for it and its claims stayed within their reach (120 s: 1 of 9 cars, 2 of 5 persons
    arrived).  With it all 9 cars and 5 persons arrive, no car stands (speed < 0.05 m/s) with its
    footprint on a crossing, the gate did withhold entries, and safety holds: 0 SUMO collisions, 0
    pedestrian_conflicts, no granted S_k within a body radius of a person on a crossing."""
    import bridge.sumo_world as sw
    from bridge.sumo_inputs import parse_xml
    from bridge.sumo_pedestrians import _segment_boxes, _shape

    crossings = np.stack([b for e in parse_xml(ped_cfg.parent / "n.net.xml").getroot().iter("edge")
                          if e.get("function") == "crossing" for ln in e.iter("lane")
                          for b in _segment_boxes(_shape(ln.get("shape")), float(ln.get("width")))])
    grants, standing = ReachGrantWatch(crossings), StandingWatch(crossings)
    real = sw.observers_for
    monkeypatch.setattr(sw, "observers_for", lambda *a, **k: real(*a, **k) + [grants, standing])
    s = sw.run_sumo(str(ped_cfg), tmp_path, _opts(controller="authority"))
    assert s["complete"], s.get("error")
    assert s["vehicles_arrived"] == s["vehicles_total"] == 9
    assert s["persons_arrived"] == 5
    assert s["collisions_sumo"] == 0 and s["pedestrian_conflicts"] == 0 and s["safe"]
    assert grants.checked > 100 and grants.inside == 0
    assert standing.steps > 1000 and standing.standing == 0
    assert s["crossing_withheld"] > 0 and s["pedestrian_withheld"] > 0
