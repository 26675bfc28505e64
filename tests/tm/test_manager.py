"""Traffic manager: decision semantics (design 3b), invariant, policies, admission.

Independent checks: claim polygons are rebuilt with scipy ConvexHull and
compared by LP (tests/tm/helpers.py); an LP intersection deeper than
VERIFY_TOL = 1e-7 m (HiGHS's feasibility accuracy) is an overlap.  Conflict
edges are compared with the LP only where the LP depth is farther than
1e-6 m from zero (closer, the 1e-9 m touching rule and the LP's accuracy
cannot be told apart).
"""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from tests.tm.helpers import (box, lp_overlapping_pairs, nested_family, random_fleet, ref_claim_polygon)
from tm.geometry import lp_depth
from tm.manager import FleetState, InvariantError, TrafficManager, paper_decision
from tm.monitor import Monitor
from tm.settings import TMSettings

seeds = st.integers(0, 2**32 - 1)


@st.composite
def scenarios(draw, max_vehicles=7):
    rng = np.random.default_rng(draw(seeds))
    families = {f"f{t}": nested_family(rng, int(rng.integers(1, 6)), draw(st.sampled_from(["box", "poly"])))
                for t in range(draw(st.integers(1, 2)))}
    n = draw(st.integers(2, max_vehicles))
    state = random_fleet(rng, families, n, spread=draw(st.floats(2.0, 8.0)), p_request=draw(st.floats(0.3, 1.0)))
    return families, state


def stacked_state(state: FleetState, **changes) -> FleetState:
    fields = {k: getattr(state, k) for k in ("ids", "family", "centre", "index", "heading", "length", "width",
                                             "requesting", "req_centre", "req_index", "req_heading")}
    fields.update(changes)
    return FleetState(**fields)


@settings(max_examples=80, deadline=None)
@given(scenarios(), st.sampled_from(["greedy", "optimal"]), st.sampled_from(["union", "timed"]), seeds)
def test_invariant_and_semantics_on_random_scenarios(scenario, policy, check, seed):
    families, state = scenario
    tm = TrafficManager(TMSettings(policy=policy, check=check, seed=seed % 1000), families)
    d = tm.decide(state)
    req = state.requesting
    # only requesters are granted; non-requesters never stopped and keep their claims
    assert not np.any(d.go & ~req)
    assert set(d.stopped) == {state.ids[v] for v in np.flatnonzero(req & ~d.go)}
    keep = ~d.go
    assert np.array_equal(d.claims.centre[keep], state.centre[keep])
    assert np.array_equal(d.claims.index[keep], state.index[keep])
    assert np.array_equal(d.claims.centre[d.go], state.req_centre[d.go])
    assert np.array_equal(d.claims.index[d.go], state.req_index[d.go])
    # the invariant, by LP on reference polygons
    assert lp_overlapping_pairs(families, list(state.family), d.claims, check) == []
    # the conflict edges are the LP conflicts of every new claim (union check, nested: k = 1)
    if check == "union":
        edges = {(int(u), int(v), k) for (u, v), k in zip(d.edges, d.edge_kinds)}
        for i in np.flatnonzero(req):
            fam_i = families[state.family[i]]
            new_i = ref_claim_polygon(fam_i, state.req_centre[i], max(state.req_index[i] - 1, 0),
                                      state.req_heading[i], state.length[i], state.width[i])
            for j in range(len(state)):
                if j == i:
                    continue
                fam_j = families[state.family[j]]
                old_j = ref_claim_polygon(fam_j, state.centre[j], max(state.index[j] - 1, 0), state.heading[j],
                                          state.length[j], state.width[j])
                kind = "new-old" if req[j] else "new-fixed"
                depth = lp_depth(new_i, old_j)
                if abs(depth) > 1e-6:
                    assert ((i, j, kind) in edges) == (depth > 0)
                if req[j] and j > i:
                    new_j = ref_claim_polygon(fam_j, state.req_centre[j], max(state.req_index[j] - 1, 0),
                                              state.req_heading[j], state.length[j], state.width[j])
                    depth = lp_depth(new_i, new_j)
                    if abs(depth) > 1e-6:
                        assert ((i, j, "new-new") in edges or (j, i, "new-new") in edges) == (depth > 0)


