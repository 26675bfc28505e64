"""SUMO's body on a lane whose length is not its shape's length (bridge.sumo_body, issue 12).

``grid6`` (SUMO's ``tools/game``), authority, 180 s: SUMO reported ``bottomTop.7`` into
``bottomTop2.4`` on ``gneE34_0`` (gap -0.02 m) while muvsim's geometric monitor saw no overlap.
``gneE34_0`` has 111.57 m of shape but length 80 (netconvert gives every lane the edge's length):
SUMO counts lane positions in length units and maps them onto the shape with the factor 1.39, so a
5 m car covers 6.97 m of road there.  ``RouteBody`` laid the back 5 m of *shape* behind the front:
1.97 m short, and two cars 1.95 m apart on muvsim's bodies overlapped in SUMO's.

The net here is one straight 100 m edge with length 70 (factor 1.43, as strong as grid6's) between
two ordinary ones; real SUMO judges.
"""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from bridge.cosim import VehicleSpec
from bridge.demand import PlannedVehicle
from bridge.sumo_adapter import SumoAdapter
from bridge.sumo_body import RouteBody, _at
from bridge.sumo_world import SumoWorld
from bridge.waypoints import load_net
from tm.geometry import polygon_distance
from tm.monitor import Monitor

CAR = (5.0, 1.8)  # SUMO's default passenger vType size (length, width)
EDGES = ("a", "b", "c")
LENGTH_B = 70.0   # edge b: 100 m of straight shape, length 70
SHAPE_B = 100.0

NODES = """<nodes>
  <node id="n0" x="0" y="0"/><node id="n1" x="100" y="0"/>
  <node id="n2" x="200" y="0"/><node id="n3" x="300" y="0"/>
</nodes>"""
PLAIN_EDGES = f"""<edges>
  <edge id="a" from="n0" to="n1" numLanes="1"/>
  <edge id="b" from="n1" to="n2" numLanes="1" length="{LENGTH_B}"/>
  <edge id="c" from="n2" to="n3" numLanes="1"/>
</edges>"""


@pytest.fixture(scope="module")
def scaled_net(tmp_path_factory):
    d = tmp_path_factory.mktemp("scaled")
    (d / "n.nod.xml").write_text(NODES)
    (d / "e.edg.xml").write_text(PLAIN_EDGES)
    out = d / "scaled.net.xml"
    subprocess.run([str(Path(sys.executable).parent / "netconvert"), "-n", str(d / "n.nod.xml"),
                    "-e", str(d / "e.edg.xml"), "-o", str(out)], check=True, capture_output=True)
    return out


@pytest.fixture(scope="module")
def net(scaled_net):
    return load_net(scaled_net)


def _route(net):
    return net.route(EDGES, 3.0, vclass="passenger")


def _factor(net, lane="b_0"):
    """SUMO's length-geometry factor of ``lane``: shape length over the net file's length."""
    shape = net.lane_shape(lane)
    return float(np.hypot(*np.diff(shape, axis=0).T).sum()) / net.sumolib_net.getLane(lane).getLength()


def test_the_net_scales_lane_b(net):
    """The premise: SUMO's length of b_0 is 70, its shape about 100 m (tolerance 1 m: netconvert
    trims the shape at the junctions); a_0's length is its shape's (to the net file's 0.01 m)."""
    assert net.sumolib_net.getLane("b_0").getLength() == pytest.approx(LENGTH_B)
    assert net.lane_length("b_0") == pytest.approx(LENGTH_B)
    # an ordinary edge: length and shape agree to the net file's 0.01 m rounding
    assert _factor(net, "a_0") == pytest.approx(1.0, abs=0.01 / net.lane_length("a_0"))
    assert _factor(net) * LENGTH_B == pytest.approx(SHAPE_B, abs=1.0)


