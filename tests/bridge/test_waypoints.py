"""Routes as polylines through lane shapes and junction-internal lanes, waypoints <= delta apart on them."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bridge.waypoints import (LANE_CHANGE_END_M, _arc, LANE_CHANGE_GAP_M, LANE_CHANGE_M, LANE_CHANGE_MIN_M,
                              LANE_CHANGE_START_M, RouteError, lane_change_plan, load_net,
                              point_polyline_distance, route_waypoints, subsample)

#: Waypoints lie on the polyline up to round-off of the interpolation (coordinates ~ 1e2..1e3 m).
ON_POLYLINE_TOL = 1e-9
#: ... and, outside lane changes, on the centre line of the lane they report (SUMO's shapes, 2 decimals).
ON_LANE_TOL = 1e-6


def check_waypoints(net, r, delta):
    w = r.waypoints
    assert w.shape == (r.count, 2) and r.count >= 2
    steps = np.hypot(*np.diff(w, axis=0).T)
    assert steps.max() <= delta + 1e-9
    assert np.all(np.diff(r.arc_length) > 0) and r.arc_length[0] == 0
    assert r.arc_length[-1] == pytest.approx(r.length_m)
    assert np.all(steps <= np.diff(r.arc_length) + 1e-9)  # chords never exceed arcs
    assert point_polyline_distance(w, r.polyline).max() <= ON_POLYLINE_TOL
    np.testing.assert_array_equal(w[0], r.polyline[0])
    np.testing.assert_array_equal(w[-1], r.polyline[-1])
    for k in np.nonzero(r.on_lane)[0]:
        d = point_polyline_distance(w[k], net.lane_shape(r.lane_ids[k]))[0]
        assert d <= ON_LANE_TOL, (k, r.lane_ids[k], d)
    # every polyline segment on a lane lies on that lane's centre line
    for i, (lane, on) in enumerate(zip(r.segment_lanes, r.segment_on_lane)):
        if on:
            assert point_polyline_distance(r.polyline[i:i + 2], net.lane_shape(lane)).max() <= ON_LANE_TOL
    # the route's edges are visited in order, with internal lanes between consecutive edges
    edge_seq = [lid.rsplit("_", 1)[0] for lid in r.segment_lanes if not lid.startswith(":")]
    assert [e for i, e in enumerate(edge_seq) if i == 0 or edge_seq[i - 1] != e] == list(r.edges)
    if len(r.edges) > 1:
        assert any(lid.startswith(":") for lid in r.segment_lanes)
    # off-lane parts (lane changes) stay between the lanes of their edge
    off = ~r.on_lane
    if off.any():
        for k in np.nonzero(off)[0]:
            edge = r.lane_ids[k].rsplit("_", 1)[0]
            lanes = [net.lane_shape(f"{edge}_{i}") for i in range(net.lane_count(edge))]
            assert min(point_polyline_distance(w[k], s)[0] for s in lanes) <= 3.2 * (len(lanes) - 1)


@st.composite
def routes(draw, net):
    edges = [e for e in sorted(net._net.getEdges()) if e.getFunction() != "internal"]
    start = draw(st.sampled_from([e.getID() for e in edges]))
    route = [start]
    for _ in range(draw(st.integers(0, 7))):
        succ = net.successors(route[-1])
        if not succ:
            break
        route.append(draw(st.sampled_from(succ)))
    return route


def test_random_routes_and_deltas(grid_net):
    net = load_net(grid_net)

    @settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
    @given(route=routes(net), delta=st.floats(0.3, 15.0), lane=st.one_of(st.none(), st.integers(0, 1)))
    def prop(route, delta, lane):
        r = route_waypoints(net, route, delta, depart_lane=lane, vehicle_id="h")
        check_waypoints(net, r, delta)
        if lane is not None:
            assert r.segment_lanes[0] == f"{route[0]}_{lane}"

    prop()


def turn_route(net, direction):
    """A two-edge route with a turn of the given SUMO direction ('r', 'l', 's')."""
    for e in sorted(net._net.getEdges(), key=lambda e: e.getID()):
        if e.getFunction() == "internal":
            continue
        for to, conns in sorted(e.getOutgoing().items(), key=lambda kv: kv[0].getID()):
            if conns and all(c.getDirection() == direction for c in conns):
                return [e.getID(), to.getID()], conns
    raise AssertionError(f"no {direction} turn in the grid")


def test_right_turns_leave_from_lane_0_and_left_turns_from_the_leftmost(grid_net):
    net = load_net(grid_net)
    right, _ = turn_route(net, "r")
    left, _ = turn_route(net, "l")
    r = route_waypoints(net, right, 2.0)
    l_ = route_waypoints(net, left, 2.0)
    assert r.lanes[0] == f"{right[0]}_0"
    assert l_.lanes[0] == f"{left[0]}_{net.lane_count(left[0]) - 1}"
    # the polyline turns by ~90 degrees through internal lanes
    for wp in (r, l_):
        assert any(lid.startswith(":") for lid in wp.lane_ids)
        turn = np.degrees((wp.heading[-1] - wp.heading[0] + np.pi) % (2 * np.pi) - np.pi)
        assert abs(abs(turn) - 90) < 1
    assert np.degrees((r.heading[-1] - r.heading[0] + np.pi) % (2 * np.pi) - np.pi) < 0  # right = clockwise


def test_right_then_left_changes_lane(grid_net):
    net = load_net(grid_net)
    # find e0 -r-> e1 -l-> e2
    for e0 in sorted(e.getID() for e in net._net.getEdges() if e.getFunction() != "internal"):
        for e1 in net.successors(e0):
            if not all(c.from_lane == 0 for c in net.connections(e0, e1)):
                continue
            for e2 in net.successors(e1):
                cs = net.connections(e1, e2)
                if all(c.from_lane == net.lane_count(e1) - 1 for c in cs) and cs[0].from_lane > 0:
                    r = route_waypoints(net, [e0, e1, e2], 3.0)
                    assert not r.on_lane.all()  # a lane change on e1
                    check_waypoints(net, r, 3.0)
                    assert r.lanes == (f"{e0}_0", f"{e1}_1", r.lanes[2])
                    return
    raise AssertionError("no right-then-left route found")


def test_unreachable_route_names_vehicle_and_edges(grid_net):
    net = load_net(grid_net)
    right, _ = turn_route(net, "r")
    far = [e for e in sorted(x.getID() for x in net._net.getEdges() if x.getFunction() != "internal")
           if e not in net.successors(right[0]) and e != right[0]][0]
    with pytest.raises(RouteError, match=rf"vehicle 'v7'.*no connection from edge '{right[0]}' to edge '{far}'"):
        route_waypoints(grid_net, [right[0], far], 3.0, vehicle_id="v7")
    with pytest.raises(RouteError, match=r"vehicle 'v8'.*edge 'nowhere'"):
        route_waypoints(grid_net, [right[0], "nowhere"], 3.0, vehicle_id="v8")
    with pytest.raises(RouteError, match="depart lane 5"):
        route_waypoints(grid_net, right, 3.0, depart_lane=5)


def test_net_is_read_once_per_file_and_routes_memoised(grid_net):
    assert load_net(grid_net) is load_net(str(grid_net))
    net = load_net(grid_net)
    right, _ = turn_route(net, "r")
    a = route_waypoints(net, right, 3.0, vehicle_id="a")
    b = route_waypoints(net, right, 3.0, vehicle_id="b")
    assert a.waypoints is b.waypoints and (a.vehicle_id, b.vehicle_id) == ("a", "b")


def test_subsample_keeps_corners_and_spacing():
    poly = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 7.0]])
    pts, arc = subsample(poly, 3.0)
    assert any(np.allclose(p, [10.0, 0.0]) for p in pts)  # the corner itself is a waypoint
    assert np.hypot(*np.diff(pts, axis=0).T).max() <= 3.0 + 1e-12
    assert len(pts) == 1 + 4 + 3  # fewest equal parts per side: 10/4 = 2.5, 7/3 = 2.33
    np.testing.assert_allclose(arc[-1], 17.0)
    with pytest.raises(ValueError, match="delta"):
        subsample(poly, 0.0)


# --------------------------------------------------------------------------- slivers and corners
from bridge.waypoints import CHAMFER_M, MIN_SEGMENT_M, REVERSAL_DEG, drop_slivers, round_corners  # noqa: E402


def _turns(p):
    d = np.diff(p, axis=0)
    h = np.arctan2(d[:, 1], d[:, 0])
    return np.degrees(np.abs((np.diff(h) + np.pi) % (2 * np.pi) - np.pi))


def test_a_sliver_where_two_lane_shapes_meet_is_dropped():
    """bs3d: a straight route with a 0.04 m segment pointing back (a 175 deg 'turn')."""
    p = np.array([[0.0, 0.0], [50.0, 0.0], [49.96, 0.003], [100.0, 0.0]])
    q, lanes, on = drop_slivers(p, ["a", "a", "b"], [True, True, True])
    assert len(q) == 3 and _turns(q).max() < 1.0  # a straight line again (deg)
    np.testing.assert_array_equal(q[[0, -1]], p[[0, -1]])
    assert lanes == ["a", "b"] and on == [True, False]  # the merged segment is on no centre line


def test_short_segments_of_a_smooth_curve_are_kept():
    a = np.linspace(0, np.pi / 2, 40)  # 0.26 m steps on a 10 m radius, 2.3 deg each
    p = np.column_stack([10 * np.cos(a), 10 * np.sin(a)])
    q, _, _ = drop_slivers(p, ["x"] * 39, [True] * 39)
    np.testing.assert_array_equal(q, p)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.floats(0.3, 30.0), st.floats(-170.0, 170.0)), min_size=2, max_size=12),
       st.sampled_from([30.0, 45.0, 60.0]))
def test_round_corners_bounds_every_turn(steps, max_turn):
    """Random polylines (segment 0.3..30 m, turns up to 170 deg): after rounding, every vertex
    turns by at most the bound or is a reversal (> REVERSAL_DEG), ends unchanged, and no point
    is further than CHAMFER_M from the original polyline."""
    h, pts = 0.0, [np.zeros(2)]
    for length, turn in steps:
        h += np.radians(turn)
        pts.append(pts[-1] + length * np.array([np.cos(h), np.sin(h)]))
    p = np.array(pts)
    n = len(p) - 1
    q, lanes, on = round_corners(p, list(range(n)), [True] * n, max_turn)
    t = _turns(q)
    assert np.all((t <= max_turn + 1e-6) | (t > REVERSAL_DEG))
    np.testing.assert_array_equal(q[[0, -1]], p[[0, -1]])
    assert point_polyline_distance(q, p).max() <= CHAMFER_M + 1e-9
    assert len(lanes) == len(on) == len(q) - 1
    assert MIN_SEGMENT_M > 0


@settings(max_examples=100, deadline=None)
@given(st.floats(1.5, 30.0), st.floats(30.0, 180.0), st.floats(1.0, 5.0))
def test_refine_turns_on_tight_curves(radius, sweep_deg, delta):
    """A smooth curve (vertices 2 deg apart, none sharp) of radius 1.5..30 m: chords delta apart
    turn by ~delta / radius, more than 45 deg on tight ones; after refinement no waypoint turns
    more than 45 deg, gaps stay <= delta and waypoints stay on the polyline (1e-9 m: round-off)."""
    from bridge.waypoints import refine_turns

    a = np.radians(np.arange(0.0, sweep_deg + 1e-9, 2.0))
    p = np.column_stack([radius * np.sin(a), radius * (1 - np.cos(a))])
    w, s = subsample(p, delta)
    w2, s2 = refine_turns(p, w, s, 45.0)
    assert len(w2) >= len(w)
    if len(w2) > 2:
        assert _turns(w2).max() <= 45.0 + 1e-9
    assert np.hypot(*np.diff(w2, axis=0).T).max() <= delta + 1e-9
    assert point_polyline_distance(w2, p).max() <= ON_POLYLINE_TOL
    np.testing.assert_array_equal(w2[[0, -1]], p[[0, -1]])


# ----------------------------------------------------------------------------- lane-change layout
def _lateral(n, arrive, leave, length, s, stepwise=True):
    """Lane coordinate (lane index, fractional on a diagonal) of a route's change at arc lengths ``s``."""
    plan = lane_change_plan(n, arrive, leave, length, stepwise=stepwise)
    if not plan:
        return np.full(len(s), float(arrive))
    if len(plan) == 1 and abs(leave - arrive) > 1:  # one diagonal across several lanes
        (s0, s1), = plan
        return arrive + (leave - arrive) * np.clip((s - s0) / (s1 - s0), 0.0, 1.0)
    step = np.sign(leave - arrive)
    y = np.full(len(s), float(arrive))
    for s0, s1 in plan:
        y += step * np.clip((s - s0) / (s1 - s0), 0.0, 1.0)
    return y


