"""The junction liveness layer for movement authority (tm.authority_gate) without a simulator.

Each test builds a :class:`JunctionFleet` by hand: straight routes with waypoints 1 m apart (the
waypoint ``k`` is the vehicle's stop point), each vehicle's claim box given explicitly (by default
its hold box: at rest at its stop point).  Geometry is exact box comparisons of the same floats;
every offset between boxes is at least 0.2 m, far from round-off.

Ordered entry (:meth:`AuthorityGate._after`: a candidate whose corridor meets a holder's takes the
token after it and keeps out of its path) is off here: every other rule is stated against a
candidate that waits for the holders its corridor meets.  Its own tests, on the same scenes, are in
``test_ordered_entry.py``.

The class (``CAR``): ``T^0`` within 0.25 m along and 0.2 m across, claims within 1.0 m across,
footprint 4 m x 1.8 m, δ = 1 m.  Hold box ``T^0 ⊕ footprint``: ±2.25 m along, ±1.1 m across;
corridor box: ±2.75 m along (δ/2 + T^0 + L/2), ±1.1 m across (T^0 + W/2).  The guard of the 10 m zone ``J``
at the origin is the zone enlarged by 1.0 + hypot(4, 1.8) / 2 = 3.193 m: [-8.193, 8.193]^2.
An east-bound route starting at x = -30 enters at waypoint 20 (x = -10: -10 + 2.25 meets the guard,
-11 + 2.25 = -8.75 does not) and leaves at its exit slot, waypoint 41 (x = 11: 11 - 2.25 = 8.75
misses the guard, 10 - 2.25 does not).
"""

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from tm.authority_gate import AuthorityGate, corridors_ahead
from tm.authority_reach import AuthorityReach
from tm.gate_paths import GatePaths
from tm.boxes import boxes_meet, corridor_hits, polygons_meet
from tm.junctions import JunctionFleet, JunctionGate, Zone

CAR = AuthorityReach(hold=0.25, hold_y=0.2, across=1.0, length=4.0, width=1.8, delta=1.0)
J = Zone("J", (-5.0, -5.0), (5.0, 5.0))
GUARD = 5.0 + 1.0 + 0.5 * np.hypot(4.0, 1.8)
HOLD = np.array([2.25, 1.1])  # hold box half extents along, across
ENTRY, EXIT = 20, 41          # of the routes below (they all start 30 m from the centre)

EAST = ((-30.0, -1.6), (60.0, -1.6))
WEST = ((30.0, 1.6), (-60.0, 1.6))
NORTH = ((1.6, -30.0), (1.6, 60.0))
SOUTH = ((-1.6, 30.0), (-1.6, -60.0))
SOUTH_FAR = ((-2.4, 30.0), (-2.4, -60.0))  # a lane 4 m from the north-bound one


def _route(start, end):
    a, b = np.asarray(start, float), np.asarray(end, float)
    n = int(np.ceil(np.linalg.norm(b - a))) + 1
    W = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
    return W, np.full(n, np.arctan2(*(b - a)[::-1]))


class Scene:
    """Vehicles ``id -> (start, end)`` (or ``id -> (W, H)`` routes, ``routes``) at stop point ``k``
    (0 unless given), requesting ``k + 1`` unless listed in ``idle``; claim boxes: ``claims[id] =
    (lo, hi)``, else the hold box at ``k``; class ``family[id]`` (``"car"`` unless given, reach
    ``reach[class]``)."""

    def __init__(self, vehicles: dict, k: dict | None = None, idle=(), claims: dict | None = None,
                 family: dict | None = None, reach: dict | None = None, routes: dict | None = None):
        self.ids = list(vehicles) + [v for v in (routes or {}) if v not in vehicles]
        self.routes = [(routes or {}).get(v) or _route(*vehicles[v]) for v in self.ids]
        self.k = np.array([(k or {}).get(v, 0) for v in self.ids], dtype=np.intp)
        self.requesting = np.array([v not in idle for v in self.ids])
        self.claims = dict(claims or {})
        self.family = [(family or {}).get(v, "car") for v in self.ids]
        self.reach = {"car": CAR, **(reach or {})}
        self.polygons = False  # whether the fleet knows the claims' oriented boxes (:meth:`claim_polygons`)

    def hold_box(self, i: int):
        W, H = self.routes[i]
        h = self.reach[self.family[i]].hold_half(H[self.k[i]:self.k[i] + 1])[0]
        return W[self.k[i]] - h, W[self.k[i]] + h

    def claim_polygons(self, rows):
        """:attr:`JunctionFleet.claim_polygons` of the scene: each row's claim box (an axis-aligned
        box, ``claims``) or its hold box at its stop point as an oriented box."""
        P = []
        for r in rows.tolist():
            if self.ids[r] in self.claims:
                (x0, y0), (x1, y1) = self.claims[self.ids[r]]
                P.append(np.array([[[x0, y0], [x1, y0], [x1, y1], [x0, y1]]], dtype=float))
            else:
                W, H = self.routes[r]
                P.append(self.reach[self.family[r]].hold_polygons(W[self.k[r]][None], np.zeros((1, 4)),
                                                                  H[self.k[r]:self.k[r] + 1]))
        return np.concatenate(P), np.repeat(np.arange(len(P)), [len(p) for p in P])

    def fleet(self):
        boxes = [self.claims.get(v) or self.hold_box(i) for i, v in enumerate(self.ids)]
        lo = np.array([b[0] for b in boxes], dtype=float).reshape(-1, 2)
        hi = np.array([b[1] for b in boxes], dtype=float).reshape(-1, 2)
        return JunctionFleet(self.ids, np.array(self.family), lo, hi,
                             (([W for W, _ in self.routes], [H for _, H in self.routes], self.k),),
                             claim_polygons=self.claim_polygons if self.polygons else None)

    def withhold(self, gate, t=0):
        n = int(self.requesting.sum())
        req = gate.withhold(t, self.fleet(), self.requesting, np.zeros((n, 2)), np.zeros((n, 2)))
        return {v for v, q in zip(self.ids, req) if q}


@pytest.fixture(autouse=True)
def _candidates_wait_for_holders(monkeypatch):
    """Ordered entry off for this module's gates (module notes)."""
    monkeypatch.setattr(AuthorityGate, "ordered_entry", False)


def _gate():
    return AuthorityGate([J], {"car": CAR})


def _holders(gate):
    return set(gate.holders[0])


def test_the_guard_is_the_zone_plus_the_claims_across_half_width_and_the_footprint():
    """Not the paper's largest claim radius: the claims no longer reach backwards."""
    gate = _gate()
    np.testing.assert_allclose(gate.hi[0], [GUARD, GUARD], rtol=0, atol=1e-12)  # sums of O(10) m
    np.testing.assert_allclose(gate.lo[0], [-GUARD, -GUARD], rtol=0, atol=1e-12)
    zs, entry, exit_, exits = gate.intervals(Scene({"A": EAST}).fleet(), 0)
    assert zs.tolist() == [0] and entry.tolist() == [ENTRY] and exit_.tolist() == [EXIT] and exits.tolist() == [True]


def test_every_rule_is_on_the_largest_guard():
    """With a bus class (claims 1.4 m across, 12 m x 2.5 m: its guard reaches 7.53 m past the zone)
    the gate's guard boxes grow to the bus's, and so do a car's entry line and exit slot (every
    class stops before any holder's claim: next test) and its release: a car keeps its token while
    its claim reaches 0.2 m into the bus's guard, 0.2 m outside it releases it."""
    bus = AuthorityReach(hold=0.25, hold_y=0.2, across=1.4, length=12.0, width=2.5, delta=1.0)
    g_bus = 5.0 + 1.4 + 0.5 * np.hypot(12.0, 2.5)
    gate = AuthorityGate([J], {"car": CAR, "bus": bus})
    gate.trim_corridors = False  # the release alone (A's corridor cut behind it would let B in beside it)
    np.testing.assert_allclose(gate.hi[0], [g_bus, g_bus], rtol=0, atol=1e-12)
    scene = Scene({"A": EAST, "B": NORTH}, k={"A": 15, "B": 15})
    fleet = scene.fleet()
    # car: x - 30 + 2.25 meets the bus's guard from x = -14 (index 16); leaves it at x = 15 (index 45)
    assert [a.tolist() for a in gate.intervals(fleet, 0)] == [[0], [16], [45], [True]]
    bus_fleet = JunctionFleet(["Q"], np.array(["bus"]), fleet.claim_lo[:1], fleet.claim_hi[:1],
                              (([scene.routes[0][0]], [scene.routes[0][1]], np.array([0])),))
    # bus: x - 30 + 6.25 meets the guard from x = -18 (index 12); leaves it at x = 19 (index 49)
    assert [a.tolist() for a in gate.intervals(bus_fleet, 0)] == [[0], [12], [49], [True]]
    assert scene.withhold(gate, t=0) == {"A"}
    for t, (tail, held) in enumerate(((g_bus - 0.2, True), (g_bus + 0.2, False)), start=1):
        claim = ((tail, -1.6 - HOLD[1]), (30.0, -1.6 + HOLD[1]))
        scene = Scene({"A": EAST, "B": NORTH}, k={"A": 50, "B": 15}, claims={"A": claim})
        assert GUARD + 0.2 < tail and scene.withhold(gate, t=t) == ({"A"} if held else {"A", "B"}), tail
        assert _holders(gate) == ({"A"} if held else {"B"})


def test_a_token_handed_out_at_the_entry_line_is_kept():
    """A car takes the token with its stop point at its entry line (index 16, x = -14, on the bus's
    guard); its claim runs from 20 m behind to the hold box there (front x = -11.75): in the bus's
    guard (from -12.53), not yet in the car's own (from -8.19).  A keeps the token and B, crossing,
    waits.  (Released against the car's own guard, the token went to B in the same round and A
    drove into the zone without one: on ``grid`` seed 1, 300 s, 361 stop points in a zone without
    its token.)"""
    bus = AuthorityReach(hold=0.25, hold_y=0.2, across=1.4, length=12.0, width=2.5, delta=1.0)
    gate = AuthorityGate([J], {"car": CAR, "bus": bus})
    k = {"A": 15, "B": 15}
    assert Scene({"A": EAST, "B": NORTH}, k=k).withhold(gate, t=0) == {"A"} == _holders(gate)
    claim = ((-34.0 - HOLD[0], -1.6 - HOLD[1]), (-14.0 + HOLD[0], -1.6 + HOLD[1]))
    assert -GUARD > claim[1][0] > -gate.hi[0][0]
    for t in range(1, 4):
        scene = Scene({"A": EAST, "B": NORTH}, k={"A": 16, "B": 15}, claims={"A": claim})
        assert scene.withhold(gate, t=t) == {"A"} and _holders(gate) == {"A"}, t


