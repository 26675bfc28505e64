"""Deterministic, cached generation of grids, demand and SUMO configurations."""

import subprocess
import xml.etree.ElementTree as ET

import pytest

import sumo_nets.generate as gen
from bridge.waypoints import load_net
from sumo_nets.generate import DEFAULT_VTYPES, GenerateError, make_demand, make_grid, sumocfg_for, write_sumocfg
from sumo_nets.sumo_tools import SumoToolError, binary

MIX = {"car": 0.6, "bus": 0.2, "truck": 0.2}  # as in conftest.py


def test_grid_is_byte_identical_across_directories(small_net, tmp_path):
    again = make_grid(tmp_path, junctions=3, spacing_m=100.0, lanes=2)
    assert again != small_net
    assert again.read_bytes() == small_net.read_bytes()
    text = again.read_text()
    assert "generated on" not in text and str(tmp_path) not in text  # no dates, no paths


def test_grid_parameters(small_net):
    root = ET.parse(small_net).getroot()
    edges = [e for e in root.iter("edge") if e.get("function") != "internal"]
    assert {len(e.findall("lane")) for e in edges} == {2}
    assert {float(lane.get("speed")) for e in edges for lane in e.findall("lane")} == {13.89}
    junctions = [j for j in root.iter("junction") if j.get("type") not in ("internal", "dead_end")]
    assert len(junctions) == 9  # 3 x 3, plus dead-end stubs
    assert any(e.get("function") == "internal" for e in root.iter("edge"))  # junction internal lanes
    # no turnarounds: no connection goes back to the reverse edge
    for c in root.iter("connection"):
        assert c.get("dir") != "t", c.attrib


def test_generation_is_cached(small_net, small_routes, gen_dir, monkeypatch):
    def boom(*a, **k):
        raise AssertionError("a cached generator ran a tool")

    monkeypatch.setattr(gen, "run_tool", boom)
    assert make_grid(gen_dir, junctions=3, spacing_m=100.0, lanes=2) == small_net
    assert make_demand(small_net, gen_dir, seed=3, vehicles=30, duration_s=60.0, class_mix=MIX) == small_routes
    # the order of the mix does not matter
    assert make_demand(small_net, gen_dir, seed=3, vehicles=30, duration_s=60.0,
                       class_mix=dict(reversed(list(MIX.items())))) == small_routes


def test_demand_is_byte_identical_across_directories(small_net, small_routes, tmp_path):
    again = make_demand(small_net, tmp_path, seed=3, vehicles=30, duration_s=60.0, class_mix=MIX)
    assert again.read_bytes() == small_routes.read_bytes()
    other = make_demand(small_net, tmp_path, seed=4, vehicles=30, duration_s=60.0, class_mix=MIX)
    assert other.read_bytes() != small_routes.read_bytes()


def test_demand_content(small_net, small_routes):
    root = ET.parse(small_routes).getroot()
    vtypes = {t.get("id"): t.attrib for t in root.iter("vType")}
    assert set(vtypes) == set(MIX)
    for name, attrs in vtypes.items():
        spec = DEFAULT_VTYPES[name]
        assert (attrs["vClass"], float(attrs["length"]), float(attrs["width"])) == (spec.vclass, spec.length,
                                                                                     spec.width)
    assert (vtypes["car"]["vClass"], vtypes["bus"]["length"], vtypes["truck"]["width"]) == ("passenger", "12", "2.4")
    vehicles = list(root.iter("vehicle"))
    assert 27 <= len(vehicles) <= 30  # one every 2 s; duarouter may drop an unroutable trip
    departs = [float(v.get("depart")) for v in vehicles]
    assert departs == sorted(departs) and 0 <= departs[0] and departs[-1] < 60
    assert {v.get("type") for v in vehicles} <= set(MIX)
    net = load_net(small_net)
    for v in vehicles:
        edges = v.find("route").get("edges").split()
        assert len(edges) >= 2
        for a, b in zip(edges[:-1], edges[1:]):
            assert net.connections(a, b), (v.get("id"), a, b)  # connected routes


def test_sumocfg_runs_in_sumo(small_routes):
    cfg = sumocfg_for(small_routes)
    proc = subprocess.run([str(binary("sumo")), "-c", str(cfg), "--end", "30", "--no-step-log"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr


def test_write_sumocfg_relative_paths(small_net, small_routes, tmp_path):
    (tmp_path / "sub").mkdir()
    cfg = write_sumocfg(tmp_path / "sub" / "x.sumocfg", small_net, [small_routes])
    root = ET.parse(cfg).getroot()
    net_value = root.find("input/net-file").get("value")
    assert not net_value.startswith("/")
    assert (cfg.parent / net_value).resolve() == small_net.resolve()


@pytest.mark.parametrize("kwargs, field", [
    (dict(junctions=1), "junctions"),
    (dict(junctions=2.5), "junctions"),
    (dict(spacing_m=5.0), "spacing_m"),
    (dict(lanes=0), "lanes"),
    (dict(speed_mps=-1.0), "speed_mps"),
])
def test_grid_rejects_bad_parameters(tmp_path, kwargs, field):
    with pytest.raises(GenerateError, match=field):
        make_grid(tmp_path, **kwargs)


@pytest.mark.parametrize("kwargs, field", [
    (dict(class_mix={"plane": 1.0}), "plane"),
    (dict(class_mix={"car": 0.0}), "class_mix"),
    (dict(class_mix={"car": -1.0}), "class_mix"),
    (dict(vehicles=0), "vehicles"),
    (dict(duration_s=0.0), "duration_s"),
    (dict(seed=-1), "seed"),
    (dict(fringe_factor=0.5), "fringe_factor"),
])
def test_demand_rejects_bad_parameters(small_net, tmp_path, kwargs, field):
    args = dict(seed=1, vehicles=10, duration_s=10.0, class_mix={"car": 1.0}) | kwargs
    with pytest.raises(GenerateError, match=field):
        make_demand(small_net, tmp_path, **args)


def test_route_demand_routes_trips_and_expands_flows(small_net, tmp_path):
    from bridge.waypoints import load_net

    net = load_net(small_net)
    e0 = sorted(e.getID() for e in net._net.getEdges() if e.getFunction() != "internal")[0]
    e2 = net.successors(net.successors(e0)[0])[0]
    src = tmp_path / "in.rou.xml"
    src.write_text(f'<routes><flow id="f" begin="0" end="10" number="2" from="{e0}" to="{e2}"/></routes>')
    a = gen.route_demand(small_net, [src], tmp_path / "a")
    b = gen.route_demand(small_net, [src], tmp_path / "b")
    assert a.read_bytes() == b.read_bytes()
    vehicles = list(ET.parse(a).getroot().iter("vehicle"))
    assert [v.get("id") for v in vehicles] == ["f.0", "f.1"]
    assert vehicles[0].find("route").get("edges").split()[-1] == e2
    bad = tmp_path / "bad.rou.xml"
    bad.write_text(f'<routes><trip id="x" depart="0" from="{e0}" to="nowhere"/></routes>')
    with pytest.raises(SumoToolError, match="nowhere"):
        gen.route_demand(small_net, [bad], tmp_path / "c")
