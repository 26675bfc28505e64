"""Offline ST-MPC synthesis (paper steps Off-1 and Off-2).

For a :class:`~controllers.models.VehicleModel` this computes

* the LQR terminal gain ``K`` (``u = K (x - x_eq)``),
* ``T^0``: a robust positively invariant set of ``A + B K`` under ``D``
  containing the Rakovic et al. (2005) outer epsilon-approximation
  ``F(alpha, s)`` of the minimal RPI set, verified exactly against the
  constraints,
* the robust one-step controllable sets ``T^l`` of eq. (4) until
  Proposition 1's condition (8) holds: ``T^N ⊇ B_delta ⊕ T^0``,
* ``T~^l = T^l ⊖ D`` (the QP constraint sets of eq. (6)) and the 2-D
  position projection of every ``T^l`` (all the traffic manager needs).

Decoupled models are synthesised per independent factor (``structure =
"auto"``): all sets are Cartesian products of low-dimensional polytopes,
which is exact because dynamics, boxes and LQR weights all separate.
``structure = "full"`` runs the same algorithm on the whole state (the
general n-D path, for coupled dynamics; much slower).

Results are cached on disk under a hash of the model and the settings.
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.linalg import solve_discrete_are

from controllers import tolerances as tol
from controllers.models import VehicleModel, decoupled_blocks
from controllers.polytope import Polytope
from controllers.settings import SynthesisSettings, default_cache_dir

__all__ = ["SynthesisError", "FactorSets", "SetFamily", "Authority", "synthesize", "along_factor", "lqr_gain", "rotate_pairs",
           "terminal_set", "one_step_set"]

CACHE_VERSION = "1"


class SynthesisError(RuntimeError):
    """Offline synthesis failed; the message says which step and why."""


@dataclass(frozen=True, eq=False)
class FactorSets:
    """The sets of one decoupled factor (a block of states and inputs).

    Attributes
    ----------
    states, inputs : ndarray of int
        Indices of the factor's states and inputs in the full model.
    A, B, K : ndarray
        Factor dynamics and terminal gain.
    levels : list of Polytope
        ``T^0 .. T^N`` of the factor, centred at the origin.
    tilde : list of Polytope
        ``T^l ⊖ D`` for ``l = 0 .. N``.
    """

    states: np.ndarray
    inputs: np.ndarray
    A: np.ndarray
    B: np.ndarray
    K: np.ndarray
    levels: list
    tilde: list
    D: Polytope
    U: Polytope


@dataclass(frozen=True)
class Authority:
    """Movement-authority data of a family (design.md §7).

    Attributes
    ----------
    decel : float
        ``a_c``, the comfortable deceleration (m/s^2) the family was built for.
    v_bar : float
        Along-road speed bound ``v̄`` (m/s).
    s_ma : float
        ``s_MA = v̄^2 / (2 a_c) + 2 delta`` (m): the lead a cruising vehicle keeps.
    n_min : int
        First level meeting condition (8) (the paper's N); the family has
        ``N = N_L >= n_min`` levels.
    """

    decel: float
    v_bar: float
    s_ma: float
    n_min: int


def along_factor(family: "SetFamily") -> int:
    """Index of the factor holding state 0 (the along-road / x position)."""
    for k, f in enumerate(family.factors):
        if 0 in f.states:
            return k
    raise SynthesisError("no factor holds state 0")


def _ma_point(model: VehicleModel, states: np.ndarray, s_ma: float) -> np.ndarray:
    """``(-s_MA, v̄)`` in the along factor's coordinates (other states 0)."""
    e = np.zeros(len(states))
    e[list(states).index(0)] = -s_ma
    e[list(states).index(2)] = float(model.z_bounds[1][0])
    return e


@dataclass(frozen=True, eq=False)
class SetFamily:
    """Everything the online controller and the traffic manager need for a class.

    Attributes
    ----------
    model : VehicleModel
    factors : list of FactorSets
    K : ndarray, shape (m, n)
        Full terminal gain.
    N : int
        Index of the last set; the family is ``T^0 .. T^N``.
    condition8 : bool
        Whether ``T^N ⊇ B_delta ⊕ T^0`` holds (always True for a returned family).
    position_sets : list of ndarray
        CCW vertices (k, 2) of ``C T^l`` for ``l = 0 .. N``, centred at 0.
    seconds : float
        Synthesis wall time (0 when loaded from cache keeps the original figure).
    from_cache : bool
    """

    model: VehicleModel
    factors: list
    K: np.ndarray
    N: int
    condition8: bool
    position_sets: list
    seconds: float
    from_cache: bool = False
    authority: Authority | None = None
    _full: dict = field(default_factory=dict, repr=False)

    def level(self, l: int) -> Polytope:
        """``T^l`` on the full state (Cartesian product of the factors, reordered)."""
        if l not in self._full:
            self._full[l] = _assemble(self, [f.levels[l] for f in self.factors])
        return self._full[l]

    def tilde_level(self, l: int) -> Polytope:
        """``T^l ⊖ D`` on the full state."""
        return _assemble(self, [f.tilde[l] for f in self.factors])

    def vertices(self, l: int) -> np.ndarray:
        """Vertices of ``T^l`` on the full state: the Cartesian product of factor vertices."""
        V = np.zeros((1, self.model.n))
        for f in self.factors:
            Vf = f.levels[l].vertices
            out = np.repeat(V, len(Vf), axis=0)
            out[:, f.states] = np.tile(Vf, (len(V), 1))
            V = out
        return V

    def sample(self, l: int, k: int, rng: np.random.Generator) -> np.ndarray:
        """``k`` random points of ``T^l`` (random convex combinations per factor)."""
        X = np.zeros((k, self.model.n))
        for f in self.factors:
            Vf = f.levels[l].vertices
            W = rng.dirichlet(np.full(len(Vf), 0.3), size=k)
            X[:, f.states] = W @ Vf
        return X

    def facet_counts(self) -> list[int]:
        """Facets of ``T^0 .. T^N`` on the full state (sum over factors)."""
        return [sum(f.levels[l].n_facets for f in self.factors) for l in range(self.N + 1)]

    def summary(self) -> dict:
        """Plain-data description (for ``muvsim sets``)."""
        return {
            "class_model": self.model.name,
            "frame": self.model.frame,
            "N": self.N,
            "condition8": self.condition8,
            "facets": self.facet_counts(),
            "factors": [len(f.states) for f in self.factors],
            "synthesis_s": round(self.seconds, 4),
            "from_cache": self.from_cache,
            **({} if self.authority is None else
               {"authority_decel": self.authority.decel, "s_ma": round(self.authority.s_ma, 3),
                "N_min": self.authority.n_min}),
        }


def _assemble(fam: SetFamily, parts: list[Polytope]) -> Polytope:
    n = fam.model.n
    rows_A, rows_b = [], []
    for f, P in zip(fam.factors, parts):
        A = np.zeros((P.n_facets, n))
        A[:, f.states] = P.A
        rows_A.append(A)
        rows_b.append(P.b)
    P = Polytope(A=np.vstack(rows_A), b=np.concatenate(rows_b))
    P._meta["dim"] = n
    return P


# ----------------------------------------------------------------------------- Off-1
def lqr_gain(A: np.ndarray, B: np.ndarray, q: float, r: float) -> np.ndarray:
    """Discrete LQR gain ``K`` with ``u = K x`` for ``Q = q I``, ``R = r I``."""
    Q = q * np.eye(A.shape[0])
    R = r * np.eye(B.shape[1])
    P = solve_discrete_are(A, B, Q, R)
    return -np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)


