"""Reach-tightened, time-indexed claims (tm/reach.py) and the one-lane fleet (tm/lane.py), as claims.

Tolerances: positions are compared with the claim boxes with GEOMETRY_TOL (1e-9 m) of slack: the
plant's repeated A x + B u + d and the closed-form reach A^k x ± r_k round differently by ~1e-13 m;
the tables themselves are already rounded outward by AUTHORITY_TABLE_TOL.
"""

import numpy as np
import pytest
from hypothesis import assume, given, settings as hsettings, strategies as st

from controllers.classes import get_class
from controllers.settings import SynthesisSettings
from controllers.synthesis import rotate_pairs
from controllers.tolerances import GEOMETRY_TOL
from tm.lane import Lane, LaneSettings, lane_class
from tm.manager import FleetState, TrafficManager
from tm.settings import TMSettings
from tm.reach import ReachModel, claims_conflict, pairwise_conflicts, reach_claims
from tests.tm.helpers import disturb as _disturb, lane_fleet

URBAN = ("car", "bus", "truck")


@pytest.fixture(scope="module")
def lcs(shared_set_cache):
    s = SynthesisSettings(cache_dir=shared_set_cache)
    return {c: lane_class(get_class(c), s) for c in URBAN}


def _point_model(lc):
    """The class's claim model with a zero footprint: boxes then bound the position itself."""
    r = lc.reach
    return ReachModel(r.Ak_al, r.Ak_ac, r.r_al, r.r_ac, r.tables, 0.0, 0.0, across=r.across)



@hsettings(max_examples=30, deadline=None)
@given(c=st.sampled_from(URBAN), seed=st.integers(0, 2 ** 31), heading=st.floats(-np.pi, np.pi),
       policy=st.sampled_from(["random", "adversarial", "push"]), sign=st.sampled_from([-1.0, 1.0]),
       frac=st.floats(0.0, 1.0))
def test_claims_are_sound_and_only_shrink_when_not_granted(lcs, c, seed, heading, policy, sign, frac):
    """A random state of T^l (any l, any heading), waypoint kept: x(t+k) lies in S_k(t) for every k
    (slot K: every later step), and S_k(t+1) ⊆ S_{k+1}(t) at every step."""
    lc = lcs[c]
    ctl, m, fam = lc.ctl, lc.vclass.model, lc.ctl.family
    rng = np.random.default_rng(seed)
    l0 = int(round(frac * fam.N))
    E = fam.sample(l0, 1, rng)                       # road frame, error coordinates
    cen = rng.uniform(-100, 100, (1, 2))
    hd = np.full(1, heading)
    X = rotate_pairs(E, hd) + np.hstack([cen, np.zeros((1, 2))])
    l = ctl.index(X, cen, hd)
    assume(l[0] <= fam.N)
    pm = _point_model(lc)
    S0 = reach_claims(pm, X, cen, hd, l)
    prev = S0
    K = pm.K
    for k in range(1, K + 8):
        U = ctl.control(X, cen, l, heading=hd)
        Ur = rotate_pairs(U, -hd)
        Xr = rotate_pairs(X - np.hstack([cen, np.zeros((1, 2))]), -hd)[0]
        d = _disturb(m, Xr, Ur[0], np.zeros(2), policy, rng, sign)
        X = X @ m.A.T + U @ m.B.T + rotate_pairs(d[None], hd)
        l = np.minimum(ctl.index(X, cen, hd), fam.N)
        p = rotate_pairs(X[:, :2] - cen, -hd)[0]     # position in the segment frame
        slot = min(k, K) - 1
        assert np.all(p >= S0.lo[0, slot] - GEOMETRY_TOL) and np.all(p <= S0.hi[0, slot] + GEOMETRY_TOL), (k, p)
        now = reach_claims(pm, X, cen, hd, l)
        want = prev.shift()
        assert np.all(now.lo >= want.lo - GEOMETRY_TOL) and np.all(now.hi <= want.hi + GEOMETRY_TOL)
        prev = now


