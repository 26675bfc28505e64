"""Real SUMO scenarios run unchanged: the configuration's defaults, SUMO's own demand and vTypes.

All with real SUMO (libsumo): SUMO's shipped ``tools/game`` scenarios (used as they are, never
edited) and files the tests write.
"""

import gzip
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis.kpis import read_tripinfo
from bridge.cli import main
from bridge.sumo_adapter import SumoAdapter
from bridge.sumo_inputs import prepare_inputs
from bridge.sumo_world import _vtype_classes
from bridge.waypoints import load_net
from sumo_nets.scenario import SUMO_DEFAULT_SEED, read_sumocfg
from sumo_nets.sumo_tools import run_tool, sumo_home
from tests.sumo_runs import run_cfg as _run, write_cfg as _cfg

GAME = sumo_home() / "tools" / "game"


def test_game_square_runs_with_no_options_and_no_sumo_collision(tmp_path):
    """square, unchanged, no option but a short window: the config's seed (none: SUMO's default),
    SUMO's own vTypes (emergency vehicles as 6.5 x 2.16 m, not cars): 0 SUMO collisions.  Its
    routes are in additional-files (FamilyError before)."""
    rc, s = _run(GAME / "square.sumocfg", tmp_path / "m", "--duration", "40")
    assert rc == 0 and s["complete"], s.get("error")
    assert s["seed"] == SUMO_DEFAULT_SEED
    assert s["collisions_sumo"] == 0 and s["collisions_geometric"] == 0 and s["invariant_violations"] == 0
    v = pd.read_csv(tmp_path / "m" / "vehicles.csv")
    em = v[v["id"].str.startswith("emergency")]
    assert len(em) > 0 and (em["vclass"].str.startswith("emergency-6.5x2.16")).all()
    rc, b = _run(GAME / "square.sumocfg", tmp_path / "b", "--duration", "40", "--baseline", "sumo")
    assert rc == 0 and b["complete"] and b["seed"] == SUMO_DEFAULT_SEED
    # the same demand: report --vs compares them (it refuses different demands)
    assert main(["report", str(tmp_path / "m"), "--vs", str(tmp_path / "b")]) == 0


def test_baseline_counts_only_finished_trips_and_delay_is_never_negative(tmp_path):
    """square writes undeparted trips into its tripinfo: they are not arrivals; delay = SUMO's
    timeLoss (free flow from the lanes' limits), so no delay is negative."""
    rc, b = _run(GAME / "square.sumocfg", tmp_path / "b", "--baseline", "sumo")
    assert rc == 0 and b["complete"]
    ti = read_tripinfo(tmp_path / "b" / "tripinfo.xml")
    finished = int(((ti["depart_s"] >= 0) & (ti["arrival_s"] >= 0)).sum())
    assert len(ti) > finished  # the config wrote unfinished/undeparted ones too
    assert b["vehicles_arrived"] == finished
    v = pd.read_csv(tmp_path / "b" / "vehicles.csv")
    assert (v["delay_s"] >= 0).all() and len(v) == finished
    assert b["halt_episodes"] == int(ti.loc[(ti["depart_s"] >= 0) & (ti["arrival_s"] >= 0), "waiting_count"].sum())


@pytest.fixture(scope="module")
def kinds_net(tmp_path_factory):
    """Two parallel 300 m roads (2 lanes, 13.89 m/s), written with netconvert."""
    d = tmp_path_factory.mktemp("kinds")
    (d / "n.nod.xml").write_text('<nodes><node id="a" x="0" y="0"/><node id="b" x="300" y="0"/>'
                                 '<node id="c" x="0" y="60"/><node id="d" x="300" y="60"/></nodes>')
    (d / "n.edg.xml").write_text('<edges><edge id="ab" from="a" to="b" numLanes="2" speed="13.89"/>'
                                 '<edge id="cd" from="c" to="d" numLanes="2" speed="13.89"/></edges>')
    net = d / "n.net.xml"
    run_tool([sumo_home() / "bin" / "netconvert", "-n", d / "n.nod.xml", "-e", d / "n.edg.xml", "-o", net], what="netconvert")
    return net


