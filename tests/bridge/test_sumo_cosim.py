"""The SUMO co-simulation end to end, with real SUMO (libsumo) judging collisions."""

import json
from types import SimpleNamespace

import pytest

from bridge.cli import main
from bridge.sumo_world import junction_zones, run_sumo
from sumo_nets.generate import write_sumocfg


def _opts(**kw):
    base = dict(seed=3, duration=40.0, tm=None, check=None, switching=None, disturbance=None, solver="exact",
                baseline=None, gui=False, quiet=True)
    base.update(kw)
    return SimpleNamespace(**base)


def test_user_sumocfg_runs_without_collisions(grid_net, grid_routes, tmp_path):
    """A .sumocfg written here (not a built-in) runs: SUMO reports no collision, nor does muvsim's
    geometric monitor, the tube invariant holds every step, and tripinfo is kept."""
    cfg = write_sumocfg(tmp_path / "mine.sumocfg", grid_net, [grid_routes])
    s = run_sumo(str(cfg), tmp_path / "out", _opts(tm="optimal", check="union", switching="early",
                                                   disturbance="adversarial"))
    assert s["complete"], s.get("error")
    assert s["collisions_sumo"] == 0 and s["collisions_geometric"] == 0
    assert s["invariant_violations"] == 0 and s["constraint_violations"] == 0
    assert s["vehicles_total"] == 20 and s["steps"] == 400
    assert (tmp_path / "out" / "tripinfo.xml").exists()
    assert (tmp_path / "out" / "vehicles.csv").stat().st_size > 100


def test_same_seed_same_summary(grid_net, grid_routes, tmp_path):
    cfg = write_sumocfg(tmp_path / "mine.sumocfg", grid_net, [grid_routes])
    a = run_sumo(str(cfg), tmp_path / "a", _opts(duration=20.0, tm="greedy", check="union", switching="early",
                                                 disturbance="random"))
    b = run_sumo(str(cfg), tmp_path / "b", _opts(duration=20.0, tm="greedy", check="union", switching="early",
                                                 disturbance="random"))
    timing = lambda k: k in ("wall_s", "rtf", "scenario") or k.endswith("_ms")  # machine-dependent
    assert {k: v for k, v in a.items() if not timing(k)} == {k: v for k, v in b.items() if not timing(k)}


def test_junctions_are_zones(grid_net):
    zones = junction_zones(grid_net)
    assert len(zones) == 9  # 3 x 3 junctions (approach stubs end in dead ends)
    for z in zones:
        assert all(lo < hi for lo, hi in zip(z.lo, z.hi))


def test_a_junction_whose_links_never_conflict_is_no_zone():
    """SUMO's ``ramp`` demo, its network unchanged: at ``gneJ4`` the on-ramp's lane joins the motorway as a
    lane of its own (right-of-way matrix without foes), at ``gneJ14`` two one-lane roads merge into one
    (foes): only ``gneJ14`` is a zone.  Read from the file, so the check holds for SUMO's own matrix."""
    import xml.etree.ElementTree as ET

    from sumo_nets.sumo_tools import sumo_home

    net = sumo_home() / "tools" / "game" / "ramp" / "ramp.net.xml"
    junctions = {j.get("id"): j for j in ET.parse(net).getroot().iter("junction")}
    foes = lambda name: [r.get("foes") for r in junctions[name].iter("request")]  # noqa: E731
    assert foes("gneJ4") == ["000", "000", "000"] and "1" in "".join(foes("gneJ14"))  # the premise
    assert len({lane.rsplit("_", 1)[0] for lane in junctions["gneJ4"].get("incLanes").split()}) == 2
    assert [z.name for z in junction_zones(net)] == ["gneJ14"]


def test_a_junction_without_a_right_of_way_matrix_stays_a_zone(tmp_path):
    """No ``<request>`` elements (a hand-written or stripped network): nothing says its links never
    conflict, so it stays a zone; with a matrix that lists a foe it is one too."""
    def net(requests: str):
        path = tmp_path / f"n{len(requests)}.net.xml"
        path.write_text('<net><junction id="J" type="priority" x="0" y="0" incLanes="a_0 b_0" intLanes="" '
                        f'shape="-5,-5 5,-5 5,5 -5,5">{requests}</junction></net>')
        return path
    assert [z.name for z in junction_zones(net(""))] == ["J"]
    assert [z.name for z in junction_zones(net('<request index="0" response="00" foes="10" cont="0"/>'
                                               '<request index="1" response="01" foes="01" cont="0"/>'))] == ["J"]
    assert junction_zones(net('<request index="0" response="00" foes="00" cont="0"/>'
                              '<request index="1" response="00" foes="00" cont="0"/>')) == []


def test_unreadable_net_ends_in_clear_message(grid_routes, tmp_path):
    bad = tmp_path / "broken.net.xml"
    bad.write_text("<net><edge id='a'")  # truncated XML
    cfg = write_sumocfg(tmp_path / "bad.sumocfg", bad, [grid_routes])
    s = run_sumo(str(cfg), tmp_path / "out", _opts(tm="optimal", check="union", switching="early",
                                                   disturbance="none"))
    assert not s["complete"] and "broken.net.xml" in s["error"]
    # what was written stays valid JSON and says why
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["error"] == s["error"]


