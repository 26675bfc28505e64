"""Stop points never rest on a crossing (tm.crossing_gate), without a simulator.

The scene: a road along x (y = 0), waypoints 1 m apart from x = -40 to 40 (the waypoint ``c`` is
the vehicle's stop point), a crossing over it at x in [-2, 2], y in [-3.5, 3.5] (the road's
width), and one pedestrian walking south on the crossing's centre line.

A toy movement-authority car stands in for the controller and the reach claims: speed at most
8 m/s, input within ±3 m/s² (no disturbance); it tracks ``min(v̄, sqrt(2 a_c (c - s)))``
(``a_c`` = 2 m/s²), so it comes to rest at its stop point when denied; its box ``S_k`` runs from
where it is after ``k`` steps of full braking to where it is after ``k`` steps of full throttle,
cut at ``c + T^0``, plus the footprint (4 m x 1.8 m; ``T^0`` within 0.25 m along, 0.2 m across);
its index ``l`` is the steps it needs to come to rest at ``c`` (at most ``N`` = 40).  It asks for
``c + 1`` while ``c`` is less than a braking distance plus 2 m ahead.

The pedestrian behaves as SUMO's persons do: it walks at 1.3 m/s but does not step onto the
crossing while a car's footprint is on it (SUMO's persons wait for a vehicle standing on their
crossing; they do not yield to an approaching one moved by ``moveToXY``).

The pedestrian rule (:class:`tm.pedestrians.PedestrianRule`, reach ``0.2 + 0.3 + 2.0 (k + 1) 0.1``)
alone lets the stop point move onto the crossing while the pedestrian is far, then withholds the
next requests as the pedestrian comes near: the car stands on the crossing, the pedestrian waits
for it, neither moves again (the deadlock of issue 12).  With the crossing gate the stop point
stays before the crossing until the car can clear it, and both arrive.
"""

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings, strategies as st

from tm.authority_reach import AuthorityReach
from tm.crossing_gate import CrossingGate
from tm.pedestrians import PedestrianRule, PedestrianSettings
from tm.reach import ReachClaims

TS = 0.1
CAR = AuthorityReach(hold=0.25, hold_y=0.2, across=1.0, length=4.0, width=1.8, delta=1.0)
CROSSING = np.array([[-2.0, -3.5], [2.0, -3.5], [2.0, 3.5], [-2.0, 3.5]])
PEDS = PedestrianSettings(v_max=2.0, radius=0.2, lag_steps=1, jump_m=0.3)
N = 40
V_MAX, U_MAX, A_C = 8.0, 3.0, 2.0
W = np.column_stack([np.arange(-40.0, 41.0), np.zeros(81)])
H = np.zeros(81)
#: hold box half extents: 0.25 + 2 along, 0.2 + 0.9 across; the crossing's run is the waypoints
#: whose hold box meets x in [-2, 2]: x in [-4, 4] (|x| - 2.25 <= 2), indices 36 .. 44, exit 45
ENTRY, EXIT = 36, 45


def claims(s: float, v: float, c: float) -> tuple[ReachClaims, int]:
    """The toy car's claim (slots 1 .. N + 2, the last one at rest at ``c``) and index for stop point ``c``."""
    K = N + 2
    t = TS * np.arange(1, K + 1)
    stop = v / U_MAX
    lo = s + np.where(t < stop, v * t - 0.5 * U_MAX * t ** 2, 0.5 * v * stop)
    hi = np.minimum(s + v * t + 0.5 * U_MAX * t ** 2, c + CAR.hold)
    lo, hi = np.minimum(lo, c + CAR.hold), np.maximum(hi, lo)
    lo[-1], hi[-1] = c - CAR.hold, c + CAR.hold
    half_y = CAR.hold_y + 0.5 * CAR.width
    box_lo = np.column_stack([lo - 0.5 * CAR.length, np.full(K, -half_y)])
    box_hi = np.column_stack([hi + 0.5 * CAR.length, np.full(K, half_y)])
    d = max(c - s, 0.0)
    l = 0 if d < 1e-3 and v < 1e-3 else min(N, math.ceil((2.0 * math.sqrt(d / A_C) + v / U_MAX) / TS))
    return ReachClaims(np.zeros((1, 2)), np.zeros(1), box_lo[None], box_hi[None]), l


