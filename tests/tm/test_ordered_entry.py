"""Ordered entry in the movement-authority junction layer (:meth:`tm.authority_gate.AuthorityGate._after`).

A candidate whose corridor through a zone meets a holder's takes the token after that holder when
it stands clear of every holder's wide path, then keeps out of those paths (:class:`tm.keep_out.KeepOut`)
until each holder lets the token go.  The scenes are those of ``test_authority_gate.py`` (its module
notes give the geometry): car class, 10 m zone ``J`` at the origin, straight routes with waypoints
1 m apart; every offset between the boxes compared is at least 0.05 m, far from round-off.

Wide paths (:meth:`tm.gate_paths.GatePaths.wide_path`): the claims' across half-width plus ``W/2``,
1.9 m, across; ``T^0 + L/2``, 2.25 m, along.  A's east-bound path (y = -1.6) covers y in
[-3.5, 0.3]; B's standing box on the north-bound lane (x = 1.6) covers x in [0.5, 2.7] and
its stop point's y +- 2.25.
"""

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings

from tm.authority_gate import AuthorityGate
from tm.boxes import boxes_meet
from tm.junctions import Zone
from tests.tm.test_authority_gate import CAR, EAST, ENTRY, EXIT, J, NORTH, Scene, _gate, _holders, fleets

#: B's last stop point whose standing box misses A's path (y = -30 + k; -30 + 24 + 2.25 = -3.75 < -3.5)
B_LAST = 24
#: A's first stop point whose path (boxes from x = -30 + k - 2.25 on) misses B's standing box (x <= 2.7)
A_PAST = 35


@pytest.mark.parametrize("ordered", [True, False])
def test_a_crossing_candidate_takes_the_token_after_the_holder_and_stays_out_of_its_path(ordered):
    """A (east-bound) holds the token; B, crossing, comes to its entry line.  With ordered entry B
    takes the token after A, comes up to the edge of A's path (stop point 24: its standing box 0.25 m
    short of it) and no further while A's path ahead still covers its own, then goes on once A's
    stop point is past (35), though A still holds the token.  Off, B waits at its entry line until
    A lets the token go."""
    gate = _gate()
    gate.ordered_entry = ordered
    assert Scene({"A": EAST}, k={"A": ENTRY - 1}).withhold(gate, t=0) == {"A"}
    asked = Scene({"A": EAST, "B": NORTH}, k={"A": ENTRY, "B": ENTRY - 1}).withhold(gate, t=1)
    assert asked == ({"A", "B"} if ordered else {"A"}) and _holders(gate) == asked
    assert gate.after == ({(0, "B"): {"A"}} if ordered else {}) and gate.ordered_granted == int(ordered)
    if not ordered:
        return
    for t, (k_a, k_b, goes) in enumerate(((25, B_LAST - 1, True), (25, B_LAST, False), (A_PAST - 1, B_LAST, False),
                                          (A_PAST, B_LAST, True)), start=2):
        withheld = gate.wide_withheld
        asked = Scene({"A": EAST, "B": NORTH}, k={"A": k_a, "B": k_b}).withhold(gate, t=t)
        assert asked == ({"A", "B"} if goes else {"A"}), (k_a, k_b)
        assert gate.wide_withheld == withheld + (not goes) and _holders(gate) == {"A", "B"}


def test_after_is_forgotten_once_the_holder_lets_the_token_go():
    """A's stop point at its exit slot and its claim out of the guard: it lets the token go, and B
    (stop point at the edge of A's path) holds it alone, after nobody; it moves on."""
    gate = _gate()
    Scene({"A": EAST}, k={"A": ENTRY - 1}).withhold(gate, t=0)
    Scene({"A": EAST, "B": NORTH}, k={"A": ENTRY, "B": ENTRY - 1}).withhold(gate, t=1)
    beyond = ((8.4, -2.7), (14.0, -0.5))  # 0.2 m past the guard's edge (8.193)
    asked = Scene({"A": EAST, "B": NORTH}, k={"A": EXIT, "B": B_LAST}, claims={"A": beyond}).withhold(gate, t=2)
    assert asked == {"A", "B"} and _holders(gate) == {"B"} and gate.after == {}


def _right_pads(size: float):
    def pads(rows, idx):
        out = np.zeros((len(idx), 4))
        out[np.asarray(rows) == 0, 2] = size  # A: every box padded on its right (south) side
        return out
    return pads


@pytest.mark.parametrize("pad", [0.0, 6.0])
def test_no_token_after_a_holder_whose_path_covers_the_candidate_already(pad):
    """A's path padded 6 m on its right (a long body's swing) reaches y = -9.5, over B's standing box
    at its entry line (y up to -8.75): B would stand in A's way with the token, so it waits for A
    to let it go.  Without the padding B takes the token after A."""
    gate = _gate()
    Scene({"A": EAST}, k={"A": ENTRY - 1}).withhold(gate, t=0)
    scene = Scene({"A": EAST, "B": NORTH}, k={"A": ENTRY, "B": ENTRY - 1})
    fleet = replace(scene.fleet(), pads=_right_pads(pad))
    req = gate.withhold(1, fleet, scene.requesting, np.zeros((2, 2)), np.zeros((2, 2)))
    assert req.tolist() == [True, pad == 0.0] and _holders(gate) == ({"A"} if pad else {"A", "B"})