def test_timed_is_less_conservative_than_union_and_both_see_overlap(lcs):
    """Two cars cruising 20 m apart: timed claims are disjoint, the union hulls meet; at 3 m both meet."""
    lc = lcs["car"]
    a = lc.ctl.authority
    X = np.array([[0.0, 0, 13.8, 0], [20.0, 0, 13.8, 0]])
    C = np.array([[a.s_ma - 4.0, 0], [20.0 + a.s_ma - 4.0, 0]])
    l = lc.ctl.index(X, C, np.zeros(2))
    assert np.all(l <= lc.ctl.N)
    S = reach_claims(lc.reach, X, C, np.zeros(2), l)
    assert not claims_conflict(S, [0], S, [1], "timed")[0]
    assert claims_conflict(S, [0], S, [1], "union")[0]
    X[1, 0], C[1, 0] = 3.0, 3.0 + a.s_ma - 4.0
    S = reach_claims(lc.reach, X, C, np.zeros(2), lc.ctl.index(X, C, np.zeros(2)))
    assert claims_conflict(S, [0], S, [1], "timed")[0] and len(pairwise_conflicts(S)[0]) == 1


@hsettings(max_examples=12, deadline=None)
@given(classes=st.lists(st.sampled_from(URBAN), min_size=2, max_size=5), gaps=st.lists(st.integers(4, 12), min_size=5,
       max_size=5), check=st.sampled_from(["timed", "union"]),
       policy=st.sampled_from(["random", "adversarial", "squeeze"]), seed=st.integers(0, 1000),
       red=st.integers(0, 80), deny=st.booleans(), tm=st.sampled_from(["front", "greedy", "optimal"]))
def test_random_fleets_on_a_lane_never_touch(lcs, classes, gaps, check, policy, seed, red, deny, tm):
    """Random mixed fleets placed at rest on one lane, entries at the lane start, a red light
    for ``red`` steps (or a TM that grants nothing), decisions front to back or by the traffic
    manager's policies (decide_reach): after every decision and every step the claims are
    pairwise disjoint, no two footprints overlap, the index invariant holds."""
    lane = Lane(LaneSettings(check=check, disturbance=policy, seed=seed, policy=tm))
    k = lane_fleet(lane, lcs, classes, gaps)
    assume(len(pairwise_conflicts(lane.all_claims(), check)[0]) == 0)
    lane.stop_k = k + 5
    lane.deny_all = deny
    for t in range(160):
        if t == red:
            lane.stop_k = None
        lane.try_enter(lcs["car"])
        lane.step()
    assert lane.claim_overlaps == 0 and lane.footprint_overlaps == 0 and lane.invariant_violations == 0
    assert len(lane.vehicles) >= len(classes)
    if not deny:
        assert lane.grants > 0


def test_counters_fire(lcs):
    """Each safety counter of the lane counts: claims placed overlapping, footprints overlapping,
    and a controller that ignores the tube (full throttle) breaks the index invariant."""
    lane = Lane(LaneSettings(disturbance="none"))
    lane.place(lcs["car"], 10)
    lane.place(lcs["car"], 11)  # 3 m apart: 5 m cars overlap
    lane.deny_all = True
    lane.step()
    assert lane.claim_overlaps > 0 and lane.footprint_overlaps > 0

    class Reckless:  # wraps the controller, returns +ū along
        def __init__(self, ctl):
            self._c = ctl

        def __getattr__(self, name):
            return getattr(self._c, name)

        def control(self, X, C, l, heading=None, v_cap=None):
            return np.tile([3.0, 0.0], (len(X), 1))

    lc = lcs["car"]
    bad = type(lc)(lc.vclass, Reckless(lc.ctl), lc.reach)
    lane = Lane(LaneSettings(disturbance="none"))
    lane.place(bad, 10)
    lane.deny_all = True
    for _ in range(5):
        lane.step()
    assert lane.invariant_violations > 0