def test_emergency_and_bicycle_footprints_equal_sumos(kinds_net, tmp_path):
    """vTypes without size get SUMO's defaults per vClass; the class's footprint equals what SUMO
    moves (read back from the running vehicle).  An unused pedestrian vType and an ``ignoring``
    vType with a length but no width are accepted."""
    rou = tmp_path / "r.rou.xml"
    rou.write_text('<routes><vType id="em" vClass="emergency"/><vType id="bike" vClass="bicycle"/>'
                   '<vType id="walker" vClass="pedestrian"/><vType id="odd" vClass="ignoring" length="3"/>'
                   '<vehicle id="e" type="em" depart="0"><route edges="ab"/></vehicle>'
                   '<vehicle id="k" type="bike" depart="0"><route edges="cd"/></vehicle>'
                   '<vehicle id="o" type="odd" depart="20"><route edges="cd"/></vehicle></routes>')
    cfg = read_sumocfg(_cfg(tmp_path / "k.sumocfg", kinds_net, routes=[rou]))
    inputs = prepare_inputs(cfg.routes, cfg.additional, tmp_path / "in")
    ad = SumoAdapter()
    demand = ad.expand_demand(cfg.path, inputs, begin_s=0.0, end_s=30.0, seed=1, step_length=0.1,
                              work_dir=tmp_path / "in")
    classes, cls_of = _vtype_classes(demand, load_net(cfg.net).max_lane_speed)
    assert [v.id for v in demand.vehicles] == ["e", "k", "o"]
    with ad:
        ad.start(cfg.path, demand=demand, inputs=inputs, preflight=False)
        for v in demand.vehicles[:2]:
            ad.admit(v, (30.0, 0.0 if v.id == "e" else 60.0), 90.0)
        ad.step()
        for vid in ("e", "k"):
            info = ad.vehicle_info(vid)
            c = classes[cls_of[vid]]
            assert (c.length, c.width) == (info.length, info.width)  # exactly SUMO's body
            assert c.vclass == info.vclass
    assert (classes[cls_of["e"]].length, classes[cls_of["e"]].width) == (6.5, 2.16)  # SUMO's emergency
    assert (classes[cls_of["k"]].length, classes[cls_of["k"]].width) == (1.6, 0.65)  # SUMO's bicycle
    assert classes[cls_of["o"]].length == 3.0 and classes[cls_of["o"]].width > 0
    # a bicycle at SUMO's 20 km/h desired speed (its vType's maxSpeed is 50 km/h); 1e-3 m/s: the
    # class rounds its bounds to 4 decimals
    assert abs(classes[cls_of["k"]].v_max - 20.0 / 3.6) < 1e-3 and classes[cls_of["e"]].v_max > 13.0


def test_gz_net_and_routes_in_additional_files_run(kinds_net, tmp_path):
    """A gzipped network and vehicles defined in an additional file (not route-files): the run
    drives them, and the additional file's outputs are not written next to it."""
    gz = tmp_path / "n.net.xml.gz"
    with open(kinds_net, "rb") as src, gzip.open(gz, "wb") as dst:
        shutil.copyfileobj(src, dst)
    add = tmp_path / "d.add.xml"
    add.write_text('<additional><vType id="car" vClass="passenger"/>'
                   '<edgeData id="dump" file="edges_out.xml"/>'
                   '<route id="r" edges="ab"/>'
                   '<flow id="f" type="car" begin="0" end="20" period="5" route="r"/></additional>')
    cfg = _cfg(tmp_path / "g.sumocfg", gz, additional=[add], end=150)
    rc, s = _run(cfg, tmp_path / "m")
    assert rc == 0 and s["complete"], s.get("error")
    assert s["vehicles_total"] == 4 and s["vehicles_arrived"] == 4 and s["collisions_sumo"] == 0
    assert not (tmp_path / "edges_out.xml").exists()


def test_random_flow_departures_equal_the_baselines(kinds_net, tmp_path):
    """A probability flow and a vType distribution, drawn by SUMO with the run's seed: the muvsim
    demand equals the baseline's (same ids, types and requested departures), only inside the
    window begin .. begin + duration (begin != 0)."""
    rou = tmp_path / "r.rou.xml"
    rou.write_text('<routes><vTypeDistribution id="mix"><vType id="p" vClass="passenger" probability="0.7"/>'
                   '<vType id="t" vClass="truck" probability="0.3"/></vTypeDistribution>'
                   '<flow id="f" type="mix" begin="0" end="1000" probability="0.15" from="ab" to="ab"/>'
                   '</routes>')
    cfg = _cfg(tmp_path / "f.sumocfg", kinds_net, routes=[rou], begin=100, end=1000, step=0.5)
    c = read_sumocfg(cfg)
    inputs = prepare_inputs(c.routes, c.additional, tmp_path / "in")
    demand = SumoAdapter().expand_demand(c.path, inputs, begin_s=100.0, end_s=160.0, seed=7, step_length=0.5,
                                         work_dir=tmp_path / "in")
    assert len(demand) > 3 and all(100.0 <= v.depart_s < 160.0 for v in demand.vehicles)
    rc, b = _run(cfg, tmp_path / "b", "--baseline", "sumo", "--seed", "7", "--duration", "60")
    assert rc == 0 and b["begin_s"] == 100.0
    ti = read_tripinfo(tmp_path / "b" / "tripinfo.xml")
    base = {r.id: (r.requested_depart_s, r.vtype) for r in ti.itertuples() if r.depart_s >= 0}
    ours = {v.id: (v.depart_s, v.type_id) for v in demand.vehicles}
    assert base and set(base) <= set(ours)
    for vid, (dep, vt) in base.items():  # tripinfo writes 2 decimals
        assert abs(ours[vid][0] - dep) < 0.01 and ours[vid][1] == vt
    # a different seed draws a different demand (the draws are SUMO's, not fixed)
    other = SumoAdapter().expand_demand(c.path, inputs, begin_s=100.0, end_s=160.0, seed=8, step_length=0.5,
                                        work_dir=tmp_path / "in")
    assert [(v.id, v.depart_s) for v in other.vehicles] != [(v.id, v.depart_s) for v in demand.vehicles]


