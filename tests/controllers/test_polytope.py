"""Property-based tests of the polytope layer.

Tolerances: set relations are decided with CONTAINMENT_TOL (1e-7) on
normalised rows; the random sets below have extents O(1..10), so round-off
in qhull (~1e-12 relative) is far inside it.
"""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.optimize import linprog

from controllers import tolerances as tol
from controllers.polytope import Polytope, PolytopeError


@st.composite
def polytopes(draw, dim=None):
    n = dim or draw(st.integers(1, 3))
    seed = draw(st.integers(0, 2**31 - 1))
    rng = np.random.default_rng(seed)
    k = draw(st.integers(n + 2, 12))
    V = rng.normal(size=(k, n)) * draw(st.floats(0.5, 5.0)) + rng.normal(size=n)
    return Polytope.from_vertices(V)


def _lp_contains(P: Polytope, x) -> bool:
    return bool(np.all(P.A @ x <= P.b + tol.MEMBERSHIP_TOL))


@settings(max_examples=40, deadline=None)
@given(polytopes(), polytopes(), st.data())
def test_minkowski_then_pontryagin_recovers_P(P, Q, data):
    if P.dim != Q.dim:
        Q = data.draw(polytopes(dim=P.dim))
    S = P + Q
    R = S - Q
    assert P <= R and R <= P  # (P ⊕ Q) ⊖ Q = P for convex P, Q


@settings(max_examples=40, deadline=None)
@given(polytopes(), st.integers(0, 2**31 - 1))
def test_membership_agrees_with_vertex_lp(P, seed):
    """x ∈ P (H-form) iff x is a convex combination of P's vertices (an LP)."""
    rng = np.random.default_rng(seed)
    V = P.vertices
    lo, hi = V.min(axis=0), V.max(axis=0)
    pts = lo + (hi - lo) * (rng.random((30, P.dim)) * 1.4 - 0.2)
    inside = P.contains(pts)
    for x, ins in zip(pts, inside):
        res = linprog(np.zeros(len(V)), A_eq=np.vstack([V.T, np.ones(len(V))]),
                      b_eq=np.concatenate([x, [1.0]]), bounds=[(0, None)] * len(V), method="highs")
        margin = np.max(P.A @ x - P.b)
        if abs(margin) > 1e-6:  # away from the boundary both tests must agree exactly
            assert ins == (res.status == 0)


@settings(max_examples=40, deadline=None)
@given(polytopes(dim=2), st.integers(0, 2**31 - 1))
def test_preimage_then_image_is_identity(P, seed):
    rng = np.random.default_rng(seed)
    M = rng.normal(size=(2, 2)) + 2 * np.eye(2)
    pre = P.preimage(M)
    back = M @ pre
    assert back.equals(P)
    # pre-image membership: x ∈ pre  iff  M x ∈ P
    X = rng.normal(size=(50, 2)) * 3
    assert np.array_equal(pre.contains(X), P.contains(X @ M.T))


@settings(max_examples=30, deadline=None)
@given(polytopes(), polytopes(), st.data())
def test_pontryagin_difference_definition(P, W, data):
    if W.dim != P.dim:
        W = data.draw(polytopes(dim=P.dim))
    W = W - W.chebyshev[0]  # centre W at the origin
    W = W.scale(0.2)
    D = P - W
    if D.is_empty:
        return
    # every point of P ⊖ W plus every vertex of W lies in P
    for v in D.vertices:
        assert P.contains(v + W.vertices).all()


@settings(max_examples=30, deadline=None)
@given(polytopes(), polytopes(), st.data())
def test_intersection_and_containment(P, Q, data):
    if Q.dim != P.dim:
        Q = data.draw(polytopes(dim=P.dim))
    I = P & Q
    if I.is_empty:
        return
    I = I.minimal()
    assert I <= P and I <= Q
    X = np.vstack([P.vertices, Q.vertices])
    assert np.array_equal(I.contains(X), P.contains(X) & Q.contains(X))


@settings(max_examples=30, deadline=None)
@given(polytopes(dim=3), st.integers(0, 2**31 - 1))
def test_support_projection_and_redundancy(P, seed):
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(5, 3))
    assert np.allclose(P.support(d), (d @ P.vertices.T).max(axis=1))
    proj = P.project([0, 2])
    assert np.allclose(proj.support(d[:, [0, 2]]), P.support(np.column_stack([d[:, 0], 0 * d[:, 0], d[:, 2]])))
    # adding redundant rows and minimising gives back the same set
    red = Polytope(A=np.vstack([P.A, P.A]), b=np.concatenate([P.b, P.b + 1.0]))
    mini = red.minimal()
    assert mini.equals(P) and mini.n_facets == P.minimal().n_facets


def test_product_box_translation_and_emptiness():
    B = Polytope.from_box([-1, -2], [1, 2])
    I = Polytope.from_box([0.0], [3.0])
    P = B * I
    assert P.dim == 3 and np.array([0.5, 1.0, 2.0]) in P and np.array([0.5, 1.0, 3.5]) not in P
    T = B + np.array([10.0, 0.0])
    assert np.array([10.5, 0.0]) in T and np.array([0.0, 0.0]) not in T
    E = Polytope.from_box([0, 0], [1, 1]) & Polytope.from_box([2, 2], [3, 3])
    assert E.is_empty
    with pytest.raises(PolytopeError):
        E.vertices
    with pytest.raises(PolytopeError, match="empty box"):
        Polytope.from_box([1.0], [0.0])


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(2, 12))
def test_zonotope_h_form_matches_vertices(seed, g):
    rng = np.random.default_rng(seed)
    G = rng.normal(size=(2, g))
    Z = Polytope.from_zonotope(np.zeros(2), G)
    signs = rng.choice([-1.0, 1.0], size=(400, g))
    pts = signs @ G.T
    assert Z.contains(pts, tol_=1e-9).all()
    # support function of a zonotope: sum |a' g|
    assert np.allclose(Z.support(Z.A), np.abs(Z.A @ G).sum(axis=1), atol=1e-9)
