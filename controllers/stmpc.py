"""Online ST-MPC (paper steps On-1 and On-2), vectorised over the vehicles of a class.

* :meth:`STMPC.index` -- the membership index of eq. (5) for many states at
  once: one matrix product per decoupled factor over all stacked levels and a
  segmented maximum (``np.maximum.reduceat``); the index is the largest of the
  per-factor indices (the sets are products of nested factors).
* :meth:`STMPC.control` -- the terminal law ``u = K (x - x_eq)`` at ``l = 0``,
  otherwise the QP of eq. (6)

      min_u |A x + B u - x_eq|^2  s.t.  A x + B u ∈ T~^{l-1}(r),  u ∈ U.

  Because ``A x_eq = x_eq`` (Assumption 2) the QP is written in the error
  ``e = x - x_eq``.  Solvers: ``exact`` (closed form per factor with one
  input: the QP separates exactly over decoupled factors, and a strictly
  convex 1-variable QP is a clipped unconstrained minimiser; vectorised over
  vehicles), ``daqp`` and ``proxsuite`` (one QP per vehicle over all inputs).

An infeasible QP inside the domain of attraction is a bug, never hidden:
:class:`InfeasibleQPError` names the vehicles.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from controllers import tolerances as tol
from controllers.membership_kernel import PolarStack
from controllers.settings import ControllerSettings
from controllers.synthesis import SetFamily, rotate_pairs

__all__ = ["STMPC", "FactorMembership", "InfeasibleQPError", "OutsideDomainError"]


class InfeasibleQPError(RuntimeError):
    """The QP of eq. (6) has no solution for a state inside the domain of attraction."""

    def __init__(self, message: str, rows: np.ndarray):
        super().__init__(message)
        self.rows = rows


class OutsideDomainError(RuntimeError):
    """A state lies outside the controller's domain of attraction."""

    def __init__(self, message: str, rows: np.ndarray):
        super().__init__(message)
        self.rows = rows


@dataclass(frozen=True, eq=False)
class _FactorTables:
    states: np.ndarray
    inputs: np.ndarray
    A: np.ndarray
    B: np.ndarray
    K: np.ndarray
    H: np.ndarray          # stacked rows of T^0..T^N
    h: np.ndarray
    starts: np.ndarray     # first row of each level
    Ht: list               # per level: rows of T~^l
    ht: list
    HtB: list              # per level: T~^l rows times B
    HtA: list              # per level: T~^l rows times A
    # level-padded tables (pad rows: 0 x <= +inf), gathered per vehicle by level
    Hp: np.ndarray         # (d, N+1, F): column j of the rows of T^l
    hp: np.ndarray         # (N+1, F)
    gp: np.ndarray         # (N, Ft): T~^l rows times B (one input)
    HtAp: np.ndarray       # (d, N, Ft): column j of T~^l rows times A
    htp: np.ndarray        # (N, Ft)
    polar: "_Polar | None" = None  # 2-D factors: sector tables for O(log F) membership


def _pad(As: list, bs: list) -> tuple[np.ndarray, np.ndarray]:
    """Stack per-level rows ``A_l x <= b_l`` into ``(d, L, F)`` columns and ``(L, F)``
    right-hand sides, padding with ``0 x <= +inf`` (never violated)."""
    L = len(As)
    d = As[0].shape[1] if L else 0
    F = max((a.shape[0] for a in As), default=0)
    Hp = np.zeros((d, L, F))
    hp = np.full((L, F), np.inf)
    for i, (a, b) in enumerate(zip(As, bs)):
        Hp[:, i, :a.shape[0]] = a.T
        hp[i, :a.shape[0]] = b
    return Hp, hp


