"""The traffic manager: Go/Stop decisions on waypoint switches, and admission.

Decision semantics (design 3b)
------------------------------
Every vehicle holds a claim (its tube, see :mod:`tm.claims`).  A requester
``i`` asks to replace its current claim ``old_i`` (which it keeps on Stop:
its hold region) by ``new_i`` (from the next waypoint, index ``l'_i`` and the
heading toward it).  A non-requester ``j`` keeps ``fixed_j``.  Conflicts:

* ``new_i ∩ fixed_j``: ``i`` must stop;
* ``new_i ∩ old_j`` (``j`` a requester): not (``i`` Go and ``j`` Stop);
* ``new_i ∩ new_j``: not both Go.

Non-requesters are never stopped and "deny every request" satisfies every
constraint, so a decision always exists.  Invariant: after every decision
the claims of all vehicles (new for Go, old for Stop, fixed for the others)
are pairwise disjoint (checked when ``TMSettings.verify`` is set, and by
:mod:`tm.monitor`).

Policies: ``optimal`` maximises ``Σ w_i g_i`` with ``w_i = 1 + waited_i / H``
(``waited_i`` consecutive denials of ``i``'s request, ``H`` the settings'
``starvation_horizon``); ``greedy`` is (P1)-(P3) extended to hold regions.
:func:`paper_decision` is the paper's graph (10) as written, for comparison.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from itertools import compress, repeat

import networkx as nx
import numpy as np

from controllers.tolerances import GEOMETRY_TOL
from tm.claims import Claims, claim_conflicts, conflicting_pairs
from tm.families import FamilyTable, build_family_table
from tm.geometry import broad_phase
from tm.kernels import merge_rows
from tm.reach import (PREFILTER_TOL_FACTOR, ReachClaims, claims_conflict, pad_slots, pairwise_conflicts,
                      union_aabb, world_aabb)
from tm.selection import propagate_stops, select_greedy, select_optimal
from tm.settings import TMSettings

__all__ = ["FleetState", "Decision", "Timings", "TrafficManager", "InvariantError",
           "paper_decision", "EDGE_KINDS"]

#: Conflict kinds on the edges of :attr:`Decision.graph`.
EDGE_KINDS = ("new-fixed", "new-old", "new-new")
_KIND_PRIORITY = ("new-fixed", "new-new", "new-old")


class InvariantError(RuntimeError):
    """The claims after a decision are not pairwise disjoint (a bug, or an invalid input state)."""


def _array(name: str, value, shape: tuple, dtype) -> np.ndarray:
    arr = np.asarray(value, dtype=dtype)
    if arr.shape != shape:
        raise ValueError(f"FleetState.{name}: shape must be {shape}, got {arr.shape}")
    if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
        raise ValueError(f"FleetState.{name}: must be finite")
    return arr


@dataclass(frozen=True, eq=False)
class FleetState:
    """What the TM receives about all ``V`` vehicles at one step.

    Parameters
    ----------
    ids : sequence of str, length V
        Unique vehicle ids.
    family : sequence of str (family keys) or ndarray of int (family indices), shape (V,)
    centre : array_like, shape (V, 2)
        Current waypoint ``r_i(k_i)`` (m).
    index : array_like of int, shape (V,)
        Current set-membership index ``l_i`` w.r.t. ``centre``.
    heading : array_like, shape (V,)
        Heading of the current claim's footprint (rad, CCW from +x).
    length, width : array_like, shape (V,)
        Footprint (m, >= 0) along and across the heading.
    requesting : array_like of bool, shape (V,), optional
        Who asks to switch waypoint (default: nobody).
    req_centre, req_index, req_heading : array_like, optional
        The request ``(r̄_i, l'_i, θ'_i)``, shapes (V, 2), (V,), (V,); rows of
        non-requesters are ignored.  Required when anybody requests.
    """

    ids: Sequence[str]
    family: object
    centre: np.ndarray
    index: np.ndarray
    heading: np.ndarray
    length: np.ndarray
    width: np.ndarray
    requesting: np.ndarray | None = None
    req_centre: np.ndarray | None = None
    req_index: np.ndarray | None = None
    req_heading: np.ndarray | None = None

    def __post_init__(self) -> None:
        ids = tuple(self.ids)
        V = len(ids)
        if len(set(ids)) != V:
            raise ValueError("FleetState.ids: must be unique")
        def set_(name, value):
            object.__setattr__(self, name, value)

        set_("ids", ids)
        fam = np.asarray(self.family)
        if fam.shape != (V,):
            raise ValueError(f"FleetState.family: shape must be ({V},), got {fam.shape}")
        set_("family", fam)
        set_("centre", _array("centre", self.centre, (V, 2), float))
        set_("index", _array("index", self.index, (V,), np.intp))
        for name in ("heading", "length", "width"):
            set_(name, _array(name, getattr(self, name), (V,), float))
        if np.any(self.length < 0) or np.any(self.width < 0):
            raise ValueError("FleetState.length, width: must be >= 0 m")
        req = np.zeros(V, dtype=bool) if self.requesting is None else self.requesting
        set_("requesting", _array("requesting", req, (V,), bool))
        anyone = bool(self.requesting.any())
        for name, shape, dtype in (("req_centre", (V, 2), float), ("req_index", (V,), np.intp),
                                   ("req_heading", (V,), float)):
            value = getattr(self, name)
            if value is None:
                if anyone:
                    raise ValueError(f"FleetState.{name}: required when some vehicle is requesting")
                value = np.zeros(shape, dtype=dtype)
            set_(name, _array(name, value, shape, dtype))

    def __len__(self) -> int:
        return len(self.ids)


@dataclass(frozen=True)
class Timings:
    """Seconds spent in one decision, by phase.

    ``claims``: family look-up and claim bounding boxes; ``broad``: broad
    phase; ``narrow``: claim polygons (Minkowski sums) and separating axes
    of the candidate pairs; ``select``: Go/Stop selection and bookkeeping.
    """

    claims: float
    broad: float
    narrow: float
    select: float

    @property
    def total(self) -> float:
        return self.claims + self.broad + self.narrow + self.select


@dataclass(frozen=True, eq=False)
class Decision:
    """The TM's answer for one step.

    Attributes
    ----------
    ids : tuple of str
        Vehicle ids, in the order of the state.
    requesting : ndarray of bool, shape (V,)
    go : ndarray of bool, shape (V,)
        True exactly for the granted requesters.
    stopped : tuple of str
        Ids of the denied requesters.
    forced : ndarray of bool, shape (V,)
        Requesters that had to stop whatever the policy: their new claim
        meets a non-requester's claim, or the hold region of such a vehicle.
    waited : ndarray of int, shape (V,)
        Consecutive denials of each request before this decision.
    edges : ndarray of int, shape (E, 2)
        Conflicts as vehicle indices ``(u, v)``: ``u``'s new claim meets
        ``v``'s claim of kind ``edge_kinds[e]``.
    edge_kinds : ndarray of str, shape (E,)
        One of :data:`EDGE_KINDS`.
    claims : Claims or ReachClaims
        Every vehicle's claim after the decision (new for Go, current otherwise);
        a :class:`~tm.reach.ReachClaims` from :meth:`TrafficManager.decide_reach`.
    timings : Timings
    """

    ids: tuple
    requesting: np.ndarray
    go: np.ndarray
    stopped: tuple
    forced: np.ndarray
    waited: np.ndarray
    edges: np.ndarray
    edge_kinds: np.ndarray
    claims: Claims | ReachClaims
    timings: Timings = field(repr=False)

    @cached_property
    def graph(self) -> nx.Graph:
        """Conflict graph: nodes are vehicle ids; an edge per conflicting pair.

        Edge attributes: ``kind`` (``new-fixed``, else ``new-new`` if the new
        claims meet, else ``new-old``), ``kinds`` (all kinds found for the
        pair) and ``new_old`` (ids whose new claim meets the other's hold
        region).  Built on first access (not part of :attr:`timings`).
        """
        G = nx.Graph()
        G.add_nodes_from(self.ids)
        for (u, v), kind in zip(self.edges.tolist(), self.edge_kinds.tolist()):
            a, b = self.ids[u], self.ids[v]
            if not G.has_edge(a, b):
                G.add_edge(a, b, kinds=set(), new_old=[])
            data = G.edges[a, b]
            data["kinds"].add(kind)
            if kind == "new-old":
                data["new_old"].append(a)
            data["kind"] = next(k for k in _KIND_PRIORITY if k in data["kinds"])
        return G


@dataclass(frozen=True, eq=False)
class _Conflicts:
    """Conflicts of the requesters' new claims, in requester-local numbering."""

    req: np.ndarray            # vehicle index of each requester
    cur: Claims
    new: Claims
    fixed_hits: np.ndarray     # (R,)
    leq: np.ndarray            # (E1, 2) requester-local: new_i ∩ old_j
    excl: np.ndarray           # (E2, 2) requester-local: new_i ∩ new_j
    edges: np.ndarray          # (E, 2) vehicle indices
    edge_kinds: np.ndarray
    seconds: tuple             # claims, broad, narrow


