"""Go/Stop selection: feasibility, exact optimality vs brute force, optimal vs greedy."""

import itertools

import numpy as np
from hypothesis import given, settings, strategies as st

from tm.selection import components, propagate_stops, select_greedy, select_optimal


@st.composite
def instances(draw, max_n=10):
    """Random requester constraint sets: fixed hits, g_i <= g_j rows and exclusion rows."""
    n = draw(st.integers(1, max_n))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    fixed_hits = (rng.random(n) < draw(st.floats(0, 0.4))) * rng.integers(1, 3, n)
    pairs = np.array([(i, j) for i in range(n) for j in range(n) if i != j], dtype=int).reshape(-1, 2)
    leq = pairs[rng.random(len(pairs)) < draw(st.floats(0, 0.3))]
    excl = pairs[(pairs[:, 0] < pairs[:, 1]) & (rng.random(len(pairs)) < draw(st.floats(0, 0.5)))]
    weights = rng.integers(50, 60, n) if draw(st.booleans()) else np.full(n, 50)
    return n, fixed_hits, leq, excl, weights


def ok(go, fixed_hits, leq, excl):
    """Independent constraint check (plain Python)."""
    return (all(not (g and h > 0) for g, h in zip(go, fixed_hits))
            and all(not (go[i] and not go[j]) for i, j in leq)
            and all(not (go[i] and go[j]) for i, j in excl))


def brute_best(n, fixed_hits, leq, excl, weights):
    return max(sum(w for g, w in zip(go, weights) if g)
               for go in itertools.product([False, True], repeat=n) if ok(go, fixed_hits, leq, excl))


@settings(max_examples=150, deadline=None)
@given(instances(), st.integers(0, 100))
def test_optimal_is_optimal_and_greedy_is_feasible(inst, seed):
    n, fixed_hits, leq, excl, weights = inst
    best = brute_best(*inst)
    for exhaustive_max in (14, 1):                              # 1: every component goes to the MILP
        go = select_optimal(n, fixed_hits, leq, excl, weights, np.random.default_rng(seed), exhaustive_max)
        assert ok(go, fixed_hits, leq, excl)
        assert weights[go].sum() == best
    greedy = select_greedy(n, fixed_hits, leq, excl, np.random.default_rng(seed))
    assert ok(greedy, fixed_hits, leq, excl)


@settings(max_examples=150, deadline=None)
@given(instances(max_n=25), st.integers(0, 100))
def test_optimal_never_stops_more_than_greedy_with_equal_weights(inst, seed):
    n, fixed_hits, leq, excl, _ = inst
    w = np.ones(n, dtype=int)
    opt = select_optimal(n, fixed_hits, leq, excl, w, np.random.default_rng(seed))
    greedy = select_greedy(n, fixed_hits, leq, excl, np.random.default_rng(seed))
    assert ok(opt, fixed_hits, leq, excl) and ok(greedy, fixed_hits, leq, excl)
    assert (~opt).sum() <= (~greedy).sum()


def test_greedy_can_be_strictly_worse():
    """Path 0-1-2-3-4 of exclusions: degrees 1, 2, 2, 2, 1.  Greedy breaks the tie at random:
    stopping 1 (or 3) first ends with 2 stops, stopping 2 first with 3.  Optimal: always 2."""
    excl = np.array([[0, 1], [1, 2], [2, 3], [3, 4]])
    stops = {int((~select_greedy(5, np.zeros(5, int), np.zeros((0, 2), int), excl,
                                  np.random.default_rng(s))).sum()) for s in range(40)}
    assert stops == {2, 3}
    opt = select_optimal(5, np.zeros(5, int), np.zeros((0, 2), int), excl, np.ones(5, int),
                         np.random.default_rng(0))
    assert (~opt).sum() == 2


