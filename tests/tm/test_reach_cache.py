"""Claim reuse (tm/reach_cache.py) and the vectorised timed check (tm/reach.py).

Tolerances: boxes are compared with GEOMETRY_TOL (1e-9 m): the plant's repeated ``A x + B u + d`` and
the closed-form reach ``A^k x ± r_k`` round differently by ~1e-13 m (as in tests/tm/test_reach.py).
"""

import numpy as np

from tm.path_claims import bare_model
from tm.reach_book import ReachBook
import pytest
from hypothesis import assume, given, settings as hsettings, strategies as st

from controllers.classes import get_class
from controllers.settings import SynthesisSettings
from controllers.synthesis import rotate_pairs
from controllers.tolerances import GEOMETRY_TOL
from tm.lane import Lane, LaneSettings, lane_class
from tm.reach import (ReachClaims, _boxes_overlap, claims_conflict, pad_slots, pairwise_conflicts, reach_claims,
                      slot_aabb, world_aabb)
from tm.reach_book import tube_escapes
from tests.tm.helpers import disturb as _disturb, lane_fleet
from tm.reach_cache import ClaimCache

URBAN = ("car", "bus", "truck")


@pytest.fixture(scope="module")
def lcs(shared_set_cache):
    s = SynthesisSettings(cache_dir=shared_set_cache)
    return {c: lane_class(get_class(c), s) for c in URBAN}


class _Book:
    """The claim models of the classes (what ClaimCache needs of a ReachBook)."""

    def __init__(self, lcs):
        self.models = {c: lc.reach for c, lc in lcs.items()}
        self.bare = {c: bare_model(m) for c, m in self.models.items()}
        self.K = max(m.K for m in self.models.values())

    claims_of = ReachBook.claims_of  # fresh claims, as the real book builds them

    def fresh(self, parts) -> ReachClaims:
        return ReachClaims.concat(*[pad_slots(reach_claims(self.models[c], X, C, H, np.minimum(L, self.models[c].N)),
                                              self.K) for c, _, X, C, H, L in parts])



def _random_fleet(lcs, classes, rng):
    """One vehicle per entry of ``classes``: a random state of a random level of its family, at a
    random waypoint and heading; returns ``X (n, 4), C (n, 2), H (n,), L (n,)`` (L: its index)."""
    X, C, H, L = [], [], [], []
    for c in classes:
        lc = lcs[c]
        fam = lc.ctl.family
        l0 = int(rng.integers(0, fam.N + 1))
        hd = rng.uniform(-np.pi, np.pi, 1)
        cen = rng.uniform(-200, 200, (1, 2))
        x = rotate_pairs(fam.sample(l0, 1, rng), hd) + np.hstack([cen, np.zeros((1, 2))])
        X.append(x[0]), C.append(cen[0]), H.append(hd[0])
        L.append(int(lc.ctl.index(x, cen, hd)[0]))
    return np.array(X), np.array(C), np.array(H), np.array(L)


def _cache_setup(lcs, classes, seed):
    """The cache property tests' start: a seeded generator, a claim book and its cache, a random
    fleet (:func:`_random_fleet`, only examples whose levels lie in the family) and its ids."""
    rng = np.random.default_rng(seed)
    book = _Book(lcs)
    X, C, H, L = _random_fleet(lcs, classes, rng)
    assume(all(L[v] <= lcs[c].ctl.N for v, c in enumerate(classes)))
    return rng, book, ClaimCache(book), X, C, H, L, [f"v{v}" for v in range(len(classes))]


def _switch_at_random(lcs, classes, X, C, H, L, rng, p_switch) -> np.ndarray:
    """Each vehicle switches (granted) to the waypoint ``delta`` ahead with probability ``p_switch``
    where its state is inside that waypoint's sets; ``C`` and ``L`` updated in place; the granted mask."""
    granted = np.zeros(len(classes), dtype=bool)
    for v, c in enumerate(classes):
        lc = lcs[c]
        step = lc.vclass.model.delta * np.array([np.cos(H[v]), np.sin(H[v])])
        l_next = int(lc.ctl.index(X[[v]], C[[v]] + step, H[[v]])[0])
        if rng.random() < p_switch and l_next <= lc.ctl.N:
            C[v], L[v], granted[v] = C[v] + step, l_next, True
    return granted