def _check_levels(table: FamilyTable, state: FleetState, fam: np.ndarray, vehicles: np.ndarray,
                  index: np.ndarray, what: str) -> None:
    """Raise, naming the vehicle, if an ``index`` is outside ``0 .. N`` of its family."""
    n_levels = table.n_levels[fam[vehicles]]
    bad = (index < 0) | (index >= n_levels)
    if bad.any():
        t = int(np.argmax(bad))
        v = int(vehicles[t])
        raise ValueError(f"vehicle {state.ids[v]!r}: {what} {int(index[t])} outside 0..{n_levels[t] - 1} "
                         f"of family {table.keys[fam[v]]!r}")


def _claims_of(table: FamilyTable, state: FleetState, requests: bool) -> tuple[np.ndarray, Claims, Claims]:
    """Current claims of all vehicles and new claims of the requesters, validated."""
    fam = table.family_index(state.family)
    _check_levels(table, state, fam, np.arange(len(state)), state.index, "index")
    cur = Claims(table, fam, state.centre, state.index, state.heading, state.length, state.width)
    req = np.flatnonzero(state.requesting) if requests else np.zeros(0, dtype=np.intp)
    _check_levels(table, state, fam, req, state.req_index[req], "requested index")
    new = Claims(table, fam[req], state.req_centre[req], state.req_index[req], state.req_heading[req],
                 state.length[req], state.width[req])
    return req, cur, new


