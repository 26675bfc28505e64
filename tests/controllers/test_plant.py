"""The disturbance policies of controllers/plant.py do what they claim.

``adversarial``: the disturbance is a vertex of D (every component at its bound) and each
component pushes the successor further from the target equilibrium than the nominal
successor.  ``random``: samples lie in D and cover it (every vertex region and every face).
"""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from controllers.classes import builtin_classes
from controllers.plant import disturbance, step
from controllers.synthesis import rotate_pairs

CLASSES = builtin_classes()
NAMES = ["paper-a", "paper-c", "car", "bus", "truck"]


def _frame_err(model, X, U, centres, heading):
    """Nominal successor's deviation from the target, in the frame D is defined in."""
    err = X @ model.A.T + U @ model.B.T - model.equilibrium(centres)
    return rotate_pairs(err, -heading) if model.frame == "road" else err


@settings(max_examples=40, deadline=None)
@given(st.sampled_from(NAMES), st.integers(0, 2**32 - 1))
def test_adversarial_is_the_full_vertex_pushing_away(name, seed):
    m = CLASSES[name].model
    rng = np.random.default_rng(seed)
    V = 50
    X = rng.normal(scale=3.0, size=(V, m.n))
    U = rng.uniform(-1.0, 1.0, size=(V, m.B.shape[1]))  # any input: the property is about d
    centres = rng.uniform(-50, 50, size=(V, 2))
    heading = rng.uniform(-np.pi, np.pi, size=V)
    Xn, D = step(m, X, U, centres, "adversarial", rng, heading=heading)
    lo, hi = (np.broadcast_to(np.asarray(b, dtype=float), (m.n,)) for b in m.d_bounds)
    err = _frame_err(m, X, U, centres, heading)
    Dl = rotate_pairs(D, -heading) if m.frame == "road" else D
    # a vertex of D: every component at one of its bounds (tolerance: rotation round-off, 1e-9)
    at_bound = np.isclose(Dl, hi, atol=1e-9) | np.isclose(Dl, lo, atol=1e-9)
    assert at_bound.all()
    # and the bound on the side away from the target, so the successor's deviation grows by the
    # full |d_i| in every component with a non-zero deviation
    succ = err + Dl
    moving = np.abs(err) > 1e-9
    grown = np.abs(succ) - np.abs(err) - np.abs(Dl)
    assert np.all(np.abs(grown[moving]) < 1e-9)
    assert np.all(lo < 0) and np.all(hi > 0)  # so a zero disturbance is never a vertex of D
    # the world-frame successor is nominal + D
    assert np.allclose(Xn, X @ m.A.T + U @ m.B.T + D, atol=1e-12)


@pytest.mark.parametrize("name", ["paper-a", "car"])
def test_random_covers_D(name):
    """20,000 samples of ``random``: all in D; every one of the 2^n vertex regions (each coordinate
    within the outer 20 % of its range on the vertex's side) and every face (within 1 % of a
    bound) holds samples; the mean is D's centre.  Tolerances: a vertex region is 0.2^n of D
    (n = 4: 1.6e-3, 32 samples expected, P(empty) = e^-32); a face slab 1 % (200 expected); the
    mean within 5 standard errors (sd of U(lo, hi) = (hi - lo) / sqrt(12))."""
    m = CLASSES[name].model
    rng = np.random.default_rng(7)
    N = 20_000
    D = disturbance(m, "random", np.zeros((N, m.n)), rng)
    lo, hi = (np.broadcast_to(np.asarray(b, dtype=float), (m.n,)) for b in m.d_bounds)
    assert np.all((D >= lo) & (D <= hi))
    u = (D - lo) / (hi - lo)  # in [0, 1]^n
    for vertex in range(2 ** m.n):
        side = np.array([(vertex >> i) & 1 for i in range(m.n)], dtype=bool)
        near = np.where(side, u >= 0.8, u <= 0.2).all(axis=1)
        assert near.sum() >= 1, f"vertex {side.astype(int)} of D never approached"
    for i in range(m.n):
        assert (u[:, i] <= 0.01).sum() >= 100 and (u[:, i] >= 0.99).sum() >= 100
    se = (hi - lo) / np.sqrt(12 * N)
    assert np.all(np.abs(D.mean(axis=0) - 0.5 * (lo + hi)) < 5 * se)


def test_random_road_frame_disturbance_lies_in_the_rotated_box():
    """For road-frame classes D holds along/across the segment: rotated back by the heading,
    every sample is in the box and reaches its corners (5 % of the range, 10,000 samples)."""
    m = CLASSES["car"].model
    rng = np.random.default_rng(3)
    N = 10_000
    X = np.zeros((N, m.n))
    heading = np.full(N, 0.7)
    _, D = step(m, X, np.zeros((N, m.B.shape[1])), np.zeros((N, 2)), "random", rng, heading=heading)
    Dl = rotate_pairs(D, -heading)
    lo, hi = (np.broadcast_to(np.asarray(b, dtype=float), (m.n,)) for b in m.d_bounds)
    assert np.all((Dl >= lo - 1e-12) & (Dl <= hi + 1e-12))  # 1e-12: rotation round-off
    u = (Dl - lo) / (hi - lo)
    assert np.all(u.min(axis=0) < 0.05) and np.all(u.max(axis=0) > 0.95)
