"""The pedestrian rule (tm.pedestrians) without a simulator.

References are independent of the code under test: claim polygons are scipy hulls of vertex
sums (tests.tm.helpers), the part of a claim inside a walking region is clipped here
(Sutherland-Hodgman) and distances are measured with plain loops.  Tolerance 1e-9 m: sums of
O(10) m coordinates, round-off ~1e-14.
"""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from tests.tm.helpers import box, nested_family, ref_claim_sequence
from tm.claims import Claims
from tm.families import build_family_table
from tm.pedestrians import PedestrianRule, PedestrianSettings, footprint_contacts, point_polygon_distance

TS = 0.1
TOL = 1e-9
#: A crossing 4 m wide across a road along x: x in [-2, 2], y in [-6, 6].
CROSSING = np.array([[-2.0, -6.0], [2.0, -6.0], [2.0, 6.0], [-2.0, 6.0]])


def claims(table, centre, index, heading=0.0, length=5.0, width=1.8, fam=0):
    n = len(centre)
    return Claims(table, np.full(n, fam), np.asarray(centre, float).reshape(n, 2), np.asarray(index),
                  np.full(n, heading, float), np.full(n, length, float), np.full(n, width, float))


def flat_table(levels=30, half=0.5):
    """Every level the same box: the claim's polygon does not depend on k (isolates the reach)."""
    return build_family_table({"f": [box(half, half)] * levels})


def test_pedestrian_on_the_crossing_blocks_a_claim_over_it_and_not_one_elsewhere():
    rule = PedestrianRule(PedestrianSettings(), [CROSSING], TS)
    t = flat_table()
    # horizon 20 steps: reach 0.3 + 0.75 + 3.0 * 21 * 0.1 = 7.35 m, the pedestrian 2.6 m from the claim
    c = claims(t, [[0.0, 0.0], [-30.0, 0.0]], [20, 20])   # over the crossing; 30 m before it
    assert rule.withhold(c, np.array([[0.0, 4.0]])).tolist() == [True, False]


def test_pedestrian_far_away_does_not_block():
    rule = PedestrianRule(PedestrianSettings(), [CROSSING], TS)
    c = claims(flat_table(), [[0.0, 0.0]], [3])
    # reach at K = 3 (lag 1): 0.3 + 0.75 + 3.0 * 4 * 0.1 = 2.25 m; the pedestrian is 10 m from the crossing
    assert not rule.withhold(c, np.array([[0.0, 16.0]])).any()
    assert not rule.withhold(c, np.zeros((0, 2))).any()


def test_pedestrian_near_a_claim_that_meets_no_walking_region_does_not_block():
    rule = PedestrianRule(PedestrianSettings(), [CROSSING], TS)
    c = claims(flat_table(), [[-20.0, 0.0]], [3])
    assert not rule.withhold(c, np.array([[-20.0, 2.0]])).any()   # beside the car, on no crossing


def test_reach_grows_with_the_claims_horizon():
    """A pedestrian d away from the claim and the crossing blocks exactly the claims whose horizon K
    gives reach r + v (K + lag) Ts >= d."""
    s = PedestrianSettings(v_max=2.0, radius=0.25, lag_steps=1, jump_m=0.5)
    rule = PedestrianRule(s, [CROSSING], TS)
    t = flat_table(60)
    # claim box: centre (0, 0), level box +-0.5 plus footprint 5 x 1.8 -> y extent +-1.4; crossing edge y = 6
    d = 3.0                                           # pedestrian at y = 1.4 + 3.0, inside the crossing
    ped = np.array([[0.0, 1.4 + d]])
    K = np.arange(1, 40)
    blocked = rule.withhold(claims(t, np.zeros((len(K), 2)), K), np.repeat(ped, 1, axis=0))
    expect = s.radius + s.jump_m + s.v_max * (K + s.lag_steps) * TS >= d - 1e-9
    assert blocked.tolist() == expect.tolist()
    assert expect.any() and not expect.all()          # the threshold lies inside the range
    # a pedestrian off the crossing but able to reach it is as dangerous: y = 7 (1 m beyond its edge)
    far = rule.withhold(claims(t, np.zeros((len(K), 2)), K), np.array([[0.0, 7.0]]))
    assert far.tolist() == (s.radius + s.jump_m + s.v_max * (K + 1) * TS >= 7.0 - 1.4 - 1e-9).tolist()