class _Polar:
    """Sector tables of nested 2-D polygons that contain the origin in their interiors.

    A point ``p`` lies in such a polygon iff it satisfies the one facet whose angular
    sector (seen from the origin, between the facet's two vertices) contains ``p``'s
    angle: that facet's triangle with the origin covers the sector.  So membership is
    one ``searchsorted`` and one row test instead of all rows.  The rows are the
    polygon's own H-rows, with the same ``MEMBERSHIP_TOL`` (a point violating its
    sector's facet by at most the tolerance violates no other facet by more, rows
    being unit normals up to scale).
    """

    def __init__(self, keys, a0, a1, b, first, last):
        self.keys, self.a0, self.a1, self.b = keys, a0, a1, b
        self.first, self.last = first, last

    @classmethod
    def build(cls, levels) -> "_Polar | None":
        """Tables for ``levels`` (Polytopes in 2-D), or None if they do not qualify."""
        if not levels or levels[0].dim != 2:
            return None
        keys, rows, first, last = [], [], [], []
        n = 0
        for lev, P in enumerate(levels):
            if np.any(P.b <= 0):
                return None  # origin not interior
            try:
                V = P.vertices
            except Exception:  # noqa: BLE001 - any failure: use the general path
                return None
            ang = np.arctan2(V[:, 1], V[:, 0])
            order = np.argsort(ang)
            V, ang = V[order], ang[order]
            nxt = np.roll(V, -1, axis=0)
            mid = 0.5 * (V + nxt)
            norm = np.linalg.norm(P.A, axis=1)
            r = np.argmax((mid @ P.A.T - P.b) / norm, axis=1)  # the facet through each edge
            # each chosen row must be tight at both ends of its edge, else do not use sectors
            scale = max(1.0, float(np.abs(P.b).max()))
            for end in (V, nxt):
                if np.any(np.abs(np.einsum("ij,ij->i", end, P.A[r]) - P.b[r]) > 1e-7 * scale):
                    return None
            keys.append(ang + 4.0 * np.pi * lev)
            rows.append(np.column_stack([P.A[r], P.b[r]]))
            first.append(n)
            n += len(V)
            last.append(n - 1)
        R = np.vstack(rows)
        return cls(np.concatenate(keys), R[:, 0].copy(), R[:, 1].copy(), R[:, 2].copy(),
                   np.array(first, dtype=np.intp), np.array(last, dtype=np.intp))

    def inside(self, x: np.ndarray, y: np.ndarray, lev: np.ndarray) -> np.ndarray:
        """Whether each point ``(x[i], y[i])`` lies in level ``lev[i]``."""
        q = np.arctan2(y, x) + 4.0 * np.pi * lev
        pos = np.searchsorted(self.keys, q, side="right") - 1
        pos = np.where(pos < self.first[lev], self.last[lev], pos)  # before the first vertex: wrap
        return self.a0[pos] * x + self.a1[pos] * y - self.b[pos] <= tol.MEMBERSHIP_TOL


@dataclass(frozen=True, eq=False)
class FactorMembership:
    """Membership index of one factor's error in its own nested levels ``T_f^0 .. T_f^N``
    (what :meth:`STMPC.factor_index` computes, for users without a controller: the claims of
    :mod:`tm.reach`).  Same tables and ``MEMBERSHIP_TOL`` as the controller's."""

    states: np.ndarray
    Hp: np.ndarray
    hp: np.ndarray
    polar: "_Polar | None"
    N: int

    @classmethod
    def of(cls, factor) -> "FactorMembership":
        """From a synthesised factor (``states`` and ``levels``, :class:`controllers.synthesis.SetFamily`)."""
        Hp, hp = _pad([P.A for P in factor.levels], [P.b for P in factor.levels])
        return cls(np.asarray(factor.states), Hp, hp, _Polar.build(factor.levels), len(factor.levels) - 1)

    def index(self, E: np.ndarray) -> np.ndarray:
        """``min{l : e_f ∈ T_f^l}`` per row of the full error ``E`` (V, n); ``N + 1`` outside."""
        Ef = np.asarray(E, dtype=float)[:, self.states]
        steps = max(1, int(np.ceil(np.log2(self.N + 2))))
        if self._stack is not None:  # sector tables: the search in one compiled loop
            return self._stack.index([(Ef[:, 0], Ef[:, 1])], self.N, steps)
        return _nested_index(lambda lev: _factor_inside(self, Ef, lev), Ef.shape[0], self.N, steps)

    @cached_property
    def _stack(self) -> PolarStack | None:
        return None if self.polar is None else PolarStack([self.polar])