def _rakovic(AK: np.ndarray, w: np.ndarray, epsilon: float, s_max: int = 10_000):
    """Generators of ``F(alpha, s) = (1-alpha)^-1 ⊕_{i<s} AK^i W`` for a box ``W``
    with half-widths ``w`` (Rakovic et al. 2005, algorithm 1, infinity norm)."""
    n = AK.shape[0]
    W = np.diag(w)
    gens = []
    Ai = np.eye(n)
    M = np.zeros(n)  # support of F_s in +-e_j
    for s in range(1, s_max + 1):
        gens.append(Ai @ W)
        M = M + np.abs(Ai) @ w
        Ai = AK @ Ai
        alpha = np.max((np.abs(Ai) @ w) / w)
        if alpha < 1.0 and alpha <= epsilon / (epsilon + M.max()):
            G = np.hstack(gens) / (1.0 - alpha)
            return G, alpha, s
    raise SynthesisError(f"no (alpha, s) found for epsilon={epsilon} within s <= {s_max}; "
                         "is A + B K stable?")


def _is_rpi(P: Polytope, AK: np.ndarray, W: Polytope) -> np.ndarray:
    """Per-facet margin of ``AK P ⊕ W ⊆ P`` (>= 0 means the facet holds)."""
    return P.b - (P.support(P.A @ AK) + W.support(P.A))


