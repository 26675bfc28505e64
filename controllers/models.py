"""Linear vehicle models satisfying the paper's Assumption 2.

A model is frozen, validated data: the discrete-time matrices ``(A, B)``,
box bounds on the non-position states ``z``, on the inputs ``u`` and on the
additive disturbance ``d``, the waypoint spacing ``delta`` and the sampling
time ``Ts``.  The state is ordered ``x = [p_x, p_y, z]`` and ``C`` selects
the first two coordinates.

Three model families are provided (each per-axis decoupled, so the set
synthesis can work on low-dimensional factors):

* :func:`double_integrator` -- the paper's section IV model,
* :func:`drag_integrator` -- a double integrator with a first-order velocity
  lag (linear drag),
* :func:`jerk_integrator` -- position, velocity and acceleration per axis,
  driven by jerk (6 states).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import expm

__all__ = [
    "ModelError",
    "VehicleModel",
    "double_integrator",
    "drag_integrator",
    "jerk_integrator",
    "decoupled_blocks",
]


class ModelError(ValueError):
    """An invalid vehicle model; the message names the offending field."""


def _box(name: str, lo, hi, size: int) -> tuple[np.ndarray, np.ndarray]:
    lo = np.asarray(lo, dtype=float).reshape(-1)
    hi = np.asarray(hi, dtype=float).reshape(-1)
    if lo.size != size or hi.size != size:
        raise ModelError(f"{name}: expected {size} lower and upper bounds, got {lo.size} and {hi.size}")
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise ModelError(f"{name}: bounds must be finite (a compact box), got [{lo}, {hi}]")
    if np.any(lo >= hi):
        bad = int(np.argmax(lo >= hi))
        raise ModelError(f"{name}: empty box, component {bad} has lower {lo[bad]} >= upper {hi[bad]}")
    return lo, hi


@dataclass(frozen=True, eq=False)
class VehicleModel:
    """Discrete-time constrained LTI vehicle ``x+ = A x + B u + d``.

    Parameters
    ----------
    name : str
        Model family, for messages and cache keys.
    A, B : ndarray
        System matrices, ``A`` of shape (n, n) with Assumption 2's structure
        ``[[I, A12], [0, A22]]``, ``B`` of shape (n, m).
    z_bounds : (lower, upper)
        Box on the non-position states ``z = x[2:]`` (must contain 0).
    u_bounds : (lower, upper)
        Box on the inputs (must contain 0).
    d_bounds : (lower, upper)
        Box disturbance set ``D`` on all n states (must contain 0).
    delta : float
        Largest distance between successive waypoints (m), > 0.
    Ts : float
        Sampling time (s), > 0.
    frame : {"world", "road"}
        ``world``: the boxes hold in world axes (the paper).  ``road``: the
        state is expressed in the frame of the current waypoint's segment
        (x along, y across the road), so the boxes bound longitudinal and
        lateral motion separately; the model must be rotation invariant
        (coordinates in (x, y) pairs) and waypoint switches are checked for
        turns up to ``turn_max_deg``.
    turn_max_deg : float
        Largest heading change between successive segments (``road`` frame).
    """

    name: str
    A: np.ndarray
    B: np.ndarray
    z_bounds: tuple
    u_bounds: tuple
    d_bounds: tuple
    delta: float
    Ts: float
    frame: str = "world"
    turn_max_deg: float = 0.0
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        A = np.atleast_2d(np.asarray(self.A, dtype=float))
        B = np.asarray(self.B, dtype=float)
        if B.ndim == 1:
            B = B[:, None]
        n = A.shape[0]
        if A.shape != (n, n) or n < 3:
            raise ModelError(f"A: expected a square matrix with n >= 3 states, got shape {A.shape}")
        if B.shape[0] != n or B.shape[1] < 1:
            raise ModelError(f"B: expected shape ({n}, m) with m >= 1, got {B.shape}")
        if not (np.all(np.isfinite(A)) and np.all(np.isfinite(B))):
            raise ModelError("A, B: entries must be finite")
        # Assumption 2: two integral effects on the position coordinates.
        if not np.allclose(A[:2, :2], np.eye(2)) or not np.allclose(A[2:, :2], 0.0):
            raise ModelError(
                "A: Assumption 2 needs A = [[I, A12], [0, A22]] with the position first "
                f"(A[:2,:2] = I and A[2:,:2] = 0); got A[:2,:2] = {A[:2, :2].tolist()}"
            )
        if not np.allclose(B[:2, :] @ np.zeros(B.shape[1]), 0.0):  # pragma: no cover
            raise ModelError("B: malformed")
        # Reachability (Kalman rank).
        blocks = [B]
        for _ in range(n - 1):
            blocks.append(A @ blocks[-1])
        rank = np.linalg.matrix_rank(np.hstack(blocks))
        if rank < n:
            raise ModelError(f"(A, B): the pair is not reachable (controllability rank {rank} < {n})")
        zlo, zhi = _box("z_bounds", *self.z_bounds, n - 2)
        ulo, uhi = _box("u_bounds", *self.u_bounds, B.shape[1])
        dlo, dhi = _box("d_bounds", *self.d_bounds, n)
        for nm, lo, hi in (("z_bounds", zlo, zhi), ("u_bounds", ulo, uhi), ("d_bounds", dlo, dhi)):
            if np.any(lo > 0) or np.any(hi < 0):
                what = "disturbance set D" if nm == "d_bounds" else nm
                raise ModelError(f"{nm}: the {what} must contain 0, got [{lo.tolist()}, {hi.tolist()}]")
        if not (np.isfinite(self.delta) and self.delta > 0):
            raise ModelError(f"delta: the waypoint spacing must be > 0 m, got {self.delta}")
        if not (np.isfinite(self.Ts) and self.Ts > 0):
            raise ModelError(f"Ts: the sampling time must be > 0 s, got {self.Ts}")
        if self.frame not in ("world", "road"):
            raise ModelError(f"frame: must be 'world' or 'road', got {self.frame!r}")
        if self.frame == "road":
            pairs_ok = n % 2 == 0 and B.shape[1] == 2
            R = np.kron(np.eye(n // 2), [[0.0, -1.0], [1.0, 0.0]]) if n % 2 == 0 else None
            if not pairs_ok or not (np.allclose(R @ A, A @ R) and np.allclose(R @ B, B @ np.array([[0, -1], [1, 0]]))):
                raise ModelError("frame: 'road' needs a rotation-invariant model (states in (x, y) pairs, "
                                 "two inputs (u_x, u_y), the same dynamics on both axes)")
            if not (0.0 <= self.turn_max_deg < 90.0):
                raise ModelError(f"turn_max_deg: must be in [0, 90) degrees, got {self.turn_max_deg}")
        for arr in (A, B, zlo, zhi, ulo, uhi, dlo, dhi):
            arr.setflags(write=False)
        object.__setattr__(self, "A", A)
        object.__setattr__(self, "B", B)
        object.__setattr__(self, "z_bounds", (zlo, zhi))
        object.__setattr__(self, "u_bounds", (ulo, uhi))
        object.__setattr__(self, "d_bounds", (dlo, dhi))
        object.__setattr__(self, "delta", float(self.delta))
        object.__setattr__(self, "Ts", float(self.Ts))

    @property
    def n(self) -> int:
        """Number of states."""
        return self.A.shape[0]

    @property
    def m(self) -> int:
        """Number of inputs."""
        return self.B.shape[1]

    @property
    def C(self) -> np.ndarray:
        """Position selector, shape (2, n)."""
        C = np.zeros((2, self.n))
        C[0, 0] = C[1, 1] = 1.0
        return C

    @property
    def x_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """State box with unbounded position: ``X = R^2 x Z``."""
        lo = np.concatenate([[-np.inf, -np.inf], self.z_bounds[0]])
        hi = np.concatenate([[np.inf, np.inf], self.z_bounds[1]])
        return lo, hi

    def equilibrium(self, position) -> np.ndarray:
        """``x_eq = [p, 0]`` for a position (2,) or positions (k, 2)."""
        p = np.asarray(position, dtype=float)
        z = np.zeros(p.shape[:-1] + (self.n - 2,))
        return np.concatenate([p, z], axis=-1)

    def key(self) -> str:
        """A hash of everything that determines the synthesised sets."""
        h = hashlib.sha256()
        h.update(self.name.encode())
        for arr in (self.A, self.B, *self.z_bounds, *self.u_bounds, *self.d_bounds):
            h.update(np.ascontiguousarray(np.round(arr, 15)).tobytes())
        h.update(np.array([self.delta, self.Ts, self.turn_max_deg]).tobytes())
        h.update(self.frame.encode())
        return h.hexdigest()[:16]


def decoupled_blocks(model: VehicleModel) -> list[tuple[np.ndarray, np.ndarray]]:
    """Split a model into independent blocks of (state indices, input indices).

    Two states are coupled when ``A`` or ``B`` links them (through a shared
    input); boxes never couple.  A block holds at least one state.  A fully
    coupled model returns a single block.
    """
    n, m = model.n, model.m
    parent = list(range(n + m))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    def union(i, j):
        parent[find(i)] = find(j)

    for i, j in zip(*np.nonzero(np.abs(model.A) > 0)):
        union(int(i), int(j))
    for i, k in zip(*np.nonzero(np.abs(model.B) > 0)):
        union(int(i), n + int(k))
    groups: dict[int, tuple[list, list]] = {}
    for i in range(n + m):
        s, u = groups.setdefault(find(i), ([], []))
        (s if i < n else u).append(i if i < n else i - n)
    out = [(np.array(s), np.array(u)) for s, u in groups.values() if s]
    out.sort(key=lambda su: int(su[0][0]))
    return out


def _zoh(Ac: np.ndarray, Bc: np.ndarray, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    n, m = Bc.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n] = Ac
    M[:n, n:] = Bc
    E = expm(M * Ts)
    A, B = E[:n, :n], E[:n, n:]
    A[np.abs(A) < 1e-15] = 0.0
    B[np.abs(B) < 1e-15] = 0.0
    return A, B


def _axes(Ac1: np.ndarray, Bc1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two identical decoupled axes, state order [p_x, p_y, z_x, z_y, ...]."""
    k = Ac1.shape[0]
    Ac = np.kron(Ac1, np.eye(2))
    Bc = np.kron(Bc1, np.eye(2))
    assert Ac.shape == (2 * k, 2 * k)
    return Ac, Bc


