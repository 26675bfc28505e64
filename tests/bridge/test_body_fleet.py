"""FleetBodies (bridge.body_fleet) gives, row by row, what RouteBody gives vehicle by vehicle.

The fleet computation replaced a per-vehicle loop in ``SumoWorld._poses`` (the largest part of a
step at 1,000 vehicles); SUMO judges the bodies it computes, so they must be the same bodies.
Routes: random walks on SUMO's own ``grid6`` (curved edges, lanes whose length is not their
shape's: the length-geometry factor) and on muvsim's ``grid`` (turns, lane changes); reference
points anywhere along them, up to 1.5 m off.  Tolerance 1e-9 m: the same operations on the same
floats (only the order of vehicles differs), so round-off at most.
"""

import numpy as np
import pytest

from bridge.body_fleet import FleetBodies
from bridge.sumo_body import RouteBody, _at
from bridge.waypoints import RouteError, load_net
from sumo_nets.sumo_tools import sumo_home

SIZES = [(5.0, 1.8), (12.0, 2.5), (7.1, 2.4)]


def _grid6():
    p = sumo_home() / "tools" / "game" / "grid6" / "grid6.net.xml"
    if not p.exists():
        pytest.skip(f"SUMO's grid6 demo is not at {p}")
    return p


def _walks(net, rng, n, hops=6):
    """``n`` routes: random walks of up to ``hops`` edges that ``net`` can draw."""
    sn = net.sumolib_net
    edges = [e for e in sn.getEdges() if not e.getID().startswith(":") and e.allows("passenger")]
    out = []
    while len(out) < n:
        e = edges[int(rng.integers(len(edges)))]
        walk = [e.getID()]
        for _ in range(hops - 1):
            nxt = [x for x in e.getOutgoing() if x.allows("passenger") and x.getID() not in walk]
            if not nxt:
                break
            e = nxt[int(rng.integers(len(nxt)))]
            walk.append(e.getID())
        if len(walk) < 2:
            continue
        try:
            out.append(net.route(walk, 3.0, vclass="passenger", turn_max_deg=45.0))
        except RouteError:
            continue
    return out


@pytest.mark.parametrize("which", ["grid6", "grid"])
def test_fleet_bodies_match_route_bodies(which, grid_net):
    net = load_net(_grid6() if which == "grid6" else grid_net)
    rng = np.random.default_rng(7)
    routes = _walks(net, rng, 40)
    fleet = FleetBodies()
    bodies = {}
    for i, r in enumerate(routes):
        b = bodies[f"v{i}"] = RouteBody(r, net, *SIZES[i % 3])
        assert len(b.seg_lane) == len(b.poly) - 1
        fleet.add(f"v{i}", b)
    fleet.remove("v3")  # a vehicle that left: the arrays are rebuilt without it
    ids = [v for v in bodies if v != "v3"] * 5
    rng.shuffle(ids)
    sig0 = np.array([rng.uniform(0.0, bodies[v].route_length) for v in ids])
    off = rng.uniform(-1.5, 1.5, len(ids))
    p = np.empty((len(ids), 2))
    for i, v in enumerate(ids):
        q, t, _ = _at(bodies[v].poly, bodies[v].parc, sig0[i:i + 1])
        p[i] = q[0] + off[i] * np.array([-t[0, 1], t[0, 0]])
    # the search window around the last arc position (moved a little), or none (NaN: a new vehicle)
    around = sig0 + rng.uniform(-3.0, 3.0, len(ids))
    around[::7] = np.nan
    sig, e = fleet.project(ids, p, around)
    front, back, lane, corners = fleet.bodies(ids, sig, e)
    for i, v in enumerate(ids):
        b = bodies[v]
        s_ref, e_ref = b.project(p[i:i + 1], None if np.isnan(around[i]) else [around[i]])
        np.testing.assert_allclose([sig[i], e[i]], [s_ref[0], e_ref[0]], rtol=0, atol=1e-9)
        f_ref, b_ref, l_ref, c_ref = b.bodies(s_ref, e_ref)
        np.testing.assert_allclose(front[i], f_ref[0], rtol=0, atol=1e-9)
        np.testing.assert_allclose(back[i], b_ref[0], rtol=0, atol=1e-9)
        assert lane[i] == l_ref[0]
        np.testing.assert_allclose(corners[i], c_ref[0], rtol=0, atol=1e-9)
    # the back really lies a body length behind the front somewhere (not a vacuous comparison)
    axis = np.hypot(*(front - back).T)
    assert np.median(axis) > 4.0