def _step_fleet(lcs, classes, X, C, H, L, rng, policy, sign, kicked=None) -> None:
    """One step of every vehicle under its ST-MPC and ``policy``'s disturbance (``X``, ``L`` in
    place); vehicle ``kicked`` (if any) gets 0.5 m/s more along than the whole one-step reach
    (inputs and D) can change its speed, ``2 r_1 + 0.5``: outside ``A x ± r_1``, the premise fails
    (a kick of 0.5 m/s alone can be cancelled by a braking input and land inside it)."""
    for v, c in enumerate(classes):
        lc = lcs[c]
        m = lc.vclass.model
        U = lc.ctl.control(X[[v]], C[[v]], L[[v]], heading=H[[v]])
        Ur = rotate_pairs(U, -H[[v]])[0]
        Xr = rotate_pairs(X[[v]] - np.r_[C[v], 0, 0], -H[[v]])[0]
        d = _disturb(m, Xr, Ur, np.zeros(2), policy, rng, sign)
        if v == kicked:
            d = d + np.array([0.0, 0.0, 2.0 * lc.reach.r_al[1, 1] + 0.5, 0.0])
        X[v] = X[v] @ m.A.T + U[0] @ m.B.T + rotate_pairs(d[None], H[[v]])[0]
        L[v] = min(int(lc.ctl.index(X[[v]], C[[v]], H[[v]])[0]), lc.ctl.N)


def _contains(outer: ReachClaims, inner: ReachClaims) -> bool:
    """Every non-empty box of ``inner`` inside the same slot of ``outer`` (within GEOMETRY_TOL)."""
    full = (inner.lo <= inner.hi).all(axis=-1)
    ok = (outer.lo >= -np.inf) & (outer.lo <= inner.lo + GEOMETRY_TOL) & (inner.hi <= outer.hi + GEOMETRY_TOL)
    return bool(np.all(ok.all(axis=-1) | ~full))


@hsettings(max_examples=25, deadline=None)
@given(classes=st.lists(st.sampled_from(URBAN), min_size=1, max_size=5), seed=st.integers(0, 2 ** 31),
       policy=st.sampled_from(["random", "adversarial", "push"]), sign=st.sampled_from([-1.0, 1.0]),
       p_switch=st.floats(0.0, 0.3), kick=st.integers(-1, 20))
def test_shifted_claims_contain_fresh_ones(lcs, classes, seed, policy, sign, p_switch, kick):
    """Random states of random levels, headings and waypoints, stepped under ST-MPC with random,
    adversarial or constant-vertex disturbances; vehicles switch to the next waypoint at random
    (granted) and one is kicked outside D at step ``kick``: at every step the cache's claims contain
    the fresh claims of the same state (S_fresh_k ⊆ S_cached_k for every vehicle and slot), their
    slot boxes are those of their boxes, every position lies in slot 1 of the claims in force of the
    step before (no tube escape, but for the kicked vehicle), and the kicked vehicle is not reused."""
    rng, book, cache, X, C, H, L, ids = _cache_setup(lcs, classes, seed)
    n = len(classes)
    length = np.array([lcs[c].vclass.length for c in classes])
    width = np.array([lcs[c].vclass.width for c in classes])
    inforce = None
    for t in range(30):
        if inforce is not None:
            esc = tube_escapes(inforce, X[:, :2], length, width)
            assert not esc[1:].any() and (t - 1 == kick or not esc[0]), t
        parts = [(c, [ids[v]], X[[v]], C[[v]], H[[v]], L[[v]]) for v, c in enumerate(classes)]
        got = cache.current(t, parts)
        fresh = book.fresh(parts)
        assert _contains(got, fresh), t
        if t == kick + 1:
            assert not cache.last_reused[0]
        assert np.array_equal(got.slot_boxes, slot_aabb(got.centre, got.heading, got.lo, got.hi))
        granted = _switch_at_random(lcs, classes, X, C, H, L, rng, p_switch)
        inforce = got if not granted.any() else ReachClaims.concat(*[
            book.fresh([parts[v][:3] + (C[[v]], H[[v]], L[[v]])]) if granted[v] else got.take([v])
            for v in range(n)])
        cache.commit(granted)
        _step_fleet(lcs, classes, X, C, H, L, rng, policy, sign, kicked=0 if t == kick else None)
    assert cache.stats.reused > 0