def _second_order(name, lag, v_max, u_max, d_max, delta, Ts, frame="world", turn_max_deg=0.0) -> VehicleModel:
    """Per-axis ``p' = v, v' = lag v + a`` (``lag = 0``: double integrator), ZOH.

    ``v_max``, ``u_max`` and ``d_max`` are scalars (same on both axes) or (x, y) pairs;
    ``d_max`` as a pair bounds (position, velocity) disturbances per axis as
    ``[d_px, d_py, d_vx, d_vy] = [dx, dy, dx, dy]``."""
    Ac, Bc = _axes(np.array([[0.0, 1.0], [0.0, lag]]), np.array([[0.0], [1.0]]))
    A, B = _zoh(Ac, Bc, Ts)
    v = np.broadcast_to(np.asarray(v_max, dtype=float), (2,))
    u = np.broadcast_to(np.asarray(u_max, dtype=float), (2,))
    d = np.tile(np.broadcast_to(np.asarray(d_max, dtype=float), (2,)), 2)
    return VehicleModel(name=name, A=A, B=B, z_bounds=(-v, v), u_bounds=(-u, u), d_bounds=(-d, d),
                        delta=delta, Ts=Ts, frame=frame, turn_max_deg=turn_max_deg)


def double_integrator(*, v_max, u_max, d_max, delta: float, Ts: float = 0.1,
                      name: str = "double-integrator", frame: str = "world",
                      turn_max_deg: float = 0.0) -> VehicleModel:
    """The paper's model: ``x = [p_x, p_y, v_x, v_y]``, ``u = [a_x, a_y]``.

    ``|v| <= v_max``, ``|u| <= u_max`` per axis; ``|d_j| <= d_max`` on all four states
    (each a scalar, or an (x, y) pair for different axes, e.g. along / across a road).
    """
    return _second_order(name, 0.0, v_max, u_max, d_max, delta, Ts, frame, turn_max_deg)