def _sorted_conflicts(state: FleetState, req: np.ndarray, cur, new, owner: np.ndarray, a: np.ndarray,
                      b: np.ndarray, seconds: tuple) -> _Conflicts:
    """The conflict table from hit pairs ``(a, b)`` of concatenated claims (current ones first, then
    the requesters' new ones, ``a`` always a new claim); ``owner`` maps a claim to its vehicle."""
    V, R = len(state), len(req)
    i = a - V                                     # requester-local index of the new claim
    b_new = b >= V
    b_req = state.requesting[owner[b]]
    local = np.full(V, -1, dtype=np.intp)
    local[req] = np.arange(R)
    kinds = np.where(b_new, "new-new", np.where(b_req, "new-old", "new-fixed"))
    return _Conflicts(
        req=req, cur=cur, new=new,
        fixed_hits=np.bincount(i[~b_req], minlength=R),
        leq=np.stack([i[b_req & ~b_new], local[owner[b[b_req & ~b_new]]]], axis=1),
        excl=np.stack([i[b_new], b[b_new] - V], axis=1),
        edges=np.stack([owner[a], owner[b]], axis=1), edge_kinds=kinds,
        seconds=seconds)


def _requester_conflicts(table: FamilyTable, state: FleetState, check: str) -> _Conflicts:
    t0 = time.perf_counter()
    req, cur, new = _claims_of(table, state, requests=True)
    V, R = len(cur), len(new)
    allc = Claims.concat(cur, new)
    owner = np.concatenate([np.arange(V), req])
    lo, hi = allc.aabb()
    t1 = time.perf_counter()
    a, b = broad_phase(lo, hi, GEOMETRY_TOL, mask=np.arange(V + R) >= V)
    swap = a < V                                  # put the new claim first
    a, b = np.where(swap, b, a), np.where(swap, a, b)
    keep = owner[a] != owner[b]                   # new_i vs old_i is no conflict
    a, b = a[keep], b[keep]
    t2 = time.perf_counter()
    hit = claim_conflicts(allc, a, b, check)
    a, b = a[hit], b[hit]
    t3 = time.perf_counter()
    return _sorted_conflicts(state, req, cur, new, owner, a, b, (t1 - t0, t2 - t1, t3 - t2))