def _maximal_rpi_in_box(AK: np.ndarray, w: np.ndarray, half: np.ndarray,
                        max_k: int = 2000) -> tuple[Polytope, int]:
    """Maximal RPI set of ``x+ = AK x + d`` (``|d| <= w``) inside the box ``|x| <= half``.

    Gilbert-Tan recursion: ``O = {x : AK^k x ∈ Box ⊖ ⊕_{j<k} AK^j W, k >= 0}``, stopped at
    the first k whose rows are all redundant (then every later row is).
    """
    n = AK.shape[0]
    E = np.vstack([np.eye(n), -np.eye(n)])
    hb = np.concatenate([half, half])
    rows_A, rows_b = [E], [hb.copy()]
    Ak = np.eye(n)
    shrink = np.zeros(2 * n)  # support of ⊕_{j<k} AK^j W in each row direction of E
    for k in range(1, max_k + 1):
        shrink = shrink + np.abs(E @ Ak) @ w
        Ak = AK @ Ak
        a_new, b_new = E @ Ak, hb - shrink
        if np.any(b_new <= 0):
            raise SynthesisError("T^0: the box does not contain the minimal RPI set")
        P = Polytope(A=np.vstack(rows_A), b=np.concatenate(rows_b))
        if np.all(P.support(a_new) <= b_new):
            return P.minimal(), k
        rows_A.append(a_new)
        rows_b.append(b_new)
    raise SynthesisError(f"T^0: maximal RPI recursion did not terminate within {max_k} steps")


def terminal_set(AK: np.ndarray, W: Polytope, w: np.ndarray,
                 settings: SynthesisSettings) -> tuple[Polytope, dict]:
    """``T^0``: a robust positively invariant set of ``x+ = AK x + d``, ``d in W``.

    ``zonotope``: the Rakovic outer epsilon-approximation ``F(alpha, s)`` itself (exact
    H-representation, 2-D factors).  ``maximal``: the maximal RPI set inside the
    bounding box of ``F(alpha, s)`` enlarged by epsilon; it contains the minimal RPI set
    (every RPI subset of the box is inside it) and has few facets in any dimension.
    """
    n = AK.shape[0]
    G, alpha, s = _rakovic(AK, w, settings.epsilon)
    info = {"alpha": float(alpha), "s": int(s), "generators": int(G.shape[1])}
    method = settings.terminal_method
    if method == "auto":
        method = "zonotope" if n <= 2 else "maximal"
    if method == "zonotope":
        if n > 2:
            raise SynthesisError("terminal_method 'zonotope' is only offered for factors of "
                                 f"dimension <= 2 (this factor has {n}); use 'maximal'")
        T0 = Polytope.from_zonotope(np.zeros(n), G).minimal()
    else:
        half = np.abs(G).sum(axis=1) + settings.epsilon
        T0, k = _maximal_rpi_in_box(AK, w, half)
        info["k"] = k
    info["method"] = method
    return T0, info