def run(gate_on: bool, ped_y0: float, steps: int = 600):
    """The scene for ``steps``; returns (car at its last waypoint, pedestrian across, steps the car
    stood with its footprint on the crossing, requests denied while its stop point was on the crossing)."""
    rule = PedestrianRule(PEDS, [CROSSING], TS)
    gate = CrossingGate([CROSSING], {"car": CAR}, {"car": N + rule.hold_steps}, rule)
    s, v, c = -40.0, V_MAX, 0                      # position, speed, stop point (index)
    ped = np.array([0.0, ped_y0])
    stood = denied_on = 0
    for _ in range(steps):
        peds = ped[None] if ped[1] > -20.0 else np.zeros((0, 2))
        if c + 1 < len(W) and W[c, 0] - s < v * v / (2 * A_C) + 2.0:
            new, l_req = claims(s, v, W[c + 1, 0])
            go = not rule.withhold_reach(new, [l_req], peds)[0]
            if go and gate_on:
                cur, _ = claims(s, v, W[c, 0])
                b = cur.slot_boxes[:, 0, -1]
                go = not gate.withhold(["car"], ["car"], [(W, H, c)], [True], peds,
                                       np.array([[b[0], b[2]]]), np.array([[b[1], b[3]]]))[0]
            denied_on += int(not go and ENTRY <= c < EXIT)
            c += int(go)
        v_des = min(V_MAX, math.sqrt(2 * A_C * max(W[c, 0] - s, 0.0)))
        v = max(v + TS * float(np.clip((v_des - v) / TS, -U_MAX, U_MAX)), 0.0)
        s = min(s + v * TS, W[c, 0])
        on = abs(s) - 0.5 * CAR.length <= 2.0
        stood += int(on and v < 1e-6)
        # the pedestrian does not step onto the crossing while the car is on it
        nxt = ped[1] - 1.3 * TS
        if not (on and ped[1] >= 3.5 > nxt):
            ped[1] = nxt
        if c == len(W) - 1 and s > W[-1, 0] - 0.1 and ped[1] < -20.0:   # both through
            break
    return bool(c == len(W) - 1 and s > W[-1, 0] - 0.1), bool(ped[1] < -3.5), stood, denied_on


def test_the_run_over_the_crossing_is_found():
    rule = PedestrianRule(PEDS, [CROSSING], TS)
    gate = CrossingGate([CROSSING], {"car": CAR}, {"car": N}, rule)
    entry, exit_, exits, regions = gate.runs("car", "car", W, H)
    assert entry.tolist() == [ENTRY] and exit_.tolist() == [EXIT] and exits.tolist() == [True]
    assert [r.tolist() for r in regions] == [[0]]


@pytest.mark.parametrize("ped_y0", [14.0, 14.5, 15.0])
def test_without_the_gate_the_car_stops_on_the_crossing_and_both_wait_for_good(ped_y0):
    """Today's behaviour (the pedestrian rule alone): the deadlock, not vacuous for the test below."""
    car, ped, stood, _ = run(gate_on=False, ped_y0=ped_y0)
    assert not car and not ped and stood > 300


@pytest.mark.parametrize("ped_y0", np.arange(4.0, 30.0, 2.0).tolist() + [13.5, 14.5, 15.0])
def test_with_the_gate_the_stop_point_never_rests_on_the_crossing_and_both_arrive(ped_y0):
    car, ped, stood, denied_on = run(gate_on=True, ped_y0=ped_y0)
    assert car and ped and stood == 0
    assert denied_on == 0                    # once on the crossing, no request of the passage was withheld


# ------------------------------------------------------------------ each entry condition on its own
def _entry(peds=np.zeros((0, 2)), k=ENTRY - 1, others=(), limit=None, route=(W, H)):
    """Is the request of a car at stop point ``k`` withheld?  ``others``: standing boxes (lo, hi)
    of other vehicles (the car's own box is inverted: it meets nothing)."""
    rule = PedestrianRule(PEDS, [CROSSING], TS)
    gate = CrossingGate([CROSSING], {"car": CAR}, {"car": N + rule.hold_steps}, rule)
    ids = ["car"] + [f"o{j}" for j in range(len(others))]
    lo = np.array([[np.inf, np.inf]] + [o[0] for o in others], dtype=float)
    hi = np.array([[-np.inf, -np.inf]] + [o[1] for o in others], dtype=float)
    routes = [(route[0], route[1], k)] + [(W, H, 0)] * len(others)
    req = np.array([True] + [False] * len(others))
    out = gate.withhold(ids, ["car"] * len(ids), routes, req, np.asarray(peds, float).reshape(-1, 2), lo, hi,
                        None if limit is None else (lambda i: limit))
    return bool(out[0]), gate


#: the gate's pedestrian threshold for this run: reach(H) + jump with H = (EXIT - ENTRY) + N = 49:
#: 0.2 + 0.3 + 2.0 (49 + 1) 0.1 + 0.3 = 10.8 m from the crossing
THRESHOLD = 10.8


