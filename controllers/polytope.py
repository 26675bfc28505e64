"""Convex polytopes in H-representation, as immutable value objects.

``Polytope(A=..., b=...)`` is the set ``{x : A x <= b}``.  Rows are kept
normalised (``|A_i| = 1``) so that every tolerance in
:mod:`controllers.tolerances` is a distance.  Operators follow the usual
set-theoretic notation:

========================  ===========================================
``P + Q``                 Minkowski sum (``Q`` a polytope)
``P + v``                 translation by a vector
``P - W``                 Pontryagin difference ``{x : x + W <= P}``
``P & Q``                 intersection
``M @ P``                 image under the linear map ``M``
``P.preimage(M)``         ``{x : M x in P}``
``x in P``                point membership; ``P <= Q`` set containment
``P * Q``                 Cartesian product
========================  ===========================================

Vertex enumeration, redundancy removal and Minkowski sums use qhull
(``scipy.spatial``); intervals (1-D) are handled in closed form.  The layer
is general in the dimension, but its cost grows quickly with it: callers
that can exploit structure (decoupled axes) should work on low-dimensional
factors and combine them with :meth:`Polytope.product`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from scipy.optimize import linprog
from scipy.spatial import ConvexHull, HalfspaceIntersection, QhullError

from controllers import tolerances as tol

__all__ = ["Polytope", "PolytopeError"]


def _origin_interior_2d(A: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """The origin as qhull's interior point of a bounded 2-D polygon, when it is one.

    Avoids the Chebyshev LP: the origin is interior when every ``b_i / |a_i|`` exceeds
    ``EMPTY_RADIUS_TOL``, and the polygon is bounded when its normals leave no angular
    gap of pi or more.  None when either test fails (the caller then uses the LP).
    """
    if len(b) < 3:
        return None
    norm = np.linalg.norm(A, axis=1)
    if np.any(norm <= 0) or np.min(b / norm) <= tol.EMPTY_RADIUS_TOL:
        return None
    ang = np.sort(np.arctan2(A[:, 1], A[:, 0]))
    gaps = np.diff(np.concatenate([ang, ang[:1] + 2 * np.pi]))
    if gaps.max() >= np.pi - 1e-9:
        return None
    return np.zeros(2)


class PolytopeError(ValueError):
    """Raised for an invalid polytope operation (empty set, unbounded set...)."""


def _normalise(A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    norms = np.linalg.norm(A, axis=1)
    keep = norms > tol.FACET_MERGE_TOL
    if not np.all(keep):
        # A zero row 0 @ x <= b_i is either always true (b_i >= 0) or empty.
        if np.any(b[~keep] < -tol.MEMBERSHIP_TOL):
            raise PolytopeError("a row 0 @ x <= b with b < 0 makes the set empty")
    A, b, norms = A[keep], b[keep], norms[keep]
    return A / norms[:, None], b / norms


def _dedupe(A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge rows with the same normal (within tolerance), keeping the tightest."""
    if len(A) == 0:
        return A, b
    # Only (numerically) identical hyperplanes are merged: qhull splits one facet into
    # simplices whose normals agree to ~1e-12.  Merging merely similar normals would
    # change the set.
    keys = np.round(np.hstack([A, b[:, None]]) / tol.FACET_MERGE_TOL).astype(np.int64)
    _, inverse = np.unique(keys, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    n_groups = inverse.max() + 1
    best_b = np.full(n_groups, np.inf)
    np.minimum.at(best_b, inverse, b)
    first = np.full(n_groups, -1)
    # representative normal: the first row of each group
    order = np.arange(len(A))[::-1]
    first[inverse[order]] = order
    return A[first], best_b


@dataclass(frozen=True, eq=False)
class Polytope:
    """The convex set ``{x : A x <= b}``.

    Parameters
    ----------
    A : array_like, shape (m, n)
        Half-space normals.  Rows are normalised on construction.
    b : array_like, shape (m,)
        Half-space offsets.
    """

    A: np.ndarray
    b: np.ndarray
    _meta: dict = field(default_factory=dict, repr=False, compare=False)

    #: Let ``M @ P`` with a numpy array ``M`` reach :meth:`__rmatmul__`.
    __array_ufunc__ = None

    def __post_init__(self) -> None:
        A = np.atleast_2d(np.asarray(self.A, dtype=float))
        b = np.asarray(self.b, dtype=float).reshape(-1)
        if A.shape[0] != b.shape[0]:
            raise PolytopeError(f"A has {A.shape[0]} rows but b has {b.shape[0]} entries")
        if not (np.all(np.isfinite(A)) and np.all(np.isfinite(b))):
            raise PolytopeError("A and b must be finite")
        A, b = _normalise(A, b)
        A.setflags(write=False)
        b.setflags(write=False)
        object.__setattr__(self, "A", A)
        object.__setattr__(self, "b", b)

    # ------------------------------------------------------------------ builders
    @classmethod
    def from_box(cls, lower, upper) -> "Polytope":
        """Axis-aligned box ``lower <= x <= upper``; infinite bounds are dropped."""
        lo = np.asarray(lower, dtype=float).reshape(-1)
        hi = np.asarray(upper, dtype=float).reshape(-1)
        if lo.shape != hi.shape:
            raise PolytopeError("lower and upper bounds differ in length")
        if np.any(lo > hi):
            raise PolytopeError(f"empty box: lower {lo} exceeds upper {hi}")
        n = lo.size
        eye = np.eye(n)
        A = np.vstack([eye, -eye])
        b = np.concatenate([hi, -lo])
        finite = np.isfinite(b)
        P = cls(A=A[finite], b=b[finite])
        P._meta["dim"] = n
        return P

    @classmethod
    def from_vertices(cls, V) -> "Polytope":
        """Convex hull of the rows of ``V`` (must be full-dimensional)."""
        V = np.atleast_2d(np.asarray(V, dtype=float))
        n = V.shape[1]
        if n == 1:
            return cls.from_box(V.min(axis=0), V.max(axis=0))
        try:
            try:
                hull = ConvexHull(V)
            except QhullError:
                hull = ConvexHull(V, qhull_options="Qt Q12 Pp")
        except QhullError as exc:
            raise PolytopeError(f"points do not span {n} dimensions: {exc}") from None
        A = hull.equations[:, :-1]
        b = -hull.equations[:, -1]
        A, b = _dedupe(*_normalise(A, b))
        P = cls(A=A, b=b)
        P._meta["vertices"] = V[hull.vertices]
        return P

    @classmethod
    def from_zonotope(cls, center, generators) -> "Polytope":
        """H-representation of the zonotope ``c + G [-1, 1]^p`` (2-D closed form,
        vertices + hull otherwise)."""
        c = np.asarray(center, dtype=float).reshape(-1)
        G = np.atleast_2d(np.asarray(generators, dtype=float))
        if G.shape[0] != c.size:
            raise PolytopeError("generators must have one row per dimension")
        G = G[:, np.linalg.norm(G, axis=0) > tol.FACET_MERGE_TOL]
        n = c.size
        if n == 1:
            r = np.abs(G).sum()
            return cls.from_box(c - r, c + r)
        if n == 2:
            normals = np.stack([-G[1], G[0]], axis=1)
            normals /= np.linalg.norm(normals, axis=1)[:, None]
            normals = np.vstack([normals, -normals])
            b = normals @ c + np.abs(normals @ G).sum(axis=1)
            A, b = _dedupe(normals, b)
            return cls(A=A, b=b)
        # n >= 3: enumerate vertices by combining signs on the hull iteratively
        V = c[None, :]
        for g in G.T:
            V = np.vstack([V + g, V - g])
            if len(V) > 4 * n:
                V = V[ConvexHull(V).vertices]
        return cls.from_vertices(V)

    # ------------------------------------------------------------------ basics
    @property
    def dim(self) -> int:
        """Dimension of the ambient space."""
        return int(self._meta.get("dim", self.A.shape[1]))

    @property
    def n_facets(self) -> int:
        """Number of half-spaces in the (irredundant, once minimised) representation."""
        return int(self.A.shape[0])

    def __repr__(self) -> str:  # pragma: no cover - cosmetic
        return f"Polytope(dim={self.dim}, facets={self.n_facets})"

    @cached_property
    def chebyshev(self) -> tuple[np.ndarray, float]:
        """Chebyshev centre and radius (radius ``-inf`` when empty, ``inf`` when unbounded)."""
        n = self.dim
        if self.n_facets == 0:
            return np.zeros(n), np.inf
        c = np.zeros(n + 1)
        c[-1] = -1.0
        A_ub = np.hstack([self.A, np.ones((self.n_facets, 1))])
        res = linprog(c, A_ub=A_ub, b_ub=self.b, bounds=[(None, None)] * n + [(0, None)],
                      method="highs")
        if res.status == 3:
            return np.zeros(n), np.inf
        if res.status != 0:
            return np.zeros(n), -np.inf
        return res.x[:n], float(res.x[-1])

    @property
    def is_empty(self) -> bool:
        """True when the set has no interior (empty or lower dimensional)."""
        return self.chebyshev[1] <= tol.EMPTY_RADIUS_TOL

    @property
    def is_bounded(self) -> bool:
        """True when the set is bounded."""
        if self.n_facets <= self.dim:
            return False
        # Bounded iff the normals positively span R^n: max d.x s.t. A x <= 0 is 0.
        for d in np.vstack([np.eye(self.dim), -np.eye(self.dim)]):
            res = linprog(-d, A_ub=self.A, b_ub=np.zeros(self.n_facets),
                          bounds=[(None, None)] * self.dim, method="highs")
            if res.status == 3 or (res.status == 0 and -res.fun > tol.MEMBERSHIP_TOL):
                return False
        return True

    @cached_property
    def vertices(self) -> np.ndarray:
        """Vertices, shape (k, n).  Raises :class:`PolytopeError` if empty or unbounded."""
        if "vertices" in self._meta:
            return self._meta["vertices"]
        n = self.dim
        if n == 1:
            a = self.A[:, 0]
            hi = np.min(self.b[a > 0] / a[a > 0]) if np.any(a > 0) else np.inf
            lo = np.max(self.b[a < 0] / a[a < 0]) if np.any(a < 0) else -np.inf
            if not (np.isfinite(lo) and np.isfinite(hi)):
                raise PolytopeError("unbounded interval has no vertices")
            if lo > hi + tol.MEMBERSHIP_TOL:
                raise PolytopeError("empty interval has no vertices")
            return np.array([[lo], [hi]])
        centre = _origin_interior_2d(self.A, self.b) if n == 2 else None
        if centre is None:
            centre, radius = self.chebyshev
            if not np.isfinite(radius):
                raise PolytopeError("unbounded or empty polytope has no vertex list")
            if radius <= tol.EMPTY_RADIUS_TOL:
                raise PolytopeError("empty (or lower-dimensional) polytope")
        hs = np.hstack([self.A, -self.b[:, None]])
        try:
            V = HalfspaceIntersection(hs, centre).intersections
        except QhullError:
            # Nearly coincident facets (qhull's triangulation of a facet in >= 3-D) can
            # trip qhull's precision checks; allow wide merges and verify downstream.
            try:
                V = HalfspaceIntersection(hs, centre, qhull_options="Qbb Qc Qt Q12 Pp").intersections
            except QhullError as exc:  # pragma: no cover - numerical failure
                raise PolytopeError(f"vertex enumeration failed: {str(exc)[:200]}") from None
        if not np.all(np.isfinite(V)):
            raise PolytopeError("unbounded polytope has no vertex list")
        V = np.unique(np.round(V, 12), axis=0)
        if n >= 2 and len(V) > n + 1:
            try:
                V = V[ConvexHull(V).vertices]
            except QhullError:  # degenerate clusters: keep the (valid, redundant) list
                pass
        return V

    def minimal(self) -> "Polytope":
        """An irredundant H-representation of the same (bounded) set."""
        if self._meta.get("minimal"):
            return self
        V = self.vertices
        if self.dim == 1:
            P = Polytope.from_box(V.min(axis=0), V.max(axis=0))
        else:
            P = Polytope.from_vertices(V)
        P._meta["minimal"] = True
        P._meta["vertices"] = V
        return P

    def support(self, directions) -> np.ndarray:
        """Support function ``h(d) = max_{x in P} d @ x`` for each row of ``directions``."""
        D = np.atleast_2d(np.asarray(directions, dtype=float))
        return (D @ self.vertices.T).max(axis=1)

    def contains(self, points, tol_: float = tol.MEMBERSHIP_TOL) -> np.ndarray:
        """Vectorised membership of the rows of ``points`` (shape (k, n))."""
        X = np.atleast_2d(np.asarray(points, dtype=float))
        return np.all(X @ self.A.T <= self.b + tol_, axis=1)

    def __contains__(self, x) -> bool:
        x = np.asarray(x, dtype=float)
        if x.ndim != 1 or x.size != self.dim:
            raise PolytopeError(f"point of shape {x.shape} in a {self.dim}-D polytope")
        return bool(self.contains(x[None, :])[0])

    def __le__(self, other: "Polytope") -> bool:
        """``self`` is a subset of ``other`` (within CONTAINMENT_TOL)."""
        if not isinstance(other, Polytope):
            return NotImplemented
        if other.n_facets == 0:
            return True
        return bool(np.all(self.support(other.A) <= other.b + tol.CONTAINMENT_TOL))

    def __ge__(self, other: "Polytope") -> bool:
        return other <= self

    def equals(self, other: "Polytope") -> bool:
        """Mutual containment within CONTAINMENT_TOL."""
        return self <= other and other <= self

    # ------------------------------------------------------------------ operators
    def __add__(self, other) -> "Polytope":
        if isinstance(other, Polytope):
            return self.minkowski_sum(other)
        v = np.asarray(other, dtype=float).reshape(-1)
        if v.size != self.dim:
            raise PolytopeError(f"cannot translate a {self.dim}-D polytope by {v.size}-vector")
        P = Polytope(A=self.A, b=self.b + self.A @ v)
        if "vertices" in self.__dict__ or "vertices" in self._meta:
            P._meta["vertices"] = self.vertices + v
        if self._meta.get("minimal"):
            P._meta["minimal"] = True
        return P

    __radd__ = __add__

    def minkowski_sum(self, other: "Polytope") -> "Polytope":
        """``{x + y : x in self, y in other}``."""
        if other.dim != self.dim:
            raise PolytopeError("Minkowski sum of polytopes of different dimension")
        V1, V2 = self.vertices, other.vertices
        V = (V1[:, None, :] + V2[None, :, :]).reshape(-1, self.dim)
        if self.dim == 1:
            return Polytope.from_box(V.min(axis=0), V.max(axis=0))
        P = Polytope.from_vertices(V)
        P._meta["minimal"] = True
        return P

    def __sub__(self, other) -> "Polytope":
        if isinstance(other, Polytope):
            return self.pontryagin_difference(other)
        v = np.asarray(other, dtype=float).reshape(-1)
        return self + (-v)

    def pontryagin_difference(self, W: "Polytope") -> "Polytope":
        """``{x : x + w in self for all w in W}`` (same normals, shifted offsets)."""
        if W.dim != self.dim:
            raise PolytopeError("Pontryagin difference of polytopes of different dimension")
        return Polytope(A=self.A, b=self.b - W.support(self.A))

    def __and__(self, other: "Polytope") -> "Polytope":
        if other.dim != self.dim:
            raise PolytopeError("intersection of polytopes of different dimension")
        P = Polytope(A=np.vstack([self.A, other.A]), b=np.concatenate([self.b, other.b]))
        P._meta["dim"] = self.dim
        return P

    def __rmatmul__(self, M) -> "Polytope":
        return self.linear_map(M)

    def linear_map(self, M) -> "Polytope":
        """Image ``{M x : x in self}``; ``M`` square invertible keeps the H-form exact."""
        M = np.atleast_2d(np.asarray(M, dtype=float))
        if M.shape[1] != self.dim:
            raise PolytopeError(f"map of shape {M.shape} on a {self.dim}-D polytope")
        if M.shape[0] == M.shape[1] and abs(np.linalg.det(M)) > 1e-12:
            P = Polytope(A=self.A @ np.linalg.inv(M), b=self.b)
            P._meta["dim"] = M.shape[0]
            return P
        V = self.vertices @ M.T
        if M.shape[0] == 1:
            return Polytope.from_box(V.min(axis=0), V.max(axis=0))
        return Polytope.from_vertices(V)

    def preimage(self, M) -> "Polytope":
        """``{x : M x in self}``."""
        M = np.atleast_2d(np.asarray(M, dtype=float))
        if M.shape[0] != self.dim:
            raise PolytopeError(f"pre-image by a map of shape {M.shape} into a {self.dim}-D set")
        P = Polytope(A=self.A @ M, b=self.b)
        P._meta["dim"] = M.shape[1]
        return P

    def project(self, dims) -> "Polytope":
        """Projection onto the coordinates ``dims`` (a bounded polytope)."""
        dims = list(dims)
        V = self.vertices[:, dims]
        if len(dims) == 1:
            return Polytope.from_box(V.min(axis=0), V.max(axis=0))
        return Polytope.from_vertices(V)

    def __mul__(self, other: "Polytope") -> "Polytope":
        return self.product(other)

    def product(self, other: "Polytope") -> "Polytope":
        """Cartesian product ``self x other`` (coordinates of ``self`` first)."""
        n1, n2 = self.dim, other.dim
        A = np.zeros((self.n_facets + other.n_facets, n1 + n2))
        A[: self.n_facets, :n1] = self.A
        A[self.n_facets:, n1:] = other.A
        P = Polytope(A=A, b=np.concatenate([self.b, other.b]))
        P._meta["dim"] = n1 + n2
        return P

    def scale(self, factor: float) -> "Polytope":
        """``factor * self`` for ``factor > 0``."""
        if factor <= 0:
            raise PolytopeError("scale factor must be positive")
        return Polytope(A=self.A, b=self.b * factor)

    def polygon(self) -> np.ndarray:
        """Vertices of a 2-D polytope in counter-clockwise order, shape (k, 2)."""
        if self.dim != 2:
            raise PolytopeError("polygon() needs a 2-D polytope")
        V = self.vertices
        c = V.mean(axis=0)
        order = np.argsort(np.arctan2(V[:, 1] - c[1], V[:, 0] - c[0]))
        return V[order]
