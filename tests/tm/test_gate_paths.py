"""tm/gate_paths.py on its own: which requested stop points lie on another vehicle's route
(:meth:`GatePaths.on_route`, :meth:`GatePaths.on_routes`).  The gate's scenes that use the paths:
tests/tm/test_authority_gate.py, tests/tm/test_ordered_entry.py."""

import numpy as np
import pytest

from tm.authority_reach import AuthorityReach
from tm.gate_paths import GatePaths
from tm.junctions import JunctionFleet

CAR = AuthorityReach(hold=0.25, hold_y=0.2, across=1.0, length=4.0, width=1.8, delta=1.0)
BIKE = AuthorityReach(hold=0.25, hold_y=0.2, across=0.4, length=1.8, width=0.6, delta=0.5)


def _fleet(rng, n):
    """``n`` random routes (10 to 60 waypoints, steps of about 1 m) in a 40 m square, cars and bicycles
    in two parts, at random stop points."""
    routes = []
    for _ in range(n):
        m = int(rng.integers(10, 60))
        W = rng.uniform(-20, 20, 2) + np.cumsum(rng.normal(0.0, 0.7, (m, 2)), axis=0)
        routes.append((W, np.zeros(m), int(rng.integers(0, m))))
    family = np.array(["car" if i % 3 else "bike" for i in range(n)])
    half = n // 2
    parts = tuple(([W for W, _, _ in p], [H for _, H, _ in p], np.array([k for *_, k in p]))
                  for p in (routes[:half], routes[half:]))
    return JunctionFleet([f"v{i}" for i in range(n)], family, np.zeros((n, 2)), np.zeros((n, 2)), parts), routes


@pytest.mark.parametrize("ahead", [0, 1, 5])
def test_on_routes_is_each_pair_within_0_6_delta_of_a_waypoint(ahead):
    """Every pair (row, j): j's stop point ``k + ahead`` (the route's last waypoint at most) within
    ``0.6 δ`` (its class's) of some waypoint of row's route, as a direct loop finds it; and
    :meth:`on_route` of one row gives the same as its pairs."""
    rng = np.random.default_rng(3)
    fleet, routes = _fleet(rng, 14)
    paths = GatePaths({"car": CAR, "bike": BIKE}, spans=None)
    rows = rng.integers(0, 14, 200)
    js = rng.integers(0, 14, 200)
    got = paths.on_routes(fleet, rows, js, ahead)
    want = []
    for r, j in zip(rows.tolist(), js.tolist()):
        Wj, _, kj = routes[j]
        p = Wj[min(kj + ahead, len(Wj) - 1)]
        tol = 0.6 * (CAR if fleet.family[j] == "car" else BIKE).delta
        want.append(bool(np.hypot(*(routes[r][0] - p).T).min() <= tol))
    assert got.tolist() == want
    assert any(want) and not all(want)
    for r in range(14):
        mine = np.flatnonzero(rows == r)
        assert paths.on_route(fleet, r, js[mine], ahead).tolist() == got[mine].tolist()


def test_on_routes_of_no_pairs():
    fleet, _ = _fleet(np.random.default_rng(0), 4)
    paths = GatePaths({"car": CAR, "bike": BIKE}, spans=None)
    assert paths.on_routes(fleet, np.zeros(0, dtype=int), np.zeros(0, dtype=int)).shape == (0,)
    assert paths.on_route(fleet, 1, np.zeros(0, dtype=int)).shape == (0,)


def test_on_routes_of_a_route_with_a_nan_waypoint_is_false_as_a_direct_minimum_makes_it():
    """A NaN waypoint makes a direct minimum distance NaN: no pair on that route counts, even one
    standing on another of its waypoints."""
    fleet, routes = _fleet(np.random.default_rng(1), 4)
    paths = GatePaths({"car": CAR, "bike": BIKE}, spans=None)
    j = np.array([0, 1, 2, 3])
    assert paths.on_routes(fleet, np.zeros(4, dtype=int), j)[0]  # its own stop point
    routes[0][0][3] = np.nan  # the same array, changed in place: measured whole from now on
    paths = GatePaths({"car": CAR, "bike": BIKE}, spans=None)
    assert not paths.on_routes(fleet, np.zeros(4, dtype=int), j).any()


def test_the_route_chunks_are_kept_per_vehicle_while_its_route_is_the_same_array():
    """:meth:`GatePaths._chunks` are kept per vehicle and made anew for a new route array (a vehicle
    whose route changed, or an id used again): a point on the new route counts, one on the old does not."""
    rng = np.random.default_rng(2)
    fleet, routes = _fleet(rng, 4)
    paths = GatePaths({"car": CAR, "bike": BIKE}, spans=None)
    W0 = routes[0][0]
    assert paths.on_routes(fleet, np.array([0]), np.array([0])).tolist() == [True]
    new = W0 + 100.0
    parts = (([new] + [W for W, _, _ in routes[1:2]], [routes[0][1], routes[1][1]], np.array([routes[0][2], routes[1][2]])),
             ([W for W, _, _ in routes[2:]], [H for _, H, _ in routes[2:]], np.array([k for *_, k in routes[2:]])))
    moved = JunctionFleet(fleet.ids, fleet.family, fleet.claim_lo, fleet.claim_hi, parts)
    assert paths.on_routes(moved, np.array([0]), np.array([0])).tolist() == [True]   # its own new stop point
    assert paths.on_routes(moved, np.array([0]), np.array([1])).tolist() == \
        [bool(np.hypot(*(new - routes[1][0][min(routes[1][2], len(routes[1][0]) - 1)]).T).min() <= 0.6)]
    lo, _ = paths._chunks(fleet, "v0", new)
    assert np.array_equal(lo[0], new[:16].min(axis=0))