def test_no_token_after_a_holder_whose_route_ends_in_the_guard():
    """A's route ends at the zone's centre: it has no wide path to keep out of, and B waits."""
    gate = _gate()
    ends = ((-30.0, -1.6), (0.0, -1.6))
    Scene({"A": ends}, k={"A": ENTRY - 1}).withhold(gate, t=0)
    assert Scene({"A": ends, "B": NORTH}, k={"A": ENTRY, "B": ENTRY - 1}).withhold(gate, t=1) == {"A"}
    assert _holders(gate) == {"A"} and gate.after == {}


@pytest.mark.parametrize("case", ["chained", "holds_another"])
def test_no_ordered_token_for_a_vehicle_with_another_zones_token(case):
    """Two zones' tokens and one of them taken after a holder: on SUMO's ``fkk_in`` (junctions 3-5 m
    apart) a vehicle took ``gneJ21``'s token after ``1_left.0`` with ``gneJ220``'s, and ``1_left.0``
    waited to pass through ``gneJ220`` for it: 106 of 114 vehicles stood for good.  So a candidate
    that wants several zones this round (``chained``: zone K 5 m north of J, entered before B's exit
    slot from J) or holds another zone's token (``holds_another``: zone F far up B's road) waits for
    the holders its corridor meets."""
    K = Zone("K", (-5.0, 10.0), (5.0, 20.0)) if case == "chained" else Zone("F", (-5.0, 40.0), (5.0, 50.0))
    gate = AuthorityGate([J, K], {"car": CAR})
    Scene({"A": EAST}, k={"A": ENTRY - 1}).withhold(gate, t=0)
    scene = Scene({"A": EAST, "B": NORTH}, k={"A": ENTRY, "B": ENTRY - 1})
    if case == "holds_another":
        fleet = scene.fleet()
        key, _, lo, hi = gate.route_through(fleet, 1, 1)
        gate.holders[1]["B"] = (key, lo, hi)
        zs, _, x, _ = gate.intervals(fleet, 1)
        gate.pending[(1, "B")] = int(x[zs == 1][0])  # kept until B's stop point reaches F's exit slot
    else:
        wz, wr = gate._wanting(scene.fleet(), np.array([1]), np.zeros((1, 2)), np.zeros((1, 2)))
        assert sorted(wz.tolist()) == [0, 1]  # B wants both at once
    assert scene.withhold(gate, t=1) == {"A"} and _holders(gate) == {"A"} and gate.after == {}
    assert ("B" in gate.holders[1]) == (case == "holds_another")


@settings(max_examples=60, deadline=None)
@given(fleets())
def test_a_holder_meets_another_only_after_it_and_never_stands_in_its_path(case):
    """Random fleets around one junction (``test_authority_gate.fleets``), each vehicle moving its
    stop point on by one waypoint a round when its request stays (claims: its hold box), ordered
    entry on: after every round, two holders' stored corridors meet only when both drive the same
    road or one took the token after the other -- and then the later one's standing box misses the
    earlier one's wide path from its stop point on; every stop point between an entry line and its
    exit slot is a holder's."""
    vehicles, k, idle, rounds = case
    gate = _gate()
    for t in range(rounds):
        scene = Scene(vehicles, k=k, idle=idle)
        asked = scene.withhold(gate, t=t)
        k = {v: k[v] + (v in asked) for v in vehicles}
        moved = Scene(vehicles, k=k)
        fleet = moved.fleet()
        row = {v: i for i, v in enumerate(moved.ids)}
        held = list(gate.holders[0].items())
        for a in range(len(held)):
            for b in range(a + 1, len(held)):
                (va, (_, lo_a, hi_a)), (vb, (_, lo_b, hi_b)) = held[a], held[b]
                if vehicles[va] == vehicles[vb] or not boxes_meet(lo_a, hi_a, lo_b, hi_b):
                    continue
                first, later = (va, vb) if va in gate.after.get((0, vb), ()) else (vb, va)
                assert first in gate.after.get((0, later), ()), (va, vb)
                path = gate.paths.wide_path(fleet, row[first], 0, k[first])
                box = gate.paths.standing_box(fleet, row[later])
                assert path is not None and not boxes_meet(path[0], path[1], box[0][None], box[1][None]), (first, later)
        for i, v in enumerate(moved.ids):
            zs, e, x, _ = gate.intervals(fleet, i)
            inside = bool(np.any((e <= k[v]) & (k[v] < x)))
            assert not inside or v in gate.holders[0], (v, k[v])
