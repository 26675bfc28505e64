"""A lane's speed limit holds in real SUMO (libsumo): a generated network with a 5 m/s edge.

netconvert builds a straight a-b-c-d road (13.89, 5, 13.89 m/s, one lane each); one car drives
it under each controller.  The limits reach muvsim from SUMO's network file (bridge.waypoints),
so this is the whole chain: network -> waypoints' limits -> controller -> SUMO.
"""

import json

import pandas as pd
import pytest

from analysis.kpis import SPEED_LIMIT_KPI_TOL
from bridge.cli import main
from sumo_nets.sumo_tools import binary, run_tool


@pytest.fixture(scope="module")
def slow_road(tmp_path_factory):
    d = tmp_path_factory.mktemp("slow")
    (d / "n.nod.xml").write_text('<nodes><node id="a" x="0" y="0"/><node id="b" x="120" y="0"/>'
                                 '<node id="c" x="180" y="0"/><node id="d" x="300" y="0"/></nodes>')
    (d / "n.edg.xml").write_text('<edges><edge id="ab" from="a" to="b" speed="13.89"/>'
                                 '<edge id="bc" from="b" to="c" speed="5"/>'
                                 '<edge id="cd" from="c" to="d" speed="13.89"/></edges>')
    net = d / "n.net.xml"
    run_tool([binary("netconvert"), "-n", d / "n.nod.xml", "-e", d / "n.edg.xml", "-o", net], what="netconvert")
    (d / "r.rou.xml").write_text('<routes><vehicle id="v" depart="0"><route edges="ab bc cd"/></vehicle></routes>')
    (d / "s.sumocfg").write_text(f'<configuration><input><net-file value="{net}"/>'
                                 f'<route-files value="{d / "r.rou.xml"}"/></input></configuration>')
    return d / "s.sumocfg"


@pytest.mark.parametrize("controller", ["authority", "paper"])
def test_a_car_keeps_a_5_mps_lane_limit_in_sumo(slow_road, tmp_path, controller):
    """Max speed over the lane limit under the front <= SPEED_LIMIT_KPI_TOL (0.025 m/s: the
    controller bounds the nominal next speed, the disturbance adds to it, see its comment);
    it arrives, SUMO reports no collision, the delay is not negative (free flow at the limits)."""
    out = tmp_path / controller
    rc = main(["run", str(slow_road), "--out", str(out), "--quiet", "--log", "none", "--controller", controller,
               "--duration", "150"])
    s = json.loads((out / "summary.json").read_text())
    assert rc == 0 and s["complete"], s.get("error")
    v = pd.read_csv(out / "vehicles.csv").set_index("id")
    assert v.loc["v", "arrival_s"] > 0
    assert v.loc["v", "speed_limit_excess_max"] <= SPEED_LIMIT_KPI_TOL
    assert s["speed_limit_excess_max"] <= SPEED_LIMIT_KPI_TOL and s["vehicles_over_limit"] == 0
    assert s["collisions_sumo"] == 0 and s["invariant_violations"] == 0
    # free flow at the limits: 120/13.89 + 60/5 + 120/13.89 less the trimmed start, more than 300/13.89
    assert v.loc["v", "free_flow_s"] > 300 / 13.89 + 5 and v.loc["v", "delay_s"] >= 0
    if controller == "authority":  # and it still cruises on the fast edges
        assert v.loc["v", "mean_speed_mps"] > 6.0


def test_ignoring_the_limits_makes_the_kpi_fire(slow_road, tmp_path):
    """--speed-limits ignore: the car crosses the 5 m/s edge at the class bound and the KPI says so
    (measured 8.89 m/s over); the run still records the option."""
    out = tmp_path / "ign"
    rc = main(["run", str(slow_road), "--out", str(out), "--quiet", "--log", "none", "--controller", "authority",
               "--speed-limits", "ignore", "--duration", "150"])
    s = json.loads((out / "summary.json").read_text())
    assert rc == 0 and s["complete"], s.get("error")
    assert s["speed_limit_excess_max"] > 8.0 and s["vehicles_over_limit"] == 1
    assert s["options"]["speed_limits"] == "ignore"