def _net(d: Path, nodes: str, edges: str) -> Path:
    (d / "n.nod.xml").write_text(f"<nodes>{nodes}</nodes>")
    (d / "n.edg.xml").write_text(f"<edges>{edges}</edges>")
    net = d / "n.net.xml"
    run_tool([sumo_home() / "bin" / "netconvert", "-n", d / "n.nod.xml", "-e", d / "n.edg.xml", "-o", net],
             what="netconvert")
    return net


_NODES = ('<node id="a" x="0" y="0"/><node id="b" x="200" y="0"/>'
          '<node id="c" x="0" y="60"/><node id="d" x="200" y="60"/>')


def test_kinked_route_and_u_turn_are_driven(tmp_path):
    """Right-angle kinks 2 m apart inside one edge (sharper than the class's 45 deg) and a U-turn
    through a junction's turnaround: corners are cut so no segment turns more than the class
    accepts, and the vehicles arrive, with no SUMO collision."""
    net = _net(tmp_path, _NODES,
               '<edge id="ab" from="a" to="b" numLanes="1" speed="13.89"/>'
               '<edge id="ba" from="b" to="a" numLanes="1" speed="13.89"/>'
               '<edge id="cd" from="c" to="d" numLanes="1" speed="13.89" '
               'shape="0,60 100,60 100,62 98,62 98,64 200,64 200,60"/>')
    rou = tmp_path / "r.rou.xml"
    rou.write_text('<routes><vehicle id="kinked" depart="0"><route edges="cd"/></vehicle>'
                   '<vehicle id="uturn" depart="0"><route edges="ab ba"/></vehicle></routes>')
    rc, s = _run(_cfg(tmp_path / "u.sumocfg", net, routes=[rou], end=200), tmp_path / "m")
    assert rc == 0 and s["complete"], s.get("error")
    assert s["vehicles_undrivable"] == 0 and s["vehicles_arrived"] == 2 and s["collisions_sumo"] == 0
    assert s["invariant_violations"] == 0


def test_an_undrivable_vehicle_is_reported_and_the_others_arrive(tmp_path):
    """A lane that reverses on the spot (a 179 deg vertex: no corner to cut; netconvert would
    smooth it, so the test writes it into the network) is reported in vehicles.csv and
    summary.json; the vehicles on the straight road arrive."""
    net = _net(tmp_path, _NODES,
               '<edge id="ab" from="a" to="b" numLanes="1" speed="13.89"/>'
               '<edge id="cd" from="c" to="d" numLanes="1" speed="13.89"/>')
    text = net.read_text()
    i = text.index('<lane id="cd_0"')
    j = text.index('shape="', i) + len('shape="')
    k = text.index('"', j)
    net.write_text(text[:j] + "0.00,58.40 120.00,58.40 60.00,59.40 200.00,58.40" + text[k:])
    rou = tmp_path / "r.rou.xml"
    rou.write_text('<routes><vehicle id="reverses" depart="0"><route edges="cd"/></vehicle>'
                   '<route id="s" edges="ab"/><flow id="ok" begin="0" end="10" number="2" route="s"/></routes>')
    rc, s = _run(_cfg(tmp_path / "u.sumocfg", net, routes=[rou], end=150), tmp_path / "m")
    assert rc == 0 and s["complete"], s.get("error")
    assert s["vehicles_undrivable"] == 1 and s["vehicles_arrived"] == 2 and s["vehicles_total"] == 3
    v = pd.read_csv(tmp_path / "m" / "vehicles.csv").set_index("id")
    assert v.loc["reverses", "status"] == "undrivable" and "turns by" in v.loc["reverses", "reason"]
    assert (v.loc[["ok.0", "ok.1"], "status"] == "driven").all()