def test_bad_lane_settings_are_named():
    with pytest.raises(ValueError, match="LaneSettings.check"):
        LaneSettings(check="both")
    with pytest.raises(ValueError, match="LaneSettings.disturbance"):
        LaneSettings(disturbance="gusty")
    with pytest.raises(ValueError, match="comfort_decel"):
        lane_class(get_class("paper-a"))


def _state(n, requesting):
    return FleetState(ids=[f"v{i}" for i in range(n)], family=["car"] * n, centre=np.zeros((n, 2)),
                      index=np.zeros(n, dtype=int), heading=np.zeros(n), length=np.full(n, 5.0),
                      width=np.full(n, 1.8), requesting=requesting, req_centre=np.zeros((n, 2)),
                      req_index=np.zeros(n, dtype=int), req_heading=np.zeros(n))


@pytest.mark.parametrize("policy", ["greedy", "optimal"])
def test_decide_reach_kinds_of_conflict(lcs, policy):
    """decide_reach on hand-made claims: a new claim that meets a non-requester's claim is denied
    (forced); two requesters whose new claims meet cannot both go, and one whose new claim meets
    the other's current claim needs it granted (optimal: the largest feasible set); claims after
    the decision are disjoint (verify on)."""
    lc = lcs["car"]
    ctl = lc.ctl
    tmgr = TrafficManager(TMSettings(check="timed", policy=policy, verify=True),
                          {"car": ctl.family.position_sets}, rotating={"car"})
    # v0 at rest on waypoint 30 (fixed, not requesting); v1 at rest 4 waypoints behind asks for 1 more
    # -> its new claim reaches v0's; v2, v3 at rest far ahead, 3 waypoints apart, both ask for 1 more
    X = np.array([[90.0, 0, 0, 0], [78.0, 0, 0, 0], [300.0, 0, 0, 0], [309.0, 0, 0, 0]])
    k = np.array([30, 26, 100, 103])
    C = np.column_stack([k * 3.0, np.zeros(4)])
    l = ctl.index(X, C, np.zeros(4))
    cur = reach_claims(lc.reach, X, C, np.zeros(4), l)
    assert len(pairwise_conflicts(cur)[0]) == 0
    req = np.array([False, True, True, True])
    Cn = np.column_stack([(k + 1) * 3.0, np.zeros(4)])
    Cn[1, 0] = 87.0   # v1 asks for the waypoint right behind v0: its claim reaches v0's body
    Cn[2, 0] = 306.0  # v2 asks for v3's waypoint, v3 for one beyond: new claims meet only each other
    ln = ctl.index(X, Cn, np.zeros(4))
    assert np.all(ln <= ctl.N)
    new = reach_claims(lc.reach, X[req], Cn[req], np.zeros(3), ln[req])
    dec = tmgr.decide_reach(_state(4, req), cur, new)
    assert not dec.go[1] and dec.forced[1]
    assert not (dec.go[2] and dec.go[3])
    if policy == "optimal":  # the only largest feasible set: v3 goes (v2 would need v3's old claim gone)
        assert dec.go[3] and not dec.go[2]
    assert len(pairwise_conflicts(dec.claims)[0]) == 0
    kinds = set(dec.edge_kinds.tolist())
    assert "new-fixed" in kinds


@hsettings(max_examples=30, deadline=None)
@given(c=st.sampled_from(URBAN), seed=st.integers(0, 2 ** 31), heading=st.floats(-np.pi, np.pi),
       frac=st.floats(0.0, 1.0), pad=st.tuples(st.floats(0.0, 3.0), st.floats(0.0, 3.0)))
