"""The junction liveness layer (tm.junctions) without a simulator: each rule on its own.

Every test builds a :class:`JunctionFleet` by hand: straight routes with waypoints 1 m apart,
each vehicle's current claim box its waypoint ± the class's largest claim half extent, and the
box its request would claim the same around the next waypoint.  Geometry is exact (box
comparisons of the same floats); the offsets between boxes are at least 0.4 m, far from
round-off.

The class (``CAR``): ``max |P^0|`` = 1 m, ``P^{N-1}`` within 3 m along and 0.5 m across the
road, ``max |P^N|`` = 4 m, footprint 4.5 m x 1.8 m, road frame.  Its largest claim spans
±5.25 m along and ±1.4 m across; its hold radius is 1 + hypot(4.5, 1.8) / 2 = 3.42 m; the
guard of the 10 m junction ``J`` at the origin is the zone enlarged by
4 + hypot(4.5, 1.8) / 2 = 6.42 m: [-11.42, 11.42]^2.  Lanes are 3.2 m apart, so the corridors
of opposite straight streams ([-3.0, -0.2] and [0.2, 3.0] across) are apart.
"""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from tm.boxes import boxes_meet
from tm.junctions import ClassReach, JunctionFleet, JunctionGate, Zone

CAR = ClassReach(hold=1.0, big=np.array([3.0, 0.5]), top=4.0, length=4.5, width=1.8, road_frame=True)
J = Zone("J", (-5.0, -5.0), (5.0, 5.0))
GUARD = 4.0 + 0.5 * np.hypot(4.5, 1.8) + 5.0

# Each starts where its next claim reaches the guard but its current one does not.
EAST = ((-17.0, -1.6), (60.0, -1.6))
WEST = ((17.0, 1.6), (-60.0, 1.6))
NORTH = ((1.6, -17.0), (1.6, 60.0))
SOUTH = ((-1.6, 17.0), (-1.6, -60.0))


def _route(start, end):
    a, b = np.asarray(start, float), np.asarray(end, float)
    n = int(np.ceil(np.linalg.norm(b - a))) + 1
    W = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
    h = np.arctan2(*(b - a)[::-1])
    return W, np.full(n, h)


class Scene:
    """Vehicles ``id -> (start, end)``, each at waypoint ``k`` (0 unless given), requesting
    unless listed in ``idle``."""

    def __init__(self, vehicles: dict, k: dict | None = None, idle=()):
        self.ids = list(vehicles)
        self.routes = [_route(*vehicles[v]) for v in self.ids]
        self.k = np.array([(k or {}).get(v, 0) for v in self.ids], dtype=np.intp)
        self.requesting = np.array([v not in idle for v in self.ids])

    def boxes(self, offset):
        c = np.array([W[min(k + offset, len(W) - 1)] for (W, _), k in zip(self.routes, self.k)]).reshape(-1, 2)
        h = np.array([H[min(k + offset, len(H) - 1)] for (_, H), k in zip(self.routes, self.k)])
        e = CAR.half_extent(h).reshape(-1, 2)
        return c - e, c + e

    def fleet(self):
        lo, hi = self.boxes(0)
        return JunctionFleet(self.ids, np.array(["car"] * len(self.ids)), lo, hi,
                             ((([W for W, _ in self.routes]), [H for _, H in self.routes], self.k),))

    def withhold(self, gate, t=0):
        n_lo, n_hi = self.boxes(1)
        r = self.requesting
        req = gate.withhold(t, self.fleet(), r, n_lo[r], n_hi[r])
        return {v for v, q in zip(self.ids, req) if q}


def _gate():
    return JunctionGate([J], {"car": CAR})


def _holders(gate):
    return set(gate.holders[0])


def test_the_guard_is_the_zone_enlarged_by_the_largest_claim_radius():
    gate = _gate()
    np.testing.assert_allclose(gate.hi[0], [GUARD, GUARD], rtol=0, atol=1e-12)  # sums of O(10) m
    np.testing.assert_allclose(gate.lo[0], [-GUARD, -GUARD], rtol=0, atol=1e-12)
    lo, hi = Scene({"A": EAST}).boxes(0)
    assert hi[0, 0] < -GUARD < Scene({"A": EAST}).boxes(1)[1][0, 0]  # the setting of every test