@hsettings(max_examples=25, deadline=None)
@given(classes=st.lists(st.sampled_from(URBAN), min_size=1, max_size=5), seed=st.integers(0, 2 ** 31),
       policy=st.sampled_from(["random", "adversarial", "push"]), sign=st.sampled_from([-1.0, 1.0]),
       p_switch=st.floats(0.2, 0.6))
def test_granted_claims_committed_are_shifted_and_contain_fresh_ones(lcs, classes, seed, policy, sign, p_switch):
    """As above, but every grant commits the granted vehicles' requested claims (their claims in
    force, :meth:`ClaimCache.commit` with ``requested``): at every step the cache's claims contain
    the fresh claims of the same state (slot by slot, GEOMETRY_TOL: the plant's and the closed-form
    reach's round-off), their slot boxes are those of their boxes, no position leaves slot 1 of the
    claims in force the step before; no row is computed fresh for a grant, and some row granted the
    step before was shifted (the fast path was taken)."""
    rng, book, cache, X, C, H, L, ids = _cache_setup(lcs, classes, seed)
    n = len(classes)
    length = np.array([lcs[c].vclass.length for c in classes])
    width = np.array([lcs[c].vclass.width for c in classes])
    inforce, granted_before, shifted_after_grant, grants = None, np.zeros(n, dtype=bool), 0, 0
    for t in range(30):
        if inforce is not None:
            assert not tube_escapes(inforce, X[:, :2], length, width).any(), t
        parts = [(c, [ids[v]], X[[v]], C[[v]], H[[v]], L[[v]]) for v, c in enumerate(classes)]
        got = cache.current(t, parts)
        assert _contains(got, book.fresh(parts)), t
        assert np.array_equal(got.slot_boxes, slot_aabb(got.centre, got.heading, got.lo, got.hi))
        shifted_after_grant += int((cache.last_reused & granted_before).sum())
        C0 = C.copy()
        granted = _switch_at_random(lcs, classes, X, C, H, L, rng, p_switch)
        g = np.flatnonzero(granted)
        requested = book.fresh([(classes[v], [ids[v]], X[[v]], C[[v]], H[[v]], L[[v]]) for v in g]) if len(g) \
            else None
        inforce = got if not len(g) else ReachClaims.concat(*[
            requested.take([list(g).index(v)]) if granted[v] else got.take([v]) for v in range(n)])
        assert np.array_equal(C0[~granted], C[~granted])
        cache.commit(granted, granted, requested, L[granted])
        granted_before = granted
        _step_fleet(lcs, classes, X, C, H, L, rng, policy, sign)
        grants += int(granted.sum()) if t < 29 else 0
    assert cache.stats.fresh_by_reason["granted"] == 0
    assume(grants > 0)
    assert shifted_after_grant > 0


def test_commit_with_requested_claims_checks_its_rows(lcs):
    """Requested claims with a wrong number of rows, a grant outside ``requesting`` or a missing index:
    a clear error naming ClaimCache.commit."""
    lc = lcs["car"]
    book = _Book({"car": lc})
    cache = ClaimCache(book)
    ctl = lc.ctl
    C = np.array([[ctl.authority.s_ma - 6.0, 0.0], [100.0, 0.0]])
    X = np.c_[C, np.zeros((2, 2))]
    H = np.zeros(2)
    L = ctl.index(X, C, H)
    parts = [("car", ["a", "b"], X, C, H, L)]
    cache.current(0, parts)
    req = book.fresh([("car", ["a"], X[:1], C[:1], H[:1], L[:1])])
    go = np.array([True, False])
    for bad in [dict(requesting=go, requested=book.fresh(parts), req_index=L),
                dict(requesting=np.array([False, True]), requested=req, req_index=L[:1]),
                dict(requesting=go, requested=req, req_index=None)]:
        with pytest.raises(ValueError, match="ClaimCache.commit"):
            cache.commit(go, **bad)