@pytest.mark.parametrize("d, withheld", [(THRESHOLD - 0.05, True), (THRESHOLD + 0.05, False)])
def test_entry_waits_for_pedestrians_within_the_passage_reach(d, withheld):
    """0.05 m either side of the threshold (coordinates of O(10) m, round-off ~1e-14)."""
    assert _entry(peds=[[0.0, 3.5 + d]])[0] is withheld


@pytest.mark.parametrize("y0, withheld", [(1.5, True), (2.5, False)])
def test_entry_counts_a_walking_area_beside_the_run_that_its_claims_reach(y0, withheld):
    """A walking area at x in [2.5, 6], y in [y0, 4] beside the road past the crossing: the run's
    claim boxes (across 1.0 + 0.9 = 1.9 m) meet it for y0 = 1.5, not for 2.5 (hold boxes reach 1.1 m:
    it is in no run either way).  A pedestrian 10.3 m north of it is within the threshold of it
    (10.8 m) but not of the crossing (hypot(2.25, 10.8) = 11.03 m): withheld only when the claims
    reach the walking area."""
    walk = np.array([[2.5, y0], [6.0, y0], [6.0, 4.0], [2.5, 4.0]])
    rule = PedestrianRule(PEDS, [CROSSING, walk], TS)
    gate = CrossingGate([CROSSING], {"car": CAR}, {"car": N + rule.hold_steps}, rule)
    out = gate.withhold(["car"], ["car"], [(W, H, ENTRY - 1)], [True], np.array([[4.25, 4.0 + 10.3]]),
                        np.full((1, 2), np.inf), np.full((1, 2), -np.inf))
    assert out.tolist() == [withheld]


def test_entry_needs_room_at_the_exit():
    x = W[EXIT, 0]
    on_exit = ((x + 2.0, -1.0), (x + 6.0, 1.0))           # meets the exit's hold box [x - 2.25, x + 2.25]
    past = ((x + 2.5, -1.0), (x + 6.0, 1.0))
    assert _entry(others=[on_exit])[0] and not _entry(others=[past])[0]


def test_entry_needs_the_junction_tokens_up_to_the_exit():
    assert _entry(limit=EXIT - 1)[0] and not _entry(limit=EXIT)[0]


def test_no_entry_onto_a_crossing_where_the_route_ends():
    assert _entry(route=(W[:ENTRY + 4], H[:ENTRY + 4]))[0]


def test_only_entries_are_withheld_and_counted():
    """Inside the run (k >= ENTRY) and before it (k + 1 < ENTRY) nothing is withheld, whoever is near."""
    near = [[0.0, 4.0]]
    assert _entry(peds=near)[0]
    for k in (ENTRY - 5, ENTRY - 2, ENTRY, EXIT - 1, EXIT + 3):
        assert not _entry(peds=near, k=k)[0], k
    withheld, gate = _entry(peds=near)
    assert withheld and gate.withheld == 1


def test_with_the_pedestrian_rule_off_the_gate_is_off():
    rule = PedestrianRule(PedestrianSettings(enabled=False), [CROSSING], TS)
    gate = CrossingGate([CROSSING], {"car": CAR}, {"car": N}, rule)
    out = gate.withhold(["car"], ["car"], [(W, H, ENTRY - 1)], [True], np.array([[0.0, 4.0]]),
                        np.full((1, 2), np.inf), np.full((1, 2), -np.inf))
    assert out.tolist() == [False]


def test_bad_inputs_are_named():
    rule = PedestrianRule(PEDS, [CROSSING], TS)
    with pytest.raises(ValueError, match="crossing 1"):
        CrossingGate([CROSSING, np.zeros((2, 2))], {"car": CAR}, {"car": N}, rule)
    with pytest.raises(ValueError, match="horizon: no entry for class"):
        CrossingGate([CROSSING], {"car": CAR}, {}, rule)
    with pytest.raises(TypeError, match="rule"):
        CrossingGate([CROSSING], {"car": CAR}, {"car": N}, None)
    gate = CrossingGate([CROSSING], {"car": CAR}, {"car": N}, rule)
    with pytest.raises(ValueError, match="one each per vehicle"):
        gate.withhold(["car"], ["car"], [], [True], np.zeros((0, 2)), np.zeros((1, 2)), np.zeros((1, 2)))


SIDES = {"w": (np.array([-2.0, 0.0]), np.array([-1.0, 0.0])), "e": (np.array([2.0, 0.0]), np.array([1.0, 0.0])),
         "n": (np.array([0.0, 3.5]), np.array([0.0, 1.0])), "s": (np.array([0.0, -3.5]), np.array([0.0, -1.0]))}