#: A truck: claims 1.6 m across, 7 m x 2.4 m; its claims stick 1.6 + hypot(7, 2.4) / 2 = 5.3 m out of
#: a zone (the car's 3.193 m): its guard reaches 10.3 m from the centre.
TRUCK = AuthorityReach(hold=0.25, hold_y=0.2, across=1.6, length=7.0, width=2.4, delta=1.0)
GUARD_TRUCK = 5.0 + TRUCK.guard_reach  # the shared guard of a fleet with trucks: 10.3 m


def _right_turn_east_to_north():
    """West-bound on the east arm (y = 1.6), a right turn at (1.6, 1.6) into the north arm (x = 1.6);
    waypoints <= 1 m apart, each heading that of the segment arriving at it."""
    W1, H1 = _route((30.0, 1.6), (1.6, 1.6))
    W2, H2 = _route((1.6, 1.6), (1.6, 60.0))
    return np.vstack([W1, W2[1:]]), np.r_[H1, H2[1:]]


def test_a_smaller_waiter_stops_before_a_bigger_holders_claims():
    """The two-class lock of issue 12 (grid, truck 29 / car 12, bus 111 / car 139), at one junction.

    T, a truck, holds the token turning right from the east arm into the north arm; B, a car, comes
    down the north arm's other lane (x = -2.4, out of the width of T's claims up the north arm,
    x >= -1.2: :func:`test_a_waiter_beside_the_exit_road_stays_out_of_the_holders_path`) and crosses T's corridor, so it waits for the token
    and moves its stop point up to its entry line.  T's claim, its body still turning at the zone's
    edge, is the box ``guard_reach`` (5.3 m) each way around (1.6, 4.8): it reaches across B's lane
    up to y = 10.1, 0.2 m short of the truck's guard (10.3).  With the car's own guard (8.193) as
    its entry line B stops at y = 11, its hold box down to 8.75, inside T's claim: the traffic
    manager must then deny T every claim on up the north arm, and B waits for T's token: neither
    moves again.  With the entry line on the largest guard of the fleet's classes B stops at y = 13
    (hold box from 10.75, 0.45 m outside the truck's guard), out of every claim T can make inside
    its guard."""
    g_truck = 5.0 + TRUCK.guard_reach
    assert abs(TRUCK.guard_reach - 5.3) < 1e-3  # hypot(7, 2.4) / 2 = 3.7000
    gate = AuthorityGate([J], {"car": CAR, "truck": TRUCK})
    routes = {"T": _right_turn_east_to_north()}
    reach, family = {"truck": TRUCK}, {"T": "truck"}
    t_in = int(gate.intervals(Scene({}, routes=routes, family=family, reach=reach).fleet(), 0)[1][0])
    assert Scene({"B": SOUTH_FAR}, k={"T": t_in - 1}, routes=routes, family=family,
                 reach=reach).withhold(gate, t=0) == {"B", "T"} and _holders(gate) == {"T"}
    claim_t = ((1.6 - TRUCK.guard_reach, 4.8 - TRUCK.guard_reach), (1.6 + TRUCK.guard_reach, 4.8 + TRUCK.guard_reach))
    assert claim_t[1][1] + 0.2 - g_truck < 1e-9
    kb, stuck = 0, 0
    for t in range(1, 40):
        scene = Scene({"B": SOUTH_FAR}, k={"T": t_in + 8, "B": kb}, idle="T", claims={"T": claim_t},
                      routes=routes, family=family, reach=reach)
        asked = scene.withhold(gate, t=t)
        assert _holders(gate) == {"T"}, t
        stuck = 0 if "B" in asked else stuck + 1
        kb += "B" in asked
    assert stuck > 5  # B waits at its entry line for T's token
    lo_b, hi_b = Scene({"B": SOUTH_FAR}, k={"B": kb}).hold_box(0)
    assert not boxes_meet(lo_b[None], hi_b[None], np.array(claim_t[0])[None], np.array(claim_t[1])[None]), \
        (kb, lo_b, hi_b)
    assert lo_b[1] > g_truck + 0.2 and kb == 17  # y = 13: 13 - 2.25 = 10.75


NARROW = AuthorityReach(hold=0.25, hold_y=0.2, across=0.6, length=4.0, width=1.8, delta=1.0)


def _toy_traffic(gate, routes, family, reach, k, steps, polygons=False):
    """A toy traffic manager around ``gate`` (the ``new-fixed`` rule of the real one): every vehicle
    asks for ``k + 1`` each step until its route's end; a request the gate lets through is granted
    when its new claim, the hull of :meth:`AuthorityReach.claim_box` over waypoints ``k - 2 ..
    k + 1`` (the body trails its stop point by up to 3 m), misses the claim of every vehicle that
    stands (was not granted the last step), whose claim is its hold box at its stop point.
    Moving claims pass each other (they are time-indexed in the real one).  Returns the stop
    points after ``steps`` steps and the step each vehicle last moved.  ``polygons``: the fleet knows
    the claims' oriented boxes (:meth:`Scene.claim_polygons`)."""
    ids = list(routes)
    k = {v: k.get(v, 0) for v in ids}
    moving = dict.fromkeys(ids, False)
    last_move = dict.fromkeys(ids, 0)

    def claim(v, kk, wide):
        W, H = routes[v]
        c = reach[family[v]]
        idx = np.arange(max(kk - 3, 0) if wide else kk, kk + 1)
        nxt = np.minimum(idx + 1, len(H) - 1)
        lo, hi = (c.claim_box if wide else c.hold_box)(np.zeros((len(idx), 4)), H[idx], H[nxt])
        return (W[idx] + lo).min(axis=0), (W[idx] + hi).max(axis=0)

    for t in range(steps):
        claims = {v: claim(v, k[v], moving[v]) for v in ids}
        asking = {v for v in ids if k[v] + 1 < len(routes[v][0])}
        scene = Scene({}, k=k, idle=[v for v in ids if v not in asking], claims=claims, routes=routes,
                      family=family, reach=reach)
        scene.polygons = polygons
        asked = scene.withhold(gate, t=t)
        granted = set()
        for v in asked:
            lo, hi = claim(v, k[v] + 1, True)
            if not any(boxes_meet(lo[None], hi[None], claims[u][0][None], claims[u][1][None])
                       for u in ids if u != v and not moving[u]):
                granted.add(v)
        for v in ids:
            moving[v] = v in granted
            k[v] += v in granted
            last_move[v] = t if v in granted else last_move[v]
    return k, last_move


def test_a_waiter_beside_the_exit_road_stays_out_of_the_holders_path():
    """The bus / opposite-car lock of issue 12 (grid seed 1: bus 85 / car 71 at A0, bus 93 / car 79
    at B2), at one junction, with the toy traffic manager :func:`_toy_traffic`.

    T, a truck, takes the token turning right from the east arm into the north arm (x = 1.6);
    B, a car, comes down the north arm's other lane (x = -1.6), crosses T's corridor and waits for
    the token.  T's claims up the north arm are 1.6 + 1.2 = 2.8 m wide to the left (x >= -1.2),
    across B's lane up to x = -0.5, as far as T^0 + L/2 = 3.75 m past its exit slot (y = 15, up
    to 18.75).  Without the rule B stops at its entry line (y = 13, hold box 10.75 .. 15.25),
    beside T's exit slot: the traffic manager denies T every claim from y = 7 on (they meet B's
    standing box), T keeps the token inside the guard and B waits for it: neither moves again.
    With the rule B's stop point stays out of T's remaining path to the slot (at y = 22, hold box
    from 19.75) until T has released the token; then both go through."""
    routes = {"T": _right_turn_east_to_north(), "B": _route(*SOUTH)}
    family, reach = {"T": "truck", "B": "narrow"}, {"truck": TRUCK, "narrow": NARROW}
    gate = AuthorityGate([J], {"narrow": NARROW, "truck": TRUCK})
    t_in = int(gate.intervals(Scene({}, routes={"T": routes["T"]}, family=family, reach=reach).fleet(), 0)[1][0])
    k, last = _toy_traffic(gate, routes, family, reach, {"T": t_in - 1}, steps=160)
    W_t, W_b = routes["T"][0], routes["B"][0]
    assert W_t[k["T"], 1] > 40.0 and W_b[k["B"], 1] < -20.0, (k, W_t[k["T"]], W_b[k["B"]], last)
    assert gate.wide_withheld > 0 and not any(gate.holders[0])


def test_without_the_token_the_stop_point_stays_before_the_entry_line():
    """A holds the token; B crosses A's corridor.  B moves its stop point waypoint by waypoint up
    to the last one whose hold box misses the guard (the entry line less T^0 and L/2), even with
    its moving claim already reaching into the guard, and no further."""
    W = _route(*NORTH)[0]
    assert W[ENTRY - 1, 1] + HOLD[0] < -GUARD - 0.2 and W[ENTRY, 1] + HOLD[0] > -GUARD + 0.2
    gate = _gate()
    assert Scene({"A": EAST}, k={"A": ENTRY - 1}).withhold(gate, t=0) == {"A"} == _holders(gate)
    for t, kb in enumerate(range(0, ENTRY), start=1):
        # B's claim runs from 10 m behind its stop point to 1 m past its hold box: into the guard near the end
        claim = ((-0.5, W[kb, 1] - 10.0), (3.7, W[kb, 1] + HOLD[0] + 1.0))
        scene = Scene({"A": EAST, "B": NORTH}, k={"A": ENTRY, "B": kb}, idle="A", claims={"B": claim})
        asked = scene.withhold(gate, t=t)
        assert ("B" in asked) == (kb + 1 < ENTRY), kb
    assert _holders(gate) == {"A"}


def test_stop_limit_is_before_the_entry_line_without_the_token_and_the_route_end_with_it():
    """What the crossing gate asks (tm.crossing_gate): how far A's stop point may go without a token
    it does not hold: ENTRY - 1 before the token, the route's end with it, ENTRY - 1 again once given back."""
    gate = _gate()
    last = len(_route(*EAST)[0]) - 1
    assert gate.stop_limit(Scene({"A": EAST}, k={"A": ENTRY - 5}).fleet(), 0) == ENTRY - 1
    assert Scene({"A": EAST}, k={"A": ENTRY - 1}).withhold(gate) == {"A"} == _holders(gate)
    assert gate.stop_limit(Scene({"A": EAST}, k={"A": ENTRY - 3}).fleet(), 0) == last
    gate.give_back(["A"])
    assert gate.stop_limit(Scene({"A": EAST}, k={"A": ENTRY - 3}).fleet(), 0) == ENTRY - 1