# ----------------------------------------------------------------------------- Off-2
def one_step_set(target_tilde: Polytope, A: np.ndarray, B: np.ndarray, U: Polytope,
                 X: Polytope) -> Polytope:
    """``{x in X : exists u in U, A x + B u in target_tilde}`` (eq. 4)."""
    n = A.shape[0]
    if abs(np.linalg.det(A)) > 1e-10:
        # Pre(S) = A^-1 (S ⊕ (-B U)): vertices of the sum, hull, then the pre-image.
        V = target_tilde.vertices
        pts = (V[:, None, :] - (U.vertices @ B.T)[None, :, :]).reshape(-1, n)
        if n == 1:
            S = Polytope.from_box(pts.min(axis=0), pts.max(axis=0))
        else:
            S = Polytope.from_vertices(pts)
        return (S.preimage(A) & X).minimal()
    # Singular A: project the lifted set {(x, u)} onto x.
    m = B.shape[1]
    lifted_A = np.vstack([
        np.hstack([target_tilde.A @ A, target_tilde.A @ B]),
        np.hstack([np.zeros((U.n_facets, n)), U.A]),
        np.hstack([X.A, np.zeros((X.n_facets, m))]),
    ])
    lifted_b = np.concatenate([target_tilde.b, U.b, X.b])
    return Polytope(A=lifted_A, b=lifted_b).project(range(n)).minimal()


def _condition8_margin(T: Polytope, T0: Polytope, pos: np.ndarray, delta: float) -> np.ndarray:
    """Per-facet margin of ``T ⊇ B_delta ⊕ T0`` (exact: support functions)."""
    a_pos = T.A[:, pos] if len(pos) else np.zeros((T.n_facets, 0))
    return T.b - (delta * np.linalg.norm(a_pos, axis=1) + T0.support(T.A))


def rotate_pairs(X: np.ndarray, angle) -> np.ndarray:
    """Rotate every (x, y) coordinate pair of the rows of ``X`` by ``angle`` (rad, per row or scalar)."""
    X = np.asarray(X, dtype=float)
    c, s = np.cos(angle), np.sin(angle)
    c = np.asarray(c)[..., None]
    s = np.asarray(s)[..., None]
    x, y = X[..., 0::2], X[..., 1::2]
    rx, ry = c * x - s * y, s * x + c * y
    out = np.empty(rx.shape[:-1] + (X.shape[-1],))
    out[..., 0::2] = rx
    out[..., 1::2] = ry
    return out


def _road_condition_points(model: VehicleModel, factors_T0: list, states: list,
                           step_deg: float = 0.5) -> tuple[np.ndarray, float]:
    """Test points and angular margin of :func:`_road_condition_margin` (they depend on
    ``T^0`` only, so they are computed once per synthesis)."""
    n = model.n
    lo, hi = np.zeros(n), np.zeros(n)
    for st, T0 in zip(states, factors_T0):
        V = T0.vertices
        lo[st], hi[st] = V.min(axis=0), V.max(axis=0)
    corners = np.array(np.meshgrid(*[[a, b] for a, b in zip(lo, hi)], indexing="ij")).reshape(n, -1).T
    h = np.radians(step_deg)
    turn = np.radians(model.turn_max_deg)
    angles = np.arange(-turn, turn + h / 2, h) if turn > 0 else np.zeros(1)
    rot = rotate_pairs(corners[None, :, :], angles[:, None]).reshape(-1, n)
    shift = np.zeros(n)
    shift[0] = -model.delta
    pts = np.vstack([rot, rot + shift])
    margin = float(np.linalg.norm(corners, axis=1).max()) * h / 2 if turn > 0 else 0.0
    return pts, margin


def _road_condition_margin(model: VehicleModel, factors_T: list, factors_T0: list, states: list,
                           step_deg: float = 0.5, points=None) -> float:
    """Worst slack of the road-frame switching condition (the analogue of (8)).

    In the frame of waypoint ``k+1`` (x along the segment ``r_k -> r_{k+1}``) a state of
    ``T^0(r_k)`` is ``R(dθ) e - (d, 0, 0, ...)`` with ``e ∈ T^0``, ``0 < d <= delta`` and
    ``|dθ| <= turn_max``.  Checked on the corners of T^0's bounding box (a superset), both
    ends of the offset segment (T^N is convex) and a grid of angles with a margin of
    ``|corner| * step / 2`` for the angles in between: sound, slightly conservative.
    Returns min over facets of slack minus margin (>= 0 means the condition holds).
    ``points``: :func:`_road_condition_points` of the same arguments, if already computed.
    """
    pts, margin = points if points is not None else _road_condition_points(model, factors_T0, states, step_deg)
    worst = np.inf
    for st, T in zip(states, factors_T):
        slack = T.b[None, :] - pts[:, st] @ T.A.T
        worst = min(worst, float(slack.min()))
    return worst - margin