def _result_claims(c: _Conflicts, go_r: np.ndarray) -> Claims | ReachClaims:
    """Claims after the decision: new for granted requesters, current for everyone else."""
    g = c.req[go_r]
    if isinstance(c.cur, ReachClaims):
        K = max(c.cur.lo.shape[1], c.new.lo.shape[1])
        cur, new = pad_slots(c.cur, K), pad_slots(c.new, K)
        centre, heading = cur.centre.copy(), cur.heading.copy()
        centre[g], heading[g] = new.centre[go_r], new.heading[go_r]
        src = np.full(len(centre), -1, dtype=np.intp)  # the granted vehicles' rows of new
        src[g] = np.flatnonzero(go_r)
        lo, hi = merge_rows(cur.lo, cur.hi, new.lo, new.hi, src)
        return ReachClaims(centre, heading, lo, hi)
    out = {}
    for name in ("centre", "index", "heading"):
        arr = getattr(c.cur, name).copy()
        arr[g] = getattr(c.new, name)[go_r]
        out[name] = arr
    return Claims(c.cur.table, c.cur.family, out["centre"], out["index"], out["heading"],
                  c.cur.length, c.cur.width)


def _reach_conflicts(state: FleetState, cur: ReachClaims, new: ReachClaims, check: str) -> _Conflicts:
    """:func:`_requester_conflicts` for reach-tightened claims (tm/reach.py): ``cur`` holds every
    vehicle's current claims, ``new`` the requesters' (in the order of ``state.requesting``)."""
    t0 = time.perf_counter()
    req = np.flatnonzero(state.requesting)
    V, R = len(state), len(req)
    if len(cur) != V or len(new) != R:
        raise ValueError(f"decide_reach: {len(cur)} current claims for {V} vehicles and {len(new)} new claims "
                         f"for {R} requesters")
    timed = check == "timed"
    owner = np.concatenate([np.arange(V), req])
    box = union_aabb if timed else world_aabb   # union_aabb: from the slot boxes (computed once, or cached)
    (lo_c, hi_c), (lo_n, hi_n) = box(cur), box(new)
    lo, hi = np.concatenate([lo_c, lo_n]), np.concatenate([hi_c, hi_n])
    empty = ~(lo <= hi).all(axis=1)
    lo, hi = np.where(empty[:, None], 0.0, lo), np.where(empty[:, None], 0.0, hi)  # never hit (narrow phase)
    t1 = time.perf_counter()
    # slot boxes meeting under the separating-axis test with tol lie within sqrt(2) tol (tm.reach)
    a, b = broad_phase(lo, hi, PREFILTER_TOL_FACTOR * GEOMETRY_TOL if timed else GEOMETRY_TOL,
                       mask=np.arange(V + R) >= V)
    swap = a < V
    a, b = np.where(swap, b, a), np.where(swap, a, b)
    keep = owner[a] != owner[b]
    a, b = a[keep], b[keep]
    t2 = time.perf_counter()
    hit = np.zeros(len(a), dtype=bool)  # the new claim a against a current (b < V) or a new one
    for rows, other, off in ((b < V, cur, 0), (b >= V, new, V)):
        if rows.any():
            hit[rows] = claims_conflict(new, a[rows] - V, other, b[rows] - off, check)
    a, b = a[hit], b[hit]
    t3 = time.perf_counter()
    return _sorted_conflicts(state, req, cur, new, owner, a, b, (t1 - t0, t2 - t1, t3 - t2))