def test_the_holder_moves_its_stop_point_through_to_the_exit_slot_and_on():
    """With the token, A's stop point moves from before the entry line through the zone to its
    exit slot and beyond, while B (crossing) waits at its entry line the whole time."""
    gate = _gate()
    for t, ka in enumerate(range(ENTRY - 1, EXIT + 5)):
        # A's claim: from 5 m behind its stop point (still in the guard until x = 13.2) to its hold box
        W = _route(*EAST)[0]
        claim = (W[ka] - [5.0 + HOLD[0], HOLD[1]], W[ka] + HOLD)
        scene = Scene({"A": EAST, "B": NORTH}, k={"A": ka, "B": ENTRY - 1}, claims={"A": claim})
        asked = scene.withhold(gate, t=t)
        assert "A" in asked and "B" not in asked, ka
        assert _holders(gate) == {"A"}


@pytest.mark.parametrize("gap_m, granted", [(-0.2, False), (0.2, True)])
def test_exit_slot_needs_room_for_the_stopped_vehicle_only(gap_m, granted):
    """A token needs room at the exit slot (x = 11) for A's hold box (±2.25 m), nothing more: L,
    parked beyond it, claims from 0.2 m short of / past that box's front (13.25 m); 0.2 m past is
    still inside the corridor's last box (11 + 2.75), which the paper's rule wanted free."""
    x_front = 11.0 + HOLD[0]
    assert x_front + 0.2 < 11.0 + 0.5 * CAR.delta + CAR.hold + 0.5 * CAR.length
    lo_l = x_front + gap_m
    gate = _gate()
    scene = Scene({"A": EAST, "L": ((lo_l + HOLD[0], -1.6), (300.0, -1.6))}, k={"A": ENTRY - 1}, idle="L")
    assert scene.withhold(gate) == ({"A"} if granted else set())
    assert _holders(gate) == ({"A"} if granted else set())


@pytest.mark.parametrize("room_m, follows", [(4.8, False), (5.2, True)])
def test_a_queue_follows_its_leader_through_with_room_for_both(room_m, follows):
    """F queues behind the holder A on the same lanes; their corridors meet.  F takes a token too
    when the road from the exit slot on has room for both hold boxes: the hold boxes at the slot
    and ceil((4 + 4) / 2 + 0.25 + 0.25) = 5 waypoints beyond it (front at 13.25 + 5 m) must miss
    L's claim, which starts 4.8 m past the slot's front (A's hold box would fit, both not) or 5.2 m
    past.  B, crossing, waits either way; F does not overtake a vehicle waiting
    longer (next test)."""
    front = 11.0 + HOLD[0]
    lo_l = front + room_m
    gate = _gate()
    assert Scene({"A": EAST}, k={"A": ENTRY - 1}).withhold(gate, t=0) == {"A"}
    W = _route(*EAST)[0]
    claim_a = (W[ENTRY + 5] - HOLD, W[ENTRY + 5] + [20.0, HOLD[1]])  # A drives on: up to x = 16.25
    vehicles = {"A": EAST, "F": EAST, "L": ((lo_l + HOLD[0], -1.6), (300.0, -1.6))}
    scene = Scene(vehicles, k={"A": ENTRY + 5, "F": ENTRY - 1}, idle="L", claims={"A": claim_a})
    asked = scene.withhold(gate, t=1)
    assert asked == ({"A", "F"} if follows else {"A"})
    assert _holders(gate) == ({"A", "F"} if follows else {"A"})
    # B, crossing, arrives now: it waits for both
    scene = Scene({**vehicles, "B": NORTH}, k={"A": ENTRY + 6, "F": ENTRY, "B": ENTRY - 1}, idle="L",
                  claims={"A": claim_a})
    assert "B" not in scene.withhold(gate, t=2)


def test_a_follower_does_not_overtake_a_crossing_vehicle_waiting_longer():
    gate = _gate()
    assert Scene({"A": EAST}, k={"A": ENTRY - 1}).withhold(gate, t=0) == {"A"}
    assert Scene({"A": EAST, "B": NORTH}, k={"A": ENTRY + 2, "B": ENTRY - 1}).withhold(gate, t=1) == {"A"}
    scene = Scene({"A": EAST, "B": NORTH, "F": EAST}, k={"A": ENTRY + 5, "B": ENTRY - 1, "F": ENTRY - 1})
    assert scene.withhold(gate, t=2) == {"A"} and _holders(gate) == {"A"}


@pytest.mark.parametrize("pass_blocked", [True, False])
def test_a_later_waiter_passes_a_blocked_one_only_off_its_path(pass_blocked):
    """A holds the token; B (north) waits for it, first in order.  C, waiting less, clips the
    guard's far corner (corridor apart from A's and B's): it takes a token -- it cannot delay B.
    D (west) misses A's corridor but crosses B's: it waits behind B.  (Paper mode's rule, the
    first blocked waiter ending the round: C waits too.)"""
    C = ((-25.0, -11.0), (5.0, 19.0))
    gate = _gate()
    gate.pass_blocked = pass_blocked
    k = {"A": ENTRY - 1, "B": ENTRY - 1}
    assert Scene({"A": EAST, "B": NORTH}, k=k).withhold(gate, t=0) == {"A"}
    scene = Scene({"A": EAST, "B": NORTH, "C": C, "D": WEST}, k={**k, "A": ENTRY + 2, "C": 20, "D": ENTRY - 1},
                  idle="A")
    fleet = scene.fleet()
    corr = {v: gate.route_through(fleet, i, 0) for i, v in enumerate(scene.ids) if v != "A"}
    a = gate.holders[0]["A"]
    assert gate.intervals(fleet, 2)[1].tolist() == [21]  # C's next stop point enters its guard
    assert not boxes_meet(corr["C"][2], corr["C"][3], a[1], a[2])
    assert not boxes_meet(corr["C"][2], corr["C"][3], corr["B"][2], corr["B"][3])
    assert boxes_meet(corr["D"][2], corr["D"][3], corr["B"][2], corr["B"][3])
    assert not boxes_meet(corr["D"][2], corr["D"][3], a[1], a[2])
    gate.wait[(0, "B")] = -1  # B has waited longest
    asked = scene.withhold(gate, t=1)
    assert asked == ({"C"} if pass_blocked else set()) and _holders(gate) == ({"A", "C"} if pass_blocked else {"A"})


def test_token_released_when_every_claim_has_left_the_guard():
    """A's stop point is past its exit slot; its claim (from its tail) still reaches 0.2 m into
    the guard: A keeps the token and B waits.  0.2 m out: released, and B gets it in the same
    round.  A vehicle gone releases its token too.  (The release alone: A's corridor cut behind
    it, next test, would let B in beside it.)"""
    gate = _gate()
    gate.trim_corridors = False
    assert Scene({"A": EAST, "B": NORTH}, k={"A": ENTRY - 1, "B": ENTRY - 1}).withhold(gate, t=0) == {"A"}
    k_a = EXIT + 4  # x = 15
    for t, (tail, held) in enumerate(((GUARD - 0.2, True), (GUARD + 0.2, False)), start=1):
        claim = ((tail, -1.6 - HOLD[1]), (15.0 + HOLD[0], -1.6 + HOLD[1]))
        scene = Scene({"A": EAST, "B": NORTH}, k={"A": k_a, "B": ENTRY - 1}, claims={"A": claim})
        asked = scene.withhold(gate, t=t)
        assert ("B" in asked) is not held and _holders(gate) == ({"A"} if held else {"B"})
    gate = _gate()
    assert Scene({"A": EAST, "B": NORTH}, k={"A": ENTRY - 1, "B": ENTRY - 1}).withhold(gate, t=0) == {"A"}
    assert Scene({"B": NORTH}, k={"B": ENTRY - 1}).withhold(gate, t=1) == {"B"} == _holders(gate)


@pytest.mark.parametrize("k_a", [ENTRY - 1, ENTRY + 5, EXIT - 1])
def test_a_token_is_kept_until_the_stop_point_reaches_the_exit_slot(k_a):
    """SUMO's ``fkk_in`` (issue 12): ``3_right.0``, handed two chained zones' tokens at once, lost the
    second 0.2 s after its claim's box first touched that guard, when the box left it again as the
    vehicle braked into a bend; it stood between the zones for good.  A takes the token at its entry
    line; at step 1 its stop point is ``k_a`` (still at the entry line, the manager having denied the
    switch; inside the guard; one short of the exit slot) and its claim's box lies wholly outside the
    guard: A keeps the token and B, whose corridor crosses A's, waits.  At step 2 A's stop point is at
    the exit slot and its claim outside the guard: released, and B takes the token.  (Released at
    step 1 when the claim's box alone decided.)"""
    gate = _gate()
    assert Scene({"A": EAST, "B": NORTH}, k={"A": ENTRY - 1, "B": ENTRY - 1}).withhold(gate, t=0) == {"A"}
    assert gate.pending == {(0, "A"): EXIT}
    behind = ((-GUARD - 6.0, -1.6 - HOLD[1]), (-GUARD - 0.2, -1.6 + HOLD[1]))
    beyond = ((GUARD + 0.2, -1.6 - HOLD[1]), (GUARD + 6.0, -1.6 + HOLD[1]))
    for t, (k, claim, held) in enumerate(((k_a, behind, True), (EXIT, beyond, False)), start=1):
        scene = Scene({"A": EAST, "B": NORTH}, k={"A": k, "B": ENTRY - 1}, claims={"A": claim})
        asked = scene.withhold(gate, t=t)
        assert ("B" in asked) is not held and _holders(gate) == ({"A"} if held else {"B"}), t
    assert (0, "A") not in gate.pending


@pytest.mark.parametrize("trim", [True, False])
def test_a_holders_corridor_is_cut_behind_it(trim):
    """A took the token at its entry line (its corridor from x = -11 to the exit slot, x = 11, ±2.75 m
    along); B, north-bound at x = 1.6 (corridor x in [0.5, 2.7]), waits.  A's stop point is at the
    exit slot, its body still in the guard (A keeps the token).  Its claim's tail at x = 6: the boxes
    from x = 4 on meet it (4 + 2.75 >= 6), the first reaching back to 1.25 -- still B's corridor: B
    waits.  Tail at x = 8 (0.19 m inside the guard): the boxes kept start at x = 6 (from 3.25), clear
    of B's corridor: B takes a token beside A.  Without the cut B waits until A has left the guard."""
    gate = _gate()
    gate.trim_corridors = trim
    assert Scene({"A": EAST, "B": NORTH}, k={"A": ENTRY - 1, "B": ENTRY - 1}).withhold(gate, t=0) == {"A"}
    for t, tail in enumerate((6.0, 8.0), start=1):
        assert tail < GUARD
        claim = ((tail, -1.6 - HOLD[1]), (11.0 + HOLD[0], -1.6 + HOLD[1]))
        asked = Scene({"A": EAST, "B": NORTH}, k={"A": EXIT, "B": ENTRY - 1}, claims={"A": claim}).withhold(gate, t=t)
        shared = trim and tail == 8.0
        assert asked == ({"A", "B"} if shared else {"A"}) and _holders(gate) == asked, (trim, tail)
    assert (gate.corridors_cut > 0) == trim