def _shared_runs_between(d, ds):
    """Lengths of the runs where ``d == 0`` with ``d != 0`` on both sides (two routes on one lane
    between two stretches where they are apart), sampled every ``ds``."""
    z = np.abs(d) <= 1e-9
    runs, i = [], 0
    while i < len(z):
        if z[i]:
            j = i
            while j < len(z) and z[j]:
                j += 1
            if i > 0 and j < len(z):
                runs.append((j - i + 1) * ds)
            i = j
        else:
            i += 1
    return runs


@given(n=st.integers(2, 5), length=st.floats(40.0, 600.0), data=st.data())
@settings(max_examples=200, deadline=None)
def test_no_two_lane_changes_on_an_edge_cross(n, length, data):
    """Two routes' lane coordinates along an edge never change order, nor touch and part, but
    through a stretch where both keep one lane for at least LANE_CHANGE_GAP_M (one follows the
    other).  Crossing diagonals deadlocked vehicles queued on them in pairs (changes to the left and
    to the right shared the middle of the edge: 18 vehicles on bench_scale's 4 x 4 grid).  Sampled
    every 5 cm: the runs measured to within two samples."""
    lanes = st.integers(0, n - 1)
    a1, l1, a2, l2 = (data.draw(lanes) for _ in range(4))
    ds = 0.05
    s = np.arange(0.0, length, ds)
    plan = lane_change_plan(n, a1, l1, length)
    k = 2 * (n - 1)
    lc = min(LANE_CHANGE_M, (length - LANE_CHANGE_END_M - LANE_CHANGE_START_M - (k - 1) * LANE_CHANGE_GAP_M) / k)
    if lc < LANE_CHANGE_MIN_M:  # too short for separate stretches: one diagonal in the middle
        one = min(LANE_CHANGE_M * abs(l1 - a1), 0.5 * length)
        assert plan == ([] if a1 == l1 else [(0.5 * (length - one), 0.5 * (length + one))])
        return
    d = _lateral(n, a1, l1, length, s) - _lateral(n, a2, l2, length, s)
    for run in _shared_runs_between(d, ds):
        assert run >= LANE_CHANGE_GAP_M - 2 * ds, (a1, l1, a2, l2, run)
    # one stretch per boundary crossed, lc long, in order, clear of the edge's ends
    assert len(plan) == abs(l1 - a1)
    for (s0, s1), nxt in zip(plan, plan[1:] + [(length, length)]):
        assert s1 - s0 == pytest.approx(lc, abs=1e-9) and s1 <= nxt[0] + 1e-9
        assert LANE_CHANGE_START_M - 1e-9 <= s0 and s1 <= length - LANE_CHANGE_END_M + 1e-9