def _synthesize_factor(model: VehicleModel, states: np.ndarray, inputs: np.ndarray,
                       settings: SynthesisSettings):
    A = model.A[np.ix_(states, states)]
    B = model.B[np.ix_(states, inputs)]
    n_b = len(states)
    K = lqr_gain(A, B, settings.q_weight, settings.r_weight)
    xlo, xhi = model.x_bounds
    ulo, uhi = model.u_bounds
    dlo, dhi = model.d_bounds
    X = Polytope.from_box(xlo[states], xhi[states])
    X._meta["dim"] = n_b
    U = Polytope.from_box(ulo[inputs], uhi[inputs])
    D = Polytope.from_box(dlo[states], dhi[states])
    if not np.allclose(dlo, -dhi):
        raise SynthesisError("d_bounds: only symmetric disturbance boxes are supported")
    AK = A + B @ K
    T0, info = terminal_set(AK, D, dhi[states], settings)
    # Verify T^0 against the constraints, naming the one violated.
    names = [f"x[{i}]" for i in states]
    for j, i in enumerate(states):
        if i < 2:
            continue
        e = np.zeros(n_b)
        e[j] = 1.0
        hi = T0.support(e[None])[0]
        lo = -T0.support(-e[None])[0]
        if hi > xhi[i] + tol.VERIFY_TOL or lo < xlo[i] - tol.VERIFY_TOL:
            raise SynthesisError(
                f"T^0 violates the state constraint on {names[j]} (z bound [{xlo[i]}, {xhi[i]}]); "
                f"T^0 spans [{lo:.4g}, {hi:.4g}]: increase the bound or reduce the disturbance")
    for r, k in enumerate(inputs):
        hi = T0.support(K[r][None])[0]
        lo = -T0.support(-K[r][None])[0]
        if hi > uhi[k] + tol.VERIFY_TOL or lo < ulo[k] - tol.VERIFY_TOL:
            raise SynthesisError(
                f"T^0 violates the input constraint on u[{k}] under the terminal law "
                f"(bound [{ulo[k]}, {uhi[k]}], K T^0 spans [{lo:.4g}, {hi:.4g}])")
    if np.any(_is_rpi(T0, AK, D) < -tol.VERIFY_TOL):
        raise SynthesisError("T^0 is not robust positively invariant (numerical failure)")
    return A, B, K, X, U, D, T0, info