def test_only_a_token_holder_may_ask_into_the_guard():
    """A request whose claim reaches the guard stays only with the zone's token; requests that
    do not reach a guard, or stay in the one their claim is already in, are never withheld."""
    gate = _gate()
    far = ((-60.0, 40.0), (60.0, 40.0))
    scene = Scene({"A": EAST, "C": NORTH, "F": far})
    assert scene.withhold(gate) == {"A", "F"}  # C crosses A's corridor: withheld
    assert _holders(gate) == {"A"}
    scene.k[:] = [5, 0, 5]  # A inside the guard (it keeps its token), F still far away
    assert scene.withhold(gate, t=1) == {"A", "F"}
    assert _holders(gate) == {"A"}


def test_several_tokens_per_junction_when_corridors_are_apart():
    """Opposite straight streams both get a token; a crossing one does not."""
    for paths, want in (({"A": EAST, "B": WEST}, {"A", "B"}),
                        ({"A": EAST, "B": WEST, "C": NORTH}, {"A", "B"}),
                        ({"A": EAST, "B": NORTH}, {"A"}),
                        ({"A": NORTH, "B": SOUTH}, {"A", "B"})):
        gate = _gate()
        assert Scene(paths).withhold(gate) == want == _holders(gate), paths


def test_no_overtaking_of_a_blocked_waiter():
    """Equal waits go in id order: the north one ("B") is blocked by A and ends the round, so
    the west one ("C"), though apart from A, does not overtake it into the junction."""
    gate = _gate()
    assert Scene({"A": EAST, "B": NORTH, "C": WEST}).withhold(gate) == {"A"} == _holders(gate)
    assert gate.wait == {(0, "B"): 0, (0, "C"): 0}


def test_a_withheld_waiter_names_the_holders_it_waits_for():
    """For analysis.waits: B (north) and C (west) wait for A's token round; B's corridor crosses A's,
    C is not let past B: both name A, the zone's holder.  A step without requests names nobody."""
    gate = _gate()
    assert Scene({"A": EAST, "B": NORTH, "C": WEST}).withhold(gate) == {"A"}
    assert gate.waiting_on == {"B": ["A"], "C": ["A"]}
    Scene({"A": EAST, "B": NORTH}, idle=("A", "B")).withhold(gate, t=1)
    assert gate.waiting_on == {}


def test_a_waiter_stuck_behind_a_claim_in_the_guard_holds_nobody_back():
    """B (north) crosses the holder A's corridor, but E stands in B's own path inside the guard
    (no token: a queue at a red light on SUMO's ``tools/game/cross``, where the first waiter of
    the red approach kept the token from the green streams for the whole run): B cannot go
    whoever holds the token, so it does not end the round, and C (west, apart from A but
    crossing B's path) gets a token.  Without E, B waits for A and C does not overtake it."""
    E = ((1.6, -8.0), (1.6, 60.0))  # on B's lane, inside the guard, standing
    gate = _gate()
    assert Scene({"A": EAST}).withhold(gate, t=0) == {"A"}
    scene = Scene({"A": EAST, "B": NORTH, "C": WEST, "E": E}, k={"A": 5}, idle="E")
    assert scene.withhold(gate, t=1) == {"A", "C"}
    assert _holders(gate) == {"A", "C"} and (0, "B") in gate.wait
    gate = _gate()
    assert Scene({"A": EAST}).withhold(gate, t=0) == {"A"}
    assert Scene({"A": EAST, "B": NORTH, "C": WEST}, k={"A": 5}).withhold(gate, t=1) == {"A"}