@settings(max_examples=60, deadline=None)
@given(scenarios(max_vehicles=10), seeds)
def test_union_and_timed_decide_alike_on_nested_families(scenario, seed):
    """With nested families the timed check (all k) reduces to k = 1, which is the union
    claim: both must give identical decisions and conflict graphs.  Fails if nesting (or
    either code path) is broken; see test_timed_differs_without_nesting for the converse."""
    families, state = scenario
    for policy in ("greedy", "optimal"):
        a = TrafficManager(TMSettings(policy=policy, check="union", seed=seed % 1000), families).decide(state)
        b = TrafficManager(TMSettings(policy=policy, check="timed", seed=seed % 1000), families).decide(state)
        assert np.array_equal(a.go, b.go)
        assert {tuple(e) + (k,) for e, k in zip(a.edges.tolist(), a.edge_kinds)} == \
               {tuple(e) + (k,) for e, k in zip(b.edges.tolist(), b.edge_kinds)}


@settings(max_examples=60, deadline=None)
@given(scenarios(max_vehicles=10), seeds)
def test_optimal_stops_no_more_than_greedy(scenario, seed):
    families, state = scenario            # fresh managers: all waits 0, equal weights
    opt = TrafficManager(TMSettings(policy="optimal", seed=seed % 1000), families).decide(state)
    greedy = TrafficManager(TMSettings(policy="greedy", seed=seed % 1000), families).decide(state)
    assert len(opt.stopped) <= len(greedy.stopped)


def test_timed_differs_without_nesting():
    """Non-nested family (vertical bar, then horizontal bar): the union claim of a (l = 2) is
    the hull of the cross (edge x + y = 3.2), the timed claims are the bars.  b asks to move
    from (2.5, 2.5) (outside the hull) to (1.5, 1.6) (inside the hull, off both bars): union
    denies it, timed grants it; likewise admission of a vehicle at (1.5, 1.5)."""
    families = {"cross": [box(0.2, 3.0), box(3.0, 0.2), box(3.0, 3.0)], "dot": [box(0.1, 0.1)]}
    state = FleetState(ids=["a", "b"], family=["cross", "dot"], centre=[[0, 0], [2.5, 2.5]], index=[2, 0],
                       heading=[0, 0], length=[0.1, 0.1], width=[0.1, 0.1], requesting=[False, True],
                       req_centre=[[0, 0], [1.5, 1.6]], req_index=[0, 0], req_heading=[0, 0])
    union = TrafficManager(TMSettings(check="union", verify=True), families)
    timed = TrafficManager(TMSettings(check="timed", verify=True), families)
    assert union.decide(state).go.tolist() == [False, False]
    assert timed.decide(state).go.tolist() == [False, True]
    cand = FleetState(ids=["c"], family=["dot"], centre=[[1.5, 1.5]], index=[0], heading=[0], length=[0.1],
                      width=[0.1])
    assert union.admit(state, cand).tolist() == [False]
    assert timed.admit(state, cand).tolist() == [True]


def _line_state(xs, index, requesting, req_xs, req_index, length=1.0, width=1.0):
    n = len(xs)
    return FleetState(ids=[f"v{t}" for t in range(n)], family=["car"] * n,
                      centre=np.c_[xs, np.zeros(n)], index=index, heading=np.zeros(n),
                      length=np.full(n, length), width=np.full(n, width), requesting=requesting,
                      req_centre=np.c_[req_xs, np.zeros(n)], req_index=req_index, req_heading=np.zeros(n))