@settings(max_examples=400, deadline=None)
@given(side=st.sampled_from(sorted(SIDES)), off=st.floats(-1.0, 1.0), D=st.floats(THRESHOLD - 0.5, THRESHOLD + 1.0),
       j=st.one_of(st.just(EXIT - ENTRY), st.integers(0, EXIT - ENTRY)),
       frac=st.one_of(st.just(1.0), st.floats(0.0, 1.0)), l=st.one_of(st.just(N), st.integers(0, N)),
       full=st.booleans(), seed=st.integers(0, 2 ** 31 - 1))
def test_a_pedestrian_the_gate_let_pass_cannot_withhold_a_request_of_the_passage(side, off, D, j, frac, l, full, seed):
    """The liveness argument of the module notes as a property: when the gate grants the entry with
    a pedestrian at ``p`` (D m out from a side of the crossing, offset ``off`` along it: on the road
    behind or ahead of the car, or beside it), then ``j <= EXIT - ENTRY`` steps later that
    pedestrian, moved straight towards the crossing by up to ``v j Ts + jump_m`` (the bound the rule
    assumes), does not make the pedestrian rule withhold any claim whose boxes lie in the run's claim
    boxes (waypoints ENTRY .. EXIT, ``claim_half``), whatever its index ``l <= N``: every box the
    whole of them (``full``) or random sub-boxes, some empty.  Pedestrians the gate withholds for
    are skipped (``D`` spans the threshold on both sides)."""
    walk = np.array([[2.5, 1.5], [6.0, 1.5], [6.0, 4.0], [2.5, 4.0]])   # beside the run (test above)
    rule = PedestrianRule(PEDS, [CROSSING, walk], TS)
    gate = CrossingGate([CROSSING], {"car": CAR}, {"car": N + rule.hold_steps}, rule)
    edge, out = SIDES[side]
    p0 = (edge + D * out + off * out[::-1])[None]
    entry = gate.withhold(["car"], ["car"], [(W, H, ENTRY - 1)], [True], p0, np.full((1, 2), np.inf),
                          np.full((1, 2), -np.inf))[0]
    assume(not entry)
    p1 = p0 - frac * (PEDS.v_max * j * TS + PEDS.jump_m) * out
    half = CAR.claim_half(np.zeros(1))[0]                               # 2.25 along, 1.9 across
    c_lo, c_hi = np.array([W[ENTRY, 0] - half[0], -half[1]]), np.array([W[EXIT, 0] + half[0], half[1]])
    K = N + 2
    if full:
        lo, hi = np.tile(c_lo, (K, 1)), np.tile(c_hi, (K, 1))
    else:
        rng = np.random.default_rng(seed)
        a, b = rng.uniform(c_lo, c_hi, (K, 2)), rng.uniform(c_lo, c_hi, (K, 2))
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        empty = rng.random(K) < 0.2
        lo[empty], hi[empty] = 1.0, 0.0
    claim = ReachClaims(np.zeros((1, 2)), np.zeros(1), lo[None], hi[None])
    assert not rule.withhold_reach(claim, [l], p1)[0]


@pytest.mark.parametrize("slack, withheld", [(0.01, False), (-0.01, True)])
def test_the_threshold_is_tight_for_a_pedestrian_walking_up_the_road(slack, withheld):
    """A pedestrian on the road behind the car, THRESHOLD + slack m west of the crossing: the gate
    lets the car enter (slack 0.01 m) and then, after EXIT - ENTRY steps walking east at the bound
    (v j Ts + jump_m = 2.1 m), the pedestrian rule does not withhold a claim of index N over the run's
    claim boxes; 0.02 m closer it would (the reach it then has is 8.7 m = reach(N)): the gate's
    threshold has no slack to spare.  (0.01 m: far above round-off of O(10) m sums, ~1e-14.)"""
    rule = PedestrianRule(PEDS, [CROSSING], TS)
    gate = CrossingGate([CROSSING], {"car": CAR}, {"car": N + rule.hold_steps}, rule)
    p0 = np.array([[-2.0 - THRESHOLD - slack, 0.0]])
    entry = gate.withhold(["car"], ["car"], [(W, H, ENTRY - 1)], [True], p0, np.full((1, 2), np.inf),
                          np.full((1, 2), -np.inf))[0]
    assert entry is np.bool_(withheld)
    p1 = p0 + np.array([[PEDS.v_max * (EXIT - ENTRY) * TS + PEDS.jump_m, 0.0]])
    half = CAR.claim_half(np.zeros(1))[0]
    lo = np.tile([W[ENTRY, 0] - half[0], -half[1]], (N + 2, 1))
    hi = np.tile([W[EXIT, 0] + half[0], half[1]], (N + 2, 1))
    claim = ReachClaims(np.zeros((1, 2)), np.zeros(1), lo[None], hi[None])
    assert rule.withhold_reach(claim, [N], p1)[0] == withheld