def synthesize(model: VehicleModel, settings: SynthesisSettings | None = None) -> SetFamily:
    """Off-1 and Off-2 for ``model``; cached on disk under a hash of model and settings.

    Raises
    ------
    SynthesisError
        If ``T^0`` violates a constraint, or condition (8) does not hold within
        ``settings.max_levels`` one-step sets.
    """
    settings = settings or SynthesisSettings()
    path = _cache_path(model, settings)
    if settings.cache and path.exists():
        try:
            return _load(model, path)
        except Exception:  # corrupt cache: recompute
            pass
    t0 = time.perf_counter()
    if settings.structure == "auto":
        blocks = decoupled_blocks(model)
    else:
        blocks = [(np.arange(model.n), np.arange(model.m))]
    prepared = []
    for states, inputs in blocks:
        if len(inputs) == 0:
            raise SynthesisError(f"states {states.tolist()} are not driven by any input")
        prepared.append((states, inputs, *_synthesize_factor(model, states, inputs, settings)))
    levels = [[p[8]] for p in prepared]
    tildes = [[p[8] - p[7]] for p in prepared]
    N = None
    road_pts = _road_condition_points(model, [lv[0] for lv in levels], [p[0] for p in prepared]) \
        if model.frame == "road" else None
    for l in range(1, settings.max_levels + 1):
        ok = True
        for k, (states, inputs, A, B, K, X, U, D, T0, info) in enumerate(prepared):
            T = one_step_set(tildes[k][-1], A, B, U, X)
            levels[k].append(T)
            tildes[k].append(T - D)
            pos = np.nonzero(states < 2)[0]
            if model.frame == "world" and np.any(_condition8_margin(T, T0, pos, model.delta) < -tol.VERIFY_TOL):
                ok = False
        if model.frame == "road":
            ok = _road_condition_margin(model, [lv[-1] for lv in levels], [lv[0] for lv in levels],
                                        [p[0] for p in prepared], points=road_pts) >= -tol.VERIFY_TOL
        if ok:
            N = l
            break
    authority = None
    if N is not None and settings.authority_decel is not None:
        authority = _extend_to_authority(model, settings, prepared, levels, tildes, N)
        N = len(levels[0]) - 1
    if N is not None:
        for _ in range(settings.extra_levels):
            for k, (states, inputs, A, B, K, X, U, D, T0, info) in enumerate(prepared):
                T = one_step_set(tildes[k][-1], A, B, U, X)
                levels[k].append(T)
                tildes[k].append(T - D)
            N += 1
    if N is None:
        raise SynthesisError(
            f"condition (8) (T^N ⊇ B_delta ⊕ T^0 with delta={model.delta}"
            f"{', road frame, turns up to %g deg' % model.turn_max_deg if model.frame == 'road' else ''}) "
            f"does not hold within "
            f"max_levels={settings.max_levels} one-step sets: reduce delta or the disturbance, "
            f"raise the input bound, or raise max_levels")
    factors = []
    Kfull = np.zeros((model.m, model.n))
    for k, (states, inputs, A, B, K, X, U, D, T0, info) in enumerate(prepared):
        factors.append(FactorSets(states=states, inputs=inputs, A=A, B=B, K=K,
                                  levels=levels[k], tilde=tildes[k], D=D, U=U))
        Kfull[np.ix_(inputs, states)] = K
    seconds = time.perf_counter() - t0
    fam = SetFamily(model=model, factors=factors, K=Kfull, N=N, condition8=True,
                    position_sets=_position_sets(factors, N), seconds=seconds, authority=authority)
    if settings.cache:
        _save(fam, path)
    return fam


def _extend_to_authority(model: VehicleModel, settings: SynthesisSettings, prepared: list,
                         levels: list, tildes: list, n_min: int) -> Authority:
    """Add one-step sets to every factor until the along factor contains ``(-s_MA, v̄)``."""
    a_c = float(settings.authority_decel)
    states0 = [p[0] for p in prepared]
    k_al = next((k for k, st in enumerate(states0) if 0 in st), None)
    if k_al is None or 2 not in states0[k_al]:
        raise SynthesisError(f"{model.name}: movement authority needs the along-road velocity (state 2) "
                             "in the factor of the along-road position (state 0)")
    u_al = float(model.u_bounds[1][prepared[k_al][1][0]])
    if not a_c < u_al:
        raise SynthesisError(f"{model.name}: SynthesisSettings.authority_decel = {a_c:g} m/s^2 must be below "
                             f"the along-road input bound {u_al:g} m/s^2")
    v_bar = float(model.z_bounds[1][0])
    s_ma = v_bar ** 2 / (2.0 * a_c) + 2.0 * model.delta
    point = _ma_point(model, states0[k_al], s_ma)[None, :]
    while not levels[k_al][-1].contains(point, tol.MEMBERSHIP_TOL)[0]:
        if len(levels[k_al]) - 1 >= settings.max_levels:
            raise SynthesisError(
                f"{model.name}: no level up to max_levels={settings.max_levels} contains the movement-"
                f"authority state (-s_MA, v̄) = ({-s_ma:.4g} m, {v_bar:g} m/s) for authority_decel={a_c:g}: "
                "raise max_levels or authority_decel")
        for k, (states, inputs, A, B, K, X, U, D, T0, info) in enumerate(prepared):
            T = one_step_set(tildes[k][-1], A, B, U, X)
            levels[k].append(T)
            tildes[k].append(T - D)
    return Authority(decel=a_c, v_bar=v_bar, s_ma=s_ma, n_min=n_min)