def test_baseline_sumo_drives_the_same_demand(grid_net, grid_routes, tmp_path):
    cfg = write_sumocfg(tmp_path / "mine.sumocfg", grid_net, [grid_routes])
    assert main(["run", str(cfg), "--baseline", "sumo", "--out", str(tmp_path / "base"), "--quiet",
                 "--duration", "200", "--seed", "3"]) == 0
    s = json.loads((tmp_path / "base" / "summary.json").read_text())
    assert s["baseline"] == "sumo" and s["collisions_sumo"] == 0 and s["vehicles_arrived"] == 20


def test_gui_without_display_is_a_clear_error(grid_net, grid_routes, tmp_path, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    cfg = write_sumocfg(tmp_path / "mine.sumocfg", grid_net, [grid_routes])
    s = run_sumo(str(cfg), tmp_path / "out", _opts(gui=True, tm="optimal", check="union", switching="early",
                                                   disturbance="none"))
    assert not s["complete"] and "display" in s["error"].lower()


def test_small_grid_every_vehicle_arrives(grid_net, tmp_path):
    """A small grid run (3 x 3 junctions, 10 vehicles, mixed classes): zero collisions reported by
    SUMO, zero by the geometric monitor, zero invariant violations, and every vehicle arrives
    (bound: 400 simulated seconds, early switching)."""
    from sumo_nets.generate import make_demand

    routes = make_demand(grid_net, tmp_path, seed=9, vehicles=10, duration_s=30.0,
                         class_mix={"car": 0.6, "bus": 0.2, "truck": 0.2})
    cfg = write_sumocfg(tmp_path / "small.sumocfg", grid_net, [routes])
    s = run_sumo(str(cfg), tmp_path / "out", _opts(duration=400.0, tm="optimal", check="union",
                                                   switching="early", disturbance="random"))
    assert s["complete"], s.get("error")
    assert s["collisions_sumo"] == 0 and s["collisions_geometric"] == 0 and s["invariant_violations"] == 0
    assert s["vehicles_total"] == 10 and s["vehicles_arrived"] == 10 and s["finished"]
    trips = (tmp_path / "out" / "tripinfo.xml").read_text()
    assert trips.count("<tripinfo ") == 10


def test_user_sumocfg_runs_with_default_options(grid_net, grid_routes, tmp_path):
    """A .sumocfg carries no muvsim options: the command line's absent ones take the defaults."""
    from bridge.sumo_world import SUMOCFG_DEFAULTS

    cfg = write_sumocfg(tmp_path / "mine.sumocfg", grid_net, [grid_routes])
    s = run_sumo(str(cfg), tmp_path / "out", _opts(duration=5.0))
    assert s["complete"], s.get("error")
    assert {k: s["options"][k] for k in SUMOCFG_DEFAULTS} == SUMOCFG_DEFAULTS
    assert s["options"]["check"] == "union"  # the paper controller's check (tm.settings.default_check)


def test_authority_runs_take_the_timed_check_unless_told(grid_net, grid_routes, tmp_path):
    """--check left out: a movement-authority run compares its claims step by step (timed), on a
    .sumocfg and on the built-in grid alike; --check union still wins when given."""
    cfg = write_sumocfg(tmp_path / "mine.sumocfg", grid_net, [grid_routes])
    s = run_sumo(str(cfg), tmp_path / "a", _opts(duration=3.0, controller="authority"))
    assert s["complete"], s.get("error")
    assert s["options"]["check"] == "timed"
    s = run_sumo(str(cfg), tmp_path / "b", _opts(duration=3.0, controller="authority", check="union"))
    assert s["options"]["check"] == "union"
    s = run_sumo("grid", tmp_path / "c", _opts(duration=3.0, controller="authority"))
    assert s["complete"], s.get("error")
    assert s["options"]["check"] == "timed"


def test_departures_put_the_whole_body_on_the_first_lane(grid_net):
    """SUMO inserts with the back at the start of the first lane (departPos="base"); muvsim's first
    waypoint (the body's centre) is half a length plus DEPART_CLEARANCE_M in, so no body sticks
    back into the junction behind (found as a SUMO junction collision on grid-large), and the
    trimmed waypoints are still at most delta apart and on the route."""
    import numpy as np

    from bridge.sumo_world import DEPART_CLEARANCE_M
    from bridge.waypoints import load_net, trim_start

    geo = load_net(grid_net)
    net = __import__("sumolib").net.readNet(str(grid_net))
    e = next(ed for ed in net.getEdges() if ed.getOutgoing() and ed.getLength() > 30)
    nxt = next(iter(e.getOutgoing()))
    r = geo.route([e.getID(), nxt.getID()], 3.0)
    for length in (5.0, 12.0):
        W = trim_start(r, 0.5 * length + DEPART_CLEARANCE_M)
        arc0 = float(np.hypot(*(W[0] - r.polyline[0])))  # first edge is straight here
        assert arc0 == pytest.approx(0.5 * length + DEPART_CLEARANCE_M, abs=1e-9)
        assert np.all(np.linalg.norm(np.diff(W, axis=0), axis=1) <= 3.0 + 1e-9)
        assert np.allclose(W[-1], r.waypoints[-1]) and len(W) < len(r.waypoints)