@pytest.mark.parametrize("seed", range(10))
def test_trim_cuts_each_holder_at_its_first_box_its_claim_meets(seed):
    """:meth:`AuthorityGate._trim` on many holders at once (random corridors of one to eight boxes and
    claim boxes, two zones): each holder's corridor is cut to its boxes from the first one its claim
    box meets, with a key counting on from the cut and its oriented boxes cut alike; a holder whose
    claim meets its first box, or none, a one-box corridor and a holder gone from the fleet keep theirs."""
    rng = np.random.default_rng(seed)
    gate = _gate()
    n = 9
    ids = [f"v{i}" for i in range(n)]
    c_lo = rng.uniform(0.0, 10.0, (n, 2))
    c_hi = c_lo + rng.uniform(1.0, 5.0, (n, 2))
    fleet = JunctionFleet(ids, np.array(["car"] * n), c_lo, c_hi, (([], [], np.zeros(0, dtype=np.intp)),))
    pos = {v: i for i, v in enumerate(ids[:-1])}  # the last one is gone
    gate.holders = [{}, {}]
    want, n_cut = {}, 0
    for i, v in enumerate(ids):
        m = int(rng.integers(1, 9))
        lo = rng.uniform(0.0, 10.0, (m, 2))
        hi = lo + rng.uniform(0.5, 3.0, (m, 2))
        key = (v, i % 2, 3) if i % 3 else (v, i % 2, 3, 2)
        gate.boxes.corridor[key] = polys = rng.normal(size=(2 * m, 4, 2))
        gate.holders[i % 2][v] = (key, lo, hi)
        meets = np.flatnonzero(np.all((lo <= c_hi[i]) & (hi >= c_lo[i]), axis=1))
        i0 = int(meets[0]) if len(meets) and v in pos and m > 1 else 0
        cut = (*key[:3], key[3] + i0 if len(key) > 3 else i0) if i0 else key
        n_cut += i0 > 0
        want[v] = (cut, lo[i0:], hi[i0:], np.concatenate([polys[i0:m], polys[m + i0:]]))
    gate._trim(fleet, pos)
    for z, hs in enumerate(gate.holders):
        for v, (key, lo, hi) in hs.items():
            w = want[v]
            assert key == w[0] and np.array_equal(lo, w[1]) and np.array_equal(hi, w[2])
            assert np.array_equal(gate.boxes.corridor[key], w[3])
    assert gate.corridors_cut == n_cut