def test_hold_seconds_extend_the_horizon():
    t = flat_table()
    ped = np.array([[0.0, 1.4 + 2.0]])
    c = claims(t, [[0.0, 0.0]], [1])                 # K = 1: reach 0.3 + 0.75 + 0.6 = 1.65 m < 2 m
    assert not PedestrianRule(PedestrianSettings(), [CROSSING], TS).withhold(c, ped).any()
    assert PedestrianRule(PedestrianSettings(hold_s=1.0), [CROSSING], TS).withhold(c, ped).all()


def test_disabled_rule_withholds_nothing():
    rule = PedestrianRule(PedestrianSettings(enabled=False), [CROSSING], TS)
    assert not rule.withhold(claims(flat_table(), [[0.0, 0.0]], [3]), np.array([[0.0, 0.0]])).any()


@pytest.mark.parametrize("kw, field", [({"v_max": -1.0}, "v_max"), ({"radius": float("nan")}, "radius"),
                                       ({"lag_steps": 1.5}, "lag_steps"), ({"hold_s": -0.1}, "hold_s"), ({"jump_m": -1.0}, "jump_m"),
                                       ({"enabled": 1}, "enabled")])
def test_settings_are_validated(kw, field):
    with pytest.raises(ValueError, match=f"PedestrianSettings.{field}"):
        PedestrianSettings(**kw)


def test_bad_region_is_refused_by_number():
    with pytest.raises(ValueError, match="walking region 1"):
        PedestrianRule(PedestrianSettings(), [CROSSING, np.zeros((2, 2))], TS)


# ------------------------------------------------------------------ the property, against a reference
def _clip(P: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """P ∩ Q for convex CCW polygons (Sutherland-Hodgman; empty array if disjoint)."""
    out = [tuple(p) for p in P]
    for a, b in zip(Q, np.roll(Q, -1, axis=0)):
        if not out:
            break
        inp, out = out, []
        side = lambda p: (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])  # noqa: E731
        for i, cur in enumerate(inp):
            prev = inp[i - 1]
            sc, sp = side(cur), side(prev)
            if sc >= 0:
                if sp < 0:
                    t = sp / (sp - sc)
                    out.append((prev[0] + t * (cur[0] - prev[0]), prev[1] + t * (cur[1] - prev[1])))
                out.append(cur)
            elif sp >= 0:
                t = sp / (sp - sc)
                out.append((prev[0] + t * (cur[0] - prev[0]), prev[1] + t * (cur[1] - prev[1])))
    return np.array(out).reshape(-1, 2)


def _dist(q, P) -> float:
    """Distance of point q to convex CCW polygon P (loops; 0 inside)."""
    if len(P) == 0:
        return np.inf
    inside = True
    best = np.inf
    for a, b in zip(P, np.roll(P, -1, axis=0)):
        d = b - a
        if d[0] * (q[1] - a[1]) - d[1] * (q[0] - a[0]) < 0:
            inside = False
        L = float(d @ d)
        t = 0.0 if L == 0 else min(max(float((q - a) @ d) / L, 0.0), 1.0)
        best = min(best, float(np.hypot(*(q - a - t * d))))
    return 0.0 if inside and len(P) >= 3 else best