def test_the_old_layout_fails_the_crossing_rule():
    """The rule above fires on crossing diagonals: changes both ways in the middle of the edge."""
    s = np.arange(0.0, 90.0, 0.05)
    up = np.clip((s - 30.0) / 30.0, 0.0, 1.0)
    assert _shared_runs_between(up - (1.0 - up), 0.05) and \
        min(_shared_runs_between(up - (1.0 - up), 0.05)) < LANE_CHANGE_GAP_M


def test_short_edges_and_forbidden_lanes_change_in_one_diagonal():
    """Too short for separate stretches (each < LANE_CHANGE_MIN_M), or a lane in between the vehicle
    may not use: one diagonal in the middle, LANE_CHANGE_M per lane, at most half the edge."""
    assert lane_change_plan(2, 1, 0, 60.0) == [(15.0, 45.0)]          # (60 - 20 - 5 - 12) / 2 < 20 m
    assert lane_change_plan(3, 0, 2, 300.0, stepwise=False) == [(120.0, 180.0)]
    # on a 300 m edge: 4 stretches of 30 m, 12 m apart (156 m), ending 20 m before the end; away
    # from lane 0 first (boundaries 0|1, 1|2), then towards it (2|1, 1|0)
    assert lane_change_plan(3, 0, 2, 300.0) == [(124.0, 154.0), (166.0, 196.0)]
    assert lane_change_plan(3, 2, 0, 300.0) == [(208.0, 238.0), (250.0, 280.0)]
    assert lane_change_plan(3, 2, 1, 300.0) == [(208.0, 238.0)]
    # our grid's inner blocks (79.2 m): 21.1 m stretches from 5 m on
    left, right = lane_change_plan(2, 0, 1, 79.2), lane_change_plan(2, 1, 0, 79.2)
    np.testing.assert_allclose([left[0], right[0]], [(5.0, 26.1), (38.1, 59.2)], rtol=0, atol=1e-9)
    assert lane_change_plan(2, 1, 1, 80.0) == []