def test_each_reason_for_fresh_claims_fires(lcs):
    """New vehicle, a step without commit (stale), a grant, a moved waypoint, an index that did not
    drop and a state that jumped further than one step of physics each give fresh claims; the rest reuse."""
    lc = lcs["car"]
    book = _Book({"car": lc})
    cache = ClaimCache(book)
    ctl, m = lc.ctl, lc.vclass.model
    C = np.array([[ctl.authority.s_ma - 6.0, 0.0]])
    X = np.array([[0.0, 0.0, 10.0, 0.0]])
    H = np.zeros(1)

    def parts(X, C, L):
        return [("car", ["a"], X, C, H, L)]

    def step(X, C, L):
        U = ctl.control(X, C, L, heading=H)
        X = X @ m.A.T + U @ m.B.T
        return X, np.minimum(ctl.index(X, C, H), ctl.N)

    L = ctl.index(X, C, H)
    assert L[0] <= ctl.N
    reasons = cache.stats.fresh_by_reason
    none, one = np.zeros(1, bool), np.ones(1, bool)
    # (what is handed to current(): a change or None, commit with granted or None, the expected reason or "reused")
    script = [(None, none, "new"), (None, None, "reused"), (None, one, "stale"), (None, none, "granted"),
              (None, none, "reused"), ("waypoint", None, "waypoint"), (None, none, "stale"),
              ("index", None, "index"), (None, none, "stale"), ("reach", None, "reach")]
    for t, (change, commit, want) in enumerate(script):
        Xq, Cq, Lq = X, C, L
        if change == "waypoint":
            Cq = C + [[3.0, 0.0]]
        elif change == "index":
            Lq = cache._last.index.copy()             # the index of the step before: not dropped
        elif change == "reach":
            Xq = X + [[0.5, 0.0, 0.0, 0.0]]           # jumped further than one step of physics
        before = dict(reasons)
        c = cache.current(t, parts(Xq, Cq, Lq))
        if want == "reused":
            assert cache.last_reused[0] and before == reasons, t
        else:
            assert not cache.last_reused[0] and reasons[want] == before[want] + 1, (t, want)
        if commit is not None:
            cache.commit(commit)
        X, L = step(X, C, L)
    assert cache.stats.reused == 2 and cache.stats.fresh == 8 == sum(reasons.values())


@hsettings(max_examples=10, deadline=None)
@given(classes=st.lists(st.sampled_from(URBAN), min_size=2, max_size=5), gaps=st.lists(st.integers(4, 12), min_size=5,
       max_size=5), check=st.sampled_from(["timed", "union"]),
       policy=st.sampled_from(["random", "adversarial", "squeeze"]), seed=st.integers(0, 1000),
       red=st.integers(0, 80), tm=st.sampled_from(["greedy", "optimal"]))
def test_decisions_on_reused_claims_never_grant_a_fresh_conflict(lcs, classes, gaps, check, policy, seed, red, tm):
    """Lane fleets (random classes, gaps, a red light, disturbances) decided by the TM on the cache's
    claims: after every decision the claims in force and the fresh claims of the same states (granted:
    their new claims) are pairwise disjoint; no footprint overlap, no index violation; claims were reused."""
    lane = Lane(LaneSettings(check=check, disturbance=policy, seed=seed, policy=tm, reuse=True))
    k = lane_fleet(lane, lcs, classes, gaps)
    assume(len(pairwise_conflicts(lane.all_claims(), check)[0]) == 0)
    lane.stop_k = k + 5
    for t in range(120):
        if t == red:
            lane.stop_k = None
        lane.try_enter(lcs["car"])
        lane.step()
    assert lane.claim_overlaps == 0 and lane.footprint_overlaps == 0 and lane.invariant_violations == 0
    assert lane._cache.stats.reused > 0 and lane.grants > 0


def test_fresh_check_of_a_reused_decision_fires(lcs):
    """A cache that hands out empty claims (unsound) lets the TM grant the follower's request into the
    leader's claim: the fresh check after the decision counts it (the real cache: nothing counted)."""
    sound = Lane(LaneSettings(disturbance="none", policy="greedy", reuse=True))
    sound.place(lcs["car"], 20)
    sound.place(lcs["car"], 22)
    for _ in range(3):
        sound.step()
    assert sound.claim_overlaps == 0
    lane = Lane(LaneSettings(disturbance="none", policy="greedy", reuse=True))
    lane.place(lcs["car"], 20)
    lane.place(lcs["car"], 22)  # 6 m apart (5 m cars): one more waypoint puts the follower into the leader
    assert len(pairwise_conflicts(lane.all_claims())[0]) == 0

    def empty():
        c = ReachClaims.concat(*[v.claim for v in lane.vehicles])
        return ReachClaims(c.centre, c.heading, np.full_like(c.lo, np.inf), np.full_like(c.hi, -np.inf))

    lane._cache = ClaimCache(_Book({"car": lcs["car"]}))
    lane._cache_models = {id(lcs["car"].reach)}
    lane._cache.current = lambda t, parts: empty()
    lane._cache.commit = lambda granted: None
    for _ in range(3):
        lane.step()
    assert lane.claim_overlaps > 0