def test_paper_graph_grants_a_tube_into_a_stopped_vehicles_hold_region():
    """i (x = 0) asks for x = 5, where non-requester k sits: i must stop.  j (x = -5) asks
    for x = 0, i's hold region; new_j misses new_i.  The paper's graph has only the edge
    (i, k): it stops i and grants j into i's hold region.  muvsim's graph has the new-old
    edge (j, i) and stops j too; its claims stay disjoint."""
    families = {"car": [box(0.5, 0.5), box(1.0, 1.0)]}
    state = _line_state([0.0, -5.0, 5.0], index=[0, 0, 0], requesting=[True, True, False],
                        req_xs=[5.0, 0.0, 0.0], req_index=[1, 1, 0])
    paper = paper_decision(families, state)
    assert paper.go.tolist() == [False, True, False]
    assert sorted(paper.graph.edges) == [("v0", "v2")]
    assert lp_overlapping_pairs(families, ["car"] * 3, paper.claims, "union") == [(0, 1)]

    d = TrafficManager(TMSettings(verify=True), families).decide(state)
    assert d.go.tolist() == [False, False, False] and d.forced.tolist() == [True, True, False]
    assert d.graph.edges["v1", "v0"]["kind"] == "new-old" and d.graph.edges["v1", "v0"]["new_old"] == ["v1"]
    assert d.graph.edges["v0", "v2"]["kind"] == "new-fixed"
    assert lp_overlapping_pairs(families, ["car"] * 3, d.claims, "union") == []


def test_graph_edge_kinds_and_nodes():
    """v0 and v1 both ask for the midpoint between them (new-new, and each new claim meets
    the other's hold region); v2 asks into non-requester v3."""
    families = {"car": [box(0.5, 0.5)]}
    state = _line_state([0.0, 3.0, 20.0, 23.0], index=[0] * 4, requesting=[True, True, True, False],
                        req_xs=[1.5, 1.5, 23.0, 0.0], req_index=[0] * 4)
    d = TrafficManager(TMSettings(), families).decide(state)
    G = d.graph
    assert sorted(G.nodes) == ["v0", "v1", "v2", "v3"]
    assert G.edges["v0", "v1"]["kinds"] == {"new-new", "new-old"} and G.edges["v0", "v1"]["kind"] == "new-new"
    assert sorted(G.edges["v0", "v1"]["new_old"]) == ["v0", "v1"]
    assert G.edges["v2", "v3"]["kind"] == "new-fixed"
    assert d.go.tolist() == [False, False, False, False]   # g0 <= g1 <= g0 and g0 + g1 <= 1


def test_chain_of_requests_moves_together():
    """v0 asks into v1's place, v1 into v2's, v2 into free space: all may go at once
    (g_0 <= g_1 <= g_2), and optimal grants all three."""
    families = {"car": [box(0.5, 0.5)]}
    state = _line_state([0.0, 3.0, 6.0], index=[0] * 3, requesting=[True] * 3, req_xs=[3.0, 6.0, 9.0],
                        req_index=[0] * 3)
    for policy in ("optimal", "greedy"):
        d = TrafficManager(TMSettings(policy=policy, verify=True), families).decide(state)
        assert d.go.all()


def test_same_seed_same_decisions_over_a_sequence():
    rng = np.random.default_rng(3)
    families = {"car": nested_family(rng, 4, "box")}
    states = [random_fleet(rng, families, 10, spread=4.0, p_request=1.0) for _ in range(6)]
    for policy in ("greedy", "optimal"):
        runs = []
        for _ in range(2):
            tm = TrafficManager(TMSettings(policy=policy, seed=11), families)
            runs.append([tm.decide(s).go for s in states])
        assert all(np.array_equal(a, b) for a, b in zip(*runs))


