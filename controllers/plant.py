"""The linear plant muvsim steps itself, and the disturbance policies.

``x(t+1) = A x(t) + B u(t) + d(t)`` with ``d(t) ∈ D`` (a box), for many
vehicles of one class at once.  Policies:

* ``none`` -- ``d = 0``;
* ``random`` -- uniform in ``D``;
* ``adversarial`` -- a vertex of ``D`` that pushes the state outward: each
  component takes the sign of the nominal successor's deviation from the
  current target equilibrium (``A x + B u - x_eq``), so the disturbance always
  works against convergence.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from controllers.models import VehicleModel

__all__ = ["DISTURBANCES", "disturbance", "step"]

DISTURBANCES = ("random", "adversarial", "none")
Disturbance = Literal["random", "adversarial", "none"]


def disturbance(model: VehicleModel, policy: str, nominal_error: np.ndarray,
                rng: np.random.Generator) -> np.ndarray:
    """Disturbances for rows of ``nominal_error = A x + B u - x_eq`` (shape (V, n))."""
    lo, hi = model.d_bounds
    V = nominal_error.shape[0]
    if policy == "none":
        return np.zeros((V, model.n))
    if policy == "random":
        return lo + (hi - lo) * rng.random((V, model.n))
    if policy == "adversarial":
        return np.where(nominal_error >= 0.0, hi, lo)
    raise ValueError(f"disturbance policy must be one of {DISTURBANCES}, got {policy!r}")


def step(model: VehicleModel, X: np.ndarray, U: np.ndarray, centres: np.ndarray, policy: str,
         rng: np.random.Generator, heading=None) -> tuple[np.ndarray, np.ndarray]:
    """One plant step for many vehicles; returns ``(X_next, D)`` (world frame).

    For ``road``-frame models the disturbance box holds in the frame of ``heading``
    (along / across the segment); it is drawn there and rotated to the world.
    """
    nominal = X @ model.A.T + U @ model.B.T
    err = nominal - model.equilibrium(centres)
    if model.frame == "road":
        from controllers.synthesis import rotate_pairs

        h = np.asarray(heading, dtype=float)
        D = rotate_pairs(disturbance(model, policy, rotate_pairs(err, -h), rng), h)
    else:
        D = disturbance(model, policy, err, rng)
    return nominal + D, D
