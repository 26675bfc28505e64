"""tm/keep_out.py: the keep-out rule of the movement-authority junction layer, on its own (the gate's
scenes that need it: tests/tm/test_authority_gate.py)."""

import numpy as np
import pytest

from tm.authority_reach import AuthorityReach
from tm.junctions import JunctionFleet
from tm.keep_out import KeepOut

CAR = AuthorityReach(hold=0.25, hold_y=0.2, across=1.0, length=4.0, width=1.8, delta=1.0)
#: a holder's wide path: one box across the north-bound lane from y = -16.8 on
PATH = (np.array([[0.0, -16.8]]), np.array([[3.0, -10.0]]))


def _north(k):
    """A car driving north on x = 1.6 (waypoints 1 m apart from y = -30) at stop point ``k``."""
    y = np.arange(-30.0, 61.0)
    return np.column_stack([np.full(len(y), 1.6), y]), np.full(len(y), np.pi / 2), k


def _fleet(ks: dict):
    """Holder "H" (its route unused here) and cars ``id -> stop point`` on the north-bound lane;
    every claim box the car's hold box at its stop point."""
    ids = ["H", *ks]
    routes = [_north(0)] + [_north(k) for k in ks.values()]
    h = CAR.hold_half(np.array([np.pi / 2]))[0]
    lo = np.array([W[k] - h for W, _, k in routes])
    hi = np.array([W[k] + h for W, _, k in routes])
    groups = (([W for W, _, _ in routes], [H for _, H, _ in routes], np.array([k for *_, k in routes])),)
    return JunctionFleet(ids, np.array(["car"] * len(ids)), lo, hi, groups)


def _apply(fleet, on_route=False):
    req = np.ones(len(fleet.ids), dtype=bool)
    return KeepOut({"car": CAR}).apply(
        fleet, req, [{"H": None}],
        lambda f, asks: [PATH if f.ids[row] == "H" else None for row, _, _ in asks],
        lambda f, row, rows, ahead=0: np.full(len(rows), on_route))


def test_a_request_into_a_holders_path_is_withheld_one_already_in_it_is_not():
    """R at y = -20 asks for y = -19: its standing box there (-21.25 .. -16.75) would meet the path
    (from -16.8 on), where it stands now (-22.25 .. -17.75) it does not: withheld.  S at y = -19
    stands in the path's reach already (it stood there before the token was handed out): kept (the
    rule does not help there, module notes).  A car far behind (y = -28): kept."""
    fleet = _fleet({"R": 10, "S": 11, "F": 2})
    out, n = _apply(fleet)
    assert dict(zip(fleet.ids, out.tolist())) == {"H": True, "R": False, "S": True, "F": True}
    assert n == 1


def test_the_holders_queue_counts_the_path_from_the_waypoint_after_its_stop_point():
    """On the holder's own route (its queue) a request counts against the path but its first box:
    with the path one box long, R's request is kept."""
    out, n = _apply(_fleet({"R": 10}), on_route=True)
    assert out.all() and n == 0


@pytest.mark.parametrize("margin_cut", [False, True])
def test_requesters_beyond_the_margin_are_not_looked_at(margin_cut):
    """The rule looks only at requesters whose claim box lies within ``margin`` of the path's box:
    with the margin cut to 0, R (its claim box 0.95 m short of the path) is no longer withheld."""
    fleet = _fleet({"R": 10})
    ko = KeepOut({"car": CAR})
    if margin_cut:
        ko.margin = 0.0
    out, n = ko.apply(fleet, np.ones(2, dtype=bool), [{"H": None}],
                      lambda f, asks: [PATH if f.ids[row] == "H" else None for row, _, _ in asks],
                      lambda f, row, rows, ahead=0: np.zeros(len(rows), dtype=bool))
    assert n == (0 if margin_cut else 1) and out[1] == margin_cut


def _east(k):
    """A car driving east on y = -1.6 (waypoints 1 m apart from x = -30) at stop point ``k``."""
    x = np.arange(-30.0, 61.0)
    return np.column_stack([x, np.full(len(x), -1.6)]), np.zeros(len(x)), k


@pytest.mark.parametrize("third", [False, True])
def test_two_holders_kept_out_of_each_others_path_one_goes(third):
    """A (north-bound, stop point y = -20) and B (east-bound, x = -20) each hold a token of their own
    zone; each asks for a stop point whose standing box (-21.25 .. -16.75 along) would enter the
    other's wide path (from -16.8 on), where each stands now it does not (SUMO's ``fkk_in``:
    ``1_left.0`` and ``2_right.0`` leaving two junctions 3 m apart whose exits merge, both kept out
    for good).  A (its id first) goes, B waits for it.  With a third holder C whose path A's request
    enters too, neither goes (only a pair is let go)."""
    routes = {"A": _north(10), "B": _east(10), "C": _east(0)}
    ids = list(routes)
    boxes = {"A": CAR.hold_half(np.array([np.pi / 2]))[0], "B": CAR.hold_half(np.array([0.0]))[0],
             "C": CAR.hold_half(np.array([0.0]))[0]}
    lo = np.array([routes[v][0][routes[v][2]] - boxes[v] for v in ids])
    hi = np.array([routes[v][0][routes[v][2]] + boxes[v] for v in ids])
    fleet = JunctionFleet(ids, np.array(["car"] * 3), lo, hi,
                          (([routes[v][0] for v in ids], [routes[v][1] for v in ids],
                            np.array([routes[v][2] for v in ids])),))
    paths = {"A": (np.array([[-16.8, -3.0]]), np.array([[-10.0, 0.0]])),   # across B's lane, ahead of B
             "B": PATH,                                                   # across A's lane, ahead of A
             "C": (np.array([[0.0, -16.8]]), np.array([[3.0, -10.0]]))}
    holders = [{"A": None}, {"B": None}] + ([{"C": None}] if third else [])
    req = np.array([True, True, False])
    ko = KeepOut({"car": CAR})
    out, n = ko.apply(fleet, req, holders, lambda f, asks: [paths[f.ids[row]] for row, _, _ in asks],
                      lambda f, row, rows, ahead=0: np.zeros(len(rows), dtype=bool))
    assert out.tolist() == ([False, False, False] if third else [True, False, False])
    assert n == (2 if third else 1) and ko.mutual_released == (0 if third else 1)