def test_forced_stops_propagate_through_hold_regions():
    # 0 hits a fixed claim; 1 wants into 0's hold region; 2 into 1's; 3 is free
    leq = np.array([[1, 0], [2, 1]])
    assert propagate_stops([True, False, False, False], leq).tolist() == [True, True, True, False]
    go = select_optimal(4, [1, 0, 0, 0], leq, np.zeros((0, 2), int), np.ones(4, int), np.random.default_rng(0))
    assert go.tolist() == [False, False, False, True]


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 40), st.integers(0, 2**32 - 1), st.floats(0, 0.3), st.floats(0, 0.5))
def test_stop_closure_is_the_fixed_point(n, seed, density, p_stop):
    """Random g_i <= g_j edges (cycles and repeated edges included): the closure is the fixed point of
    "j stopped, so i stops" applied to all edges until nothing changes."""
    rng = np.random.default_rng(seed)
    leq = rng.integers(0, n, size=(int(density * n * n), 2))
    start = rng.random(n) < p_stop
    before, want = start.copy(), start.copy()
    while True:
        add = want[leq[:, 1]] & ~want[leq[:, 0]]
        if not add.any():
            break
        want[leq[add, 0]] = True
    got = propagate_stops(start, leq)
    assert got.dtype == bool and np.array_equal(got, want)
    assert np.array_equal(start, before)                                 # the input is not changed


def _greedy_by_recount(n, fixed_hits, leq, excl, rng):
    """select_greedy as it was: the active degrees recounted after every stop."""
    stopped = np.zeros(n, dtype=bool)
    while True:
        ex = excl[~stopped[excl[:, 0]] & ~stopped[excl[:, 1]]]
        lq = leq[~stopped[leq[:, 0]] & stopped[leq[:, 1]]]
        deg = np.where(stopped, 0, fixed_hits) \
            + np.bincount(ex.ravel(), minlength=n) + np.bincount(lq[:, 0], minlength=n)
        best = deg.max() if n else 0
        if best == 0:
            return ~stopped
        ties = np.flatnonzero(deg == best)
        stopped[ties[rng.integers(len(ties))] if len(ties) > 1 else ties[0]] = True


@settings(max_examples=80, deadline=None)
@given(st.integers(0, 40), st.integers(0, 2**32 - 1), st.floats(0, 0.3), st.floats(0, 0.3), st.floats(0, 0.4))
def test_greedy_equals_the_recount_draw_for_draw(n, seed, d_excl, d_leq, p_fixed):
    """Degrees kept up to date: the same Go set and the same random draws as the recount after every
    stop (random instances with ties, repeated rows, both orders of a pair, forced stops)."""
    rng = np.random.default_rng(seed)
    m = max(n, 1)
    excl = rng.integers(0, m, size=(int(d_excl * n * n), 2))
    excl = excl[excl[:, 0] != excl[:, 1]] if n else excl[:0]
    leq = rng.integers(0, m, size=(int(d_leq * n * n), 2))[: n * n]
    fixed = np.where(rng.random(n) < p_fixed, rng.integers(1, 3, n), 0)
    r1, r2 = np.random.default_rng(seed + 1), np.random.default_rng(seed + 1)
    got = select_greedy(n, fixed, leq, excl, r1)
    assert np.array_equal(got, _greedy_by_recount(n, fixed, leq, excl, r2))
    assert r1.random() == r2.random()                                   # as many draws


def test_same_rng_seed_same_tie_breaks():
    excl = np.array([[i, j] for i in range(6) for j in range(i + 1, 6)])    # a clique: one goes
    runs = [select_optimal(6, np.zeros(6, int), np.zeros((0, 2), int), excl, np.ones(6, int),
                           np.random.default_rng(7)) for _ in range(2)]
    assert np.array_equal(*runs) and runs[0].sum() == 1
    winners = {int(np.flatnonzero(select_optimal(6, np.zeros(6, int), np.zeros((0, 2), int), excl,
                                                 np.ones(6, int), np.random.default_rng(s)))[0])
               for s in range(30)}
    assert len(winners) > 1                                       # ties are not always won by 0


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 40), st.integers(0, 2**32 - 1), st.floats(0, 0.2))
def test_components_match_networkx(n, seed, density):
    import networkx as nx
    rng = np.random.default_rng(seed)
    pairs = np.array([(i, j) for i in range(n) for j in range(i + 1, n)], dtype=int).reshape(-1, 2)
    edges = pairs[rng.random(len(pairs)) < density]
    label = components(n, edges)
    G = nx.Graph()
    G.add_nodes_from(range(n))
    G.add_edges_from(edges.tolist())
    for comp in nx.connected_components(G):
        assert {int(label[v]) for v in comp} == {min(comp)}