def _starvation_state():
    """A (v0) asks for the crossing at (0, 0); B (v1) and C (v2) ask for places each of which
    meets A's new claim but not each other's; B and C re-request every step (a stream)."""
    return FleetState(ids=["A", "B", "C"], family=["car"] * 3,
                      centre=[[0.0, -6.0], [-6.0, 1.0], [6.0, 1.0]], index=[0, 0, 0], heading=[0, 0, 0],
                      length=[1.0] * 3, width=[1.0] * 3, requesting=[True, True, True],
                      req_centre=[[0.0, 0.0], [-1.2, 1.0], [1.2, 1.0]], req_index=[0, 0, 0],
                      req_heading=[0, 0, 0])


def test_starvation_bound_of_the_optimal_policy():
    """Optimal: A's weight H + waited beats B + C (2H) once waited > H, i.e. A is granted at
    step H + 2 at the latest (at step H + 1 the weights tie and the seed decides).  Greedy
    stops the degree-2 vehicle A forever."""
    H = 5
    families = {"car": [box(0.5, 0.5)]}
    state = _starvation_state()
    for seed in range(4):
        tm = TrafficManager(TMSettings(starvation_horizon=H, seed=seed), families)
        first = next(step for step in range(1, 3 * H) if tm.decide(state).go[0])
        assert H + 1 <= first <= H + 2
        assert tm.waited("A") == 0 and tm.waited("B") == 1
    tm = TrafficManager(TMSettings(policy="greedy", starvation_horizon=H), families)
    assert not any(tm.decide(state).go[0] for _ in range(3 * H))
    assert tm.waited("A") == 3 * H


def test_waits_reset_when_not_requesting_and_weights_are_reported():
    families = {"car": [box(0.5, 0.5)]}
    state = _starvation_state()
    tm = TrafficManager(TMSettings(starvation_horizon=50), families)
    tm.decide(state)
    d = tm.decide(state)
    assert d.waited.tolist() == [1, 0, 0] and tm.waited("A") == 2
    tm.decide(stacked_state(state, requesting=[False, True, True]))
    assert tm.waited("A") == 0


def test_admission_is_sequential_and_respects_current_claims():
    families = {"car": [box(0.5, 0.5), box(1.0, 1.0)]}
    tm = TrafficManager(TMSettings(), families)
    current = _line_state([0.0], [1], [False], [0.0], [0])
    cand = FleetState(ids=["c0", "c1", "c2", "c3"], family=["car"] * 4,
                      centre=[[1.5, 0.0], [10.0, 0.0], [11.0, 0.0], [20.0, 0.0]], index=[0, 0, 0, 0],
                      heading=[0, 0, 0, 0], length=[1.0] * 4, width=[1.0] * 4)
    # c0 meets v0; c2 meets c1 (admitted before it); c3 is free
    assert tm.admit(current, cand).tolist() == [False, True, False, True]
    # against the claims after a decision: v0's granted move to x = 20 blocks c3
    moved = _line_state([0.0], [0], [True], [20.0], [0])
    d = tm.decide(moved)
    assert d.go.tolist() == [True]
    assert tm.admit(d.claims, cand).tolist() == [True, True, False, False]


def test_verify_raises_on_an_invalid_input_state():
    families = {"car": [box(1.0, 1.0)]}
    overlapping = _line_state([0.0, 1.0], [0, 0], [False, False], [0.0, 0.0], [0, 0])
    with pytest.raises(InvariantError, match="v0"):
        TrafficManager(TMSettings(verify=True), families).decide(overlapping)
    TrafficManager(TMSettings(verify=False), families).decide(overlapping)     # not checked: no raise


