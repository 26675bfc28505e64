"""Restarting from rest behind a close follower (the grid queue that never moved).

A vehicle at rest at its stop point (index 0) claims its hold box ``T^0 ⊕ footprint``; a follower
may stop with its own hold box right behind that (any gap > 0).  A request with speed-limit slack
(index ``l_min + s``) claims the larger level ``T^{l_min + s - k}`` of the new stop point, whose
backward, negative-velocity part the reach keeps: the new claim reaches behind the hold box and
meets the follower's, which cannot move (the leader stands in its way).  Measured on ``grid``
(authority, seed 1): cars 74 (leader, at a junction's entry with its token, slack 3) and 27 (0.2 m
claim gap behind it) denied each other from ~170 s to the 894 s cap, 9 more cars queued behind.
:func:`controllers.speed_limits.restart_slack` drops the slack of a vehicle at rest whose request
was denied.

Tolerance: claims are compared by the TM itself (GEOMETRY_TOL); the gaps here are >= 0.2 m.
"""

import numpy as np
import pytest

from controllers.classes import get_class
from controllers.settings import SynthesisSettings
from controllers.speed_limits import SpeedSettings, restart_slack
from tm.lane import lane_class
from tm.manager import FleetState, TrafficManager
from tm.reach import pairwise_conflicts, reach_claims
from tm.settings import TMSettings


@pytest.fixture(scope="module")
def car(shared_set_cache):
    return lane_class(get_class("car"), SynthesisSettings(cache_dir=shared_set_cache))


def _state(requesting):
    n = len(requesting)
    return FleetState(ids=[f"v{i}" for i in range(n)], family=["car"] * n, centre=np.zeros((n, 2)),
                      index=np.zeros(n, dtype=int), heading=np.zeros(n), length=np.full(n, 5.0),
                      width=np.full(n, 1.8), requesting=np.asarray(requesting), req_centre=np.zeros((n, 2)),
                      req_index=np.zeros(n, dtype=int), req_heading=np.zeros(n))


def test_restart_slack_drops_only_at_rest_after_a_denial():
    out = restart_slack(np.array([3, 3, 3, 0, 5]), np.array([0, 0, 7, 0, 0]),
                        np.array([True, False, True, True, True]))
    assert out.tolist() == [0, 3, 3, 0, 0]


@pytest.mark.parametrize("check", ["union", "timed"])
@pytest.mark.parametrize("gap", [0.2, 0.3])
def test_leader_at_rest_restarts_past_a_close_follower(car, check, gap):
    """Leader v0 and follower v1 at rest on a lane, hold boxes ``gap`` apart, both asking for the
    next waypoint (3 m on).  With the slack of a binding speed bound (``slack_steps``) the
    leader's new claim meets the follower's claim and the follower's new claim meets the
    leader's: nobody goes, step after step (the wait-for cycle).  With :func:`restart_slack`
    the leader, denied once, asks without slack and is granted."""
    ctl, rm = car.ctl, car.reach
    delta = car.vclass.model.delta
    tm = TrafficManager(TMSettings(check=check, policy="optimal", verify=True),
                        {"car": ctl.family.position_sets}, rotating={"car"})
    hd = np.zeros(2)
    cL = 90.0
    probe = reach_claims(rm, np.array([[cL, 0, 0, 0.0]]), np.array([[cL, 0.0]]), hd[:1], np.zeros(1, dtype=int))
    box = float(probe.hi[0, :, 0].max() - probe.lo[0, :, 0].min())  # hold box T^0 ⊕ footprint, along
    cF = cL - box - gap
    X = np.array([[cL, 0, 0, 0.0], [cF, 0, 0, 0.0]])
    C = np.array([[cL, 0.0], [cF, 0.0]])
    l = ctl.index(X, C, hd)
    assert l.tolist() == [0, 0]
    cur = reach_claims(rm, X, C, hd, l)
    assert len(pairwise_conflicts(cur, check)[0]) == 0
    Cn = C + [delta, 0.0]
    lp = ctl.index(X, Cn, hd)
    slack = np.full(2, SpeedSettings().slack_steps)
    denied = np.zeros(2, dtype=bool)
    went = None
    for step in range(3):  # nothing moves while both are denied: the same decision each step
        s = restart_slack(slack, l, denied)
        new = reach_claims(rm, X, Cn, hd, np.minimum(lp + s, ctl.N))
        dec = tm.decide_reach(_state([True, True]), cur, new)
        if step == 0:  # with slack: the cycle (each new claim meets the other's current claim)
            assert not dec.go.any()
            assert {tuple(e) for e in dec.edges.tolist()} >= {(0, 1), (1, 0)}
        if dec.go.any():
            went = step
            break
        denied = np.ones(2, dtype=bool)
    assert went == 1 and dec.go.tolist() == [True, False]