def test_straight_connections_of_sumos_cross_are_driven_at_the_lane_speed(tmp_path):
    """SUMO's ``tools/game/cross`` network, unchanged: the nodes where its arms' lane counts change
    (``m1`` .. ``m4``) bend the lanes of their straight connections sideways by a lane width over
    ~8 m.  Those internal lanes are flagged straight (a turning connection's are not: the right
    turn keeps its curve speed) and a lone car on the green through route keeps the lane's speed
    through them, as SUMO's drivers do: its speed bound never drops below 13.89 m/s and it loses
    less than 4 s to free flow, start and stop at its route's end included (at the curve speed of
    the S-bends, 4.2 m/s, it lost 12.6 s); 0 SUMO collisions, its claims held."""
    from bridge.waypoints import load_net
    from sumo_nets.sumo_tools import sumo_home

    net = sumo_home() / "tools" / "game" / "cross" / "cross.net.xml"
    geo = load_net(net)
    through, right = geo.route("1fi 1si 2o 2fo".split(), 3.0), geo.route("3fi 3si 2o 2fo".split(), 3.0)
    flagged = {lane for lane, s in zip(through.lane_ids, geo.straight_through(through)) if s}
    assert flagged == {":m1_1_1", ":0_7_0", ":m2_3_0"}
    assert ":0_3_0" in right.lane_ids and ":0_3_0" not in {
        lane for lane, s in zip(right.lane_ids, geo.straight_through(right)) if s}
    (tmp_path / "r.rou.xml").write_text('<routes><vehicle id="v" depart="0" departSpeed="13.89">'
                                        '<route edges="1fi 1si 2o 2fo"/></vehicle></routes>')
    cfg = tmp_path / "s.sumocfg"  # the network's own light program: the through route is green 0-33 s
    cfg.write_text(f'<configuration><input><net-file value="{net}"/><route-files value="r.rou.xml"/></input>'
                   f'</configuration>')
    out = tmp_path / "m"
    rc = main(["run", str(cfg), "--out", str(out), "--quiet", "--log", "none", "--duration", "60"])
    s = json.loads((out / "summary.json").read_text())
    assert rc == 0 and s["complete"] and s["safe"], s.get("error") or s["safety_violations"]
    assert s["collisions_sumo"] == 0 and s["tube_escapes"] == 0
    v = pd.read_csv(out / "vehicles.csv").set_index("id")
    assert v.loc["v", "arrival_s"] > 0 and v.loc["v", "delay_s"] < 4.0


@pytest.fixture(scope="module")
def corner(tmp_path_factory):
    """An L-shaped road (a-b-c, a left turn at b, 13.89 m/s, one lane), built by netconvert at its
    default turn acceleration and at 3 m/s^2, with one car driving it."""
    d = tmp_path_factory.mktemp("corner")
    (d / "n.nod.xml").write_text('<nodes><node id="a" x="0" y="0"/><node id="b" x="150" y="0"/>'
                                 '<node id="c" x="150" y="150"/></nodes>')
    (d / "n.edg.xml").write_text('<edges><edge id="ab" from="a" to="b" speed="13.89"/>'
                                 '<edge id="bc" from="b" to="c" speed="13.89"/></edges>')
    (d / "r.rou.xml").write_text('<routes><vehicle id="v" depart="0"><route edges="ab bc"/></vehicle></routes>')
    cfgs = {}
    for name, extra in (("default", []), ("three", ["--junctions.limit-turn-speed", "3"])):
        net = d / f"{name}.net.xml"
        run_tool([binary("netconvert"), "-n", d / "n.nod.xml", "-e", d / "n.edg.xml", "-o", net, *extra],
                 what="netconvert")
        cfgs[name] = d / f"{name}.sumocfg"
        cfgs[name].write_text(f'<configuration><input><net-file value="{net}"/>'
                              f'<route-files value="{d / "r.rou.xml"}"/></input></configuration>')
    return cfgs


def test_curve_speed_takes_the_networks_turn_acceleration(corner, tmp_path):
    """``--lat-accel net``: the curve speed uses the lateral acceleration the network's turn speeds
    were built with (``limitTurnSpeed``: netconvert's 5.5 m/s^2 by default, 3 when built so), which
    SUMO's drivers drive; without the option 2.0.  The car is through the corner sooner the larger
    it is, keeps every lane limit (the junction lane's included), 0 SUMO collisions."""
    runs = {}
    for label, cfg, extra in (("net55", corner["default"], ["--lat-accel", "net"]),
                              ("net3", corner["three"], ["--lat-accel", "NET"]), ("opt2", corner["default"], [])):
        out = tmp_path / label
        rc = main(["run", str(cfg), "--out", str(out), "--quiet", "--log", "none", "--duration", "90", *extra])
        s = json.loads((out / "summary.json").read_text())
        assert rc == 0 and s["complete"] and s["safe"], s.get("error") or s["safety_violations"]
        assert s["collisions_sumo"] == 0 and s["speed_limit_excess_max"] <= SPEED_LIMIT_KPI_TOL
        runs[label] = (s["options"]["lat_accel"], pd.read_csv(out / "vehicles.csv").set_index("id").loc["v"])
    assert [runs[k][0] for k in ("net55", "net3", "opt2")] == [5.5, 3.0, 2.0]
    t = {k: r[1]["travel_time_s"] for k, r in runs.items()}
    assert t["net55"] < t["net3"] < t["opt2"], t
