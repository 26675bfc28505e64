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
        lambda f, rows, js, ahead=0: np.full(len(js), on_route))


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
                      lambda f, rows, js, ahead=0: np.zeros(len(js), dtype=bool))
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
                      lambda f, rows, js, ahead=0: np.zeros(len(js), dtype=bool))
    assert out.tolist() == ([False, False, False] if third else [True, False, False])
    assert n == (2 if third else 1) and ko.mutual_released == (0 if third else 1)
    # who each withheld one was kept out for (analysis.waits): B for A; with C, A for B and C
    assert ko.kept_from == ({"A": ["B", "C"], "B": ["A"]} if third else {"B": ["A"]})


def _reference(ko, fleet, req, holders, paths, on_route):
    """The rule holder by holder, as :meth:`KeepOut.apply` wrote it before its pairs were taken all at
    once: the same answers expected."""
    ids = fleet.ids
    pos = {v: i for i, v in enumerate(ids)}
    out, by = req.copy(), {}
    r = np.flatnonzero(req)
    for hs in holders:
        for h in hs:
            row = pos[h]
            lo, hi = paths[h]
            p_lo, p_hi = lo.min(axis=0) - ko.margin, hi.max(axis=0) + ko.margin
            near = r[np.all((fleet.claim_lo[r] <= p_hi) & (fleet.claim_hi[r] >= p_lo), axis=1)]
            near = near[near != row]
            if not len(near):
                continue
            a_lo, a_hi = ko.standing_boxes(fleet, near, 1)
            n_lo, n_hi = ko.standing_boxes(fleet, near, 0)
            co = {pos[v] for v in hs}
            for i, j in enumerate(near.tolist()):
                h1 = np.all((a_lo[i] <= hi) & (a_hi[i] >= lo), axis=1)
                h0 = np.all((n_lo[i] <= hi) & (n_hi[i] >= lo), axis=1)
                if on_route(row, j):
                    h1, h0 = h1[1:], h0[1:]
                elif j in co:
                    continue
                if h1.any() and not h0.any():
                    by.setdefault(j, set()).add(row)
    out[list(by)] = False
    return out, len(by) - ko._mutual(ids, by, out)


@pytest.mark.parametrize("seed", range(20))
def test_all_pairs_at_once_give_what_the_holders_one_by_one_give(seed):
    """Random scenes: holders on the north- and east-bound lanes with wide paths of one to four boxes
    ahead of them, requesters on both lanes, some on a holder's route (its queue): the withheld
    requests and their count are those of the rule taken holder by holder."""
    rng = np.random.default_rng(seed)
    n = 12
    lanes = [_north, _east]
    routes = [lanes[i % 2](int(rng.integers(0, 40))) for i in range(n)]
    ids = [f"v{i}" for i in range(n)]
    half = [CAR.hold_half(np.array([H[k]]))[0] for _, H, k in routes]
    lo = np.array([W[k] - h for (W, _, k), h in zip(routes, half)])
    hi = np.array([W[k] + h for (W, _, k), h in zip(routes, half)])
    fleet = JunctionFleet(ids, np.array(["car"] * n), lo, hi,
                          (([W for W, _, _ in routes], [H for _, H, _ in routes], np.array([k for *_, k in routes])),))
    held = rng.choice(n, size=4, replace=False).tolist()
    holders = [{ids[held[0]]: None, ids[held[1]]: None}, {ids[held[2]]: None}, {ids[held[3]]: None}]
    paths = {}
    for i in held:
        W, H, k = routes[i]
        m = int(rng.integers(1, 5))
        idx = np.minimum(np.arange(k, k + m) + int(rng.integers(0, 3)), len(W) - 1)
        e = CAR.hold_half(H[idx]) + rng.uniform(0.0, 2.0, (m, 2))
        paths[ids[i]] = (W[idx] - e, W[idx] + e)
    queue = {(i, j): bool(rng.random() < 0.3) for i in range(n) for j in range(n)}
    req = rng.random(n) < 0.8
    ko = KeepOut({"car": CAR})
    out, count = ko.apply(fleet, req, holders, lambda f, asks: [paths[f.ids[row]] for row, _, _ in asks],
                          lambda f, rows, js, ahead=0: np.array([queue[a, b] for a, b in zip(rows.tolist(), js.tolist())],
                                                                 dtype=bool))
    want, want_count = _reference(KeepOut({"car": CAR}), fleet, req, holders, paths, lambda a, b: queue[a, b])
    assert out.tolist() == want.tolist() and count == want_count
