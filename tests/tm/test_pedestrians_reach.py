"""The pedestrian rule on reach-tightened, time-indexed claims (authority mode, tm.reach), without a simulator.

Box ``S_k`` of a claim is slot ``k`` (``k = 1 .. K``): where the vehicle's footprint can be at step
``t + k``.  The rule refuses a claim when some ``S_k``, ``k <= min(max(l, 1) + hold_steps, K)``,
meets a walking region within a pedestrian's ``k``-step reach ``r + j + v (k + lag) Ts``.
References are independent of the code under test: box corners are built here with a rotation
matrix, clipped to the regions (Sutherland-Hodgman) and measured with plain loops
(tests.tm.test_pedestrians).  Tolerance 1e-9 m: sums of O(10) m coordinates, round-off ~1e-14.
"""

import numpy as np
from hypothesis import given, settings, strategies as st

from tests.tm.helpers import box
from tests.tm.test_pedestrians import _clip, _dist
from tm.pedestrians import PedestrianRule, PedestrianSettings
from tm.reach import ReachClaims

TS = 0.1
TOL = 1e-9
#: A crossing 4 m wide across a road along x: x in [-2, 2], y in [-6, 6].
CROSSING = np.array([[-2.0, -6.0], [2.0, -6.0], [2.0, 6.0], [-2.0, 6.0]])
#: Settings with round numbers: reach_k = 0.2 + 0.3 + 2.0 (k + 1) 0.1 = 0.7 + 0.2 k.
S = PedestrianSettings(v_max=2.0, radius=0.2, lag_steps=1, jump_m=0.3)


def reach_k(s: PedestrianSettings, k) -> np.ndarray:
    return s.radius + s.jump_m + s.v_max * (np.asarray(k, float) + s.lag_steps) * TS


def driving_claim(K: int = 40, x0: float = -20.0, dx: float = 2.0, half=(2.5, 0.9)) -> ReachClaims:
    """One vehicle heading +x along y = 0, its box ``S_k`` centred at ``x0 + dx k`` (half extents ``half``)."""
    k = np.arange(1, K + 1)
    mid = np.column_stack([x0 + dx * k, np.zeros(K)])
    h = np.asarray(half, float)
    return ReachClaims(np.zeros((1, 2)), np.zeros(1), (mid - h)[None], (mid + h)[None])


def first_last_meeting(c: ReachClaims):
    """Slots (1-based) of the first and last box ``S_k`` that meets the crossing (x in [-2, 2])."""
    meet = (c.lo[0, :, 0] <= 2.0) & (c.hi[0, :, 0] >= -2.0)
    k = np.flatnonzero(meet) + 1
    return int(k[0]), int(k[-1])


def distance_on_crossing(c: ReachClaims, k: int, d: float) -> float:
    """Distance from a pedestrian at (0, 0.9 + d) to the part of box S_k on the crossing (it meets it)."""
    gap = max(c.lo[0, k - 1, 0], 0.0, -c.hi[0, k - 1, 0])
    return float(np.hypot(gap, d))


def test_a_pedestrian_who_can_reach_the_crossing_at_step_k_blocks_the_claim_whose_s_k_meets_it():
    c = driving_claim()
    assert first_last_meeting(c) == (8, 12)          # boxes 5 m long moving 2 m/step
    rule = PedestrianRule(S, [CROSSING], TS)
    # on the crossing (x = 0), d from the boxes' side y = 0.9; S_11 covers x = 0: distance d, reach 2.9 m
    d_in = float(reach_k(S, 11)) - 0.05
    assert distance_on_crossing(c, 11, d_in) <= float(reach_k(S, 11))
    assert rule.withhold_reach(c, [39], np.array([[0.0, 0.9 + d_in]])).tolist() == [True]


def test_a_pedestrian_who_cannot_reach_it_in_time_does_not_block():
    """The rule is time-indexed: a pedestrian who could reach the crossing within the whole horizon
    (K = 40 steps) but not by the last step the claim is on it (k1 = 24) does not block it."""
    c = driving_claim()
    k0, k1 = first_last_meeting(c)
    rule = PedestrianRule(S, [CROSSING], TS)
    d_out = 3.0                                      # on the crossing (y = 3.9)
    assert all(distance_on_crossing(c, k, d_out) > float(reach_k(S, k)) for k in range(k0, k1 + 1))
    assert d_out < float(reach_k(S, 40))             # the whole-horizon rule would block it
    assert rule.withhold_reach(c, [39], np.array([[0.0, 0.9 + d_out]])).tolist() == [False]


def test_blocked_exactly_when_some_slot_on_the_crossing_is_within_the_pedestrians_reach_then():
    """Sweep over the claim's index l (checked slots 1 .. l) and the pedestrian's distance d from the
    boxes' side (standing at x = 0): blocked iff some k in k0 .. min(l, k1) has S_k's part on the
    crossing within reach_k (here the rule's three tests are exact: the nearest point of S_k lies on
    the crossing)."""
    c = driving_claim()
    k0, k1 = first_last_meeting(c)
    rule = PedestrianRule(S, [CROSSING], TS)
    got, want = [], []
    for d in (0.5, 2.0, 2.5, 2.85, 3.0, 5.5):
        ped = np.array([[0.0, 0.9 + d]])
        for l in range(1, 40):
            got.append(bool(rule.withhold_reach(c, [l], ped)[0]))
            want.append(any(distance_on_crossing(c, k, d) <= float(reach_k(S, k)) + TOL
                            for k in range(k0, min(l, k1) + 1)))
    assert got == want
    assert 0 < sum(want) < len(want)