def _decision(state: FleetState, c: _Conflicts, go_r: np.ndarray, waited_r: np.ndarray,
              t_select: float) -> Decision:
    V = len(state)
    go = np.zeros(V, dtype=bool)
    go[c.req] = go_r
    forced = np.zeros(V, dtype=bool)
    forced[c.req] = propagate_stops(c.fixed_hits > 0, c.leq)
    waited = np.zeros(V, dtype=np.int64)
    waited[c.req] = waited_r
    return Decision(ids=state.ids, requesting=state.requesting, go=go,
                    stopped=tuple(map(state.ids.__getitem__, c.req[~go_r].tolist())), forced=forced, waited=waited,
                    edges=c.edges, edge_kinds=c.edge_kinds, claims=_result_claims(c, go_r),
                    timings=Timings(*c.seconds, t_select))


def paper_decision(families: Mapping[str, Sequence[np.ndarray]] | FamilyTable, state: FleetState,
                   seed: int | np.random.Generator = 0) -> Decision:
    """The paper's TM as written: graph (10) plus (P1)-(P3).

    Edges only between a requested set ``new_i`` and the ``r̄``-sets of the
    others (``new_j`` for requesters, ``fixed_j`` for the rest): stopped
    vehicles' hold regions are ignored, so the granted tubes may overlap
    them (design 3b).  Not a policy of :class:`TrafficManager`; it exists to
    show that difference.  Uses the ``union`` check (condition (9)).

    Parameters
    ----------
    families : mapping or FamilyTable
    state : FleetState
    seed : int or numpy.random.Generator
        Breaks ties between equal degrees.
    """
    table = families if isinstance(families, FamilyTable) else build_family_table(families)
    rng = np.random.default_rng(seed)
    c = _requester_conflicts(table, state, "union")
    keep = c.edge_kinds != "new-old"
    c = replace(c, leq=np.zeros((0, 2), dtype=np.intp), edges=c.edges[keep], edge_kinds=c.edge_kinds[keep])
    t0 = time.perf_counter()
    go_r = select_greedy(len(c.req), c.fixed_hits, c.leq, c.excl, rng)
    return _decision(state, c, go_r, np.zeros(len(c.req), dtype=np.int64), time.perf_counter() - t0)


