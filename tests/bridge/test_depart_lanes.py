"""departLane: numbers as written, SUMO's keywords as SUMO picks the lane (bridge.departure.DepartLanes,
NetGeometry.start_lanes), read from route files with and without a .sumocfg; real SUMO where SUMO is
what it is about."""

import subprocess
import sys
import xml.etree.ElementTree as ET
from collections import Counter
from pathlib import Path

import pytest

from bridge.demand import DemandError, read_demand
from bridge.departure import DepartLanes
from bridge.waypoints import RouteError, load_net
from tests.sumo_runs import run_cfg, write_cfg


def test_keywords_pick_as_sumo_does():
    """first: the rightmost; best: among the fewest lane changes, in turn; free / allowed: among
    all, in turn (per first edge and candidate set); random: among all, seeded; none or no lanes:
    the route's own choice (None)."""
    costs = {0: 1, 1: 0, 2: 0}
    d = DepartLanes(seed=3)
    assert d.pick("e", None, costs) is None and d.pick("e", "free", {}) is None
    assert d.pick("e", "first", costs) == 0
    assert [d.pick("e", "best", costs) for _ in range(4)] == [1, 2, 1, 2]
    assert [d.pick("e", "free", costs) for _ in range(4)] == [0, 1, 2, 0]
    assert [d.pick("f", "allowed", costs) for _ in range(2)] == [0, 1]  # its own turn: another edge
    drawn = [d.pick("e", "random", costs) for _ in range(300)]
    again = DepartLanes(seed=3)  # its draws alone, from the same seed
    assert set(drawn) == {0, 1, 2} and drawn == [again.pick("e", "random", costs) for _ in range(300)]


def test_start_lanes_count_the_lane_changes(netgenerate_grid):
    """On a 3-lane netgenerate grid a left turn at the first junction leaves from the leftmost lane:
    0 changes from there, 1 and 2 from the others; a straight route: 0 from every lane."""
    geo = load_net(netgenerate_grid(3, 3, 200, 3, "n.net.xml"))
    assert geo.start_lanes(["A0B0", "B0C0"], "passenger") == {0: 0, 1: 0, 2: 0}
    left = geo.start_lanes(["A0B0", "B0B1"], "passenger")
    assert left[max(left)] == 0 and left[0] == max(left) and sorted(left.values()) == [0, 1, 2]


def test_route_file_depart_lanes(tmp_path):
    f = tmp_path / "r.rou.xml"
    f.write_text('<routes><vehicle id="a" depart="0" departLane="2"><route edges="x"/></vehicle>'
                 '<vehicle id="b" depart="0" departLane="free"><route edges="x"/></vehicle>'
                 '<vehicle id="c" depart="0"><route edges="x"/></vehicle></routes>')
    a, b, c = read_demand(f).vehicles
    assert (a.depart_lane, a.depart_lane_rule) == (2, None)
    assert (b.depart_lane, b.depart_lane_rule) == (None, "free")
    assert (c.depart_lane, c.depart_lane_rule) == (None, None)
    f.write_text('<routes><vehicle id="v" depart="0" departLane="left"><route edges="x"/></vehicle></routes>')
    with pytest.raises(DemandError, match=r"vehicle 'v': departLane='left'.*free"):
        read_demand(f)


def test_a_free_flow_spreads_over_the_lanes_in_sumo(tmp_path, netgenerate_grid):
    """A flow with departLane="free" on a 3-lane road (a .sumocfg, SUMO's own expansion): muvsim
    starts its vehicles on all three lanes in turn, as SUMO's drivers spread over them (SUMO's
    tripinfo of each run); a numeric departLane is kept; 0 SUMO collisions.  (Before, every one
    started on the route's own choice, lane 0.)"""
    netgenerate_grid(3, 2, 300, 3)
    (tmp_path / "r.rou.xml").write_text(
        '<routes><flow id="f" begin="0" end="12" period="2" departLane="free" departSpeed="0">'
        '<route edges="A0B0 B0C0"/></flow>'
        '<vehicle id="n" depart="1" departLane="1" departSpeed="0"><route edges="A1B1 B1C1"/></vehicle></routes>')
    cfg = write_cfg(tmp_path / "s.sumocfg", "net.net.xml", routes=["r.rou.xml"])
    out = tmp_path / "m"
    rc, s = run_cfg(cfg, out, "--duration", "120")
    assert rc == 0 and s["complete"] and s["safe"], s.get("error") or s["safety_violations"]
    assert s["vehicles_arrived"] == 7 and s["collisions_sumo"] == 0
    lanes = {t.get("id"): t.get("departLane") for t in ET.parse(out / "tripinfo.xml").getroot().iter("tripinfo")}
    assert Counter(v for k, v in lanes.items() if k.startswith("f.")) == {"A0B0_0": 2, "A0B0_1": 2, "A0B0_2": 2}
    assert lanes["n"] == "A1B1_1"


def test_a_depart_lane_the_vclass_may_not_use_is_named(tmp_path):
    """A numeric departLane onto a lane the vehicle's vClass may not use (a bus lane for a car):
    a RouteError naming the vehicle, the lane, the edge and the lanes it may use (the run reports
    that vehicle undrivable and goes on)."""
    (tmp_path / "n.nod.xml").write_text('<nodes><node id="a" x="0" y="0"/><node id="b" x="200" y="0"/></nodes>')
    (tmp_path / "n.edg.xml").write_text('<edges><edge id="ab" from="a" to="b" numLanes="2" speed="13.89">'
                                        '<lane index="0" allow="bus"/></edge></edges>')
    net = tmp_path / "n.net.xml"
    subprocess.run([str(Path(sys.executable).parent / "netconvert"), "-n", str(tmp_path / "n.nod.xml"),
                    "-e", str(tmp_path / "n.edg.xml"), "-o", str(net)], check=True, capture_output=True)
    geo = load_net(net)
    assert geo.route(["ab"], 3.0, depart_lane=1, vclass="passenger").depart_lane_index == 1
    with pytest.raises(RouteError, match=r"vehicle 'v': depart lane 0 of edge 'ab' does not admit vClass "
                                         r"'passenger' \(lanes it may use: \[1\]\)"):
        geo.route(["ab"], 3.0, depart_lane=0, vclass="passenger", vehicle_id="v")