def test_standing_many_keeps_the_boxes_standing_box_gives():
    """:meth:`GatePaths.standing_many` keeps, for the fleet asked, every row's standing box as the
    floats :meth:`GatePaths.standing_box` gives one row at a time (two classes, padding per row and
    waypoint); a row kept already is left as it is, and a new fleet starts afresh."""
    rng = np.random.default_rng(4)
    fleet, routes = _fleet(rng, 10)
    for r, (W, H, k) in enumerate(routes):
        H[:] = rng.uniform(-np.pi, np.pi, len(H))
    fleet = JunctionFleet(fleet.ids, fleet.family, fleet.claim_lo, fleet.claim_hi, fleet.parts,
                          pads=lambda rows, idx: np.column_stack([0.1 * rows, 0.01 * idx, 0.2 + 0 * rows, 0.3 * (idx % 3)]))
    paths = GatePaths({"car": CAR, "bike": BIKE}, spans=None)
    paths.standing_many(fleet, np.array([3, 1, 3, 7, 0, 9, 2]))
    memo = paths._stand_memo[1]
    assert sorted(memo) == [0, 1, 2, 3, 7, 9]
    for r in memo:
        want = paths.standing_box(fleet, r)
        assert np.array_equal(memo[r][0], want[0]) and np.array_equal(memo[r][1], want[1])
        assert paths.standing(fleet, r) is memo[r]
    kept = memo[3]
    paths.standing_many(fleet, np.array([3, 4]))
    assert paths._stand_memo[1][3] is kept and 4 in paths._stand_memo[1]
    other = JunctionFleet(fleet.ids, fleet.family, fleet.claim_lo, fleet.claim_hi, fleet.parts)
    paths.standing_many(other, np.array([5]))
    assert paths._stand_memo[0] is other and list(paths._stand_memo[1]) == [5]


def _with_stops(fleet, pads):
    """``fleet`` with :attr:`JunctionFleet.stops` taken one row at a time from its routes and ``pads``
    (the reference the whole-fleet tables must match)."""
    def stops(ahead):
        W, Hi, Ho, idx = [], [], [], []
        for r in range(len(fleet.ids)):
            Wr, Hr, k = fleet.route(r)
            i = min(k + ahead, len(Wr) - 1)
            W.append(Wr[i])
            Hi.append(Hr[i])
            Ho.append(Hr[min(i + 1, len(Wr) - 1)])
            idx.append(i)
        rows = np.arange(len(fleet.ids))
        return np.array(W), np.array(Hi), np.array(Ho), pads(rows, np.array(idx))
    return JunctionFleet(fleet.ids, fleet.family, fleet.claim_lo, fleet.claim_hi, fleet.parts, pads=pads,
                         stops=stops)


@pytest.mark.parametrize("seed", range(5))
def test_stop_tables_give_the_boxes_and_routes_row_by_row(seed):
    """:func:`standing_boxes` and :meth:`GatePaths.on_routes` from the fleet's stop tables
    (:attr:`JunctionFleet.stops`) give the floats and answers they give row by row."""
    from tm.gate_paths import standing_boxes

    rng = np.random.default_rng(seed)
    fleet, routes = _fleet(rng, 16)
    for W, H, k in routes:
        H[:] = rng.uniform(-np.pi, np.pi, len(H))

    def pads(rows, idx):
        return np.column_stack([0.1 * rows, 0.01 * idx, 0.2 + 0 * rows, 0.3 * (idx % 3)])
    plain = JunctionFleet(fleet.ids, fleet.family, fleet.claim_lo, fleet.claim_hi, fleet.parts, pads=pads)
    tabled = _with_stops(plain, pads)
    classes = {"car": CAR, "bike": BIKE}
    paths = GatePaths(classes, spans=None)
    for ahead in (0, 1, 3):
        rows = rng.integers(0, 16, 12)
        for a, b in zip(standing_boxes(classes, plain, rows, ahead), standing_boxes(classes, tabled, rows, ahead)):
            assert np.array_equal(a, b)
        rs, js = rng.integers(0, 16, 50), rng.integers(0, 16, 50)
        assert np.array_equal(paths.on_routes(plain, rs, js, ahead), paths.on_routes(tabled, rs, js, ahead))
    assert tabled.stop_table(1) is tabled.stop_table(1)  # asked once per fleet
    bad = JunctionFleet(fleet.ids, fleet.family, fleet.claim_lo, fleet.claim_hi, fleet.parts,
                        stops=lambda ahead: (np.zeros((16, 2)), np.zeros(16), np.zeros(16), -np.ones((16, 4))))
    with pytest.raises(ValueError):
        bad.stop_table(0)