def test_body_pad_widens_every_box_by_exactly_the_pad(lcs, c, seed, heading, frac, pad):
    """``body_pad`` (the simulator's body beyond the footprint rectangle, bridge.sumo_body) moves
    every non-empty box's sides out by exactly the pad (tolerance 1e-9 m, round-off), keeps empty
    boxes empty, and :func:`tm.reach_book.tube_escapes` given the same pad still finds the position
    part (no escape for ``x(t)`` itself in ``S_1``'s position box; an escape 0.1 m outside it)."""
    from tm.reach_book import tube_escapes

    lc = lcs[c]
    fam = lc.ctl.family
    rng = np.random.default_rng(seed)
    l0 = int(round(frac * fam.N))
    E = fam.sample(l0, 1, rng)
    cen = rng.uniform(-100, 100, (1, 2))
    hd = np.full(1, heading)
    X = rotate_pairs(E, hd) + np.hstack([cen, np.zeros((1, 2))])
    l = lc.ctl.index(X, cen, hd)
    assume(l[0] <= fam.N)
    base = reach_claims(lc.reach, X, cen, hd, l)
    padded = reach_claims(lc.reach, X, cen, hd, l, body_pad=np.array([pad]))
    ok = (base.lo <= base.hi).all(axis=-1)
    np.testing.assert_allclose(padded.lo[ok], base.lo[ok] - np.array(pad), atol=1e-9)
    np.testing.assert_allclose(padded.hi[ok], base.hi[ok] + np.array(pad), atol=1e-9)
    assert np.all(padded.lo[~ok] > padded.hi[~ok])
    L, Wd = lc.reach.length, lc.reach.width
    mid = 0.5 * (padded.lo[0, 0] + padded.hi[0, 0])  # centre of S_1, in the segment frame
    inside = cen + rotate_pairs(mid[None], hd)
    assert not tube_escapes(padded, inside, [L], [Wd], pad=np.array([pad]))[0]
    half = 0.5 * (padded.hi[0, 0] - padded.lo[0, 0]) - np.array([0.5 * L, 0.5 * Wd]) - np.array(pad)
    out = cen + rotate_pairs((mid + np.array([half[0] + 0.1, 0.0]))[None], hd)
    assert tube_escapes(padded, out, [L], [Wd], pad=np.array([pad]))[0]
    with pytest.raises(ValueError, match="body_pad"):
        reach_claims(lc.reach, X, cen, hd, l, body_pad=np.array([[-0.1, 0.0]]))


@hsettings(max_examples=30, deadline=None)
@given(c=st.sampled_from(URBAN), seed=st.integers(0, 2 ** 31), heading=st.floats(-np.pi, np.pi),
       frac=st.floats(0.0, 1.0), pad=st.tuples(*[st.floats(0.0, 3.0)] * 4))
def test_one_sided_body_pad_moves_each_side_by_its_own_pad(lcs, c, seed, heading, frac, pad):
    """A one-sided ``body_pad`` ``(back, front, right, left)`` (bridge.sumo_body.PadTable.pads)
    moves each side of every non-empty box by its own pad and no other (tolerance 1e-9 m,
    round-off), and :func:`tm.reach_book.tube_escapes` / :func:`tm.reach_book.footprint_claims`
    read it the same way: a position 0.1 m past ``S_1``'s position box on either side escapes,
    ``S_1``'s middle does not."""
    from tm.reach_book import footprint_claims, tube_escapes

    lc = lcs[c]
    fam = lc.ctl.family
    rng = np.random.default_rng(seed)
    E = fam.sample(int(round(frac * fam.N)), 1, rng)
    cen = rng.uniform(-100, 100, (1, 2))
    hd = np.full(1, heading)
    X = rotate_pairs(E, hd) + np.hstack([cen, np.zeros((1, 2))])
    l = lc.ctl.index(X, cen, hd)
    assume(l[0] <= fam.N)
    p = np.array([pad])
    plo, phi = np.array([pad[0], pad[2]]), np.array([pad[1], pad[3]])
    base = reach_claims(lc.reach, X, cen, hd, l)
    padded = reach_claims(lc.reach, X, cen, hd, l, body_pad=p)
    ok = (base.lo <= base.hi).all(axis=-1)
    np.testing.assert_allclose(padded.lo[ok], base.lo[ok] - plo, atol=1e-9)
    np.testing.assert_allclose(padded.hi[ok], base.hi[ok] + phi, atol=1e-9)
    assert np.all(padded.lo[~ok] > padded.hi[~ok])
    L, Wd = lc.reach.length, lc.reach.width
    half = np.array([0.5 * L, 0.5 * Wd])
    plo_box, phi_box = padded.lo[0, 0] + half + plo, padded.hi[0, 0] - half - phi  # S_1's positions
    mid = 0.5 * (plo_box + phi_box)
    assert not tube_escapes(padded, cen + rotate_pairs(mid[None], hd), [L], [Wd], pad=p)[0]
    for e in ([phi_box[0] + 0.1, mid[1]], [plo_box[0] - 0.1, mid[1]],
              [mid[0], phi_box[1] + 0.1], [mid[0], plo_box[1] - 0.1]):
        assert tube_escapes(padded, cen + rotate_pairs(np.array([e]), hd), [L], [Wd], pad=p)[0]
    fp = footprint_claims(cen, hd, [L], [Wd], K=2, pad=p)
    np.testing.assert_allclose(fp.lo[0], np.tile(-half - plo, (2, 1)), atol=1e-12)
    np.testing.assert_allclose(fp.hi[0], np.tile(half + phi, (2, 1)), atol=1e-12)
    with pytest.raises(ValueError, match="body_pad"):
        reach_claims(lc.reach, X, cen, hd, l, body_pad=np.zeros((1, 3)))