def _factor_inside(t, Ef: np.ndarray, lev: np.ndarray) -> np.ndarray:
    """Row ``i`` of a factor's error ``Ef`` (V, d) in the factor's level ``lev[i]`` (``t``: a
    :class:`_FactorTables` or :class:`FactorMembership`)."""
    if t.polar is not None:
        return t.polar.inside(Ef[:, 0], Ef[:, 1], lev)
    viol = -t.hp[lev]
    for j in range(Ef.shape[1]):
        viol += t.Hp[j][lev] * Ef[:, j, None]
    return viol.max(axis=1) <= tol.MEMBERSHIP_TOL


def _nested_index(inside, V: int, N: int, steps: int) -> np.ndarray:
    """Smallest level ``0 .. N`` for which ``inside(lev)`` holds per row, ``N + 1`` where none does.
    The levels are nested (``T^l ⊆ T^{l+1}``), so membership is monotone in ``l``: a binary search
    over ``[0, N+1]`` for every row at once."""
    lo = np.zeros(V, dtype=np.intp)
    hi = np.full(V, N + 1, dtype=np.intp)
    for _ in range(steps):
        mid = np.minimum((lo + hi) // 2, N)
        ok = inside(mid)
        open_ = lo < hi
        hi = np.where(open_ & ok, mid, hi)
        lo = np.where(open_ & ~ok, mid + 1, lo)
    return hi


class STMPC:
    """The ST-MPC of one vehicle class, applied to many vehicles at once.

    Parameters
    ----------
    family : SetFamily
        Output of :func:`controllers.synthesis.synthesize`.
    settings : ControllerSettings, optional
    """

    def __init__(self, family: SetFamily, settings: ControllerSettings | None = None):
        self.family = family
        self.settings = settings or ControllerSettings()
        self.model = family.model
        self.N = family.N
        self._tables = []
        for f in family.factors:
            H = np.vstack([P.A for P in f.levels])
            h = np.concatenate([P.b for P in f.levels])
            counts = [P.n_facets for P in f.levels]
            starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.intp)
            HtB = [P.A @ f.B for P in f.tilde]
            HtA = [P.A @ f.A for P in f.tilde]
            Hp, hp = _pad([P.A for P in f.levels], [P.b for P in f.levels])
            HtAp, htp = _pad(HtA[:self.N], [P.b for P in f.tilde[:self.N]])
            gp = _pad([g[:, :1] for g in HtB[:self.N]], [P.b for P in f.tilde[:self.N]])[0][0] \
                if f.B.shape[1] == 1 else np.zeros((0, 0))
            self._tables.append(_FactorTables(
                states=f.states, inputs=f.inputs, A=f.A, B=f.B, K=f.K, H=H, h=h, starts=starts,
                Ht=[P.A for P in f.tilde], ht=[P.b for P in f.tilde], HtB=HtB, HtA=HtA,
                Hp=Hp, hp=hp, gp=gp, HtAp=HtAp, htp=htp, polar=_Polar.build(f.levels)))
        self._steps = max(1, int(np.ceil(np.log2(self.N + 2))))
        # sector tables of the 2-D factors for the compiled index search (controllers.membership_kernel)
        self._factor_stacks = [None if t.polar is None else PolarStack([t.polar]) for t in self._tables]
        self._stack = PolarStack([t.polar for t in self._tables]) \
            if all(t.polar is not None for t in self._tables) else None
        self._daqp = None
        self.authority = family.authority
        if self.settings.mode == "authority" and self.authority is None:
            raise ValueError(f"{self.model.name}: ControllerSettings.mode='authority' needs a family synthesised "
                             "with SynthesisSettings.authority_decel set (this one is the paper's family)")
        # along factor: the table of state 0, and the factor-local column of the velocity (state 2)
        self._along = next(k for k, t in enumerate(self._tables) if 0 in t.states)
        st = list(self._tables[self._along].states)
        self._along_v = st.index(2) if 2 in st else None
        # across factor (state 1, road-frame models): in authority mode it keeps its own tube
        # (:meth:`control`), so the claims' across extent follows its own index (tm.reach)
        self._across = next((k for k, t in enumerate(self._tables) if 1 in t.states and k != self._along), None) \
            if self.model.frame == "road" else None
        # the fastest along-road speed any tube allows (T^N is the largest set): a speed bound at or
        # above it can never bind
        f = family.factors[self._along]
        if self._along_v is None:
            self.v_top = float("inf")
        else:
            e = np.zeros(len(st))
            e[self._along_v] = 1.0
            self.v_top = float(f.levels[self.N].support(e[None])[0])

    # ------------------------------------------------------------------ On-1
    def error(self, X: np.ndarray, centres: np.ndarray, heading=None) -> np.ndarray:
        """``x - x_eq(r)``, expressed in the road frame of ``heading`` for ``road`` models."""
        E = np.asarray(X, dtype=float) - self.model.equilibrium(centres)
        if self.model.frame == "road":
            if heading is None:
                raise ValueError(f"{self.model.name}: a road-frame model needs the segment headings")
            E = rotate_pairs(E, -np.asarray(heading, dtype=float))
        return E

    def index(self, X: np.ndarray, centres: np.ndarray, heading=None) -> np.ndarray:
        """Membership index ``l = min{l : x ∈ T^l(r)}`` of eq. (5) for each row.

        Parameters
        ----------
        X : ndarray, shape (V, n)
        centres : ndarray, shape (V, 2)
            Waypoints ``r``; the sets are centred at ``x_eq = [r, 0]``.
        heading : ndarray, shape (V,), optional
            Segment headings (rad), for ``road``-frame models only.

        Returns
        -------
        ndarray of int, shape (V,)
            ``N + 1`` marks a state outside the domain of attraction.
        """
        E = self.error(X, centres, heading)
        if self._stack is not None:  # every factor has sector tables: the search in one compiled loop
            return self._stack.index([(E[:, t.states[0]], E[:, t.states[1]]) for t in self._tables], self.N,
                                     self._steps)
        return _nested_index(lambda lev: self._inside(E, lev), E.shape[0], self.N, self._steps)

    def factor_index(self, E: np.ndarray, factor: int) -> np.ndarray:
        """Membership index of factor ``factor`` alone: ``min{l : e_f ∈ T_f^l}`` for each row of the
        error ``E`` (V, n) (:meth:`error`); ``N + 1`` outside ``T_f^N``.  Never above :meth:`index`
        (the joint index is the largest over the factors)."""
        t = self._tables[factor]
        Ef = np.asarray(E, dtype=float)[:, t.states]
        if t.polar is not None:
            return self._factor_stacks[factor].index([(Ef[:, 0], Ef[:, 1])], self.N, self._steps)
        return _nested_index(lambda lev: _factor_inside(t, Ef, lev), Ef.shape[0], self.N, self._steps)

    def _inside(self, E: np.ndarray, lev: np.ndarray) -> np.ndarray:
        """Row ``i`` of ``E`` in ``T^{lev[i]}`` (error coordinates), every factor."""
        ok = np.ones(E.shape[0], dtype=bool)
        for t in self._tables:
            ok &= _factor_inside(t, E[:, t.states], lev)
        return ok

    def index_scan(self, X: np.ndarray, centres: np.ndarray, heading=None) -> np.ndarray:
        """:meth:`index` by testing every level (no nesting assumed); the reference in tests."""
        E = self.error(X, centres, heading)
        l = np.zeros(E.shape[0], dtype=np.intp)
        for t in self._tables:
            viol = E[:, t.states] @ t.H.T - t.h
            worst = np.maximum.reduceat(viol, t.starts, axis=1)
            inside = worst <= tol.MEMBERSHIP_TOL
            lf = np.where(inside.any(axis=1), np.argmax(inside, axis=1), self.N + 1)
            np.maximum(l, lf, out=l)
        return l

    def terminal_input(self, X: np.ndarray, centres: np.ndarray, heading=None) -> np.ndarray:
        """``u = K (x - x_eq)`` for each row (world-frame input)."""
        U = self.error(X, centres, heading) @ self.family.K.T
        return self._to_world(U, heading)

    def _to_world(self, U, heading):
        if self.model.frame == "road":
            return rotate_pairs(U, np.asarray(heading, dtype=float))
        return U

    # ------------------------------------------------------------------ movement authority
    def lead(self, X: np.ndarray, centres: np.ndarray, heading=None) -> np.ndarray:
        """``s(c) - s(x)``: how far each waypoint ``c`` lies ahead along its segment (m)."""
        return -self.error(X, centres, heading)[:, 0]

    def authority_lead(self, v_cap=None) -> np.ndarray | float:
        """The lead a vehicle asks for: ``s_MA``, or ``v_cap^2 / (2 a_c) + 2 delta`` when a lower
        speed limit applies (a longer authority would make the tube, which must shrink by one
        level a step, push the vehicle above the limit)."""
        a = self.authority
        if v_cap is None:
            return a.s_ma
        v = np.clip(np.asarray(v_cap, dtype=float), 0.0, a.v_bar)
        return v ** 2 / (2.0 * a.decel) + 2.0 * self.model.delta

    def may_request(self, X: np.ndarray, centres: np.ndarray, heading, l_next: np.ndarray,
                    v_cap=None) -> np.ndarray:
        """Movement-authority request rule (design.md §7): ask ``c -> c + delta`` iff the state
        lies in ``T^{N_L}(c + delta)`` (``l_next <= N``, the index w.r.t. the next waypoint) and
        the lead to the current waypoint is below :meth:`authority_lead`.  Paper mode:
        ``l_next <= N`` only."""
        ok = np.asarray(l_next) <= self.N
        if self.settings.mode == "authority":
            ok &= self.lead(X, centres, heading) < self.authority_lead(v_cap)
        return ok

    def desired_speed(self, E: np.ndarray, v_cap=None) -> np.ndarray:
        """``v_des = min(v̄, cap, sqrt(2 a_c max(lead - s0, 0)))`` for error rows ``E`` (road frame).

        ``v_cap``: per-row further speed limits (lane limit, curve speed; m/s), or None."""
        a = self.authority
        lead = -E[:, 0] - self.settings.standoff
        v = np.minimum(a.v_bar, np.sqrt(2.0 * a.decel * np.maximum(lead, 0.0)))
        if v_cap is not None:
            v = np.minimum(v, np.maximum(np.asarray(v_cap, dtype=float), 0.0))
        return v

    # ------------------------------------------------------------------ On-2
    def control(self, X: np.ndarray, centres: np.ndarray, l: np.ndarray,
                ids: list | None = None, heading=None, v_cap=None) -> np.ndarray:
        """Inputs (world frame) for states ``X`` at indices ``l`` w.r.t. waypoints ``centres``.

        In ``authority`` mode the along-road factor's cost is ``(v+ - v_des)^2`` (see
        :meth:`desired_speed`); every other factor's cost is that of eq. (6).

        ``v_cap`` (per row, m/s; lane limits and curve speeds with their look-ahead, see
        :mod:`controllers.speed_limits`) is, in both modes, a traffic rule on top of the tube:
        the bound ``|v+| <= v_cap`` on the nominal next along-road speed ``v+ = (A e + B u)_v``,
        intersected with the tube's feasible inputs ``{u in U : A x + B u in T~^{l-1}(r)}``.
        The tube constraint is never relaxed: when the intersection is empty **the tube wins**
        and the input is the tube-feasible one nearest the speed bound (its end of the tube's
        interval), so a cap can never make the QP infeasible.  Road-frame models only (a
        world-frame class has no along-road input); at ``l = 0`` the terminal law applies
        unchanged (``T^0`` is a zero-velocity set).

        Raises
        ------
        OutsideDomainError
            If some ``l > N``.
        InfeasibleQPError
            If the QP is infeasible for a state in ``T^l`` (a bug, never hidden).
        """
        X = np.asarray(X, dtype=float)
        l = np.asarray(l, dtype=np.intp)
        if np.any(l > self.N):
            rows = np.nonzero(l > self.N)[0]
            raise OutsideDomainError(
                f"{self.model.name}: vehicle(s) {_names(rows, ids)} outside the domain of attraction", rows)
        E = self.error(X, centres, heading)
        U = E @ self.family.K.T
        qp = np.nonzero(l > 0)[0]
        if qp.size:
            lev = self.tube_levels(E[qp], l[qp])
            solver = self.settings.solver
            vdes = cap = None
            if v_cap is not None and self.model.frame == "road" and self._along_v is not None:
                cap = np.maximum(np.broadcast_to(np.asarray(v_cap, dtype=float), (len(l),))[qp], 0.0)
            if self.settings.mode == "authority":
                vdes = self.desired_speed(E[qp], cap if cap is not None else
                                          None if v_cap is None else np.asarray(v_cap, dtype=float)[qp])
            if solver == "exact" and all(len(t.inputs) == 1 for t in self._tables):
                U[qp] = self._solve_exact(E[qp], lev, qp, ids, vdes, cap)
            else:
                U[qp] = self._solve_generic(E[qp], lev, qp, ids, "daqp" if solver == "exact" else solver,
                                            vdes, cap)
        return self._to_world(U, heading)

    def tube_levels(self, E: np.ndarray, l: np.ndarray) -> np.ndarray:
        """The level ``T~`` each factor's next state must lie in, per row (n_factors, V), for rows
        of index ``l >= 1``: ``l - 1`` for every factor (eq. (6)); in ``authority`` mode the across
        factor keeps its own tube, ``max(l_y - 1, 0)`` with ``l_y <= l`` its own index
        (:meth:`factor_index`).  That is a subset of ``T~^{l-1}`` (nested levels), so the joint
        index still drops by one each step; and ``x_y(t+k) ∈ T_y^{max(l_y - k, 0)}``: the claims'
        across extent (:func:`tm.reach.reach_claims`) follows ``l_y``, not ``l``."""
        l = np.asarray(l, dtype=np.intp)
        lev = np.tile(l - 1, (len(self._tables), 1))
        if self.settings.mode == "authority" and self._across is not None:
            ly = np.minimum(self.factor_index(E, self._across), l)
            lev[self._across] = np.maximum(ly - 1, 0)
        return lev

    def _solve_exact(self, E, lev, rows, ids, vdes=None, cap=None):
        """Closed form per single-input factor, every vehicle at once (levels gathered: ``lev``
        (n_factors, V), :meth:`tube_levels`); ``cap``: the speed bound on the along factor (see
        :meth:`control`; the tube wins)."""
        U = np.empty((E.shape[0], self.model.m))
        ulo, uhi = self.model.u_bounds
        for ti, t in enumerate(self._tables):
            k = int(t.inputs[0])
            Ef = E[:, t.states]
            b = t.B[:, 0]
            if vdes is not None and ti == self._along:
                j = self._along_v  # min (A e + b u)_v - v_des)^2: a 1-D least squares
                u_free = (vdes - Ef @ t.A[j]) / b[j]
            else:
                u_free = -((Ef @ t.A.T) @ b) / (b @ b)
            lo, hi, bad = self._interval(t, Ef, lev[ti], ulo[k], uhi[k])
            if bad.any():
                r = rows[np.nonzero(bad)[0]]
                raise InfeasibleQPError(
                    f"{self.model.name}: QP (6) infeasible for vehicle(s) {_names(r, ids)} inside the "
                    f"domain of attraction (factor states {t.states.tolist()})", r)
            mid = np.where(lo > hi, 0.5 * (lo + hi), u_free)
            lo, hi = np.minimum(lo, hi), np.maximum(lo, hi)
            if cap is not None and ti == self._along:
                lo, hi = _cap_interval(lo, hi, Ef @ t.A[self._along_v], b[self._along_v], cap)
            U[:, k] = np.clip(mid, lo, hi)
        return U

    @staticmethod
    def _interval(t, Ef, lev, ulo, uhi):
        """The inputs ``[lo, hi]`` of a single-input factor with ``A e + b u in T~^{lev}`` and
        ``u in U``, per row, and whether that is empty (beyond ``QP_FEAS_TOL``)."""
        g = t.gp[lev]                                   # (V, Ft)
        beta = t.htp[lev].copy()                        # h~ - H~ A e
        for j in range(len(t.states)):
            beta -= t.HtAp[j][lev] * Ef[:, j, None]
        pos, neg = g > tol.FACET_MERGE_TOL, g < -tol.FACET_MERGE_TOL
        zero = ~(pos | neg)
        safe = np.where(zero, 1.0, g)
        ratio = beta / safe
        hi = np.minimum(uhi, np.where(pos, ratio, np.inf).min(axis=1))
        lo = np.maximum(ulo, np.where(neg, ratio, -np.inf).max(axis=1))
        bad = (zero & (beta < -tol.QP_FEAS_TOL)).any(axis=1) | (lo > hi + tol.QP_FEAS_TOL)
        return lo, hi, bad

    def cap_admits(self, X: np.ndarray, centres: np.ndarray, heading, l: np.ndarray, v_cap) -> np.ndarray:
        """Whether the tube of index ``l`` around ``centres`` lets each vehicle keep its next
        along-road speed within ``v_cap`` (some tube-feasible input gives ``|v+| <= v_cap``).

        The request rule asks this of the waypoint it would switch to: a grant whose tube forces the
        vehicle above its speed bound (the tube wins over a cap, :meth:`control`) is not asked for.
        True where ``l = 0`` (the terminal law, a zero-velocity set), ``l > N`` (outside: the
        request is refused anyway), for world-frame models and for multi-input factors."""
        l = np.asarray(l, dtype=np.intp)
        ok = np.ones(len(l), dtype=bool)
        t = self._tables[self._along]
        if v_cap is None or self.model.frame != "road" or self._along_v is None or len(t.inputs) != 1:
            return ok
        rows = np.flatnonzero((l >= 1) & (l <= self.N))
        if not len(rows):
            return ok
        E = self.error(np.asarray(X, dtype=float)[rows], np.asarray(centres)[rows],
                       None if heading is None else np.asarray(heading)[rows])
        Ef = E[:, t.states]
        k = int(t.inputs[0])
        ulo, uhi = self.model.u_bounds
        lo, hi, bad = self._interval(t, Ef, l[rows] - 1, ulo[k], uhi[k])
        lo, hi = np.minimum(lo, hi), np.maximum(lo, hi)
        cap = np.maximum(np.broadcast_to(np.asarray(v_cap, dtype=float), (len(l),))[rows], 0.0)
        j = self._along_v
        base, b = Ef @ t.A[j], t.B[j, 0]
        vlo, vhi = np.minimum(base + b * lo, base + b * hi), np.maximum(base + b * lo, base + b * hi)
        ok[rows] = ~bad & (vlo <= cap + tol.QP_FEAS_TOL) & (vhi >= -cap - tol.QP_FEAS_TOL)
        return ok

    def _qp_data(self, e, lev, vdes=None, cap=None):
        """Dense QP data of eq. (6) on all inputs: 0.5 u'Hu + f'u, G u <= g (``lev``: each factor's
        tube level, :meth:`tube_levels`; ``vdes``: the movement-authority cost on the along factor
        instead; ``cap``: rows ``|v+| <= cap``)."""
        m = self.model.m
        Hq = np.zeros((m, m))
        f = np.zeros(m)
        G_rows, g_rows = [], []
        for ti, t in enumerate(self._tables):
            ef = e[t.states]
            Ae = t.A @ ef
            Bf = t.B
            if vdes is not None and ti == self._along:
                j = self._along_v
                Ae, Bf = np.array([Ae[j] - vdes]), Bf[j:j + 1]
            Hq[np.ix_(t.inputs, t.inputs)] += Bf.T @ Bf
            f[t.inputs] += Bf.T @ Ae
            lv = int(lev[ti])
            G = np.zeros((t.Ht[lv].shape[0], m))
            G[:, t.inputs] = t.HtB[lv]
            G_rows.append(G)
            g_rows.append(t.ht[lv] - t.HtA[lv] @ ef)
            if cap is not None and ti == self._along:
                j = self._along_v
                Gc = np.zeros((2, m))
                Gc[:, t.inputs] = np.array([t.B[j], -t.B[j]])
                base = float(t.A[j] @ ef)
                G_rows.append(Gc)
                g_rows.append(np.array([cap - base, cap + base]))
        return Hq, f, np.vstack(G_rows), np.concatenate(g_rows)

    def _solve_generic(self, E, lev, rows, ids, solver, vdes=None, cap=None):
        U = np.empty((E.shape[0], self.model.m))
        ulo, uhi = self.model.u_bounds
        for i in range(E.shape[0]):
            vd = None if vdes is None else float(vdes[i])
            ci = None if cap is None else float(cap[i])
            Hq, f, G, g = self._qp_data(E[i], lev[:, i], vd, ci)
            u, ok = self._solve_one(solver, Hq, f, G, g, ulo, uhi, int(lev.max(axis=0)[i]) + 1)
            if ci is not None and not ok:
                # the speed bound misses the tube: the tube wins.  The tube's v+ then lies wholly
                # above cap or wholly below -cap; either way min (v+ - cap)^2 over the tube is its
                # end nearest [-cap, cap], the input _solve_exact takes.
                Hq, f, G, g = self._qp_data(E[i], lev[:, i], ci)
                u, ok = self._solve_one(solver, Hq, f, G, g, ulo, uhi, int(lev.max(axis=0)[i]) + 1)
            if not ok or np.any(G @ u > g + tol.QP_FEAS_TOL * 10) or np.any(u < ulo - 1e-6) \
                    or np.any(u > uhi + 1e-6):
                r = rows[[i]]
                raise InfeasibleQPError(
                    f"{self.model.name}: QP (6) ({solver}) failed for vehicle {_names(r, ids)} inside "
                    f"the domain of attraction", r)
            U[i] = np.clip(u, ulo, uhi)
        return U

    def _solve_one(self, solver, Hq, f, G, g, ulo, uhi, lev):
        if solver == "daqp":
            return _solve_daqp(Hq, f, G, g, ulo, uhi)
        return self._solve_proxsuite(Hq, f, G, g, ulo, uhi, lev)

    def _solve_proxsuite(self, Hq, f, G, g, ulo, uhi, lev):
        import proxsuite

        # Normalise rows (proxsuite reports false infeasibility otherwise, design §5).
        scale = np.linalg.norm(G, axis=1)
        keep = scale > tol.FACET_MERGE_TOL
        Gn = G[keep] / scale[keep, None]
        gn = g[keep] / scale[keep]
        # A fresh problem per solve: re-using one with update() (warm start from the previous
        # vehicle's answer) gave answers 1.7e-2 away from the minimiser on the drag model.
        qp = proxsuite.proxqp.dense.QP(Hq.shape[0], 0, Gn.shape[0], True)
        qp.settings.eps_abs = tol.PROXSUITE_EPS_ABS
        qp.settings.eps_primal_inf = tol.PROXSUITE_EPS_PRIMAL_INF
        qp.settings.verbose = False
        qp.init(Hq, f, None, None, Gn, np.full(gn.shape, -1e20), gn, ulo, uhi)
        qp.solve()
        status = qp.results.info.status
        ok = status == proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED
        return np.array(qp.results.x), ok