def test_fleet_bodies_refuse_an_unknown_vehicle(grid_net):
    net = load_net(grid_net)
    fleet = FleetBodies()
    fleet.add("a", RouteBody(_walks(net, np.random.default_rng(1), 1)[0], net, 5.0, 1.8))
    with pytest.raises(KeyError, match="'b' has no body"):
        fleet.bodies(["a", "b"], np.zeros(2), np.zeros(2))


@pytest.mark.parametrize("which", ["grid6", "grid"])
def test_project_along_with_hints_is_the_sequential_search(which, grid_net):
    """The waypoints' arc positions searched all at once around hints (the route's own arc positions,
    as SumoWorld gives them) are those of the search one waypoint after the other, and the route's;
    so are the chords' middles (RouteBody.leans) and the leans themselves.  Tolerance 1e-9 m."""
    net = load_net(_grid6() if which == "grid6" else grid_net)
    for r in _walks(net, np.random.default_rng(11), 12):
        b = RouteBody(r, net, 5.0, 1.8)
        W, A = np.asarray(r.waypoints), np.asarray(r.arc_length)
        seq = b.project_along(W)
        np.testing.assert_allclose(b.project_along(W, A), seq, rtol=0, atol=1e-9)
        np.testing.assert_allclose(seq, A, rtol=0, atol=1e-6)
        mid = W[:-1] + 0.5 * np.diff(W, axis=0)
        np.testing.assert_allclose(b.project_along(mid, 0.5 * (A[:-1] + A[1:])), b.project_along(mid),
                                   rtol=0, atol=1e-9)
        np.testing.assert_array_equal(b.leans(W, A), b.leans(W))


def test_world_waypoint_arcs_of_trimmed_routes(grid_net, monkeypatch):
    """SumoWorld's waypoint arcs (hints from the route when the waypoints are its tail, as
    ``trim_start`` makes them) are the one-after-the-other search's, trimmed or not, and for
    waypoints that are not the route's (no hints) too.  Tolerance 1e-9 m."""
    from bridge.cosim import VehicleSpec
    from bridge.demand import PlannedVehicle
    from bridge.sumo_world import SumoWorld
    from bridge.waypoints import trim_start

    net = load_net(grid_net)
    routes = _walks(net, np.random.default_rng(4), 6)
    planned = {f"v{i}": PlannedVehicle(f"v{i}", "car", 0.0, r.edges, None, None, "passenger", 5.0, 1.8)
               for i, r in enumerate(routes)}
    w = SumoWorld(None, planned, {f"v{i}": r for i, r in enumerate(routes)}, net=net)
    for i, r in enumerate(routes):
        vid = f"v{i}"
        for s0, cut in ((0.0, 0), (3.25, 0), (0.3 * r.length_m, 0), (3.25, 2)):
            W = trim_start(r, s0)
            W = W[:len(W) - cut]  # authority mode stops short of the route's end
            w._arcs.pop(vid, None)
            with monkeypatch.context() as mp:  # the route's run of waypoints: searched at once, no sequence
                mp.setattr(RouteBody, "project", lambda *a, **k: pytest.fail("searched one by one"))
                w._waypoint_arcs(VehicleSpec(vid, "car", W))
            w._arcs.pop(vid, None)
            got = w._waypoint_arcs(VehicleSpec(vid, "car", W))
            np.testing.assert_allclose(got, w.route_body(vid).project_along(W), rtol=0, atol=1e-9)
        W = np.asarray(r.waypoints)[::2]  # not the route's tail: searched in order
        w._arcs.pop(vid, None)
        np.testing.assert_allclose(w._waypoint_arcs(VehicleSpec(vid, "car", W)),
                                   w.route_body(vid).project_along(W), rtol=0, atol=1e-9)