@pytest.mark.parametrize("c", URBAN)
def test_across_extent_follows_the_across_factors_own_index(lcs, c):
    """A vehicle cruising on its lane's centre line (across state 0) far behind its stop point: its
    claims' across half-width is that of ``T_y^1`` (the across factor's own index 0, plus one level
    of slack) plus ``W/2`` at every slot, where the joint level's across range (the model without
    ``across``) reaches more than twice that at some slot (car 0.95 m, bus 1.58 m by ``T_y^N``)."""
    from dataclasses import replace

    lc = lcs[c]
    ctl, rm = lc.ctl, lc.reach
    v = 13.0
    X = np.array([[0.0, 0.0, v, 0.0]])
    lead = min(float(ctl.authority_lead()), 60.0)
    cen, hd = np.array([[lead, 0.0]]), np.zeros(1)
    l = ctl.index(X, cen, hd)
    assert l[0] <= rm.N
    tight = reach_claims(rm, X, cen, hd, l)
    loose = reach_claims(replace(rm, across=None), X, cen, hd, l)
    half_w = 0.5 * rm.width
    y1 = max(-rm.tables.y_lo[1], rm.tables.y_hi[1])
    full = (tight.lo <= tight.hi).all(axis=-1)[0]
    assert np.all(tight.hi[0, full, 1] <= y1 + half_w + GEOMETRY_TOL)
    assert np.all(-tight.lo[0, full, 1] <= y1 + half_w + GEOMETRY_TOL)
    assert loose.hi[0, full, 1].max() - half_w > 2.0 * y1
    # along, nothing changes
    assert np.array_equal(tight.lo[..., 0], loose.lo[..., 0]) and np.array_equal(tight.hi[..., 0], loose.hi[..., 0])


@hsettings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2 ** 31), n=st.integers(1, 6))
def test_drawn_polygon_holds_every_slot_box(seed, n):
    """ReachClaims.polygons (what ``--log full`` draws): for random boxes, headings and empty slots,
    every corner of every non-empty slot box lies in the vehicle's drawn polygon (within
    GEOMETRY_TOL: one rotation each way); a vehicle with no non-empty slot is drawn as its centre."""
    from tm.geometry import halfspaces
    from tm.reach import ReachClaims

    rng = np.random.default_rng(seed)
    K = 7
    a = rng.uniform(-20, 20, (n, K, 2))
    b = a + rng.uniform(-2, 10, (n, K, 2))  # some inverted: empty slots
    lo, hi = np.minimum(a, b), b
    lo[rng.random((n, K)) < 0.3] = np.inf  # empty slots as the claims mark them
    hi[np.isinf(lo[..., 0])] = -np.inf
    claims = ReachClaims(rng.uniform(-100, 100, (n, 2)), rng.uniform(-np.pi, np.pi, n), lo, hi)
    P = claims.polygons()
    assert P.shape == (n, 4, 2)
    for i in range(n):
        full = [k for k in range(K) if np.all(claims.lo[i, k] <= claims.hi[i, k])]
        if not full:
            assert np.allclose(P[i], claims.centre[i])
            continue
        A, c = halfspaces(P[i])
        for k in full:
            assert np.all(claims.world_corners(i, k + 1) @ A.T <= c + 1e-9)