def test_tokens_go_in_order_of_waiting_not_of_id():
    """Z has waited since step 0 (blocked by A's token); A leaves, and at step 1 "B" (an earlier
    id) asks across Z's path: Z, waiting longer, gets the token, B waits."""
    gate = _gate()
    assert Scene({"A": EAST, "Z": NORTH}).withhold(gate, t=0) == {"A"}
    assert gate.wait == {(0, "Z"): 0}
    assert Scene({"B": WEST, "Z": NORTH}).withhold(gate, t=1) == {"Z"} == _holders(gate)
    assert gate.wait == {(0, "B"): 1}  # served waiters and vehicles gone leave the queue


def test_no_token_through_a_claim_in_the_guard():
    """E is inside the guard without a token (admitted there) on A's path: A gets no token.
    A claim in the guard elsewhere (G, on the crossing road's far side) does not stop A."""
    gate = _gate()
    E = ((-3.0, -1.6), (60.0, -1.6))
    assert Scene({"A": EAST, "E": E}, idle="E").withhold(gate) == set()
    assert _holders(gate) == set()
    gate = _gate()
    G = ((-1.6, 8.0), (-1.6, 60.0))
    assert Scene({"A": EAST, "G": G}, idle="G").withhold(gate) == {"A"} == _holders(gate)


@pytest.mark.parametrize("gap_m, granted", [(-0.5, False), (0.5, True)])
def test_exit_slot_needs_room_for_the_largest_claim(gap_m, granted):
    """The exit slot is the first waypoint whose hold region misses the guard (x = 15 here:
    15 - 3.42 > 11.42); a token needs room there for the largest claim (±5.25 m along).  A
    parked vehicle L whose claim starts 0.5 m inside / beyond that room."""
    slot = 15.0
    assert slot - 1 - CAR.hold_radius <= GUARD < slot - CAR.hold_radius
    x_l = slot + 5.25 + gap_m + 5.25  # L's claim box starts at x_l - 5.25
    gate = _gate()
    scene = Scene({"A": EAST, "L": ((x_l, -1.6), (300.0, -1.6))}, idle="L")
    assert scene.withhold(gate) == ({"A"} if granted else set())
    assert _holders(gate) == ({"A"} if granted else set())


def test_no_admission_into_a_holders_corridor():
    """With A holding the token, a vehicle appearing on A's corridor (D) is not admitted, one
    elsewhere (F) is; without a holder both are."""
    gate = _gate()
    fam, centre, heading = np.array(["car", "car"]), np.array([[10.0, -1.6], [10.0, 30.0]]), np.zeros(2)
    assert gate.admissible(np.array([True, True]), fam, centre, heading).tolist() == [True, True]
    assert Scene({"A": EAST}).withhold(gate) == {"A"}
    assert gate.admissible(np.array([True, True]), fam, centre, heading).tolist() == [False, True]
    assert gate.admissible(np.array([False, True]), fam, centre, heading).tolist() == [False, True]


def test_token_released_when_the_claim_has_left_the_guard():
    """A keeps its token while its claim meets the guard, and gives it back once it has left
    (or A is gone); the crossing vehicle C then gets it."""
    gate = _gate()
    scene = Scene({"A": EAST, "C": NORTH})
    assert scene.withhold(gate, t=0) == {"A"}
    exit_k = int(np.ceil(GUARD + 5.25 - (-17.0)))  # first waypoint whose claim box misses the guard
    scene.k[0] = exit_k - 1
    assert scene.withhold(gate, t=1) == {"A"} and _holders(gate) == {"A"}
    scene.k[0] = exit_k
    assert scene.withhold(gate, t=2) == {"A", "C"} and _holders(gate) == {"C"}
    gate = _gate()
    assert Scene({"A": EAST, "C": NORTH}).withhold(gate, t=0) == {"A"}
    assert Scene({"C": NORTH}).withhold(gate, t=1) == {"C"} == _holders(gate)


def test_corridor_ends_at_the_exit_slot_and_is_cached():
    """The corridor holds every waypoint's largest claim from the current waypoint to the
    exit slot; a route ending inside the guard has no slot.  Cached per (vehicle, zone, waypoint)."""
    gate = _gate()
    fleet = Scene({"A": EAST, "T": ((-17.0, -1.6), (0.0, -1.6))}).fleet()
    key, slot, lo, hi = gate.route_through(fleet, 0, 0)
    assert key == ("A", 0, 0) and len(lo) == 15 - (-17) + 1
    np.testing.assert_allclose(slot[0], [15.0 - 5.25, -1.6 - 1.4], rtol=0, atol=1e-12)
    assert gate.route_through(fleet, 0, 0)[2] is lo
    key, slot, lo, _ = gate.route_through(fleet, 1, 0)
    assert slot is None and len(lo) == 18  # to its last waypoint, inside the guard