def test_body_on_a_scaled_lane_is_length_units_long(net):
    """A car whose whole body is on b_0: its body runs from the front back ``L * shape / length``
    metres of shape (SUMO's back position, MSLane::interpolateLanePosToGeometryPos), not ``L``.
    Tolerance 1e-9 m (round-off)."""
    b = RouteBody(_route(net), net, *CAR)
    k = b.lanes.index("b_0")
    f = _factor(net)
    arc_b0 = b.parc[np.flatnonzero(b.seg_lane == k)[0]]  # route arc where b_0 starts
    sigma = arc_b0 + 50.0  # reference point 50 m into b_0
    front, back, lane, _ = b.bodies(np.array([sigma]), np.zeros(1))
    assert b.lanes[int(lane[0])] == "b_0"
    assert np.hypot(*(front[0] - back[0])) == pytest.approx(CAR[0] * f, abs=1e-9)


@pytest.fixture()
def world(scaled_net, tmp_path, net):
    routes = tmp_path / "vtypes.rou.xml"
    routes.write_text('<routes><vType id="car" vClass="passenger" length="5" width="1.8"/></routes>')
    sim = SumoAdapter()
    sim.start(net=scaled_net, routes=routes, seed=1)
    planned = {v: PlannedVehicle(v, "car", 0.0, EDGES, None, None, "passenger", *CAR) for v in ("lead", "follow")}
    rts = {v: _route(net) for v in planned}
    w = SumoWorld(sim, planned, rts, net=net)
    yield w
    sim.close()


def _bodies_at(w, s_lead, s_follow):
    ids = ["lead", "follow"]
    centre = np.vstack([_at(w.route_body(v).poly, w.route_body(v).parc, np.array([s]))[0]
                        for v, s in zip(ids, (s_lead, s_follow))])
    w._sigma.update(lead=s_lead, follow=s_follow)
    polys = w.bodies(ids, centre, np.zeros(2), np.full(2, CAR[0]), np.full(2, CAR[1]))
    w.push(ids, centre, np.zeros(2))
    return ids, centre, polys


@pytest.mark.parametrize("gap_m", [0.2, -0.15])
def test_sumo_and_the_monitor_agree_on_a_scaled_lane(world, gap_m):
    """Two cars in line on b_0 whose bodies as muvsim computes them are ``gap_m`` apart (0.2 m) or
    overlap (0.15 m): SUMO reports a collision exactly when they overlap, and the geometric monitor
    (given those bodies, as the co-simulation gives them) counts the overlap in the same case.
    Before the fix the 0.2 m case was a SUMO collision (lane gap (0.2 + 5) / 1.43 - 5 = -1.4 m)
    that the monitor did not see: grid6's bottomTop.7 / bottomTop2.4."""
    w = world
    b = w.route_body("lead")
    k = b.lanes.index("b_0")
    arc_b0 = b.parc[np.flatnonzero(b.seg_lane == k)[0]]
    s_lead = arc_b0 + 60.0
    # on a straight lane the bodies' gap shrinks metre for metre as the follower moves up: place it
    # from the gap muvsim's bodies have 20 m behind (whatever length those bodies have)
    c_lead = b.bodies(np.array([s_lead]), np.zeros(1))[3]
    c_20 = b.bodies(np.array([s_lead - 20.0]), np.zeros(1))[3]
    d20 = float(polygon_distance(c_lead, c_20)[0])
    s_follow = s_lead - 20.0 + d20 - gap_m
    # one at a time: two cars inserted at the same start are a collision of their own
    w.insert(VehicleSpec("lead", "car", np.asarray(w.routes["lead"].waypoints)), None)
    w.step()
    p_lead = _at(b.poly, b.parc, np.array([s_lead]))[0]
    for insert_follow in (False, True):  # the lead pushed every step (held there), as the loop does
        w._sigma["lead"] = s_lead
        w.bodies(["lead"], p_lead, np.zeros(1), np.full(1, CAR[0]), np.full(1, CAR[1]))
        w.push(["lead"], p_lead, np.zeros(1))
        if insert_follow:
            w.insert(VehicleSpec("follow", "car", np.asarray(w.routes["follow"].waypoints)), None)
        assert w.step() == []
    ids, centre, polys = _bodies_at(w, s_lead, s_follow)
    np.testing.assert_allclose(polygon_distance(polys[:1], polys[1:])[0], max(gap_m, 0.0), atol=1e-6)
    pairs = w.step()  # SUMO judges a pose pushed before step n in step n + 1 (measured)
    _bodies_at(w, s_lead, s_follow)
    pairs += w.step()
    assert w.pose_mismatches == 0
    assert w.adapter.lane_ids(["lead", "follow"]) == ["b_0", "b_0"]
    sumo_hit = ("follow", "lead") in [tuple(sorted(p)) for p in pairs]
    mon = Monitor().step(ids, centre, np.zeros(2), np.full(2, CAR[0]), np.full(2, CAR[1]), polygons=polys)
    assert sumo_hit == (gap_m < 0)
    assert (mon.footprint_overlaps == 1) == (gap_m < 0)