@hsettings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2 ** 31), n=st.integers(1, 6))
def test_claim_polygons_are_the_slot_boxes_each_once(seed, n):
    """tm.reach.claim_polygons (the junction gate's oriented view of a vehicle's claims): for random
    boxes, headings, empty and repeated slots, the polygons of vehicle ``i`` are its non-empty slot
    boxes' world corners (``world_corners``, counter-clockwise, from the front right corner), each box once (a repeated slot
    shares its box in the claims' :class:`~tm.slot_boxes.SlotBoxes`: counted once), within 1e-9 m
    (the same rotation, a sum's rounding apart); with tight boxes (:class:`SlotBoxes`) too."""
    from tm.reach import ReachClaims, claim_polygons
    from tm.slot_boxes import SlotBoxes

    rng = np.random.default_rng(seed)
    K = 7
    a = rng.uniform(-20, 20, (n, K, 2))
    lo, hi = a, a + rng.uniform(0.1, 10, (n, K, 2))
    empty = rng.random((n, K)) < 0.3
    lo[empty], hi[empty] = np.inf, -np.inf
    claims = ReachClaims(rng.uniform(-100, 100, (n, 2)), rng.uniform(-np.pi, np.pi, n), lo, hi)
    u = SlotBoxes.from_frames(claims.centre, claims.heading, lo, hi)
    rep = np.concatenate([u.start[:, :1], u.start[:, :-1]], axis=1)  # slot k takes slot k - 1's box
    tight = ReachClaims(claims.centre, claims.heading, lo, hi, SlotBoxes(u.centre, u.heading, u.half, rep, u.count))
    for i in range(n):
        full = [k for k in range(K) if not empty[i, k]]
        P = claim_polygons(claims, i)
        assert P.shape == (len(full), 4, 2)
        for q, k in enumerate(full):
            # world_corners starts at the rear right corner, the polygons at the front right one
            want = np.roll(claims.world_corners(i, k + 1), -1, axis=0)
            np.testing.assert_allclose(P[q], want, rtol=0, atol=1e-9)
        T = claim_polygons(tight, i)
        want = sorted({int(rep[i, k]) for k in range(K) if u.count[i, k]})
        assert len(T) == len(want)


@hsettings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2 ** 31), n=st.integers(1, 6), m=st.integers(0, 8))
def test_claim_polygons_of_rows_are_each_rows_polygons(seed, n, m):
    """tm.reach.claim_polygons_of (the junction gate's batched view): for rows in any order, repeated
    or not, the boxes owned by position ``t`` are claim_polygons of ``rows[t]`` in the same order,
    exactly (the same arithmetic), and the owners are non-decreasing."""
    from tm.reach import ReachClaims, claim_polygons, claim_polygons_of

    rng = np.random.default_rng(seed)
    K = 5
    lo = rng.uniform(-20, 20, (n, K, 2))
    hi = lo + rng.uniform(0.1, 10, (n, K, 2))
    empty = rng.random((n, K)) < 0.3
    lo[empty], hi[empty] = np.inf, -np.inf
    claims = ReachClaims(rng.uniform(-100, 100, (n, 2)), rng.uniform(-np.pi, np.pi, n), lo, hi)
    rows = rng.integers(0, n, m)
    P, owner = claim_polygons_of(claims, rows)
    assert np.all(np.diff(owner) >= 0)
    for t, r in enumerate(rows.tolist()):
        np.testing.assert_array_equal(P[owner == t], claim_polygons(claims, r))