def _cap_interval(lo, hi, base, b, cap):
    """``[lo, hi]`` (a factor's tube-feasible inputs) intersected with ``|base + b u| <= cap``
    row-wise; where they do not meet, the end of ``[lo, hi]`` nearest the cap's interval (the
    tube wins)."""
    if abs(b) <= tol.FACET_MERGE_TOL:  # the input does not move v+ in one step: nothing to bound
        return lo, hi
    c1, c2 = (cap - base) / b, (-cap - base) / b
    clo, chi = np.minimum(c1, c2), np.maximum(c1, c2)
    nlo, nhi = np.maximum(lo, clo), np.minimum(hi, chi)
    meet = nlo <= nhi
    near = np.where(chi < lo, lo, hi)  # empty: the cap lies wholly below or wholly above [lo, hi]
    return np.where(meet, nlo, near), np.where(meet, nhi, near)


def _solve_daqp(Hq, f, G, g, ulo, uhi):
    import daqp

    m = Hq.shape[0]
    bupper = np.concatenate([uhi, g])
    blower = np.concatenate([ulo, np.full(g.shape, -1e30)])
    sense = np.zeros(m + g.size, dtype=np.int32)
    x, _, exitflag, _ = daqp.solve(np.ascontiguousarray(Hq), np.ascontiguousarray(f),
                                   np.ascontiguousarray(G), bupper, blower, sense)
    return np.asarray(x), exitflag == 1


def _names(rows, ids) -> str:
    if ids is None:
        return ", ".join(f"#{int(r)}" for r in rows[:10])
    return ", ".join(str(ids[int(r)]) for r in rows[:10])
