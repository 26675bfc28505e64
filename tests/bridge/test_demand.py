"""Reading SUMO route files into the demand muvsim admits itself."""

import pytest

from bridge.demand import DemandError, DepartureQueue, read_demand


def test_generated_demand(grid_routes):
    d = read_demand(grid_routes)
    assert len(d) >= 18
    departs = [v.depart_s for v in d.vehicles]
    assert departs == sorted(departs)
    sizes = {v.type_id: (v.vclass, v.length, v.width) for v in d.vehicles}
    assert sizes.get("car", ("passenger", 5.0, 1.8)) == ("passenger", 5.0, 1.8)
    assert sizes.get("bus", ("bus", 12.0, 2.5)) == ("bus", 12.0, 2.5)
    assert sizes.get("truck", ("truck", 7.1, 2.4)) == ("truck", 7.1, 2.4)
    assert all(v.depart_lane is None and len(v.edges) >= 2 for v in d.vehicles)  # departLane="best"
    xml = d.vtypes_xml()
    assert "<vType" in xml and "<vehicle" not in xml and 'id="bus"' in xml


def write(tmp_path, body, name="r.rou.xml"):
    p = tmp_path / name
    p.write_text(f"<routes>\n{body}\n</routes>\n")
    return p


def test_named_routes_lanes_positions_and_defaults(tmp_path):
    p = write(tmp_path, """
        <vType id="van" vClass="delivery"/>
        <route id="r1" edges="a b c"/>
        <vehicle id="x" depart="5" route="r1" type="van" departLane="1" departPos="12.5"/>
        <vehicle id="y" depart="1.5"><route edges="d e"/></vehicle>
    """)
    d = read_demand(p)
    y, x = d.vehicles
    assert (x.id, x.edges, x.depart_lane, x.depart_pos_m, x.length, x.width) == ("x", ("a", "b", "c"), 1, 12.5,
                                                                                   6.5, 2.16)
    assert (y.id, y.type_id, y.vclass, y.length, y.depart_lane, y.depart_pos_m) == (
        "y", "DEFAULT_VEHTYPE", "passenger", 5.0, None, None)


@pytest.mark.parametrize("body, match", [
    ('<trip id="t" depart="0" from="a" to="b"/>', r"<trip> .*'t'.*duarouter"),
    ('<flow id="f" begin="0" end="9" number="3" from="a" to="b"/>', r"<flow> .*'f'.*duarouter"),
    ('<vehicle id="v" depart="0" type="ghost"><route edges="a"/></vehicle>', r"unknown type 'ghost'"),
    ('<vehicle id="v" depart="0" route="nope"/>', r"unknown route 'nope'"),
    ('<vehicle id="v" depart="triggered"><route edges="a"/></vehicle>', r"depart='triggered'"),
    ('<vehicle id="v" depart="0"/>', r"'v'> has no route"),
    ('<vehicle id="v" depart="0"><route edges="a"/></vehicle><vehicle id="v" depart="1"><route edges="a"/>'
     '</vehicle>', r"duplicate vehicle id 'v'"),
    ('<vType id="odd" vClass="ship"/>', r"vType id='odd'.*set length and width"),
])
def test_refused_and_malformed(tmp_path, body, match):
    p = write(tmp_path, body)
    with pytest.raises(DemandError, match=match) as err:
        read_demand(p)
    assert str(p) in str(err.value)


def test_unreadable_files(tmp_path):
    with pytest.raises(DemandError, match="cannot read"):
        read_demand(tmp_path / "missing.rou.xml")
    bad = tmp_path / "bad.rou.xml"
    bad.write_text("<routes><vehicle")
    with pytest.raises(DemandError, match=r"bad\.rou\.xml: not a well-formed"):
        read_demand(bad)


def test_departure_queue_releases_in_order_and_never_drops(grid_routes):
    d = read_demand(grid_routes)
    q = DepartureQueue(d)
    got = []
    t = 0.0
    while q.remaining:
        got += q.release(t)
        t += 0.1
    assert [v.id for v in got] == [v.id for v in d.vehicles]
    assert q.release(1e9) == [] and q.next_depart_s is None