def drag_integrator(*, v_max, u_max, d_max, delta: float, tau: float = 5.0, Ts: float = 0.1,
                    name: str = "drag-integrator", frame: str = "world",
                    turn_max_deg: float = 0.0) -> VehicleModel:
    """Double integrator with first-order velocity lag: ``v' = -v/tau + a``."""
    if not (np.isfinite(tau) and tau > 0):
        raise ModelError(f"tau: the velocity time constant must be > 0 s, got {tau}")
    return _second_order(name, -1.0 / tau, v_max, u_max, d_max, delta, Ts, frame, turn_max_deg)


def jerk_integrator(*, v_max: float, a_max: float, j_max: float, d_max: float, delta: float,
                    Ts: float = 0.1, name: str = "jerk-integrator") -> VehicleModel:
    """Jerk-limited model: ``x = [p_x, p_y, v_x, v_y, a_x, a_y]``, ``u = jerk``."""
    Ac, Bc = _axes(np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]]),
                   np.array([[0.0], [0.0], [1.0]]))
    A, B = _zoh(Ac, Bc, Ts)
    return VehicleModel(name=name, A=A, B=B,
                        z_bounds=(-np.array([v_max, v_max, a_max, a_max]),
                                  np.array([v_max, v_max, a_max, a_max])),
                        u_bounds=(-np.full(2, j_max), np.full(2, j_max)),
                        d_bounds=(-np.full(6, d_max), np.full(6, d_max)),
                        delta=delta, Ts=Ts)