def _position_sets(factors: list[FactorSets], N: int) -> list[np.ndarray]:
    out = []
    for l in range(N + 1):
        ivals = {}
        poly = None
        for f in factors:
            pos = [j for j, i in enumerate(f.states) if i < 2]
            if len(pos) == 2:
                poly = f.levels[l].project(pos).polygon()
            elif len(pos) == 1:
                V = f.levels[l].vertices[:, pos[0]]
                ivals[int(f.states[pos[0]])] = (V.min(), V.max())
        if poly is None:
            (x0, x1), (y0, y1) = ivals[0], ivals[1]
            poly = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
        out.append(poly)
    return out


# ----------------------------------------------------------------------------- cache
def _cache_path(model: VehicleModel, settings: SynthesisSettings) -> Path:
    key = hashlib.sha256(f"{CACHE_VERSION}-{model.key()}-{settings.key()}".encode()).hexdigest()[:20]
    return Path(settings.cache_dir or default_cache_dir()) / f"sets-{key}.npz"


def _save(fam: SetFamily, path: Path) -> None:
    data = {"N": np.array(fam.N), "seconds": np.array(fam.seconds), "nf": np.array(len(fam.factors))}
    if fam.authority is not None:
        a = fam.authority
        data["authority"] = np.array([a.decel, a.v_bar, a.s_ma, a.n_min], dtype=float)
    for k, f in enumerate(fam.factors):
        data[f"f{k}_states"] = f.states
        data[f"f{k}_inputs"] = f.inputs
        data[f"f{k}_K"] = f.K
        for l in range(fam.N + 1):
            data[f"f{k}_L{l}_A"] = f.levels[l].A
            data[f"f{k}_L{l}_b"] = f.levels[l].b
            data[f"f{k}_L{l}_V"] = f.levels[l].vertices
            data[f"f{k}_T{l}_A"] = f.tilde[l].A
            data[f"f{k}_T{l}_b"] = f.tilde[l].b
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(f".tmp{np.random.default_rng().integers(1 << 30)}.npz")
    np.savez(tmp, **data)
    tmp.replace(path)


def _load(model: VehicleModel, path: Path) -> SetFamily:
    with np.load(path) as z:
        N = int(z["N"])
        factors = []
        Kfull = np.zeros((model.m, model.n))
        xlo, xhi = model.x_bounds
        for k in range(int(z["nf"])):
            states, inputs, K = z[f"f{k}_states"], z[f"f{k}_inputs"], z[f"f{k}_K"]
            levels, tildes = [], []
            for l in range(N + 1):
                P = Polytope(A=z[f"f{k}_L{l}_A"], b=z[f"f{k}_L{l}_b"])
                P._meta.update(vertices=z[f"f{k}_L{l}_V"], minimal=True)
                levels.append(P)
                tildes.append(Polytope(A=z[f"f{k}_T{l}_A"], b=z[f"f{k}_T{l}_b"]))
            A = model.A[np.ix_(states, states)]
            B = model.B[np.ix_(states, inputs)]
            D = Polytope.from_box(model.d_bounds[0][states], model.d_bounds[1][states])
            U = Polytope.from_box(model.u_bounds[0][inputs], model.u_bounds[1][inputs])
            factors.append(FactorSets(states=states, inputs=inputs, A=A, B=B, K=K,
                                      levels=levels, tilde=tildes, D=D, U=U))
            Kfull[np.ix_(inputs, states)] = K
        seconds = float(z["seconds"])
        authority = None
        if "authority" in z.files:
            a = z["authority"]
            authority = Authority(decel=float(a[0]), v_bar=float(a[1]), s_ma=float(a[2]), n_min=int(a[3]))
    return SetFamily(model=model, factors=factors, K=Kfull, N=N, condition8=True,
                     position_sets=_position_sets(factors, N), seconds=seconds, from_cache=True,
                     authority=authority)