def test_padding_covers_the_longer_body(net):
    """The claims' padding behind a waypoint on b_0 takes in the part of SUMO's body beyond the
    rectangle ``L x W``: at least ``L (scale - 1)`` (2.1 m for the car here), tolerance 1e-9 m."""
    r = _route(net)
    b = RouteBody(r, net, *CAR)
    from bridge.groups import _headings

    W, arc = r.waypoints, r.arc_length
    table = b.pad_table(arc, W, _headings(W), (-10.0, -0.5), (1.2, 0.5))
    kb = b.lanes.index("b_0")
    arc_b0 = b.parc[np.flatnonzero(b.seg_lane == kb)[0]]
    k = int(np.argmin(np.abs(arc - (arc_b0 + 50.0))))
    assert table.pads(k, arc[k] - 10.0)[0] >= CAR[0] * (_factor(net) - 1.0) - 1e-9


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.floats(-12.0, 12.0), st.floats(-1.0, 1.0), st.sampled_from([CAR, (12.0, 2.5)]))
def test_padding_covers_the_body_across_a_change_of_scale(net, ds, lat, size):
    """Reference points up to 12 m either side of where the front passes from b_0 (factor 1.43)
    onto c_0 (factor 1): while the front is on c_0 the back, on b_0, moves 1.43 m per metre of the
    front, so between two samples the body changes by more than the sample spacing.  Every such
    position has SUMO's body inside the rectangle ``L x W`` widened by the waypoint's padding
    (car and bus sizes).  Tolerance 1e-9 m (round-off)."""
    from bridge.groups import _headings

    r = _route(net)
    b = RouteBody(r, net, *size)
    W, arc = r.waypoints, r.arc_length
    box_lo, box_hi = (-40.0, -0.5), (1.2, 0.5)
    table = b.pad_table(arc, W, _headings(W), box_lo, box_hi)
    kc = b.lanes.index("c_0")
    s_c = b.parc[np.flatnonzero(b.seg_lane == kc)[0]]  # route arc where c_0 starts
    sigma = s_c - 0.5 * size[0] + ds  # the front at s_c + ds
    k = int(np.searchsorted(arc, sigma + 0.6))  # the first waypoint ahead: its claims hold sigma
    s_, e_ = np.array([sigma]), np.array([lat * box_hi[1]])
    _, _, _, corners = b.bodies(s_, e_)
    q, t, _ = _at(b.poly, b.parc, s_)
    p = q[0] + e_[0] * np.array([-t[0, 1], t[0, 0]])
    H = _headings(W)
    c, s = np.cos(H[k]), np.sin(H[k])
    d = p - W[k]
    a, y = c * d[0] + s * d[1], -s * d[0] + c * d[1]
    assert box_lo[0] <= a <= box_hi[0] and box_lo[1] <= y <= box_hi[1]
    pad = table.pads(k, sigma - 5.0)  # back, front, right, left
    rel = corners[0] - p
    ra = c * rel[:, 0] + s * rel[:, 1]
    ry = -s * rel[:, 0] + c * rel[:, 1]
    assert np.all(-ra <= size[0] / 2 + pad[0] + 1e-9)
    assert np.all(ra <= size[0] / 2 + pad[1] + 1e-9)
    assert np.all(-ry <= size[1] / 2 + pad[2] + 1e-9)
    assert np.all(ry <= size[1] / 2 + pad[3] + 1e-9)
