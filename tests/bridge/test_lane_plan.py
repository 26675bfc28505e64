"""Where a route changes lanes (SUMO's ``ramp``, its network unchanged).

On ``tools/game/ramp`` the highway's three lanes run 381 m on ``gneE2``, then 53 m on ``offramp``,
whose lane 0 leads only to the exit.  A highway route that starts on lane 0 needs one change to lane
1; both edges can take it.  On ``offramp`` it is one diagonal in the middle of the edge, right
before the split (the edge is too short for :func:`bridge.waypoints.lane_change_plan`'s stretches);
there lane 1's traffic, at 33 m/s, never left it free and the exit's vehicles queued behind
(``--controller authority``, 180 s: 2 of 25 entered exit vehicles arrived, 15 with the change on
``gneE2``)."""

from pathlib import Path

import numpy as np

from bridge.waypoints import lane_change_plan, load_net, LANE_CHANGE_MIN_M
from sumo_nets.sumo_tools import sumo_home

HIGHWAY = ["gneE2", "offramp", "gneE3", "gneE7"]


def _net() -> Path:
    return sumo_home() / "tools" / "game" / "ramp" / "ramp.net.xml"


def test_a_change_both_edges_can_take_is_made_on_the_one_with_room_for_it():
    geo = load_net(_net())
    r = geo.route(HIGHWAY, 3.0, depart_lane=0, vclass="passenger")
    on = [i for i, ln in enumerate(r.lane_ids) if ln.startswith("offramp_")]
    assert on and all(r.lane_ids[i] == "offramp_1" for i in on)  # already on lane 1 along offramp
    assert set(r.lanes[:2]) == {"gneE2_1", "offramp_1"}
    # gneE2 leaves on lane 1: its waypoints change from lane 0 in gneE2's own stretch
    e2 = [i for i, ln in enumerate(r.lane_ids) if ln.startswith("gneE2_")]
    assert r.lane_ids[e2[0]] == "gneE2_0" and r.lane_ids[e2[-1]] == "gneE2_1"
    # the reason: offramp's stretches would be too short (one diagonal), gneE2's are not
    length = lambda e: min(float(np.sum(np.hypot(*np.diff(geo.lane_shape(f"{e}_{j}"), axis=0).T)))  # noqa: E731
                           for j in range(geo.lane_count(e)))
    assert geo._short_for_changes("offramp") and not geo._short_for_changes("gneE2")
    assert len(lane_change_plan(3, 0, 1, length("offramp"))) == 1
    assert (lambda p: p[0][1] - p[0][0])(lane_change_plan(3, 0, 1, length("gneE2"))) >= LANE_CHANGE_MIN_M


def test_the_fewest_changes_still_come_first():
    """The short-edge rule only breaks ties: a route needing one change makes one, and a start on
    lane 1 makes none (the counts ``start_lanes`` gives departLane="best")."""
    geo = load_net(_net())
    assert geo.start_lanes(HIGHWAY, "passenger") == {0: 1, 1: 0, 2: 0}
    r = geo.route(HIGHWAY, 3.0, depart_lane=1, vclass="passenger")
    assert all(ln.endswith("_1") or ln.startswith(":") for ln in r.lane_ids[:len(r.lane_ids) // 2])