def test_corridor_runs_from_the_stop_point_to_the_exit_slot_and_is_cached():
    """Corridor boxes at every waypoint from the stop point to the exit slot (±2.75 along, ±1.1
    across); the slot box is the hold box there; a route ending inside the guard has no slot."""
    gate = _gate()
    fleet = Scene({"A": EAST, "T": ((-30.0, -1.6), (0.0, -1.6))}, k={"A": ENTRY - 1, "T": ENTRY - 1}).fleet()
    key, slot, lo, hi = gate.route_through(fleet, 0, 0)
    assert key == ("A", 0, ENTRY - 1) and len(lo) == EXIT - ENTRY + 2
    np.testing.assert_allclose(lo[0], [-11.0 - 2.75, -1.6 - 1.1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(hi[-1], [11.0 + 2.75, -1.6 + 1.1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(slot[0], [11.0 - HOLD[0], -1.6 - HOLD[1]], rtol=0, atol=1e-12)
    np.testing.assert_allclose(slot[1], [11.0 + HOLD[0], -1.6 + HOLD[1]], rtol=0, atol=1e-12)
    assert gate.route_through(fleet, 0, 0)[2] is lo
    _, slot, lo, _ = gate.route_through(fleet, 1, 0)
    assert slot is None and len(lo) == 30 - (ENTRY - 1) + 1  # to its last waypoint, inside the guard


def test_opposite_streams_hold_tokens_together_crossing_ones_do_not():
    """Corridors are the hold regions along the path (±1.1 m across): opposite lanes 3.2 m apart
    do not meet, so both streams cross at once; a crossing one waits."""
    k = {v: ENTRY - 1 for v in "ABC"}
    for paths, want in (({"A": EAST, "B": WEST}, {"A", "B"}), ({"A": EAST, "B": WEST, "C": NORTH}, {"A", "B"}),
                        ({"A": NORTH, "B": SOUTH}, {"A", "B"}), ({"A": EAST, "C": NORTH}, {"A"})):
        gate = _gate()
        assert Scene(paths, k=k).withhold(gate) == want == _holders(gate), paths


def test_a_token_given_back_at_a_red_is_needed_again_from_inside():
    """A holds the token with its stop point inside the guard, then stands at a red light and
    gives it back (tm.signals): its next request needs the token again; B, crossing and waiting
    since before, gets it first (A's standing claim is not on B's route), and A waits."""
    gate = _gate()
    assert Scene({"A": EAST}, k={"A": ENTRY - 1}).withhold(gate, t=0) == {"A"}
    assert Scene({"A": EAST, "B": NORTH}, k={"A": ENTRY + 3, "B": ENTRY - 1}).withhold(gate, t=1) == {"A"}
    gate.give_back(["A"])
    assert _holders(gate) == set() and gate.given_back == {"A": {0}}
    gate.give_back([])  # the light turned green: A asks again
    asked = Scene({"A": EAST, "B": NORTH}, k={"A": ENTRY + 3, "B": ENTRY - 1}).withhold(gate, t=2)
    assert asked == {"B"} == _holders(gate)
    gate = _gate()  # alone, A gets it back
    assert Scene({"A": EAST}, k={"A": ENTRY - 1}).withhold(gate, t=0) == {"A"}
    gate.give_back(["A"])
    gate.give_back([])
    assert Scene({"A": EAST}, k={"A": ENTRY + 3}).withhold(gate, t=1) == {"A"} == _holders(gate)
    assert gate.given_back == {}


def test_no_admission_into_a_holders_corridor():
    gate = _gate()
    fam, centre, heading = np.array(["car", "car"]), np.array([[0.0, -1.6], [0.0, 30.0]]), np.zeros(2)
    assert gate.admissible(np.array([True, True]), fam, centre, heading).tolist() == [True, True]
    assert Scene({"A": EAST}, k={"A": ENTRY - 1}).withhold(gate) == {"A"}
    assert gate.admissible(np.array([True, True]), fam, centre, heading).tolist() == [False, True]


@st.composite
def fleets(draw):
    n = draw(st.integers(1, 8))
    rng = np.random.default_rng(draw(st.integers(0, 2**31 - 1)))
    roads = [EAST, WEST, NORTH, SOUTH, ((-30.0, 1.6), (1.6, 60.0))]  # the last one turns left-ish
    vehicles = {f"v{i}": roads[rng.integers(len(roads))] for i in range(n)}
    k = {v: int(rng.integers(ENTRY - 8, ENTRY)) for v in vehicles}
    idle = [v for v in vehicles if rng.random() < 0.3]
    return vehicles, k, idle, int(draw(st.integers(1, 40)))


@settings(max_examples=60, deadline=None)
@given(fleets())
def test_holders_corridors_never_meet_and_only_holders_stop_inside(case):
    """Random fleets around one junction, each vehicle moving its stop point on by one waypoint a
    round when its request stays (claims: its hold box): after every round the stored corridors of
    two holders are apart unless both drive the same road (a queue through the junction), and
    every stop point between an entry line and its exit slot is a holder's."""
    vehicles, k, idle, rounds = case
    gate = _gate()
    for t in range(rounds):
        scene = Scene(vehicles, k=k, idle=idle)
        asked = scene.withhold(gate, t=t)
        held = list(gate.holders[0].items())
        for a in range(len(held)):
            for b in range(a + 1, len(held)):
                (va, (_, lo_a, hi_a)), (vb, (_, lo_b, hi_b)) = held[a], held[b]
                assert vehicles[va] == vehicles[vb] or not boxes_meet(lo_a, hi_a, lo_b, hi_b), (va, vb)
        k = {v: k[v] + (v in asked) for v in vehicles}
        moved = Scene(vehicles, k=k)
        for i, v in enumerate(moved.ids):
            zs, e, x, _ = gate.intervals(moved.fleet(), i)
            inside = bool(np.any((e <= k[v]) & (k[v] < x)))
            assert not inside or v in gate.holders[0], (v, k[v])


def _turn_scene(k_f: int, right_pad: float, f_holds: bool = False):
    """T (truck) holds the token at the last waypoint before its right turn into the north arm; F
    (car) queues behind it on the same lanes, stop point ``k_f``, asking for ``k_f + 1``.  T's
    claims up the north arm carry ``right_pad`` metres of body padding on their right (east) side,
    as SUMO's bent body of a long vehicle at a turn's start does (grid seed 1: bus 111 at D0, right
    pad 5.62 m): its boxes from the turn on swing back over the east arm, where F stands."""
    routes = {"T": _right_turn_east_to_north(), "F": _right_turn_east_to_north()}
    family, reach = {"T": "truck", "F": "narrow"}, {"truck": TRUCK, "narrow": NARROW}
    gate = AuthorityGate([J], {"narrow": NARROW, "truck": TRUCK})
    W, H = routes["T"]
    corner = int(np.flatnonzero(np.abs(H - H[0]) > 1e-9)[0]) - 1  # the last waypoint on the east arm
    t_in = int(gate.intervals(Scene({}, routes={"T": routes["T"]}, family=family, reach=reach).fleet(), 0)[1][0])
    assert Scene({}, routes={"T": routes["T"]}, k={"T": t_in - 1}, family=family, reach=reach).withhold(gate) == {"T"}

    def pads(rows, idx):
        out = np.zeros((len(idx), 4))
        out[(np.asarray(rows) == 0) & (np.asarray(idx) > corner), 2] = right_pad  # T: its boxes on the north arm
        return out

    W_f = routes["F"][0]
    # F drives up: its claims reach from its hold box forward to x = 9, inside the 10.3 m guard
    # (a holder keeps its token while they do)
    claims = {"F": ((9.0, W_f[k_f, 1] - HOLD[1]), tuple(W_f[k_f] + HOLD))} if f_holds else None
    scene = Scene({}, routes=routes, k={"T": corner, "F": k_f}, idle="T", family=family, reach=reach,
                  claims=claims)
    fleet = replace(scene.fleet(), pads=pads)
    if f_holds:  # F follows T through (JunctionGate._follows): it holds the token too
        key, _, lo, hi = gate.route_through(fleet, 1, 0)
        gate.holders[0]["F"] = (key, lo, hi)
    req = gate.withhold(1, fleet, scene.requesting, np.zeros((1, 2)), np.zeros((1, 2)))
    assert ("F" in gate.holders[0]) == f_holds
    return gate, dict(zip(scene.ids, req)), W, corner


def test_a_follower_stays_out_of_the_claims_its_turning_leader_has_still_to_make():
    """The queue lock of issue 12 (grid seed 1, D0: bus 111 turning right at its entry, car 124
    standing 3.5 m behind it, for good): the holder's queue may close up to its current claims,
    not into the boxes of its path ahead that swing back over the arm it comes from.  With a 7 m
    right pad, T's box at the first north-arm waypoint reaches x = 1.6 + 1.6 + 1.2 + 7 = 11.4 m;
    F (hold box ±2.25 m) asking for the first waypoint whose box would reach past that (but stays
    outside the 10.3 m guard: no token needed) is withheld, by this rule alone.  Without the padding
    (T's turn claims stay in the north arm, x <= 4.4) the same request is made; and one waypoint
    further back F's request is made (it closes up as far as T's claims allow)."""
    W_f = _right_turn_east_to_north()[0]
    reach_x = 1.6 + TRUCK.across + 0.5 * TRUCK.width + 7.0       # 11.4: T's padded turn box, east edge
    k_ask = int(np.flatnonzero(W_f[:, 0] - HOLD[0] > reach_x)[-1])  # F's box now clear of it, next not
    assert W_f[k_ask + 1, 0] - HOLD[0] > GUARD_TRUCK + 0.2        # and outside the guard: no token asked
    for f_holds in (False, True):  # in grid's lock car 124 held D0's token too, following bus 111
        gate, asked, W, corner = _turn_scene(k_ask, 7.0, f_holds)
        assert not asked["F"] and gate.wide_withheld == 1, f_holds
        assert gate.waiting_on == {"F": ["T"]}  # kept out of T's path: it waits for T (analysis.waits)
    gate, asked, _, _ = _turn_scene(k_ask, 0.0)
    assert asked["F"] and gate.wide_withheld == 0
    gate, asked, _, _ = _turn_scene(k_ask - 1, 7.0)
    assert asked["F"] and gate.wide_withheld == 0


def test_a_turning_candidate_lets_a_waiter_beside_its_path_go_first():
    """The hand-out lock of issue 12 (grid seed 2: bus 84 took C1's token to turn left while bus 80
    waited at its entry line beside its path; 84's turn claims met 80's standing box and neither
    moved again), with the toy traffic manager :func:`_toy_traffic`.

    A (truck, turning right from the east arm into the north arm) and B (car, down the north arm's
    other lane) both stand at their entry lines from step 0; A is first in line (same wait, id
    order).  A's path up the north arm (x >= -1.2, to y = 17.8) meets B's standing box (x <= -0.5,
    y 10.75 .. 15.25); B's straight path (x <= 0.3) misses A's standing box on the east arm.  So A
    yields: B takes the token, passes, and A follows once B's claims have left the guard.  Without
    :meth:`AuthorityGate._yields` A takes the token, the manager denies its claims up the north arm
    (they meet B standing) and B waits for A's token: neither arrives."""
    routes = {"A": _right_turn_east_to_north(), "B": _route(*SOUTH)}
    family, reach = {"A": "truck", "B": "narrow"}, {"truck": TRUCK, "narrow": NARROW}
    gate = AuthorityGate([J], {"narrow": NARROW, "truck": TRUCK})
    entry = {v: int(gate.intervals(Scene({}, routes={v: routes[v]}, family=family, reach=reach).fleet(), 0)[1][0])
             for v in routes}
    k, last = _toy_traffic(gate, routes, family, reach, {v: entry[v] - 1 for v in routes}, steps=200)
    W_a, W_b = routes["A"][0], routes["B"][0]
    assert W_a[k["A"], 1] > 40.0 and W_b[k["B"], 1] < -20.0, (k, last)
    assert gate.yielded > 0


def test_waiters_that_would_all_yield_round_a_cycle_do_not_all_wait():
    """The yield rule's cycle (issue 12, ``grid`` seed 1 with path-frame plants: the four approaches
    of one zone each yielded to the next, nobody took the token, 33 of 150 never arrived).  The
    geometry is stubbed: ``meets[a][b]`` says whether a's path beyond its stop point meets b's
    standing box.  Round a cycle nobody yields (the first in line takes the token); a waiter yields
    to one that yields to nobody, and along a chain of such waiters to its end; where its targets
    lead only round a cycle it does not wait."""
    gate = AuthorityGate([J], {"narrow": NARROW})

    def with_relation(meets):
        gate.paths.standing = lambda fleet, row: row                              # noqa: E731
        gate.paths.beyond_meets = lambda fleet, row, z, box: box in meets[row]    # noqa: E731
        gate.paths.on_route = lambda fleet, row, j, ahead=0: np.zeros(len(j), dtype=bool)  # noqa: E731

    waiters = np.arange(4)
    with_relation({0: {1}, 1: {2}, 2: {3}, 3: {0}})  # each meets the next: a cycle of four
    assert [gate._yields(None, r, 0, waiters) for r in range(4)] == [False] * 4
    with_relation({0: {1}, 1: set(), 2: set(), 3: set()})  # 0 meets 1, 1 meets nobody: 0 lets 1 go
    assert gate._yields(None, 0, 0, waiters) and not gate._yields(None, 1, 0, waiters)
    with_relation({0: {1}, 1: {2}, 2: set(), 3: set()})  # a chain: 1 yields to 2, and 0 to 1
    assert gate._yields(None, 1, 0, waiters) and gate._yields(None, 0, 0, waiters)
    assert not gate._yields(None, 2, 0, waiters)
    with_relation({0: {1}, 1: {2}, 2: {3}, 3: {1}})  # 0 leads into the cycle 1 -> 2 -> 3 -> 1: nobody waits
    assert [gate._yields(None, r, 0, waiters) for r in range(4)] == [False] * 4
    with_relation({0: {1}, 1: {0}, 2: set(), 3: set()})  # mutual: neither is a target (paths meet both ways)
    assert not gate._yields(None, 0, 0, waiters) and not gate._yields(None, 1, 0, waiters)


# ----------------------------------------------------------------------------- chained zones
J2 = Zone("J2", (13.0, -5.0), (23.0, 5.0))  # its guard starts 1.6 m past J's: no car stands between


def _chain_run(gate, steps=300):
    """A through J then J2, B through J2 then J, on lanes whose corridors meet (0.8 m either side
    of the axis); each asks for its next waypoint every step and moves
    when the gate lets it (claims: the hold boxes).  Returns the stop points and, per step, the
    zones each one holds."""
    def turn(a, corner, b):
        W1, H1 = _route(a, corner)
        W2, H2 = _route(corner, b)
        return np.vstack([W1, W2[1:]]), np.r_[H1, H2[1:]]
    # A comes up from the south into J and turns east through J2; B comes down from the north into
    # J2 and turns west through J: neither one's entry line lies on the other's exit road
    routes = {"A": turn((0.0, -40.0), (0.0, -0.8), (60.0, -0.8)), "B": turn((18.0, 40.0), (18.0, 0.8), (-60.0, 0.8))}
    scene = Scene({}, routes=routes)
    f = scene.fleet()
    (za, ea, xa, _), (zb, eb, xb, _) = gate.intervals(f, 0), gate.intervals(f, 1)
    k = {"A": int(ea[za == 0][0]) - 1, "B": int(eb[zb == 1][0]) - 1}  # both at their first entry line
    held = []
    for t in range(steps):
        done = {v for v, (W, _) in routes.items() if k[v] >= len(W) - 1}
        asked = Scene({}, k=k, idle=done, routes=routes).withhold(gate, t=t)
        for v in asked:
            k[v] += 1
        held.append({v: {z for z in range(2) if v in gate.holders[z]} for v in routes})
    return k, held, (za, ea, xa), (zb, eb, xb), {v: len(W) - 1 for v, (W, _) in routes.items()}


@pytest.mark.parametrize("chain", [True, False])
def test_chained_zones_are_taken_together_or_two_vehicles_lock(chain):
    """Two zones whose guards lie 1.6 m apart (a car's standing box is 4.5 m long): a route through
    both enters the second guard before its exit slot from the first.  A (east, J then J2) and B
    (west, J2 then J), their corridors meeting in both zones, reach their first entry lines at
    once.  Asked for one zone at a time (``chain`` off), A takes J and B takes J2, each moves up
    to the next zone's entry line inside the guard it holds and waits there for the other's token:
    neither moves again (the ``fkk_in`` lock, issue 12).  Chained, A is handed both tokens at
    once, B neither; A drives through both and B follows: both reach their routes' ends."""
    gate = AuthorityGate([J, J2], {"car": CAR})
    gate.chain = chain
    k, held, (za, ea, xa), (zb, eb, xb), ends = _chain_run(gate)
    assert ea[za == 1][0] <= xa[za == 0][0] and eb[zb == 0][0] <= xb[zb == 1][0]  # the chain, both ways
    if chain:
        assert k == ends
        assert held[0] == {"A": {0, 1}, "B": set()}  # both tokens at the first hand-out, to A alone
        # never one token each; B was handed J once A had left it, and gave it back (J2 was A's)
        assert not any(h["A"] and h["B"] and h["A"] | h["B"] == {0, 1} for h in held)
        assert gate.chain_revoked > 0
    else:
        assert held[0] == {"A": {0}, "B": {1}}
        assert k["A"] < ends["A"] and k["B"] < ends["B"]
        assert held[-1] == {"A": {0}, "B": {1}}  # for good: each waits for the other's token


@pytest.mark.parametrize("all_or_none", [True, False])
def test_a_vehicle_held_back_in_one_chained_zone_takes_no_token_in_the_other(all_or_none):
    """SUMO's ``fkk_in`` (issue 12): ``4_vertical.0`` waited longest for ``276184048`` and ``gneJ21``,
    chained; cars standing at a red held it back in ``gneJ21``, yet it took ``276184048``'s token
    every round and gave it back (all or none), and ``1_right.1``, next in line for both, lost
    ``276184048`` to it and gave back ``gneJ21``'s: for good.  A (east through J, then J2) waits
    longest; a standing car I on A's path in J2 holds A back there.  B, straight south
    through J alone, crosses A's corridor in J (and neither one's path meets the other's standing box
    or exit slot).  With ``all_or_none`` A takes no token in J and B
    takes J's; without, A takes J's, B waits behind it, and A gives J's back: nobody moves."""
    gate = AuthorityGate([J, J2], {"car": CAR})
    gate.all_or_none = all_or_none
    routes = {"A": _route((-40.0, -0.8), (60.0, -0.8)), "B": _route(*SOUTH), "I": _route((16.0, -0.8), (60.0, -0.8))}
    f = Scene({}, routes=routes).fleet()
    (za, ea, xa, _), (zb, eb, _, _) = gate.intervals(f, 0), gate.intervals(f, 1)
    assert ea[za == 1][0] <= xa[za == 0][0] and zb.tolist() == [0]  # A: J and J2 chained; B: J only
    k = {"A": int(ea[za == 0][0]) - 1, "B": int(eb[0]) - 1, "I": 2}  # I at x = 18, in J2's guard
    gate.wait[(0, "A")] = gate.wait[(1, "A")] = -1  # A has waited longest
    for t in range(3):
        asked = Scene({}, k=k, idle="I", routes=routes).withhold(gate, t=t)
        assert asked == ({"B"} if all_or_none else set()), t
        assert _holders(gate) == ({"B"} if all_or_none else set()) and not gate.holders[1]
    assert (gate.chain_revoked == 0) == all_or_none


def _stalled_holder_run(h_x: float, stall_steps, steps: int = 12) -> tuple[AuthorityGate, list]:
    """H (truck) takes the token at its entry line on the east arm to turn right into the north arm,
    then stands (not asking) with its stop point at ``x = h_x`` on the east arm, inside the guard;
    C (car) comes down the north arm's other lane (x = -1.6) to go straight through, standing at
    its entry line and asking.  Their corridors meet at the corner (H's box there spans both
    headings: x >= 1.6 - 4.25); C's corridor (x <= -0.5) misses H's standing box when it stands at
    x = 8 (x >= 4.25), not at the corner (x = 1.6).  Returns the gate and, per step, whether C's
    request was let through."""
    routes = {"H": _right_turn_east_to_north(), "C": _route(*SOUTH)}
    family, reach = {"H": "truck"}, {"truck": TRUCK}
    gate = AuthorityGate([J], {"car": CAR, "truck": TRUCK})
    gate.stall_steps = stall_steps
    entry = {v: int(gate.intervals(Scene({}, routes={v: routes[v]}, family=family, reach=reach).fleet(), 0)[1][0])
             for v in routes}
    assert Scene({}, routes={"H": routes["H"]}, k={"H": entry["H"] - 1}, family=family,
                 reach=reach).withhold(gate, t=0) == {"H"}
    k_h = int(np.argmin(np.linalg.norm(routes["H"][0] - (h_x, 1.6), axis=1)))
    let = []
    for t in range(1, steps + 1):
        scene = Scene({}, routes=routes, k={"H": k_h, "C": entry["C"] - 1}, idle="H", family=family, reach=reach)
        let.append("C" in scene.withhold(gate, t=t))
        assert "H" in gate.holders[0]
    return gate, let


@pytest.mark.parametrize("h_x, stall_steps, first", [(8.0, 5, 6), (8.0, None, None), (1.6, 5, None)])
def test_a_waiter_passes_a_stalled_holder_off_its_standing_box(h_x, stall_steps, first):
    """The 6 x 6 grid's lock of issue 12 (bench_scale, D5): holder bus 247 stood at its turn's start,
    its next claims meeting bus 318's standing claim in the next lane; 318 waited for the token in
    line behind bus 263, whose corridor met 247's corridor: none of the three moved again.  A holder
    whose stop point has not moved for ``stall_steps`` steps no longer holds back a candidate whose
    corridor misses its standing box (:meth:`AuthorityGate._passable`): C takes the token beside H
    at step 1 + ``stall_steps`` (its stop point set at step 1, the first step it was seen), never while H stands
    in C's corridor, nor with the rule off."""
    gate, let = _stalled_holder_run(h_x, stall_steps)
    assert let.index(True) + 1 == first if first else not any(let), let
    assert ("C" in gate.holders[0]) == bool(first) and (gate.stalled_passed > 0) == bool(first)


@pytest.mark.parametrize("stall_steps", [3, None])
def test_a_waiter_held_back_by_a_stalled_holder_alone_holds_nobody_back(stall_steps):
    """A holds the token, standing in the middle of the zone (x = 0 on the east-bound lane); B
    (north-bound, waiting longest) crosses A's corridor and A's standing box (x -2.25 .. 2.25 meets
    B's corridor, x 0.5 .. 2.7): B waits for A.  D (west-bound) misses A's corridor and standing box
    but crosses B's corridor: it waits behind B (``pass_blocked``) -- until A has stood for
    ``stall_steps`` steps: then B, held back by a stalled holder alone, holds nobody back and D
    takes a token (:meth:`JunctionGate._hand_out` with :meth:`AuthorityGate._stalled`); B still
    waits.  Off (None), D waits as long as A stands."""
    gate = _gate()
    gate.stall_steps = stall_steps
    assert Scene({"A": EAST}, k={"A": ENTRY - 1}).withhold(gate, t=0) == {"A"}
    gate.wait[(0, "B")] = -1
    let = []
    for t in range(1, 8):
        scene = Scene({"A": EAST, "B": NORTH, "D": WEST}, k={"A": 30, "B": ENTRY - 1, "D": ENTRY - 1}, idle="A")
        asked = scene.withhold(gate, t=t)
        assert "B" not in asked and "A" in gate.holders[0]
        let.append("D" in asked)
    assert let == ([False] * 3 + [True] * 4 if stall_steps else [False] * 7)
    assert gate.stalled_passed == 0  # B was not let past A: its corridor meets A's standing box


def test_a_chain_of_zones_is_wanted_together_from_its_first_entry():
    """A route east through five zones: Z0 (passed already), then A, B and C, each guard beginning
    before the exit slot of the one before: B's entry lies at or before A's exit slot, C's only
    before B's (past A's: reached through B), and D further on, apart.  A vehicle asking for A's
    entry wants A, B and C at once (:meth:`AuthorityGate._wanting`), not Z0 behind it nor D; one
    asking only for a waypoint between the zones wants nothing."""
    zones = [Zone("Z0", (-70.0, -5.0), (-60.0, 5.0)), Zone("A", (-5.0, -5.0), (5.0, 5.0)),
             Zone("B", (9.0, -5.0), (19.0, 5.0)), Zone("C", (23.0, -5.0), (33.0, 5.0)),
             Zone("D", (60.0, -5.0), (70.0, 5.0))]
    gate = AuthorityGate(zones, {"car": CAR})
    route = _route((-100.0, -1.6), (100.0, -1.6))
    f = Scene({}, routes={"V": route}).fleet()
    zs, e, x, _ = gate.intervals(f, 0)
    ent, ext = dict(zip(zs.tolist(), e.tolist())), dict(zip(zs.tolist(), x.tolist()))
    assert set(ent) == {0, 1, 2, 3, 4}
    assert ent[2] <= ext[1] < ent[3] <= ext[2] < ent[4] - 1  # B chained to A; C to B only; D apart
    assert ext[0] < ent[1] - 1  # Z0 lies behind, with room between
    for k, want in ((ent[1] - 1, [1, 2, 3]), (ext[0] + 1, [])):
        f = Scene({}, k={"V": k}, routes={"V": route}).fleet()
        wz, wr = gate._wanting(f, np.array([0]), np.zeros((1, 2)), np.zeros((1, 2)))
        assert sorted(wz.tolist()) == want and set(wr.tolist()) <= {0}


def test_queue_lanes_are_judged_per_zone():
    """:meth:`AuthorityGate._follows` compares the follower's path through a zone with its leader's
    (kept per pair of paths).  A and its leader B drive east in one lane through J; at K B turns
    north while A goes on: through J they are a queue, through K not -- also when the gate judged
    J for the same pair before."""
    K = Zone("K", (35.0, -5.0), (45.0, 5.0))
    east = _route((-40.0, -1.6), (100.0, -1.6))
    w1, h1 = _route((-40.0, -1.6), (38.4, -1.6))
    w2, h2 = _route((38.4, -1.6), (38.4, 60.0))
    turn = (np.vstack([w1, w2[1:]]), np.r_[h1, h2[1:]])

    def follows(gate, z, k):
        scene = Scene({}, k=k, routes={"A": east, "B": turn})
        return gate._follows(scene.fleet(), {"A": 0, "B": 1}, 0, z, ["B"])

    gate = AuthorityGate([J, K], {"car": CAR})
    f = Scene({}, routes={"A": east}).fleet()
    zs, e, _, _ = gate.intervals(f, 0)
    entry = dict(zip(zs.tolist(), e.tolist()))
    at_j = {"A": entry[0] - 1, "B": entry[0] + 6}
    at_k = {"A": entry[1] - 1, "B": entry[1] + 6}
    assert follows(gate, 0, at_j)          # one lane through J: a queue
    assert not follows(gate, 1, at_k)      # through K B turns away: not one
    assert not follows(AuthorityGate([J, K], {"car": CAR}), 1, at_k)  # the same judged afresh


def test_wide_paths_asked_together_equal_each_asked_alone():
    """:meth:`tm.gate_paths.GatePaths.wide_paths` computes the paths not kept yet together, one class at a
    time (the keep-out rule asks for every holder's at once): the same boxes as each asked alone on a
    fresh gate, for vehicles of two classes with body padding, a stop point past the slot (None) and
    a repeated ask; kept answers are the computed ones."""
    routes = {"A": _right_turn_east_to_north(), "B": _route(*NORTH), "C": _route(*WEST), "D": _route(*EAST)}
    family = {"A": "truck", "B": "narrow", "C": "truck", "D": "narrow"}
    reach = {"truck": TRUCK, "narrow": NARROW}
    k = {"A": 15, "B": 18, "C": 25, "D": 60}  # D: past its exit slot

    def pads(rows, idx):
        rows, idx = np.asarray(rows), np.asarray(idx)
        return np.column_stack([0.1 * rows, 0.05 * idx, 0.3 * (rows % 2), 0.01 * idx * (rows + 1)])

    scene = Scene({}, routes=routes, k=k, family=family, reach=reach)
    fleet = replace(scene.fleet(), pads=pads)
    asks = [(0, 0, 15), (1, 0, 18), (2, 0, 27), (3, 0, 60), (1, 0, 18), (0, 0, 16)]
    gate = AuthorityGate([J], {"narrow": NARROW, "truck": TRUCK})
    together = gate.paths.wide_paths(fleet, asks)
    assert together[3] is None and all(p is not None for n, p in enumerate(together) if n != 3)
    for ask, got in zip(asks, together):
        alone = AuthorityGate([J], {"narrow": NARROW, "truck": TRUCK}).paths.wide_path(fleet, *ask)
        if alone is None:
            assert got is None
            continue
        np.testing.assert_array_equal(got[0], alone[0])  # the same floats: elementwise, as alone
        np.testing.assert_array_equal(got[1], alone[1])
        kept = gate.paths.wide_path(fleet, *ask)
        assert kept[0] is got[0] or np.array_equal(kept[0], got[0])


def test_entry_limit_is_the_waypoint_before_the_first_guard_entry():
    """A vehicle entering on a route (bridge/departure.py) may have its first stop point up to the
    waypoint before the route's first guard interval: the east-bound route enters at waypoint 20, so
    19; a route starting inside the guard (its first interval starts at 0) is limited by the next one
    only; a route meeting no guard by its last waypoint."""
    gate = AuthorityGate([J], {"car": CAR})
    W, H = _route(*EAST)
    assert gate.entry_limit(W, H, "car") == ENTRY - 1
    W2 = np.vstack([W[ENTRY + 5:], W[-1] + np.array([[1.0, 0.0]])])  # from inside the guard, on east
    assert gate.entry_limit(W2, np.full(len(W2), 0.0), "car") == len(W2) - 1
    far, Hf = _route((-80.0, -1.6), (-40.0, -1.6))
    assert gate.entry_limit(far, Hf, "car") == len(far) - 1
    two = Zone("K", (45.0, -5.0), (55.0, 5.0))
    gate2 = AuthorityGate([J, two], {"car": CAR})
    assert gate2.entry_limit(W2, np.full(len(W2), 0.0), "car") < len(W2) - 1  # K ahead limits it


# ---------------------------------------------------------------- routes that only pass by a zone
BESIDE = ((30.0, 7.0), (-60.0, 7.0))  # west-bound, 7 m north of J's centre: its hold boxes reach J's guard


def test_a_route_that_does_not_pass_through_a_zone_has_no_interval_there():
    """``through`` names the zones a route passes through (SUMO: the junctions of its edges): a road
    beside the junction, whose hold boxes reach the guard, gets no entry line there and needs no token
    (SUMO's A10KW: the opposite carriageway beside an on-ramp merge); a vehicle left out of
    ``through`` keeps every zone its route reaches, as before."""
    scene = Scene({"A": EAST, "P": BESIDE})
    fleet = scene.fleet()
    old = _gate()
    assert old.intervals(fleet, 1)[0].tolist() == [0]  # without: P's route has an interval at J
    W, H = scene.routes[1]
    assert old.entry_limit(W, H, "car") < len(W) - 1
    gate = AuthorityGate([J], {"car": CAR}, through={"P": frozenset(), "A": frozenset({"J"})})
    assert gate.intervals(fleet, 1)[0].tolist() == [] and gate.intervals(fleet, 0)[0].tolist() == [0]
    assert gate.entry_limit(W, H, "car", "P") == len(W) - 1
    assert gate.passes(["P", "A", "X"], [0, 0, 0]).tolist() == [False, True, True]


def test_a_passer_by_neither_waits_for_the_token_nor_holds_the_zone_back():
    """P stands beside J on its own road (its stop point inside J's guard) with a claim box that covers
    A's corridor and exit slot (a world bounding box of claims along a diagonal road covers the next
    carriageway: SUMO's A10KW, 2026-12-07).  Its route does not pass through J, so it is neither an
    intruder in A's corridor nor a claim on A's exit slot: A takes the token, and P's own request to
    move on inside the guard is not withheld.  Without ``through`` P asks for J's token too, and A is
    held back by P's claim."""
    claim = ((-3.0, -4.0), (15.0, 9.0))  # covers A's corridor from x = -3 and its exit slot (x = 11)
    scene = Scene({"A": EAST, "P": BESIDE}, k={"A": ENTRY - 1, "P": 30}, claims={"P": claim})
    old = _gate()
    assert "A" not in scene.withhold(old) and "A" not in old.holders[0]
    gate = AuthorityGate([J], {"car": CAR}, through={"P": frozenset(), "A": frozenset({"J"})})
    assert scene.withhold(gate) == {"A", "P"} and set(gate.holders[0]) == {"A"}


def _diagonal(offset: float):
    """A route along the 45 degree diagonal through J, ``offset`` m to its left (lanes side by side)."""
    d, n = np.array([1.0, 1.0]) / np.sqrt(2.0), np.array([-1.0, 1.0]) / np.sqrt(2.0)
    return _route(tuple(-30.0 * d + offset * n), tuple(60.0 * d + offset * n))


@pytest.mark.parametrize("oriented", [True, False])
def test_lanes_side_by_side_on_a_diagonal_road_hold_the_token_together(oriented):
    """Two vehicles on lanes 3.2 m apart of a road at 45 degrees through a zone: their corridors'
    world boxes overlap (each box's diagonal reaches across the gap), their oriented boxes do not,
    so both take the token in the same round (A10KW's motorway merges took the one token in turn,
    whatever the lane).  A vehicle crossing their road still waits for them.  With the world boxes
    alone (``oriented`` False: the check the gate made before) only the first takes it."""
    gate = _gate()
    if not oriented:
        gate.corridors_meet = lambda *a: JunctionGate.corridors_meet(gate, *a)
    routes = {"A": _diagonal(-1.6), "B": _diagonal(1.6)}
    probe = Scene({}, routes=routes)
    entry = int(gate.intervals(probe.fleet(), 0)[1][0])
    assert int(gate.intervals(probe.fleet(), 1)[1][0]) == entry  # the same entry line on both lanes
    k = {"A": entry - 1, "B": entry - 1, "C": ENTRY - 1}
    scene = Scene({"C": SOUTH}, k=k, routes=routes)
    fleet = scene.fleet()
    ra, rb = (gate.route_through(fleet, scene.ids.index(v), 0) for v in "AB")
    assert boxes_meet(ra[2], ra[3], rb[2], rb[3])  # the world boxes overlap
    gate.wait.update({(0, "A"): -3, (0, "B"): -2, (0, "C"): -1})
    asked = scene.withhold(gate, t=0)
    assert asked == ({"A", "B"} if oriented else {"A"}) and _holders(gate) == asked


@pytest.mark.parametrize("turn_max_deg", [15.0, 30.0])
def test_a_turning_corridor_keeps_its_world_boxes(turn_max_deg):
    """Only through movements are compared as oriented boxes (``oriented_turn_max_deg``): lane A of
    a diagonal road (lanes 3.5 m apart) turns 20 degrees right, away from lane B, inside the zone;
    their oriented boxes miss, their world boxes meet.  With the default bound (15 degrees) A's
    corridor keeps its world boxes and B waits for A (on ``grid`` seed 5, oriented boxes on turning
    corridors locked 27 of 150); with a bound above its turn both take the token."""
    gate = _gate()
    gate.oriented_turn_max_deg = turn_max_deg
    W1, H1 = _diagonal(-1.75)
    cut = int(np.argmin(np.linalg.norm(W1 - W1[0] - 30.0 * np.array([1.0, 1.0]) / np.sqrt(2.0), axis=1)))
    h = np.pi / 4 - np.deg2rad(20.0)
    tail = W1[cut] + np.arange(1, 61)[:, None] * np.array([np.cos(h), np.sin(h)])
    routes = {"A": (np.vstack([W1[:cut + 1], tail]), np.r_[H1[:cut + 1], np.full(60, h)]), "B": _diagonal(1.75)}
    probe = Scene({}, routes=routes)
    k = {v: int(gate.intervals(probe.fleet(), i)[1][0]) - 1 for i, v in enumerate("AB")}
    scene = Scene({}, k=k, routes=routes)
    fleet = scene.fleet()
    ra, rb = (gate.route_through(fleet, scene.ids.index(v), 0) for v in "AB")
    assert boxes_meet(ra[2], ra[3], rb[2], rb[3])
    gate.wait.update({(0, "A"): -3, (0, "B"): -2})
    asked = scene.withhold(gate, t=0)
    assert asked == ({"A"} if turn_max_deg < 20.0 else {"A", "B"}) and _holders(gate) == asked


# ----------------------------------------------------------------------------- standing at a red
def test_a_candidate_whose_corridor_meets_a_car_at_a_red_waits_without_the_token():
    """SUMO's ``fkk_in`` (lights changed only by hand): a bicycle took ``gneJ21``'s token to turn left
    past the front of a car standing at its red, stopped short of it (the manager denied its claims)
    and held the token for the rest of the run.  R stands at a red on the north-bound lane inside
    the guard, its hold box up to y = -2.25 (-4.5 + 2.25); C, east-bound at y = -1.6 and waiting at
    its entry line, has a corridor ``hold_y + W/2`` = 1.1 m either side of its waypoints (down to
    y = -2.7): no waypoint of C's lies in R's box, but the corridor meets it.  C waits (counted
    ``red_yielded``) and takes the token once R's light is green (R no longer standing: then R's
    claim is an ordinary intruder, and C waits for it as before: here R moved off).  With R 1.5 m
    further south (hold box up to y = -3.75) C's corridor misses it and C takes the token at once;
    with the rule of :class:`JunctionGate` alone (waypoints in the box) C takes it beside R."""
    def run(r_y, gate=None):
        return _beside_a_red(EAST, ((1.6, r_y - 20.0), (1.6, 60.0)), gate)

    gate, asked = run(-4.5)
    assert asked == set() and _holders(gate) == set() and gate.red_yielded == 1
    gate, asked = run(-6.0)
    assert asked == {"C"} == _holders(gate) and gate.red_yielded == 0
    gate = _gate()
    gate._standing_hits = lambda *a: JunctionGate._standing_hits(gate, *a)  # the base rule alone
    gate, asked = run(-4.5, gate)
    assert asked == {"C"} == _holders(gate)


def _beside_a_red(c_route, r_route, gate=None):
    """C at its entry line asks for the token while R, at waypoint 20 of its route, stands at a red
    (:meth:`JunctionGate.give_back`); the gate (a fresh one unless given) and the requests that stay."""
    gate = gate or _gate()
    scene = Scene({"C": c_route, "R": r_route}, k={"C": ENTRY - 1, "R": 20}, idle="R")
    gate.give_back(["R"])  # R stands at a red (tm.signals)
    return gate, scene.withhold(gate)


def test_a_route_ending_in_the_guard_behind_a_car_at_a_red_waits_without_the_token():
    """The generated ``tlsgrid``: car 29, whose route ends at its lane's end beside a junction, took
    the token behind car 27 standing at the red in the guard on the same lane: its last waypoint
    lay 0.08 m clear of 27's claim box (the rule of :class:`JunctionGate`: waypoints in the box),
    its hold box there 2.6 m into it.  At green 27 waited for the token and 29 for 27, for good.
    C's route ends at x = -7 (waypoint 23, inside the guard: no exit slot); R stands at a red on
    C's lane at x = -4.5, its hold box from x = -6.75 (0.25 m clear of C's last waypoint, 2.0 m into
    C's hold box there).  C waits (``red_yielded``); with R at x = -1.5 (hold box from -3.75, 0.5 m
    clear of C's corridor box at x = -7, ±2.75 m) C takes the token; with the wide path cut at the
    exit slot as before (none here), C takes it beside R."""
    c = ((-30.0, -1.6), (-7.0, -1.6))
    assert len(_route(*c)[0]) == 24

    def run(r_x, gate=None):
        r = ((r_x - 20.0, -1.6), (r_x + 65.0, -1.6))
        assert np.allclose(_route(*r)[0][20], (r_x, -1.6))
        return _beside_a_red(c, r, gate)

    gate, asked = run(-4.5)
    assert asked == set() and _holders(gate) == set() and gate.red_yielded == 1
    gate, asked = run(-1.5)
    assert asked == {"C"} == _holders(gate) and gate.red_yielded == 0
    gate = _gate()
    gate.paths.path_idx = lambda f, r, z, first, to_end=False: GatePaths.path_idx(gate.paths, f, r, z, first)  # as before
    gate, asked = run(-4.5, gate)
    assert asked == {"C"} == _holders(gate)

def test_a_waiter_does_not_yield_to_one_that_waits_for_a_car_at_a_red():
    """The hand-out of :func:`test_a_turning_candidate_lets_a_waiter_beside_its_path_go_first`, with R
    standing at a red on B's lane inside the guard, ahead of B (B's corridor runs into R's box: B
    waits for R, not for the token, and takes none).  A yielded to B, for as long as R's light
    stayed red (SUMO's ``fkk_in``: ``1_horizontal.0`` let ``3_right.1`` go first for 120 s, which
    waited behind a car at a red).  Now A takes the token; without R, A yields to B as before."""
    routes = {"A": _right_turn_east_to_north(), "B": _route(*SOUTH), "R": _route(*SOUTH)}
    family, reach = {"A": "truck", "B": "narrow", "R": "narrow"}, {"truck": TRUCK, "narrow": NARROW}
    for with_r in (True, False):
        gate = AuthorityGate([J], {"narrow": NARROW, "truck": TRUCK})
        rs = routes if with_r else {v: routes[v] for v in "AB"}
        entry = {v: int(gate.intervals(Scene({}, routes={v: routes[v]}, family=family, reach=reach).fleet(), 0)[1][0])
                 for v in "AB"}
        k = {"A": entry["A"] - 1, "B": entry["B"] - 1, "R": entry["B"] + 6}
        if with_r:
            gate.give_back(["R"])
        scene = Scene({}, routes=rs, k={v: k[v] for v in rs}, idle="R", family=family, reach=reach)
        asked = scene.withhold(gate)
        assert (asked == {"A"} == _holders(gate)) == with_r, (with_r, asked)
        assert (gate.yielded > 0) != with_r


def _diagonal_exit():
    """East-bound on y = -1.6 to x = 0, then north-east (45 degrees) from (0, -1.6)."""
    W1, H1 = _route((-30.0, -1.6), (0.0, -1.6))
    W2, H2 = _route((0.0, -1.6), (60.0 / np.sqrt(2), -1.6 + 60.0 / np.sqrt(2)))
    return np.vstack([W1, W2[1:]]), np.r_[H1, H2[1:]]


def test_an_exit_slot_on_a_diagonal_road_is_free_beside_the_opposite_lane():
    """SUMO's ``fkk_in``: a car turning onto the diagonal road ``-148050455#0`` never found its exit
    slot free while a queue stood on the opposite lane ``148050455#0``: on a road not along an axis
    the world boxes of lanes side by side overlap.  C exits J onto a 45-degree road; Q stands on the
    lane to its left (3.2 m across, south-west bound) beside C's exit slot.  The world boxes of the
    slot and of Q's claim meet, their oriented boxes do not: with the claims' oriented boxes
    (:attr:`JunctionFleet.claim_polygons`) C takes the token (``slots_freed``); with world boxes
    only, it waits.  Q on C's own lane, on the slot, takes it in both."""
    gate = _gate()
    W, H = _diagonal_exit()
    fleet0 = Scene({}, routes={"C": (W, H)}).fleet()
    entry, slot = (int(a[0]) for a in gate.intervals(fleet0, 0)[1:3])
    left = np.array([-np.sin(H[-1]), np.cos(H[-1])])
    for shift, taken in ((3.2, False), (0.0, True)):
        q = W[slot] + shift * left
        ahead = 30.0 * np.array([np.cos(H[-1]), np.sin(H[-1])])
        Wq, Hq = _route(q + ahead, q - ahead)
        kq = int(np.argmin(np.linalg.norm(Wq - q, axis=1)))
        for oriented in (True, False):
            gate = _gate()
            scene = Scene({}, routes={"C": (W, H), "Q": (Wq, Hq)}, k={"C": entry - 1, "Q": kq}, idle="Q")
            fleet = scene.fleet()
            lo_q, hi_q = scene.hold_box(1)
            half = CAR.hold_half(H[slot:slot + 1])[0]
            lo_s, hi_s = W[slot] - half, W[slot] + half
            assert boxes_meet(lo_q[None], hi_q[None], lo_s[None], hi_s[None])  # the world boxes meet
            if oriented:
                fleet = replace(fleet, claim_polygons=scene.claim_polygons)
            req = gate.withhold(0, fleet, scene.requesting, np.zeros((1, 2)), np.zeros((1, 2)))
            got = "C" in _holders(gate)
            assert got == (oriented and not taken), (shift, oriented, req)
            assert gate.slots_freed == int(got)


def _diagonal_at(offset: float, deg: float = 30.0):
    """A straight route through the origin at ``deg`` degrees, ``offset`` m to the left of it, from
    30 m before the origin to 60 m past it, waypoints 1 m apart."""
    u = np.array([np.cos(np.deg2rad(deg)), np.sin(np.deg2rad(deg))])
    o = offset * np.array([-u[1], u[0]])
    return _route(o - 30.0 * u, o + 60.0 * u)


@pytest.mark.parametrize("case", ["behind", "beside"])
@pytest.mark.parametrize("oriented", [True, False])
def test_intruders_are_judged_on_the_corridor_ahead_as_oriented_boxes(case, oriented):
    """SUMO's ``fokr_bs_demo`` (issue 12): two cars standing side by side at a red light inside
    junction ``38`` had given their tokens back; at green each one's corridor met the other's claim
    box, world boxes of a road at 14 degrees, and one's also met the front of the car queued right
    behind it: none of the three moved again.  A stands inside J, its token given back, and asks
    again; I stands in the guard without a token, idle.  ``behind``: I is queued on A's lane, its
    front 0.25 m inside the corridor box at A's stop point (which reaches 2.75 m back) and 0.75 m
    clear of the next one.  ``beside``: A and I stand side by side on a road at 30 degrees, 3.2 m
    apart: their world boxes meet, their oriented boxes (1.1 m either side of each lane) do not.
    With :attr:`AuthorityGate.oriented_intruders` A takes the token; without, I holds it back."""
    gate = _gate()
    gate.oriented_intruders = oriented
    if case == "behind":
        routes = {"A": _route(*EAST), "I": _route(*EAST)}
        k = {"A": ENTRY + 5, "I": ENTRY}                                  # A at x = -5
        claims = {"I": ((-12.0, -1.6 - HOLD[1]), (-7.5, -1.6 + HOLD[1]))}  # its front 2.5 m behind A's stop point
        assert -12.0 < -GUARD  # in the guard
    else:
        routes = {"A": _diagonal_at(-1.6), "I": _diagonal_at(1.6)}
        k = {"A": 26, "I": 26}                                           # 4 m before the origin, side by side
        claims = {}
    scene = Scene({}, routes=routes, k=k, idle="I", claims=claims)
    fleet = scene.fleet()
    lo_a, hi_a = fleet.claim_lo[0], fleet.claim_hi[0]
    assert np.all(np.abs(lo_a) < GUARD) and np.all(np.abs(hi_a) < GUARD)  # A inside the guard

    fleet = replace(fleet, claim_polygons=scene.claim_polygons)
    key, _, c_lo, c_hi = gate.route_through(fleet, 0, 0)
    assert boxes_meet(c_lo, c_hi, fleet.claim_lo[1:], fleet.claim_hi[1:])  # the whole corridor's world boxes meet I
    gate.given_back["A"] = {0}
    asked = gate.withhold(0, fleet, scene.requesting, np.zeros((1, 2)), np.zeros((1, 2)))
    assert bool(asked[0]) == oriented and ("A" in _holders(gate)) == oriented


class _OneByOneIntruders(AuthorityGate):
    """:meth:`AuthorityGate._intruder_hits` as it was written before its pairs were taken all at once:
    candidate by candidate, the claims of its zone near its corridor ahead, then the oriented boxes."""

    def _intruder_hits(self, fleet, keys, zq, rq, first, c_lo, c_hi, zs, rs):
        first2, lo2, hi2 = corridors_ahead(first, c_lo, c_hi)
        hits = corridor_hits(zq, rq, first2, lo2, hi2, zs, rs, fleet.claim_lo, fleet.claim_hi)
        if fleet.claim_polygons is None or not hits.any():
            return hits
        self.oriented_asked = getattr(self, "oriented_asked", 0) + int(hits.sum())
        for q in np.flatnonzero(hits).tolist():
            a, b = int(first2[q]), int(first2[q + 1])
            js = rs[np.searchsorted(zs, zq[q], "left"):np.searchsorted(zs, zq[q], "right")]
            js = js[js != rq[q]]
            near = np.all((lo2[a:b, None] <= fleet.claim_hi[js]) & (hi2[a:b, None] >= fleet.claim_lo[js]),
                          axis=2).any(axis=0)
            js = js[near]
            hits[q] = len(js) > 0 and polygons_meet(self.boxes.ahead(fleet, int(rq[q]), keys[q], len(self._routes[keys[q]][2])),
                                                    fleet.claim_polygons(js)[0])
        return hits


def test_intruders_judged_all_at_once_as_candidate_by_candidate():
    """Queues on all four arms of ``J`` (three cars each, 6 m apart) and a car ``X`` on the west arm's
    lane whose route ends 4 m past the centre, inside the guard, without a token (an intruder in the
    north- and south-bound corridors once it stands there) under the toy traffic manager: the gate with
    :meth:`AuthorityGate._intruder_hits` taking every (candidate, claim) pair at once moves every
    vehicle as the candidate-by-candidate one does, step by step."""
    routes = {}
    for name, ((x0, y0), (x1, y1)) in {"E": EAST, "W": WEST, "N": NORTH, "S": SOUTH}.items():
        d = np.array([x1 - x0, y1 - y0]) / np.hypot(x1 - x0, y1 - y0)
        for i in range(3):
            a = np.array([x0, y0]) - 6.0 * i * d
            routes[f"{name}{i}"] = _route(a, (x1, y1))
    routes["X"] = _route((-30.0, 1.6), (4.0, 1.6))
    family = dict.fromkeys(routes, "car")
    runs = []
    for cls in (AuthorityGate, _OneByOneIntruders):
        gate = cls([J], {"car": CAR})
        runs.append((_toy_traffic(gate, routes, family, {"car": CAR}, {"X": 30}, steps=120, polygons=True),
                     gate))
    (got, mine), (want, ref) = runs
    assert got == want and mine.tokens_granted == ref.tokens_granted
    assert ref.oriented_asked > 0