def test_lane_speed_limits_and_permissions_reach_the_vehicle(tmp_path):
    """Each waypoint carries the speed limit of its lane (8 then 20 m/s here); a one-edge route
    of a passenger car starts on the first lane it may use, not the sidewalk (lane 0)."""
    from bridge.waypoints import load_net

    net = _net(tmp_path, '<node id="a" x="0" y="0"/><node id="b" x="100" y="0"/><node id="c" x="300" y="0"/>',
               '<edge id="ab" from="a" to="b" numLanes="2" speed="8" sidewalkWidth="2"/>'
               '<edge id="bc" from="b" to="c" numLanes="2" speed="20" sidewalkWidth="2"/>')
    geo = load_net(net)
    r = geo.route(["ab", "bc"], 3.0, vclass="passenger")
    lim = geo.speed_limits(r)
    on_ab = np.array([lane.startswith("ab_") for lane in r.lane_ids])
    on_bc = np.array([lane.startswith("bc_") for lane in r.lane_ids])
    assert on_ab.any() and on_bc.any()
    assert np.all(lim[on_ab] == 8.0) and np.all(lim[on_bc] == 20.0)
    one = geo.route(["bc"], 3.0, vclass="passenger")
    assert one.depart_lane_index == 1 and all(lane == "bc_1" for lane in one.lane_ids)
    rou = tmp_path / "r.rou.xml"
    rou.write_text('<routes><vehicle id="v" depart="0"><route edges="bc"/></vehicle></routes>')
    rc, s = _run(_cfg(tmp_path / "s.sumocfg", net, routes=[rou], end=100), tmp_path / "m")
    assert rc == 0 and s["vehicles_arrived"] == 1 and s["collisions_sumo"] == 0


def test_trips_loaded_ahead_get_the_route_sumo_computes(tmp_path):
    """A <trip> (origin and destination only) loaded long before its departure: the demand has
    the route SUMO routed for it, not its two end edges."""
    net = _net(tmp_path, '<node id="a" x="0" y="0"/><node id="b" x="100" y="0"/><node id="c" x="200" y="0"/>'
                         '<node id="d" x="300" y="0"/>',
               '<edge id="ab" from="a" to="b" speed="13.89"/><edge id="bc" from="b" to="c" speed="13.89"/>'
               '<edge id="cd" from="c" to="d" speed="13.89"/>')
    rou = tmp_path / "r.rou.xml"
    rou.write_text('<routes><trip id="t" depart="40" from="ab" to="cd"/></routes>')
    c = read_sumocfg(_cfg(tmp_path / "t.sumocfg", net, routes=[rou]))
    inputs = prepare_inputs(c.routes, c.additional, tmp_path / "in")
    d = SumoAdapter().expand_demand(c.path, inputs, begin_s=0.0, end_s=60.0, seed=1, step_length=0.5,
                                    work_dir=tmp_path / "in")
    assert [(v.id, v.depart_s, v.edges) for v in d.vehicles] == [("t", 40.0, ("ab", "bc", "cd"))]


def test_prepared_inputs_drop_demand_and_outputs_keep_the_rest(tmp_path):
    """The co-simulation's SUMO gets vTypes, routes, distributions, persons and signal programs,
    not vehicles, trips or flows (at any depth) nor output elements; gzipped files are read."""
    import xml.etree.ElementTree as ET

    rou = tmp_path / "r.rou.xml.gz"
    with gzip.open(rou, "wt") as fh:
        fh.write('<routes><vType id="t"/><route id="r" edges="ab"/><vehicle id="v" depart="0" route="r"/>'
                 '<interval begin="0" end="9"><flow id="f" begin="0" end="9" number="2" route="r"/></interval>'
                 '<person id="p" depart="0"><walk edges="ab"/></person><trip id="x" depart="1" from="ab" to="ab"/>'
                 '</routes>')
    add = tmp_path / "a.add.xml"
    add.write_text('<additional><edgeData id="d" file="o.xml"/><tlLogic id="j" type="static" programID="1" offset="0">'
                   '<phase duration="30" state="G"/></tlLogic></additional>')
    p = prepare_inputs([rou], [add], tmp_path / "w")
    nd = ET.parse(p.no_demand_routes[0]).getroot()
    assert {e.tag for e in nd.iter()} == {"routes", "vType", "route", "interval", "person", "walk"}
    assert [e.tag for e in ET.parse(p.no_demand_additional[0]).getroot()] == ["tlLogic"]
    assert [e.tag for e in ET.parse(p.expansion_additional[0]).getroot()] == ["tlLogic"]
    assert p.expansion_routes == (rou,)  # SUMO reads the route files themselves
