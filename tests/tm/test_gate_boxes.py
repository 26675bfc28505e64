"""tm.gate_boxes.GateBoxes: what the junction gate keeps of its corridors and exit slots as oriented
boxes (the gate's own rules on them: tests/tm/test_authority_gate.py)."""

import numpy as np

from tm.authority_reach import AuthorityReach
from tm.gate_boxes import GateBoxes

CAR = AuthorityReach(hold=0.2, hold_y=0.2, across=1.0, length=5.0, width=1.8, delta=3.0)


def _route(h_deg: float, n: int = 6, y0: float = 0.0):
    """A straight route along ``h_deg`` from ``(0, y0)``, 3 m between waypoints, then a bend: the last
    two headings turned by 30 degrees."""
    h = np.deg2rad(h_deg)
    W = np.array([[3.0 * i * np.cos(h), y0 + 3.0 * i * np.sin(h)] for i in range(n)])
    H = np.full(n, h)
    H[-2:] += np.deg2rad(30.0)
    return W, H


def test_through_corridors_keep_boxes_turns_do_not_and_meeting_is_cached():
    b = GateBoxes({"car": CAR})
    W, H = _route(45.0)
    idx, nxt = np.arange(0, 3), np.arange(1, 4)
    b.note_route(("a", 0, 0), CAR, W, H, idx, nxt, np.zeros((3, 4)), exits=True, turn_max_deg=15.0)
    assert b.corridor[("a", 0, 0)].shape == (6, 4, 2) and b.slot[("a", 0, 0)].shape == (2, 4, 2)
    # a corridor whose headings spread over 30 degrees keeps none, and counts as meeting (its world boxes stand)
    idx2, nxt2 = np.arange(2, 5), np.minimum(np.arange(3, 6), 5)
    b.note_route(("t", 0, 2), CAR, W, H, idx2, nxt2, np.zeros((3, 4)), exits=False, turn_max_deg=15.0)
    assert b.corridor[("t", 0, 2)] is None and ("t", 0, 2) not in b.slot
    assert b.corridors_meet(("a", 0, 0), ("t", 0, 2)) and b.corridors_meet(("a", 0, 0), ("gone", 0, 0))
    # a lane 3.5 m to the side on the same diagonal: world boxes overlap, oriented boxes miss
    W2, H2 = _route(45.0, y0=3.5 * np.sqrt(2.0))
    b.note_route(("b", 0, 0), CAR, W2, H2, idx, nxt, np.zeros((3, 4)), exits=False, turn_max_deg=15.0)
    assert not b.corridors_meet(("a", 0, 0), ("b", 0, 0))
    b.corridor[("b", 0, 0)] = b.corridor[("a", 0, 0)]  # the answer is kept per pair of keys
    assert not b.corridors_meet(("a", 0, 0), ("b", 0, 0)) and b.corridors_meet(("b", 0, 0), ("a", 0, 0))


def test_a_cut_keeps_both_headings_boxes_from_the_cut_on():
    b = GateBoxes({"car": CAR})
    m = 4
    b.corridor["k"] = np.arange(2 * m * 8, dtype=float).reshape(2 * m, 4, 2)
    b.cut("k", "k1", 1, m)
    assert np.array_equal(b.corridor["k1"], np.concatenate([b.corridor["k"][1:m], b.corridor["k"][m + 1:]]))
    b.cut("nothing", "n1", 1, m)  # a corridor not kept (a turn): nothing to cut
    assert "n1" not in b.corridor
