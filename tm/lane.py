"""One straight lane of movement-authority vehicles under a reach-claim traffic manager.

Pure numpy, no SUMO: the reference for the reach claims' properties (tests) and the muvsim side
of ``benchmarks/bench_lane.py``.  The lane is the x axis, waypoints ``c_j = j delta``; a stop
line (a red light) bounds the waypoints vehicles may ask for.  Every step:

1. requests: ``c -> c + delta`` by the movement-authority rule
   (:meth:`controllers.stmpc.STMPC.may_request`), never past the stop line while it is red;
2. the TM grants them front to back, each only if its new claims miss every other vehicle's
   claims (``timed``: step k against step k; ``union``: the hulls), the claims of vehicles
   granted before it this step included;
3. ST-MPC inputs, plant step with the disturbance policy;
4. monitor: the index invariant of eq. (5), footprint overlaps, and pairwise claim conflicts
   recomputed from the new states (must stay 0: monotonicity);
5. entry at the lane start (condition (12)): a new vehicle at ``v_entry`` enters once its claims
   miss every claim on the lane.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from controllers.authority import build_tables
from controllers.classes import VehicleClass
from controllers.settings import ControllerSettings, SynthesisSettings
from controllers.stmpc import STMPC
from controllers.synthesis import synthesize
from tm.settings import TMSettings
from tm.path_claims import bare_model
from tm.reach_book import ReachBook
from tm.manager import FleetState, TrafficManager
from tm.reach import (ReachClaims, ReachModel, candidate_pairs, claims_conflict, pairwise_conflicts, reach_claims,
                      world_aabb)

__all__ = ["LaneSettings", "LaneClass", "Lane", "lane_class"]

POLICIES = ("none", "random", "adversarial", "squeeze")


@dataclass(frozen=True)
class LaneSettings:
    """Options of a lane run (validated).

    Parameters
    ----------
    check : {"timed", "union"}
    disturbance : {"none", "random", "adversarial", "squeeze"}
        ``adversarial``: each component pushes away from the waypoint's equilibrium;
        ``squeeze``: leaders pushed back, followers forward (the along disturbance of the
        front half of the fleet is ``-d̄``, of the rear half ``+d̄``).
    seed : int
    v_entry : float
        Speed (m/s) of a vehicle entering at ``x = 0``.
    policy : {"front", "greedy", "optimal"}
        ``front``: requests granted front to back, each against every claim (this step's grants
        included); ``greedy``, ``optimal``: the traffic manager's policies
        (:meth:`tm.manager.TrafficManager.decide_reach`).
    reuse : bool
        With ``greedy`` or ``optimal``: the TM decides on the current claims of
        :class:`tm.reach_cache.ClaimCache` (shifted claims of the previous step where they are
        sound, :mod:`tm.reach_cache`) instead of fresh ones; after every decision the fresh claims
        (granted: their new ones) are also checked pairwise (``claim_overlaps``).
    """

    check: str = "timed"
    disturbance: str = "random"
    seed: int = 0
    v_entry: float = 13.89
    policy: str = "front"
    reuse: bool = False

    def __post_init__(self) -> None:
        if self.check not in ("timed", "union"):
            raise ValueError(f"LaneSettings.check: must be 'timed' or 'union', got {self.check!r}")
        if self.disturbance not in POLICIES:
            raise ValueError(f"LaneSettings.disturbance: must be one of {POLICIES}, got {self.disturbance!r}")
        if self.policy not in ("front", "greedy", "optimal"):
            raise ValueError(f"LaneSettings.policy: must be 'front', 'greedy' or 'optimal', got {self.policy!r}")
        if self.reuse and self.policy == "front":
            raise ValueError("LaneSettings.reuse: needs policy 'greedy' or 'optimal' (the traffic manager)")
        if not self.v_entry >= 0:
            raise ValueError(f"LaneSettings.v_entry: must be >= 0 m/s, got {self.v_entry}")


@dataclass(frozen=True, eq=False)
class LaneClass:
    """A class ready for the lane: controller and claim model."""

    vclass: VehicleClass
    ctl: STMPC
    reach: ReachModel


def lane_class(vclass: VehicleClass, synthesis: SynthesisSettings | None = None) -> LaneClass:
    """Movement-authority family, controller and claim model of ``vclass``."""
    if vclass.comfort_decel is None:
        raise ValueError(f"class {vclass.name!r} has no comfort_decel: it has no movement-authority mode")
    s = synthesis or SynthesisSettings()
    from dataclasses import replace

    fam = synthesize(vclass.model, replace(s, authority_decel=vclass.comfort_decel))
    ctl = STMPC(fam, ControllerSettings(mode="authority"))
    return LaneClass(vclass, ctl, ReachModel.build(fam, build_tables(fam), vclass.length, vclass.width))


@dataclass
class _Vehicle:
    cls: LaneClass
    vid: int
    x: np.ndarray
    k: int
    l: int
    claim: ReachClaims = field(repr=False)


class Lane:
    """A lane run (see the module docstring)."""

    def __init__(self, settings: LaneSettings, delta: float = 3.0):
        self.settings = settings
        self.delta = float(delta)
        self.rng = np.random.default_rng(settings.seed)
        self.vehicles: list[_Vehicle] = []
        self.t = 0
        self.stop_k: int | None = None  # red light: no waypoint beyond this index
        self.next_id = 0
        self._tm = None
        self._cache = None      # ClaimCache (settings.reuse), built with the first decision
        self.deny_all = False  # the TM that grants nothing (its claims must stay disjoint)
        self.invariant_violations = 0
        self.footprint_overlaps = 0
        self.claim_overlaps = 0
        self.requests = self.grants = 0
        self.crossings: dict[float, list[tuple[int, float]]] = {}  # line -> [(vehicle, time)]

    # ------------------------------------------------------------------ helpers
    def _c(self, k) -> np.ndarray:
        k = np.atleast_1d(k)
        return np.column_stack([k * self.delta, np.zeros(len(k))])

    def claims_of(self, v: _Vehicle, k: int, l: int) -> ReachClaims:
        return reach_claims(v.cls.reach, v.x[None], self._c(k), np.zeros(1), np.array([l]))

    def _conflicts(self, c: ReachClaims, others: list[ReachClaims]) -> bool:
        if not others:
            return False
        o = ReachClaims.concat(*others)
        la, ha = world_aabb(c)
        lb, hb = world_aabb(o)
        _, j = candidate_pairs(la, ha, lb, hb)
        if not len(j):
            return False
        return bool(claims_conflict(c, np.zeros(len(j), dtype=np.intp), o, j, self.settings.check).any())

    def all_claims(self) -> ReachClaims | None:
        return ReachClaims.concat(*[v.claim for v in self.vehicles]) if self.vehicles else None

    def place(self, lc: LaneClass, k: int) -> _Vehicle:
        """Put a vehicle of ``lc`` at rest on waypoint ``k`` (in ``T^0``), whatever the claims
        (tests build their fleets with it; :meth:`try_enter` is the checked entry)."""
        x = np.array([k * self.delta, 0.0, 0.0, 0.0])
        l = int(lc.ctl.index(x[None], self._c(k), np.zeros(1))[0])
        v = _Vehicle(lc, self.next_id, x, int(k), l, None)
        v.claim = self.claims_of(v, v.k, v.l)
        self.vehicles.append(v)
        self.next_id += 1
        return v

    def positions(self) -> np.ndarray:
        return np.array([v.x[0] for v in self.vehicles])

    # ------------------------------------------------------------------ entry
    def try_enter(self, lc: LaneClass, x0: float = 0.0) -> bool:
        """Insert a vehicle of ``lc`` at ``x0`` and ``v_entry`` if some waypoint ahead gives it
        claims that miss every claim on the lane; the largest such authority is taken."""
        ctl = lc.ctl
        x = np.array([x0, 0.0, self.settings.v_entry, 0.0])
        lead_max = ctl.authority_lead()
        ks = np.arange(int(np.ceil(x0 / self.delta)), int((x0 + lead_max) // self.delta) + 1)
        if self.stop_k is not None:
            ks = ks[ks <= self.stop_k]
        if not len(ks):
            return False
        ls = ctl.index(np.repeat(x[None], len(ks), axis=0), self._c(ks), np.zeros(len(ks)))
        others = [v.claim for v in self.vehicles]
        for k, l in sorted(zip(ks[ls <= ctl.N], ls[ls <= ctl.N]), reverse=True):
            v = _Vehicle(lc, self.next_id, x.copy(), int(k), int(l), None)
            v.claim = self.claims_of(v, v.k, v.l)
            if not self._conflicts(v.claim, others):
                self.vehicles.append(v)
                self.next_id += 1
                return True
        return False

    # ------------------------------------------------------------------ one step
    def _by_class(self) -> dict:
        groups: dict = {}
        for i, v in enumerate(self.vehicles):
            groups.setdefault(id(v.cls), (v.cls, []))[1].append(i)
        return groups

    def _batch_claims(self, k_of, l_of) -> ReachClaims:
        """Claims of every vehicle for waypoints ``k_of[i]`` and indices ``l_of[i]`` (batched per class)."""
        n = len(self.vehicles)
        parts, rows = [], []
        for lc, idx in self._by_class().values():
            X = np.array([self.vehicles[i].x for i in idx])
            parts.append(reach_claims(lc.reach, X, self._c(np.asarray(k_of)[idx]), np.zeros(len(idx)),
                                      np.asarray(l_of)[idx]))
            rows += idx
        allc = ReachClaims.concat(*parts)
        inv = np.empty(n, dtype=np.intp)
        inv[np.array(rows)] = np.arange(n)
        return allc.take(inv)

    def step(self, Ts: float = 0.1) -> None:
        n = len(self.vehicles)
        if n:
            self._decide()
        order = sorted(range(n), key=lambda i: -self.vehicles[i].x[0])
        rank = np.empty(n, dtype=np.intp)
        rank[np.array(order, dtype=np.intp)] = np.arange(n)
        # 3: controls and plant, batched per class
        for lc, idx in self._by_class().values():
            ctl, m = lc.ctl, lc.vclass.model
            X = np.array([self.vehicles[i].x for i in idx])
            C = self._c(np.array([self.vehicles[i].k for i in idx]))
            l = np.array([self.vehicles[i].l for i in idx])
            hd = np.zeros(len(idx))
            U = ctl.control(X, C, l, heading=hd)
            D = np.vstack([self._disturbance(m, X[r], U[r], C[r], rank[i], n) for r, i in enumerate(idx)])
            Xn = X @ m.A.T + U @ m.B.T + D
            ln = ctl.index(Xn, C, hd)
            self.invariant_violations += int(np.sum(~((ln < l) | ((l == 0) & (ln == 0)))))
            for r, i in enumerate(idx):
                v = self.vehicles[i]
                for line, log in self.crossings.items():
                    if v.x[0] < line <= Xn[r, 0]:
                        log.append((v.vid, (self.t + 1) * Ts))
                v.x, v.l = Xn[r], int(min(ln[r], ctl.N))
        self.t += 1
        # 4: monitor
        if n:
            allc = self._batch_claims([v.k for v in self.vehicles], [v.l for v in self.vehicles])
            for i, v in enumerate(self.vehicles):
                v.claim = allc.take([i])
        if n > 1:
            P = self.positions()
            L = np.array([v.cls.vclass.length for v in self.vehicles])
            W = np.array([v.cls.vclass.width for v in self.vehicles])
            Y = np.array([v.x[1] for v in self.vehicles])
            i, j = np.triu_indices(n, 1)
            hit = (np.abs(P[i] - P[j]) < 0.5 * (L[i] + L[j])) & (np.abs(Y[i] - Y[j]) < 0.5 * (W[i] + W[j]))
            self.footprint_overlaps += int(hit.sum())
            ci, cj = pairwise_conflicts(allc, self.settings.check)
            self.claim_overlaps += len(ci)

    def _decide(self) -> None:
        """1-2: requests (batched per class), grants front to back against every other claim."""
        n = len(self.vehicles)
        want = np.zeros(n, dtype=bool)
        lp = np.zeros(n, dtype=np.intp)
        for lc, idx in self._by_class().values():
            ctl = lc.ctl
            X = np.array([self.vehicles[i].x for i in idx])
            k = np.array([self.vehicles[i].k for i in idx])
            hd = np.zeros(len(idx))
            lq = ctl.index(X, self._c(k + 1), hd)
            ok = ctl.may_request(X, self._c(k), hd, lq)
            if self.stop_k is not None:
                ok &= k + 1 <= self.stop_k
            if self.deny_all:
                ok[:] = False
            want[idx], lp[idx] = ok, np.minimum(lq, ctl.N)
        req = np.nonzero(want)[0]
        self.requests += len(req)
        cur = ReachClaims.concat(*[v.claim for v in self.vehicles])
        if self.settings.policy != "front":
            self._decide_tm(want, lp, cur)
            return
        lo, hi = cur.lo.copy(), cur.hi.copy()
        if len(req):
            k_new = [v.k + 1 for v in self.vehicles]
            new = self._batch_claims(k_new, [int(lp[i]) if want[i] else 0 for i in range(n)])
            new = new.take(req)
            K = max(lo.shape[1], new.lo.shape[1])
            lo, hi = _pad_to(lo, K), _pad_to(hi, K)
            nlo, nhi = _pad_to(new.lo, K), _pad_to(new.hi, K)
            centre, heading = cur.centre.copy(), cur.heading.copy()
            alo, ahi = world_aabb(ReachClaims(centre, heading, lo, hi))
            for r in sorted(range(len(req)), key=lambda r: -self.vehicles[req[r]].x[0]):
                i = int(req[r])
                cand = ReachClaims(self._c(self.vehicles[i].k + 1), np.zeros(1), nlo[[r]], nhi[[r]])
                la, ha = world_aabb(cand)
                _, j = candidate_pairs(la, ha, alo, ahi)
                j = j[j != i]
                others = ReachClaims(centre, heading, lo, hi)
                if len(j) and claims_conflict(cand, np.zeros(len(j), dtype=np.intp), others, j,
                                              self.settings.check).any():
                    continue
                v = self.vehicles[i]
                v.k, v.l = v.k + 1, int(lp[i])
                centre[i], lo[i], hi[i] = cand.centre[0], nlo[r], nhi[r]
                alo[i], ahi[i] = la[0], ha[0]
                v.claim = cand
                self.grants += 1
            cur = ReachClaims(centre, heading, lo, hi)
        ci, _ = pairwise_conflicts(cur, self.settings.check)
        self.claim_overlaps += len(ci)

    def _tm_for(self) -> TrafficManager:
        """The traffic manager, (re)built when a class joins (waiting counts carried over)."""
        have = {v.cls.vclass.name: v.cls for v in self.vehicles}
        if self._tm is None or not set(have) <= set(self._tm.table.keys):
            fams = {name: lc.ctl.family.position_sets for name, lc in have.items()}
            tm = TrafficManager(TMSettings(check=self.settings.check, policy=self.settings.policy,
                                           seed=self.settings.seed), fams, rotating=set(fams))
            if self._tm is not None:
                tm._waited = dict(self._tm._waited)
            self._tm = tm
        return self._tm

    def _decide_tm(self, want: np.ndarray, lp: np.ndarray, cur: ReachClaims) -> None:
        n = len(self.vehicles)
        req = np.nonzero(want)[0]
        k_new = np.array([v.k + 1 for v in self.vehicles])
        new = self._batch_claims(k_new, np.where(want, lp, 0)).take(req)
        state = FleetState(ids=[str(v.vid) for v in self.vehicles], family=[v.cls.vclass.name for v in self.vehicles],
                           centre=cur.centre, index=[v.l for v in self.vehicles], heading=np.zeros(n),
                           length=[v.cls.vclass.length for v in self.vehicles],
                           width=[v.cls.vclass.width for v in self.vehicles], requesting=want,
                           req_centre=self._c(k_new), req_index=lp, req_heading=np.zeros(n))
        fresh = cur
        if self.settings.reuse:
            cur = self._cached_claims()
        dec = self._tm_for().decide_reach(state, cur, new)
        if self.settings.reuse:
            self._cache.commit(dec.go)
        for r, i in enumerate(req):
            if dec.go[i]:
                v = self.vehicles[i]
                v.k, v.l = v.k + 1, int(lp[i])
                v.claim = new.take([r])
                self.grants += 1
        ci, _ = pairwise_conflicts(dec.claims, self.settings.check)
        self.claim_overlaps += len(ci)
        if self.settings.reuse:  # what fresh claims say of the decision taken on cached ones
            after = ReachClaims.concat(*[v.claim if dec.go[i] else fresh.take([i]) for i, v in enumerate(self.vehicles)])
            ci, _ = pairwise_conflicts(after, self.settings.check)
            self.claim_overlaps += len(ci)

    def _cached_claims(self) -> ReachClaims:
        """Current claims of every vehicle from the claim cache (vehicle order: one part per run of a class)."""
        from tm.reach_cache import ClaimCache

        if self._cache is None or not {id(v.cls.reach) for v in self.vehicles} <= self._cache_models:
            book = _LaneBook({v.cls.vclass.name: v.cls.reach for v in self.vehicles})
            self._cache = ClaimCache(book)
            self._cache_models = {id(m) for m in book.models.values()}
        parts = []
        for v in self.vehicles:
            name = v.cls.vclass.name
            if parts and parts[-1][0] == name:
                parts[-1][1].append(str(v.vid))
                parts[-1][2].append(v.x)
                parts[-1][3].append(self._c(v.k)[0])
                parts[-1][5].append(v.l)
            else:
                parts.append((name, [str(v.vid)], [v.x], [self._c(v.k)[0]], None, [v.l]))
        parts = [(c, ids, np.array(X), np.array(C), np.zeros(len(ids)), np.array(L)) for c, ids, X, C, _, L in parts]
        return self._cache.current(self.t, parts)

    def _disturbance(self, m, x, U, c, rank, n) -> np.ndarray:
        lo, hi = m.d_bounds
        pol = self.settings.disturbance
        if pol == "none":
            return np.zeros(m.n)
        if pol == "random":
            return lo + (hi - lo) * self.rng.random(m.n)
        if pol == "adversarial":
            err = m.A @ x + m.B @ U - np.concatenate([c, np.zeros(m.n - 2)])
            return np.where(err >= 0, hi, lo)
        # squeeze: leaders (front half) pushed back, followers forward
        d = lo + (hi - lo) * self.rng.random(m.n)
        sign = -1.0 if rank < n / 2 else 1.0
        d[[0, 2]] = sign * hi[[0, 2]]
        return d

    def remove_beyond(self, x_end: float) -> int:
        """Drop vehicles past ``x_end`` (they left the lane); returns how many."""
        keep = [v for v in self.vehicles if v.x[0] <= x_end]
        gone = len(self.vehicles) - len(keep)
        self.vehicles = keep
        return gone


class _LaneBook:
    """The part of :class:`tm.reach_book.ReachBook` a claim cache needs, from the lane classes' models."""

    def __init__(self, models: dict):
        self.models = dict(models)
        self.bare = {c: bare_model(m) for c, m in self.models.items()}

    claims_of = ReachBook.claims_of

    @property
    def K(self) -> int:
        return max(m.K for m in self.models.values())


def _pad_to(a: np.ndarray, K: int) -> np.ndarray:
    """Pad claim slots (n, k, 2) to K with the last slot (it stands for every later step)."""
    return a if a.shape[1] == K else np.concatenate([a, np.repeat(a[:, -1:], K - a.shape[1], axis=1)], axis=1)