def test_changes_to_either_side_use_their_own_stretch_on_the_grid(grid_net):
    """On our grid (2 lanes, 79-90 m edges): a change away from lane 0 is a diagonal in the first
    half of the edge's change block, one towards it in the second, at least LANE_CHANGE_GAP_M later
    and ending LANE_CHANGE_END_M before the edge's end (waypoints 1 m apart: to within 1 m)."""
    net = load_net(grid_net)
    found, ends = {}, {}
    for e0 in sorted(e.getID() for e in net._net.getEdges() if e.getFunction() != "internal"):
        for e1 in net.successors(e0):
            for e2 in net.successors(e1):
                r = route_waypoints(net, [e0, e1, e2], 1.0)
                off = np.flatnonzero(~r.on_lane & np.array([lid.startswith(e1 + "_") for lid in r.lane_ids]))
                if not len(off):
                    continue
                arrive, leave = int(r.lane_ids[off[0] - 1].rsplit("_", 1)[1]), int(r.lanes[1].rsplit("_", 1)[1])
                check_waypoints(net, r, 1.0)
                # arc position along e1 of the diagonal's waypoints, by projection on the leaving lane
                shape = net.lane_shape(r.lanes[1])
                seg = np.diff(shape, axis=0)
                u = seg[0] / np.hypot(*seg[0])
                s_off = (r.waypoints[off] - shape[0]) @ u
                found[(arrive, leave)] = (s_off.min(), s_off.max())
                ends[(arrive, leave)] = float(_arc(shape)[-1])
    assert {(1, 0), (0, 1)} <= set(found)
    right, left = found[(1, 0)], found[(0, 1)]
    assert left[1] + LANE_CHANGE_GAP_M <= right[0] + 1.0
    assert right[1] <= ends[(1, 0)] - LANE_CHANGE_END_M + 1.0 and left[0] >= LANE_CHANGE_START_M - 1.0