# ------------------------------------------------------------------ the vectorised timed check
def _timed_reference(a, i, b, j, tol=GEOMETRY_TOL):
    """The timed check as first written: the separating-axis test of every slot pair."""
    K = max(a.lo.shape[1], b.lo.shape[1])
    la, ua = pad_slots(a, K).lo[i], pad_slots(a, K).hi[i]
    lb, ub = pad_slots(b, K).lo[j], pad_slots(b, K).hi[j]
    hit = _boxes_overlap(a.centre[i][:, None], a.heading[i][:, None], la, ua,
                         b.centre[j][:, None], b.heading[j][:, None], lb, ub, tol)
    return hit.any(axis=1)


def _aabb_reference(c):
    ok = (c.lo <= c.hi).all(axis=-1, keepdims=True)
    lo = np.where(ok, c.lo, np.inf).min(axis=1)
    hi = np.where(ok, c.hi, -np.inf).max(axis=1)
    cs, sn = np.abs(np.cos(c.heading)), np.abs(np.sin(c.heading))
    mid = c.centre + rotate_pairs(0.5 * (lo + hi), c.heading)
    half = 0.5 * (hi - lo)
    ext = np.column_stack([cs * half[:, 0] + sn * half[:, 1], sn * half[:, 0] + cs * half[:, 1]])
    return mid - ext, mid + ext


@hsettings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2 ** 31), n=st.integers(2, 12), K=st.integers(1, 9), right=st.booleans(),
       gap=st.sampled_from([0.0, 0.5e-9, 1.2e-9, 2e-9, 1e-3]))
def test_vectorised_timed_check_decides_as_the_reference(seed, n, K, right, gap):
    """Random boxes (random or right-angle headings, some empty slots, some pairs touching at gaps
    around the tolerance): the pre-filtered timed check reports exactly the reference's conflicts,
    and the world boxes are the reference's (to 1e-12 m: the same formula, reordered)."""
    rng = np.random.default_rng(seed)
    heading = rng.integers(0, 4, n) * np.pi / 2 if right else rng.uniform(-np.pi, np.pi, n)
    centre = rng.uniform(-6, 6, (n, 2))
    lo = rng.uniform(-3, 0, (n, K, 2))
    hi = lo + rng.uniform(0, 3, (n, K, 2))
    if right:  # two axis-aligned boxes ``gap`` apart along x
        heading[:2] = 0.0
        centre[:2] = 0.0
        lo[1, :, 0] = hi[0, :, 0] + gap
        hi[1, :, 0] = lo[1, :, 0] + 1.0
        lo[:2, :, 1], hi[:2, :, 1] = -1.0, 1.0
    empty = rng.random((n, K)) < 0.15
    lo[empty], hi[empty] = np.inf, -np.inf
    c = ReachClaims(centre, heading, lo, hi)
    i, j = np.triu_indices(n, 1)
    assert np.array_equal(claims_conflict(c, i, c, j, "timed"), _timed_reference(c, i, c, j))
    c2 = ReachClaims(centre, heading, lo, hi)  # other instance: no cached slot boxes
    short = ReachClaims(centre[:3], heading[:3], lo[:3, :max(K - 2, 1)], hi[:3, :max(K - 2, 1)])
    ii, jj = np.repeat(np.arange(len(short)), n), np.tile(np.arange(n), len(short))
    assert np.array_equal(claims_conflict(short, ii, c2, jj, "timed"), _timed_reference(short, ii, c2, jj))
    for check, ref in (("timed", _timed_reference), ("union", lambda a, i, b, j: claims_conflict(a, i, b, j, "union"))):
        pi, pj = pairwise_conflicts(c, check)                    # grid broad phase, then the check
        assert {*zip(pi.tolist(), pj.tolist())} == {*zip(i[ref(c, i, c, j)].tolist(), j[ref(c, i, c, j)].tolist())}
    got, want = world_aabb(c), _aabb_reference(c)
    fin = np.isfinite(want[0]).all(axis=1)
    assert np.allclose(got[0][fin], want[0][fin], atol=1e-12) and np.allclose(got[1][fin], want[1][fin], atol=1e-12)


