"""Movement-authority mode through the co-simulation loop (``CosimSettings.controller = "authority"``):
cruise speed, safety as a property over random free-plane scenarios, the tube-escape counter."""

import json
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

import bridge.cosim as cosim_mod
from bridge.cosim import Cosim, CosimSettings, VehicleSpec
from bridge.layouts import crossing, subsample
from bridge.scenarios import kpi_tables, run_multi
from controllers.classes import builtin_classes
from tm.settings import TMSettings

CLASSES = builtin_classes()
URBAN = ["car", "bus", "truck"]


def _speeds(sim: Cosim, vclass: str, max_steps: int = 4000) -> np.ndarray:
    sim._admit(0.0)
    v = []
    while not sim.done and sim.t < max_steps:
        sim.step()
        g = sim.groups[vclass]
        if g.ids:
            v.append(float(np.linalg.norm(g.X[0, 2:4])))
    assert sim.done, "the vehicle did not arrive"
    return np.array(v)


def test_single_car_cruises_at_the_lane_limit():
    """A car alone on a 600 m straight (random disturbances): its median speed is at least 13.5 m/s
    (the issue's target; v̄ = 13.89 m/s), where the paper's sets cap it near 5 m/s."""
    sp = VehicleSpec("a", "car", subsample([[0.0, 0.0], [600.0, 0.0]], 3.0))
    v = _speeds(Cosim(CLASSES, [sp], CosimSettings(controller="authority")), "car")
    assert np.median(v) >= 13.5
    assert v.max() <= 13.89 + 1e-6  # the along-road speed bound v̄ (tolerance: float rounding only)
    paper = _speeds(Cosim(CLASSES, [sp], CosimSettings()), "car", max_steps=20000)
    assert paper.max() < 6.0  # paper mode unchanged: capped by T^N (5.38 m/s measured)


def _merge(n: int, rng, vclass: str) -> list[VehicleSpec]:
    """Two roads meeting at 40 deg into one (a merge: claims conflict where the roads join)."""
    specs = []
    for i in range(n):
        side = 1.0 if i % 2 else -1.0
        start = np.array([-120.0 * np.cos(np.radians(20)), side * 120.0 * np.sin(np.radians(20))])
        pts = np.array([start, [0.0, 0.0], [150.0, 0.0]])
        specs.append(VehicleSpec(f"m{i}", vclass, subsample(pts, CLASSES[vclass].model.delta),
                                 depart_s=float(rng.uniform(0, 8))))
    return specs


def _queue(n: int, rng, vclass: str) -> list[VehicleSpec]:
    """Vehicles entering one straight road one after another (followers, admission)."""
    W = subsample([[0.0, 0.0], [400.0, 0.0]], CLASSES[vclass].model.delta)
    return [VehicleSpec(f"q{i}", vclass, W, depart_s=float(t)) for i, t in enumerate(np.sort(rng.uniform(0, 6, n)))]


@st.composite
def authority_scenarios(draw):
    seed = draw(st.integers(0, 2**31 - 1))
    rng = np.random.default_rng(seed)
    kind = draw(st.sampled_from(["crossing", "merge", "queue"]))
    vclass = draw(st.sampled_from(URBAN))
    if kind == "crossing":
        specs, _ = crossing(draw(st.integers(1, 2)), vclass, 3.0, headway_s=float(rng.uniform(1.0, 4.0)))
    elif kind == "merge":
        specs = _merge(draw(st.integers(2, 5)), rng, vclass)
    else:
        specs = _queue(draw(st.integers(2, 5)), rng, vclass)
    opts = CosimSettings(tm=TMSettings(policy=draw(st.sampled_from(["greedy", "optimal"])),
                                       check=draw(st.sampled_from(["union", "timed"])), seed=seed % 1000),
                         disturbance=draw(st.sampled_from(["random", "adversarial", "none"])), seed=seed % 1000,
                         controller="authority", frame=draw(st.sampled_from(["path", "road"])))
    return kind, specs, opts