def test_the_claims_index_bounds_the_checked_slots_and_empty_boxes_meet_nothing():
    c = driving_claim()
    k0, _ = first_last_meeting(c)
    rule = PedestrianRule(S, [CROSSING], TS)
    ped = np.array([[0.0, 0.0]])                     # on the crossing, in the vehicle's path
    assert rule.withhold_reach(c, [k0], ped).tolist() == [True]
    assert rule.withhold_reach(c, [k0 - 1], ped).tolist() == [False]   # S_k on it only after the tube's end
    assert PedestrianRule(PedestrianSettings(hold_s=0.1), [CROSSING], TS).withhold_reach(c, [k0 - 1], ped).all()
    lo, hi = c.lo.copy(), c.hi.copy()
    lo[0, k0 - 1:], hi[0, k0 - 1:] = np.inf, -np.inf  # the boxes on the crossing are empty
    assert not rule.withhold_reach(ReachClaims(c.centre, c.heading, lo, hi), [39], ped).any()


def test_disabled_rule_and_no_pedestrian_withhold_nothing():
    c = driving_claim()
    ped = np.array([[0.0, 0.0]])
    assert not PedestrianRule(PedestrianSettings(enabled=False), [CROSSING], TS).withhold_reach(c, [39], ped).any()
    assert not PedestrianRule(S, [CROSSING], TS).withhold_reach(c, [39], np.zeros((0, 2))).any()


def test_index_count_must_match():
    import pytest

    with pytest.raises(ValueError, match="1 claims but 2 indices"):
        PedestrianRule(S, [CROSSING], TS).withhold_reach(driving_claim(), [3, 4], np.zeros((1, 2)))


# ------------------------------------------------------------------ the property, against a reference
def _corners(c: ReachClaims, i: int, k: int) -> np.ndarray:
    lo, hi = c.lo[i, k - 1], c.hi[i, k - 1]
    C = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
    th = c.heading[i]
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    return C @ R.T + c.centre[i]


def _case(rng):
    n, K = 6, int(rng.integers(3, 30))
    centre = rng.uniform(-10, 10, (n, 2))
    heading = rng.uniform(-np.pi, np.pi, n)
    # boxes moving along the segment frame's x, growing, some empty
    x = np.cumsum(rng.uniform(0.0, 1.5, (n, K)), axis=1) - rng.uniform(0, 10, (n, 1))
    half = rng.uniform(0.5, 3.0, (n, K, 2))
    mid = np.stack([x, rng.uniform(-0.5, 0.5, (n, K))], axis=-1)
    lo, hi = mid - half, mid + half
    empty = rng.random((n, K)) < 0.15
    lo[empty], hi[empty] = np.inf, -np.inf
    index = rng.integers(0, K + 3, n)
    regions = []
    for _ in range(int(rng.integers(1, 5))):
        w, h = rng.uniform(1, 6, 2)
        th = rng.uniform(0, np.pi)
        R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
        regions.append(box(w, h) @ R.T + rng.uniform(-10, 10, 2))
    peds = rng.uniform(-14, 14, (int(rng.integers(1, 8)), 2))
    s = PedestrianSettings(v_max=float(rng.uniform(0.5, 5.0)), radius=float(rng.uniform(0.1, 0.5)),
                           lag_steps=int(rng.integers(0, 3)), hold_s=float(rng.choice([0.0, 0.5, 1.5])),
                           jump_m=float(rng.uniform(0.0, 1.0)))
    return ReachClaims(centre, heading, lo, hi), index, regions, peds, s


def _granted_are_out_of_reach(c, index, regions, peds, s) -> np.ndarray:
    rule = PedestrianRule(s, regions, TS)
    withheld = rule.withhold_reach(c, index, peds)
    K = c.lo.shape[1]
    hold = int(np.ceil(s.hold_s / TS - 1e-9))
    for v in np.flatnonzero(~withheld):
        for k in range(1, min(max(int(index[v]), 1) + hold, K) + 1):
            if np.any(c.lo[v, k - 1] > c.hi[v, k - 1]):
                continue                                # empty: the vehicle cannot be there
            Sk = _corners(c, v, k)
            reach = float(reach_k(s, k))
            for G in regions:
                part = _clip(Sk, G)
                for p in peds:
                    assert _dist(p, part) > reach - TOL, (v, k)
    return withheld


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_a_granted_reach_claims_s_k_never_meets_a_pedestrians_k_step_reach_on_a_walking_region(seed):
    _granted_are_out_of_reach(*_case(np.random.default_rng(seed)))


def test_the_random_cases_both_withhold_and_grant():
    """The property test is not vacuous: over these cases both outcomes occur."""
    rng = np.random.default_rng(11)
    out = np.concatenate([_granted_are_out_of_reach(*_case(rng)) for _ in range(40)])
    assert 0.1 < out.mean() < 0.9