@hsettings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2 ** 31), n=st.integers(2, 14), K=st.integers(1, 7), check=st.sampled_from(["timed", "union"]))
def test_decide_reach_conflicts_are_the_brute_force_ones(seed, n, K, check):
    """Random claim boxes (random headings, empty slots, some long ones) and random requests: the
    conflicts decide_reach finds (broad phase on the union of the slot boxes or the hulls, then the
    narrow phase per kind of pair) are exactly those of every pair tested by the reference."""
    from tm.manager import FleetState, TrafficManager
    from tm.settings import TMSettings

    rng = np.random.default_rng(seed)

    def claims(m):
        lo = rng.uniform(-4, 0, (m, K, 2))
        hi = lo + rng.uniform(0, 4, (m, K, 2))
        hi[:, :, 0] += rng.uniform(0, 30, (m, 1)) * (rng.random((m, 1)) < 0.3)
        empty = rng.random((m, K)) < 0.1
        lo[empty], hi[empty] = np.inf, -np.inf
        return ReachClaims(rng.uniform(-15, 15, (m, 2)), rng.uniform(-np.pi, np.pi, m), lo, hi)

    cur = claims(n)
    req = rng.random(n) < 0.5
    R = int(req.sum())
    new = claims(R)
    state = FleetState(ids=[f"v{i}" for i in range(n)], family=["a"] * n, centre=cur.centre, index=np.zeros(n, int),
                       heading=cur.heading, length=np.ones(n), width=np.ones(n), requesting=req,
                       req_centre=cur.centre, req_index=np.zeros(n, int), req_heading=cur.heading)
    square = [np.array([[-1.0, -1], [1, -1], [1, 1], [-1, 1]])]
    dec = TrafficManager(TMSettings(check=check), {"a": square}).decide_reach(state, cur, new)
    got = {(int(u), int(v), k) for (u, v), k in zip(dec.edges.tolist(), dec.edge_kinds.tolist())}
    got = {(min(u, v), max(u, v), k) if k == "new-new" else (u, v, k) for u, v, k in got}
    ref = _timed_reference if check == "timed" else (lambda a, i, b, j: claims_conflict(a, i, b, j, "union"))
    want = set()
    rq = np.flatnonzero(req)
    for r, u in enumerate(rq):
        others = np.array([v for v in range(n) if v != u], dtype=np.intp)
        if len(others):
            hit = ref(new, np.full(len(others), r), cur, others)
            for v in others[hit]:
                want.add((int(u), int(v), "new-old" if req[v] else "new-fixed"))
        for r2 in range(r + 1, R):
            if ref(new, np.array([r]), new, np.array([r2]))[0]:
                want.add((int(u), int(rq[r2]), "new-new"))
    assert got == want


def test_bad_parts_are_named(lcs):
    cache = ClaimCache(_Book({"car": lcs["car"]}))
    X, C = np.zeros((2, 4)), np.zeros((2, 2))
    with pytest.raises(ValueError, match="class 'tram' has no claim model"):
        cache.current(0, [("tram", ["a", "b"], X, C, np.zeros(2), np.zeros(2, int))])
    with pytest.raises(ValueError, match="class 'car': 2 ids but"):
        cache.current(0, [("car", ["a", "b"], X, C[:1], np.zeros(2), np.zeros(2, int))])
    cache.current(0, [("car", ["a", "b"], X, C, np.zeros(2), np.zeros(2, int))])
    with pytest.raises(ValueError, match="granted must have shape"):
        cache.commit(np.zeros(3, bool))


def test_offered_claims_are_handed_out_only_for_the_same_state(lcs):
    """Claims offered for step t are handed out by current(t) as they are when ids, states, waypoints
    and indices match bit for bit; any difference (another state, another step) gets the cache's own."""
    lc = lcs["car"]
    book = _Book({"car": lc})
    cache = ClaimCache(book)
    X = np.array([[0.0, 0.0, 10.0, 0.0], [40.0, 0.0, 0.0, 0.0]])
    C = np.array([[lc.ctl.authority.s_ma - 6.0, 0.0], [40.0, 0.0]])
    H = np.zeros(2)
    L = np.minimum(lc.ctl.index(X, C, H), lc.ctl.N)
    parts = [("car", ["a", "b"], X, C, H, L)]
    fresh = book.fresh(parts)
    cache.offer(3, parts, fresh)
    got = cache.current(3, parts)
    assert got is fresh and cache.stats.offered == 2
    cache.offer(4, parts, fresh)
    moved = [("car", ["a", "b"], X + [[1e-6, 0, 0, 0]], C, H, L)]
    other = cache.current(4, moved)
    assert other is not fresh and cache.stats.offered == 2
    assert _contains(other, book.fresh(moved))
    cache.offer(9, parts, fresh)
    assert cache.current(5, parts) is not fresh                 # offered for another step
    with pytest.raises(ValueError, match="1 claims for 2 vehicles"):
        cache.offer(6, parts, fresh.take([0]))