def test_state_validation_names_the_problem():
    families = {"car": [box(1.0, 1.0)]}
    tm = TrafficManager(TMSettings(), families)
    with pytest.raises(ValueError, match="'v1'.*index 3"):
        tm.decide(_line_state([0.0, 9.0], [0, 3], [False, False], [0.0, 0.0], [0, 0]))
    with pytest.raises(ValueError, match="'v0'.*requested index 2"):
        tm.decide(_line_state([0.0, 9.0], [0, 0], [True, False], [0.0, 0.0], [2, 0]))
    with pytest.raises(ValueError, match="unique"):
        FleetState(ids=["a", "a"], family=["car"] * 2, centre=np.zeros((2, 2)), index=[0, 0],
                   heading=[0, 0], length=[1, 1], width=[1, 1])
    with pytest.raises(ValueError, match="req_centre"):
        FleetState(ids=["a"], family=["car"], centre=np.zeros((1, 2)), index=[0], heading=[0], length=[1],
                   width=[1], requesting=[True])
    with pytest.raises(ValueError, match="centre.*shape"):
        FleetState(ids=["a"], family=["car"], centre=np.zeros(2), index=[0], heading=[0], length=[1], width=[1])
    with pytest.raises(TypeError, match="TMSettings"):
        TrafficManager({"policy": "greedy"}, families)


@settings(max_examples=12, deadline=None)
@given(seeds, st.sampled_from(["greedy", "optimal"]), st.sampled_from(["union", "timed"]))
def test_multi_step_random_walk_keeps_the_invariant(seed, policy, check):
    """Vehicles follow straight routes of waypoints delta apart; indices decrease by one per
    step; a vehicle whose index is at most 1 requests the next waypoint with a random index;
    on Go it takes the new claim.  New vehicles are admitted at random places.  After every
    step: LP invariant on reference polygons, and the monitor finds no claim violation."""
    rng = np.random.default_rng(seed)
    families = {"car": nested_family(rng, 4, "box"), "bus": nested_family(rng, 3, "poly")}
    state = random_fleet(rng, families, 6, spread=6.0)
    direction = rng.uniform(-np.pi, np.pi, size=len(state))
    ids, fam = list(state.ids), list(state.family)
    centre, index = state.centre.copy(), state.index.copy()
    heading, length, width = state.heading.copy(), state.length.copy(), state.width.copy()
    tm = TrafficManager(TMSettings(policy=policy, check=check, seed=seed % 1000, verify=True), families)
    monitor = Monitor(check)
    delta = 1.5
    for step in range(8):
        V = len(ids)
        n_levels = np.array([len(families[f]) for f in fam])
        requesting = index <= 1
        req_centre = centre + delta * np.c_[np.cos(direction), np.sin(direction)]
        st_ = FleetState(ids=ids, family=fam, centre=centre, index=index, heading=heading, length=length,
                         width=width, requesting=requesting, req_centre=req_centre,
                         req_index=(rng.random(V) * n_levels).astype(int), req_heading=direction)
        d = tm.decide(st_)
        assert lp_overlapping_pairs(families, fam, d.claims, check) == []
        assert monitor.step(ids, d.claims.centre, d.claims.heading, length, width, d.claims).claim_violations == 0
        centre, heading = d.claims.centre.copy(), d.claims.heading.copy()
        index = np.where(d.go, d.claims.index, np.maximum(d.claims.index - 1, 0))
        # one candidate per step at a random place
        key = ["car", "bus"][int(rng.integers(2))]
        cand = FleetState(ids=[f"n{step}"], family=[key], centre=rng.uniform(-6, 6, size=(1, 2)),
                          index=[int(rng.integers(len(families[key])))], heading=[rng.uniform(-3, 3)],
                          length=[rng.uniform(0.5, 3)], width=[rng.uniform(0.3, 1.5)])
        current = FleetState(ids=ids, family=fam, centre=centre, index=index, heading=heading,
                             length=length, width=width)
        if tm.admit(current, cand)[0]:
            ids.append(cand.ids[0])
            fam.append(key)
            centre = np.vstack([centre, cand.centre])
            index = np.append(index, cand.index)
            heading = np.append(heading, cand.heading)
            length = np.append(length, cand.length)
            width = np.append(width, cand.width)
            direction = np.append(direction, rng.uniform(-np.pi, np.pi))
    assert monitor.steps == 8 and monitor.claim_violations == 0