@settings(max_examples=16, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(authority_scenarios())
def test_authority_mode_is_safe(scenario):
    """Random crossings, merges and queues of cars, buses or trucks, random TM policies, checks,
    disturbance policies (adversarial included) and plant frames (path, road): no footprint overlap, reach claims pairwise
    disjoint after every step, the index invariant holds, x(t+1) always inside S_1(t); the TM decided
    on the monitor's fresh claims of the same state (tm.reach_cache offer), never recomputed."""
    kind, specs, opts = scenario
    sim = Cosim(CLASSES, specs, opts)
    sim.run(max_steps=900)
    figures, _, _ = kpi_tables(sim)
    assert figures["collisions_geometric"] == 0
    assert figures["footprint_overlaps"] == 0
    assert figures["claim_violations"] == 0
    assert figures["invariant_violations"] == 0
    assert figures["constraint_violations"] == 0
    assert figures["tube_escapes"] == 0
    assert sim.monitor.steps > 0
    st = sim.claim_cache.stats
    assert st.offered > 0 and st.reused == 0 and st.fresh <= len(specs)  # fresh: the first decision only


def test_crossing_authority_all_arrive_and_safe():
    """The ``crossing`` scenario (8 cars through one square zone) through run_multi: every car
    arrives, every safety counter 0, and the zone is used (tokens handed out, none ignored)."""
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as d:
        opts = SimpleNamespace(vclass="car", tm="optimal", check="union", switching="early", disturbance="random",
                               solver="exact", duration=None, vehicles=8, seed=0, controller="authority")
        summary = run_multi("crossing", Path(d), opts)
        written = json.loads((Path(d) / "summary.json").read_text())
    assert summary["complete"] and written["safe"] is True
    assert written["tube_escapes"] == 0 and written["claim_violations"] == 0
    assert written["vehicles_arrived"] == 8
    assert written["zones"] == 1 and written["zones_ignored"] == 0
    assert written["junction_tokens"] >= 8  # each car crosses the square once, with a token


def test_tube_escape_counter_fires(monkeypatch):
    """A plant pushed 2 m sideways (far outside the disturbance box D): the vehicle leaves its S_1,
    the tube-escape counter fires and the safety verdict names it."""
    real = cosim_mod.plant_step

    def pushed(model, X, U, cen, disturbance, rng, heading=None):
        Xn, d = real(model, X, U, cen, disturbance, rng, heading=heading)
        Xn = Xn.copy()
        Xn[:, 1] += 2.0
        return Xn, d

    sp = VehicleSpec("a", "car", subsample([[0.0, 0.0], [60.0, 0.0]], 3.0))
    sim = Cosim(CLASSES, [sp], CosimSettings(controller="authority"))
    sim._admit(0.0)
    sim.step()
    assert sim.monitor.tube_escapes == 0  # unpushed: inside
    monkeypatch.setattr(cosim_mod, "plant_step", pushed)
    sim.step()
    assert sim.monitor.tube_escapes == 1
    figures, _, _ = kpi_tables(sim)
    assert figures["tube_escapes"] == 1
    assert figures["safe"] is False and "tube_escapes" in figures["safety_violations"]


def test_controller_setting_validated():
    """A bad controller name, or a class without comfort_decel in authority mode: clear errors."""
    with pytest.raises(ValueError, match="CosimSettings.controller"):
        CosimSettings(controller="fast")
    sp = VehicleSpec("a", "paper-a", subsample([[0.0, 0.0], [30.0, 0.0]], CLASSES["paper-a"].model.delta))
    with pytest.raises(ValueError, match="paper-a.*comfort_decel"):
        Cosim(CLASSES, [sp], CosimSettings(controller="authority"))


def _turn(R: float, delta: float = 3.0) -> np.ndarray:
    """60 m straight east, a 90 degree left arc of radius R, 60 m straight north, subsampled."""
    t = np.linspace(-0.5 * np.pi, 0.0, 24)
    arc = np.column_stack([R * np.cos(t), R + R * np.sin(t)])
    return subsample(np.vstack([[[-60.0, 0.0]], arc, [[R, R + 60.0]]]), delta)


def _turn_run(W, frame):
    sim = Cosim(CLASSES, [VehicleSpec("a", "car", W)], CosimSettings(controller="authority", frame=frame))
    sim._admit(0.0)
    xy, v = [], []
    while not sim.done and sim.t < 3000:
        sim.step()
        g = sim.groups["car"]
        if g.ids:
            xy.append(sim.world_states(g)[0, :2])
            v.append(float(np.hypot(*sim.world_states(g)[0, 2:4])))
    assert sim.done
    return sim, np.array(xy), np.array(v)


def test_a_path_frame_car_turns_without_crawling():
    """One car through a 90 degree left turn of radius 15 m (issue 12: in the road frame the stop
    point cannot go round the corner until the car is nearly there; bench_turn: slowest 0.81 m/s).
    With the path frame its slowest speed within the turn and 10 m either side is at least 4 m/s
    (the curve speed there is sqrt(2 / (1/15)) = 5.5 m/s; bench_turn measured 5.47), with the road
    frame below 2 m/s; every safety counter 0 in both."""
    W = _turn(15.0)
    slowest = {}
    for frame in ("path", "road"):
        sim, xy, v = _turn_run(W, frame)
        near = (xy[:, 0] > -10.0) & (xy[:, 1] < 25.0)  # from 10 m before the arc to 10 m after it
        slowest[frame] = v[near].min()
        figures, _, _ = kpi_tables(sim)
        assert figures["safe"] is True, (frame, figures["safety_violations"])
        assert figures["tube_escapes"] == 0 and figures["invariant_violations"] == 0
    assert slowest["path"] >= 4.0 and slowest["road"] < 2.0, slowest


def test_a_path_frame_drives_a_route_the_road_frame_refuses():
    """A route with a 90 degree kink (no arc): the road frame refuses it, naming the vehicle and the
    waypoint; the path frame drives it (slowly round the kink: the curve speed of its curvature),
    safely, to the end."""
    W = subsample([[0.0, 0.0], [45.0, 0.0], [45.0, 45.0]], 3.0)
    k = int(np.flatnonzero((W[:, 0] == 45.0) & (W[:, 1] == 0.0))[0])  # the kink
    with pytest.raises(ValueError, match=rf"vehicle a: its route turns by 90.0 deg at waypoint {k}; "):
        Cosim(CLASSES, [VehicleSpec("a", "car", W)], CosimSettings(controller="authority", frame="road"))
    sim, xy, v = _turn_run(W, "path")
    assert np.hypot(*(xy[-1] - W[-1])) < 1.0
    figures, _, _ = kpi_tables(sim)
    assert figures["safe"] is True and figures["tube_escapes"] == 0


def test_frame_setting_validated():
    with pytest.raises(ValueError, match="CosimSettings.frame: must be one of"):
        CosimSettings(controller="authority", frame="world")
    with pytest.raises(ValueError, match="'path' needs controller 'authority'"):
        CosimSettings(frame="path")
    assert CosimSettings(controller="authority").path_frame and not CosimSettings().path_frame


@pytest.mark.parametrize("frame", ["path", "road"])
def test_entry_claims_are_computed_once_per_waiting_vehicle(frame, monkeypatch):
    """A queue departing at once onto one road: most vehicles wait many steps for their entry to
    clear.  Their entry claims (condition (12)) are computed at their first attempt only, and what
    the admission sees each step equals a fresh computation for the vehicles then waiting (cars and
    buses mixed: the kept claims have the longer horizon, padded with the last slot)."""
    from bridge.fleet_claims import FleetClaims

    W = subsample([[0.0, 0.0], [300.0, 0.0]], CLASSES["car"].model.delta)
    specs = [VehicleSpec(f"q{i}", "bus" if i % 3 == 1 else "car", W, depart_s=0.0) for i in range(6)]
    sim = Cosim(CLASSES, specs, CosimSettings(controller="authority", frame=frame, seed=1))
    fresh_rows, seen = [], []
    real_fresh, real_entry = FleetClaims._entry_fresh, FleetClaims.entry_claims

    def counting(self, ready, *a):
        fresh_rows.extend(sp.id for sp in ready)
        return real_fresh(self, ready, *a)

    def checking(self, ready, cand, with_index=False, starts=None):
        got = real_entry(self, ready, cand, with_index, starts)
        want, idx = real_fresh(self, ready, cand.family, cand.centre, cand.heading,
                               [None] * len(ready) if starts is None else starts)
        K = want.lo.shape[1]
        assert np.array_equal(got[0].lo[:, :K], want.lo) and np.array_equal(got[0].hi[:, :K], want.hi)
        assert (got[0].lo[:, K:] == got[0].lo[:, K - 1:K]).all()  # padding: the last slot repeated
        assert np.array_equal(got[1], idx)
        seen.append(len(ready))
        return got

    monkeypatch.setattr(FleetClaims, "_entry_fresh", counting)
    monkeypatch.setattr(FleetClaims, "entry_claims", checking)
    sim.run(max_steps=600)
    assert sum(seen) > 3 * len(specs)  # vehicles waited several steps ...
    assert sorted(fresh_rows) == sorted(sp.id for sp in specs)  # ... yet each was computed once
    assert all(r.admitted_s is not None for r in sim.records.values())


@pytest.mark.parametrize("check", ["timed", "union"])
def test_ordered_entry_only_with_time_indexed_claims(check):
    """The junction layer's ordered entry (:meth:`tm.authority_gate.AuthorityGate._after`) is on with
    the timed check and off with ``union``, whose claims are the hull of a vehicle's slots: wider than
    the standing box a candidate coming up to a holder's path keeps out of it."""
    sp = VehicleSpec("a", "car", subsample([[0.0, 0.0], [60.0, 0.0]], 3.0))
    sim = Cosim(CLASSES, [sp], CosimSettings(controller="authority", tm=TMSettings(check=check)))
    assert sim.junctions.ordered_entry is (check == "timed")


@pytest.mark.parametrize("check", ["timed", "union"])
def test_crossing_takes_tokens_in_order_with_the_timed_check(check):
    """The ``crossing`` scenario (8 cars from four arms through one zone): with the timed check some
    tokens are taken after holders whose corridors cross (``junction_ordered``, ordered entry), with
    ``union`` none; either way every car arrives and every safety counter stays 0."""
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as d:
        opts = SimpleNamespace(vclass="car", tm="optimal", check=check, switching="early", disturbance="random",
                               solver="exact", duration=None, vehicles=8, seed=0, controller="authority")
        run_multi("crossing", Path(d), opts)
        written = json.loads((Path(d) / "summary.json").read_text())
    assert written["safe"] is True and written["vehicles_arrived"] == 8
    assert (written["junction_ordered"] > 0) is (check == "timed")


def test_stop_tables_are_the_routes_and_pads_row_by_row():
    """The junction gate's stop tables (:meth:`bridge.request_filters.RequestFilters._stop_table`: the groups'
    :meth:`~bridge.groups._Group.stop_points` and the fleet claims' padding memo) hold, for every row,
    the floats its route and its padding lookup give one row at a time, at several steps of a crossing."""
    specs, zones = crossing(2, "car", 3.0, headway_s=1.5)
    sim = Cosim(CLASSES, specs, CosimSettings(controller="authority", seed=1), zones=zones)
    checked = 0
    for _ in range(300):
        sim.step()
        fleet = getattr(sim.filters, "_junction_fleet", None)
        if fleet is None or not len(fleet.ids) or sim.t % 25:
            continue
        for ahead in (0, 1, 2):
            W, Hi, Ho, P = fleet.stop_table(ahead)
            for r in range(len(fleet.ids)):
                Wr, Hr, k = fleet.route(r)
                i = min(k + ahead, len(Wr) - 1)
                assert np.array_equal(W[r], Wr[i]) and Hi[r] == Hr[i] and Ho[r] == Hr[min(i + 1, len(Wr) - 1)]
                assert np.array_equal(P[r], fleet.pad_rows(np.array([r]), np.array([i]))[0])
            checked += 1
    assert checked