@st.composite
def fleets(draw):
    n = draw(st.integers(1, 8))
    seed = draw(st.integers(0, 2**31 - 1))
    rng = np.random.default_rng(seed)
    roads = [EAST, WEST, NORTH, SOUTH, ((-17.0, 1.6), (1.6, 60.0))]  # the last one turns left-ish
    vehicles = {f"v{i}": roads[rng.integers(len(roads))] for i in range(n)}
    k = {v: int(rng.integers(0, 12)) for v in vehicles}
    idle = [v for v in vehicles if rng.random() < 0.3]
    return vehicles, k, idle, int(draw(st.integers(1, 6)))


@settings(max_examples=60, deadline=None)
@given(fleets())
def test_holders_corridors_never_meet_and_only_holders_ask_into_the_guard(case):
    """Random fleets around one junction, stepped a few times with vehicles moving on: the
    stored corridors of a zone's holders are pairwise apart after every round, and every
    request left standing whose claim newly reaches the guard is a holder's."""
    vehicles, k, idle, rounds = case
    gate = _gate()
    for t in range(rounds):
        scene = Scene(vehicles, k=k, idle=idle)
        asked = scene.withhold(gate, t=t)
        held = list(gate.holders[0].values())
        for a in range(len(held)):
            for b in range(a + 1, len(held)):
                assert not boxes_meet(held[a][1], held[a][2], held[b][1], held[b][2])
        c_lo, c_hi = scene.boxes(0)
        n_lo, n_hi = scene.boxes(1)
        for i, v in enumerate(scene.ids):
            reach = np.all(n_lo[i] <= gate.hi[0]) and np.all(n_hi[i] >= gate.lo[0])
            inside = np.all(c_lo[i] <= gate.hi[0]) and np.all(c_hi[i] >= gate.lo[0])
            if v in asked and reach and not inside:
                assert v in gate.holders[0]
        k = {v: k[v] + (v in asked) * 3 for v in vehicles}


def test_bad_zones_and_families_are_named():
    with pytest.raises(ValueError, match=r"Zone 'J2': lo and hi must be finite .* lo <= hi"):
        Zone("J2", (5.0, 0.0), (-5.0, 1.0))
    with pytest.raises(ValueError, match="Zone 'J3'"):
        Zone("J3", (0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
    with pytest.raises(ValueError, match="ClassReach.of: need the position sets P\\^0 .. P\\^N with N >= 1"):
        ClassReach.of([np.zeros((4, 2))], 4.5, 1.8, True)


def test_fleet_route_reads_each_row_of_every_part():
    """:meth:`JunctionFleet.route` finds a row in its part (rows count on across the parts), reads
    the current waypoint as the part's index array holds it when asked (the loop moves it on in
    place), and refuses a row beyond the fleet."""
    W = [np.full((3, 2), float(i)) for i in range(5)]
    H = [np.full(3, 0.1 * i) for i in range(5)]
    k1, k2 = np.array([0, 1]), np.array([2, 0, 1])
    fleet = JunctionFleet([f"v{i}" for i in range(5)], np.array(["car"] * 5), np.zeros((5, 2)), np.zeros((5, 2)),
                          ((W[:2], H[:2], k1), (W[2:], H[2:], k2)))
    for row, k in enumerate([0, 1, 2, 0, 1]):
        w, h, kk = fleet.route(row)
        assert w is W[row] and h is H[row] and kk == k and type(kk) is int
    k2[1] += 1
    assert fleet.route(3)[2] == 1
    assert fleet.route(np.int64(4))[0] is W[4]
    with pytest.raises(IndexError):
        fleet.route(5)