@hsettings(max_examples=25, deadline=None)
@given(classes=st.lists(st.sampled_from(URBAN), min_size=1, max_size=4), seed=st.integers(0, 2 ** 31),
       policy=st.sampled_from(["random", "adversarial"]), p_grow=st.floats(0.0, 0.4),
       p_switch=st.floats(0.0, 0.3))
def test_padded_shifted_claims_contain_fresh_padded_ones(lcs, classes, seed, policy, p_grow, p_switch):
    """Claims with a footprint padding (SUMO's bodies): each vehicle's pad (n, 2) shrinks at random from
    step to step (a PadTable's padding is non-increasing in the window start) and sometimes grows.
    At every step the cache's claims contain the fresh claims built with the pad needed now; a row whose
    pad exceeds the pad its claims in force were built with is never reused (reason ``pad``)."""
    rng, book, cache, X, C, H, L, ids = _cache_setup(lcs, classes, seed)
    n = len(classes)
    pad = rng.uniform(0.0, 1.5, (n, 2))
    built = None  # the pads the claims in force were built with
    for t in range(25):
        parts = [(c, [ids[v]], X[[v]], C[[v]], H[[v]], L[[v]], pad[[v]]) for v, c in enumerate(classes)]
        before = cache.stats.fresh_by_reason["pad"]
        got = cache.current(t, parts)
        fresh = ReachClaims.concat(*[pad_slots(reach_claims(book.models[c], X[[v]], C[[v]], H[[v]],
                                                            np.minimum(L[[v]], book.models[c].N), body_pad=pad[[v]]),
                                               book.K) for v, c in enumerate(classes)])
        assert _contains(got, fresh), t
        if built is not None:
            grew = (pad > built).any(axis=1)
            assert not (cache.last_reused & grew).any(), t
            if grew.any():
                assert cache.stats.fresh_by_reason["pad"] > before, t
            built = np.where(cache.last_reused[:, None], built, pad)
        else:
            built = pad.copy()
        granted = _switch_at_random(lcs, classes, X, C, H, L, rng, p_switch)
        cache.commit(granted)
        built[granted] = np.inf  # granted: fresh next step (not reused)
        grew = ~granted & (rng.random(n) < p_grow)
        pad = np.where(grew[:, None], pad + rng.uniform(1e-6, 0.5, (n, 2)) * (rng.random((n, 2)) < 0.5)
                       + np.array([[0.0, 1e-6]]), pad * rng.uniform(0.7, 1.0, (n, 2)))
        _step_fleet(lcs, classes, X, C, H, L, rng, policy, 1.0)
    assert cache.stats.reused > 0


def test_a_grown_pad_gives_fresh_claims(lcs):
    """Mutation check of the pad premise: the same state with a pad that grew by 0.2 m along is
    recomputed (reason ``pad``), and the cached claims would not have contained the fresh ones."""
    lc = lcs["car"]
    book = _Book({"car": lc})
    cache = ClaimCache(book)
    ctl, m = lc.ctl, lc.vclass.model
    C = np.array([[ctl.authority.s_ma - 6.0, 0.0]])
    X = np.array([[0.0, 0.0, 10.0, 0.0]])
    H = np.zeros(1)
    L = np.minimum(ctl.index(X, C, H), ctl.N)
    pad = np.array([[0.3, 0.1]])
    first = cache.current(0, [("car", ["a"], X, C, H, L, pad)])
    cache.commit(np.zeros(1, bool))
    U = ctl.control(X, C, L, heading=H)
    X = X @ m.A.T + U @ m.B.T
    L = np.minimum(ctl.index(X, C, H), ctl.N)
    big = pad + [[0.2, 0.0]]
    got = cache.current(1, [("car", ["a"], X, C, H, L, big)])
    assert not cache.last_reused[0] and cache.stats.fresh_by_reason["pad"] == 1
    fresh = pad_slots(reach_claims(book.models["car"], X, C, H, L, body_pad=big), book.K)
    assert _contains(got, fresh) and not _contains(first.shift(), fresh)