class TrafficManager:
    """Central traffic manager (design 3b-3f).

    Parameters
    ----------
    settings : TMSettings
    families : mapping of str to sequence of ndarray (k_l, 2)
        Per vehicle class key, CCW convex position sets ``P^0 .. P^N``
        centred at the origin (the 2-D projections of the ST-MPC sets).
    rotating : collection of str
        Keys of road-frame families: their sets turn with each claim's heading.

    Notes
    -----
    The manager's only state is the random generator (seeded from
    ``settings.seed``) and the number of consecutive denials of each
    vehicle's request (by id).  A vehicle that does not request, is
    granted, or is absent from the state has its count reset.

    Weights of the ``optimal`` policy are ``w_i = 1 + waited_i / H`` (solved
    in the equivalent integers ``H + waited_i``).  With equal waits the
    fewest requests are denied.  A request that conflicts with ``m``
    requests that are granted and renewed every step (``waited = 0``) is
    denied while ``H + waited < m H``: it is granted after at most
    ``(m - 1) H + 1`` denials, as soon as nothing fixed blocks it.  The
    ``greedy`` policy has no such bound.
    """

    def __init__(self, settings: TMSettings, families: Mapping[str, Sequence[np.ndarray]],
                 rotating=()) -> None:
        if not isinstance(settings, TMSettings):
            raise TypeError(f"settings: must be a TMSettings, got {type(settings).__name__}")
        self.settings = settings
        self.table = build_family_table(families, rotating)
        self._rng = np.random.default_rng(settings.seed)
        self._waited: dict[str, int] = {}

    def reset(self) -> None:
        """Forget waiting times and re-seed the tie-breaking generator."""
        self._rng = np.random.default_rng(self.settings.seed)
        self._waited = {}

    def waited(self, vehicle_id: str) -> int:
        """Consecutive denials of ``vehicle_id``'s request so far."""
        return self._waited.get(vehicle_id, 0)

    def decide(self, state: FleetState) -> Decision:
        """Grant or deny every request in ``state``.

        Returns
        -------
        Decision

        Raises
        ------
        InvariantError
            With ``settings.verify``, if the resulting claims are not pairwise disjoint.
        """
        return self._decide(state, _requester_conflicts(self.table, state, self.settings.check))

    def decide_reach(self, state: FleetState, current: ReachClaims, requested: ReachClaims) -> Decision:
        """:meth:`decide` with reach-tightened claims (design.md §7, :mod:`tm.reach`).

        ``current``: every vehicle's claims ``S_k`` for its current waypoint and state;
        ``requested``: the requesters' claims for their requested waypoints (rows in the order
        of ``state.requesting``).  Same policies, waiting times and conflict kinds as
        :meth:`decide`; ``settings.check`` is ``timed`` (step k against step k) or ``union``.
        ``decision.claims`` is then a :class:`~tm.reach.ReachClaims`.  ``state``'s centres,
        indices and footprints are not used here (the claims hold them).
        """
        return self._decide(state, _reach_conflicts(state, current, requested, self.settings.check))

    def _decide(self, state: FleetState, c: _Conflicts) -> Decision:
        s = self.settings
        t0 = time.perf_counter()
        req_ids = list(map(state.ids.__getitem__, c.req.tolist()))
        waited_r = np.fromiter(map(self._waited.get, req_ids, repeat(0)), dtype=np.int64, count=len(req_ids))
        if s.policy == "greedy":
            go_r = select_greedy(len(c.req), c.fixed_hits, c.leq, c.excl, self._rng)
        else:
            go_r = select_optimal(len(c.req), c.fixed_hits, c.leq, c.excl, s.starvation_horizon + waited_r,
                                  self._rng, s.exhaustive_max, s.milp_time_limit)
        stop = ~np.asarray(go_r, dtype=bool)
        self._waited = dict(zip(compress(req_ids, stop.tolist()), (waited_r[stop] + 1).tolist()))
        decision = _decision(state, c, go_r, waited_r, time.perf_counter() - t0)
        if s.verify:
            i, j = (pairwise_conflicts(decision.claims, s.check) if isinstance(decision.claims, ReachClaims)
                    else conflicting_pairs(decision.claims, s.check))
            if len(i):
                pairs = [(state.ids[a], state.ids[b]) for a, b in zip(i[:10], j[:10])]
                raise InvariantError(f"{len(i)} pair(s) of claims overlap after the decision, e.g. {pairs}")
        return decision

    def claims(self, state: FleetState) -> Claims:
        """Current claims of the vehicles of ``state`` (requests ignored)."""
        return _claims_of(self.table, state, requests=False)[1]

    def admit(self, current: FleetState | Claims, candidates: FleetState) -> np.ndarray:
        """Initial condition (12): which new vehicles may enter (design 3f).

        Candidates are taken in order; one enters only if its claim is
        disjoint from every current claim and from the claims of the
        candidates admitted before it in this call.  The others wait.

        Parameters
        ----------
        current : FleetState or Claims
            Vehicles in the network: a state (their current claims; requests
            ignored) or claims, e.g. ``decision.claims`` to include this
            step's grants.
        candidates : FleetState
            Vehicles waiting to enter (requests ignored).

        Returns
        -------
        ndarray of bool, shape (C,)
            Admitted mask.
        """
        cur = current if isinstance(current, Claims) else self.claims(current)
        if cur.table is not self.table:
            raise ValueError("admit: current claims were built with another FamilyTable")
        cand = self.claims(candidates)
        n, C = len(cur), len(cand)
        i, j = conflicting_pairs(Claims.concat(cur, cand), self.settings.check, mask=np.arange(n + C) >= n)
        blocked = np.zeros(C, dtype=bool)
        blocked[j[i < n] - n] = True
        among = np.stack([i[i >= n] - n, j[i >= n] - n], axis=1)      # candidate pairs, first < second
        earlier = [[] for _ in range(C)]
        for a, b in among.tolist():
            earlier[b].append(a)
        admitted = np.zeros(C, dtype=bool)
        for k in range(C):
            admitted[k] = not blocked[k] and not any(admitted[e] for e in earlier[k])
        return admitted