def _case(rng):
    fam = nested_family(rng, 8, str(rng.choice(["box", "poly"])))
    table = build_family_table({"f": fam})
    n = 6
    c = Claims(table, np.zeros(n, int), rng.uniform(-8, 8, (n, 2)), rng.integers(0, 8, n),
               rng.uniform(-np.pi, np.pi, n), rng.uniform(2, 6, n), rng.uniform(1, 2.5, n))
    regions = []
    for _ in range(int(rng.integers(1, 5))):
        w, h = rng.uniform(1, 6, 2)
        th = rng.uniform(0, np.pi)
        R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
        regions.append(box(w, h) @ R.T + rng.uniform(-8, 8, 2))
    peds = rng.uniform(-12, 12, (int(rng.integers(1, 8)), 2))
    s = PedestrianSettings(v_max=float(rng.uniform(0.5, 5.0)), radius=float(rng.uniform(0.1, 0.5)),
                           lag_steps=int(rng.integers(0, 3)), hold_s=float(rng.choice([0.0, 0.5, 1.5])),
                           jump_m=float(rng.uniform(0.0, 1.0)))
    return fam, c, regions, peds, s


def _granted_are_out_of_reach(fam, c, regions, peds, s) -> np.ndarray:
    rule = PedestrianRule(s, regions, TS)
    withheld = rule.withhold(c, peds)
    for v in np.flatnonzero(~withheld):
        for k in range(1, int(rule.horizon(c.index[v])) + 1):
            S = ref_claim_sequence({"f": fam}, "f", c, v, k)      # the vehicle's footprint at t + k lies in S
            reach = s.radius + s.jump_m + s.v_max * (k + s.lag_steps) * TS
            for G in regions:
                part = _clip(S, G)
                for p in peds:
                    assert _dist(p, part) > reach - TOL, (v, k)
    return withheld


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_a_granted_claim_is_never_within_a_pedestrians_reach_on_a_walking_region(seed):
    _granted_are_out_of_reach(*_case(np.random.default_rng(seed)))


def test_the_random_cases_both_withhold_and_grant():
    """The property test is not vacuous: over these cases both outcomes occur."""
    rng = np.random.default_rng(7)
    out = np.concatenate([_granted_are_out_of_reach(*_case(rng)) for _ in range(40)])
    assert 0.1 < out.mean() < 0.9


# ------------------------------------------------------------------ the measured counter
def test_footprint_contacts_fire_on_touch_only():
    ids, peds = ["car"], ["p0", "p1", "p2"]
    # car 5 x 1.8 at the origin heading +x: side at y = 0.9; bodies of radius 0.3
    P = np.array([[0.0, 0.9 + 0.29], [0.0, 0.9 + 0.31], [2.5 + 0.2, 0.0]])
    got = footprint_contacts(ids, np.zeros((1, 2)), np.zeros(1), np.array([5.0]), np.array([1.8]), peds, P, 0.3)
    assert got == {("car", "p0"), ("car", "p2")}
    # turned by 90 degrees the car runs along y: p0 and p1 inside, p2 1.8 m beside its side
    got = footprint_contacts(ids, np.zeros((1, 2)), np.array([np.pi / 2]), np.array([5.0]), np.array([1.8]),
                             peds, P, 0.3)
    assert got == {("car", "p0"), ("car", "p1")}


def test_point_polygon_distance():
    sq = box(1.0, 1.0)[None].repeat(3, axis=0)
    d = point_polygon_distance(sq, np.array([[0.0, 0.0], [3.0, 0.0], [4.0, 5.0]]))
    assert np.allclose(d, [0.0, 2.0, 5.0], atol=TOL)


def test_raise_speed_only_raises_the_bound_and_the_reach():
    rule = PedestrianRule(PedestrianSettings(v_max=2.0), [CROSSING], TS)
    r0 = float(rule.reach(10))
    rule.raise_speed(1.0)
    assert rule.v_max == 2.0 and float(rule.reach(10)) == r0
    rule.raise_speed(4.0)
    assert rule.v_max == 4.0 and float(rule.reach(10)) == pytest.approx(r0 + 2.0 * 11 * TS, abs=TOL)
