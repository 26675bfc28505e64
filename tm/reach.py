"""Reach-tightened, time-indexed claims of movement-authority vehicles (design.md §7 "Claims").

A vehicle with state ``x(t)``, waypoint ``c`` (its stop point) and index ``l`` claims, for
``k = 1 .. K``,

    S_k(t) = proj(Reach_k(x(t)) ∩ T^{max(l-k, 0)}(c)) ⊕ footprint,

as a box in the frame of ``c``'s segment (x along, y across), closed form:

* ``Reach_k``: the interval hull of ``A^k x + sum_{j<k} A^j (B u_j + d_j)`` over the input and
  disturbance boxes (exact for boxes) -- centre ``A^k x``, radius
  ``r_k = sum_{j<k} |A^j B| ū + |A^j| d̄`` per factor;
* ``T^m``: its velocity range, and ``g_m``, ``h_m`` of :mod:`controllers.authority`, so the
  along extent is ``[max(p_lo_k, h_m(v_hi_k)), min(p_hi_k, g_m(v_lo_k))]`` with
  ``[v_lo_k, v_hi_k]`` the reach's velocity interval cut to ``T^m``'s;
* across: the reach's interval cut to ``T^m``'s across range;
* the footprint: its bounding box in the segment frame (``body_offset``: the largest angle
  between the body and the segment, 0 on a straight), plus ``body_pad``: how far the simulator's
  own body may reach beyond it (SUMO's lane-following body, :mod:`bridge.sumo_body`).

The last slot ``k = K`` holds ``T^0 ⊕ footprint`` whole: it stands for every ``k >= K``
(``K > N >= l``, so the tube has ended in ``T^0``).  The projection of an intersection lies in
the intersection of the interval bounds, so every box is a sound outer bound: ``x(t+k) ∈ S_k``
whenever the waypoint stays (proof: physics and the tube).  Not granted, claims only shrink:
``S_k(t+1) ⊆ S_{k+1}(t)`` (the reach nests, the index drops, the tables are monotone).

Checks: ``timed`` compares ``S_k(i)`` with ``S_k(j)`` for each ``k``; ``union`` compares the
segment-frame bounding boxes of ``∪_k S_k`` (a superset of the union: sound, and robust
against a vehicle that stops instantly).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.authority import AuthorityTables
from controllers.synthesis import SetFamily, along_factor, rotate_pairs
from controllers.tolerances import GEOMETRY_TOL

__all__ = ["ReachModel", "ReachClaims", "reach_claims", "claims_conflict", "pairwise_conflicts", "world_aabb",
           "candidate_pairs", "pad_slots"]


@dataclass(frozen=True, eq=False)
class ReachModel:
    """Per-class data of the claim boxes (read-only arrays), ``K = N + 2`` slots.

    Attributes
    ----------
    Ak_al, Ak_ac : ndarray, shape (K, 2, 2)
        ``A^k`` of the along and across factors, in ``(p, v)`` order.
    r_al, r_ac : ndarray, shape (K, 2)
        Reach radii ``r_k`` (``k = 0 .. K-1``) of the along and across factors.
    tables : AuthorityTables
    length, width : float
        Footprint (m).
    """

    Ak_al: np.ndarray
    Ak_ac: np.ndarray
    r_al: np.ndarray
    r_ac: np.ndarray
    tables: AuthorityTables
    length: float
    width: float

    @property
    def N(self) -> int:
        return self.tables.N

    @property
    def K(self) -> int:
        """Claim slots: ``k = 1 .. K`` (the last one stands for every later step)."""
        return self.N + 2

    @classmethod
    def build(cls, family: SetFamily, tables: AuthorityTables, length: float, width: float) -> "ReachModel":
        """Powers and radii of both factors of ``family`` (road frame, 2-D factors)."""
        m = family.model
        K = family.N + 2
        out = {}
        for name, pos, vel in (("al", 0, 2), ("ac", 1, 3)):
            f = next(f for f in family.factors if pos in f.states)
            st = list(f.states)
            idx = [st.index(pos), st.index(vel)]
            A = f.A[np.ix_(idx, idx)]
            B = f.B[idx, :]
            ub = m.u_bounds[1][f.inputs]
            db = m.d_bounds[1][[pos, vel]]
            Ak = np.empty((K, 2, 2))
            r = np.zeros((K, 2))
            P = np.eye(2)
            for k in range(K):
                Ak[k] = P
                if k + 1 < K:
                    r[k + 1] = r[k] + np.abs(P @ B) @ ub + np.abs(P) @ db
                P = A @ P
            out[f"Ak_{name}"], out[f"r_{name}"] = Ak, r
        for a in out.values():
            a.flags.writeable = False
        return cls(tables=tables, length=float(length), width=float(width), **out)


@dataclass(frozen=True, eq=False)
class ReachClaims:
    """Claim boxes of ``n`` vehicles: ``centre + R(heading) [lo, hi]`` for slots ``k = 1 .. K``.

    Attributes
    ----------
    centre : ndarray, shape (n, 2)
        Waypoints ``c`` (world).
    heading : ndarray, shape (n,)
        Segment headings (rad).
    lo, hi : ndarray, shape (n, K, 2)
        Box corners in the segment frame, footprint included; slot ``j`` is ``k = j + 1``.
        An empty box (``lo > hi``) never conflicts.
    """

    centre: np.ndarray
    heading: np.ndarray
    lo: np.ndarray
    hi: np.ndarray

    def __len__(self) -> int:
        return len(self.centre)

    def shift(self) -> "ReachClaims":
        """``S_{k+1}(t)`` as the claims for ``t + 1`` (reuse for vehicles not granted):
        drop slot 1, repeat the last (``T^0``, every later step)."""
        lo = np.concatenate([self.lo[:, 1:], self.lo[:, -1:]], axis=1)
        hi = np.concatenate([self.hi[:, 1:], self.hi[:, -1:]], axis=1)
        return ReachClaims(self.centre, self.heading, lo, hi)

    def take(self, idx) -> "ReachClaims":
        return ReachClaims(self.centre[idx], self.heading[idx], self.lo[idx], self.hi[idx])

    @staticmethod
    def concat(*parts: "ReachClaims") -> "ReachClaims":
        K = max(p.lo.shape[1] for p in parts)
        def pad(a):  # pad with the last slot (it stands for every later step)
            return np.concatenate([a, np.repeat(a[:, -1:], K - a.shape[1], axis=1)], axis=1)
        return ReachClaims(np.concatenate([p.centre for p in parts]), np.concatenate([p.heading for p in parts]),
                           np.concatenate([pad(p.lo) for p in parts]), np.concatenate([pad(p.hi) for p in parts]))

    def world_corners(self, i: int, k: int) -> np.ndarray:
        """Corners (4, 2) of box ``S_k`` of vehicle ``i`` in the world (``k >= 1``)."""
        lo, hi = self.lo[i, k - 1], self.hi[i, k - 1]
        C = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
        return self.centre[i] + rotate_pairs(C, self.heading[i])


def reach_claims(rm: ReachModel, X: np.ndarray, centre: np.ndarray, heading: np.ndarray,
                 index: np.ndarray, body_offset=0.0, body_pad=None) -> ReachClaims:
    """Claims of vehicles of one class (vectorised over vehicles and steps).

    Parameters
    ----------
    rm : ReachModel
    X : ndarray, shape (n, 4)
        World states ``[p_x, p_y, v_x, v_y]``.
    centre : ndarray, shape (n, 2)
        Current (or requested) waypoints.
    heading : ndarray, shape (n,)
        Their segment headings.
    index : ndarray of int, shape (n,)
        Membership index of ``x`` w.r.t. ``centre`` (``<= N``).
    body_offset : float or ndarray (n,)
        Largest angle (rad) between the body and the segment over the claim.
    body_pad : ndarray (n, 2), optional
        How far (m, along and across the segment) the simulator's body may reach beyond the
        footprint rectangle centred on the position (e.g. SUMO's lane-following body around turns,
        :meth:`bridge.sumo_body.RouteBody.pads`); added to the footprint's half extents.
    """
    X = np.asarray(X, dtype=float)
    centre = np.asarray(centre, dtype=float)
    heading = np.asarray(heading, dtype=float)
    index = np.asarray(index, dtype=np.intp)
    n, K, T = len(X), rm.K, rm.tables
    if np.any(index > rm.N) or np.any(index < 0):
        raise ValueError(f"reach_claims: index must lie in 0 .. N = {rm.N}, got {index.min()} .. {index.max()}")
    E = rotate_pairs(X - np.hstack([centre, np.zeros((n, 2))]), -heading)  # segment frame, error
    k = np.arange(1, K + 1)
    m = np.maximum(index[:, None] - k[None, :], 0)                      # (n, K)
    # reach intervals per factor: centre A^k e, radius r_k
    ca = np.einsum("kij,nj->nki", rm.Ak_al[1:], E[:, [0, 2]])
    cy = np.einsum("kij,nj->nki", rm.Ak_ac[1:], E[:, [1, 3]])
    ra, ry = rm.r_al[1:], rm.r_ac[1:]
    Kr = ca.shape[1]  # K - 1 reach slots; the last slot is T^0 whole
    p_lo, p_hi = ca[..., 0] - ra[None, :, 0], ca[..., 0] + ra[None, :, 0]
    v_lo = np.maximum(ca[..., 1] - ra[None, :, 1], T.v_lo[m[:, :Kr]])
    v_hi = np.minimum(ca[..., 1] + ra[None, :, 1], T.v_hi[m[:, :Kr]])
    mm = m[:, :Kr]
    a_lo = np.maximum(np.maximum(p_lo, T.h(mm, v_hi)), T.p_lo[mm])
    a_hi = np.minimum(np.minimum(p_hi, T.g(mm, v_lo)), T.p_hi[mm])
    y_lo = np.maximum(cy[..., 0] - ry[None, :, 0], T.y_lo[mm])
    y_hi = np.minimum(cy[..., 0] + ry[None, :, 0], T.y_hi[mm])
    lo = np.empty((n, K, 2))
    hi = np.empty((n, K, 2))
    lo[:, :Kr, 0], hi[:, :Kr, 0], lo[:, :Kr, 1], hi[:, :Kr, 1] = a_lo, a_hi, y_lo, y_hi
    lo[:, Kr:, 0], hi[:, Kr:, 0] = T.p_lo[0], T.p_hi[0]
    lo[:, Kr:, 1], hi[:, Kr:, 1] = T.y_lo[0], T.y_hi[0]
    off = np.broadcast_to(np.asarray(body_offset, dtype=float), (n,))
    c, s = np.abs(np.cos(off)), np.abs(np.sin(off))
    fx = 0.5 * (rm.length * c + rm.width * s)
    fy = 0.5 * (rm.length * s + rm.width * c)
    if body_pad is not None:
        pad = np.asarray(body_pad, dtype=float).reshape(n, 2)
        if np.any(pad < 0) or not np.all(np.isfinite(pad)):
            raise ValueError("reach_claims: body_pad must be finite and >= 0")
        fx, fy = fx + pad[:, 0], fy + pad[:, 1]
    empty = (lo[..., 0] > hi[..., 0]) | (lo[..., 1] > hi[..., 1])
    lo[..., 0] -= fx[:, None]
    hi[..., 0] += fx[:, None]
    lo[..., 1] -= fy[:, None]
    hi[..., 1] += fy[:, None]
    lo[empty], hi[empty] = np.inf, -np.inf  # keep empty boxes empty after the footprint
    return ReachClaims(centre, heading, lo, hi)


def pad_slots(c: ReachClaims, K: int) -> ReachClaims:
    """``c`` with ``K`` slots: a shorter horizon is padded with its last slot (every later step)."""
    k = c.lo.shape[1]
    if k == K:
        return c
    if k > K:
        raise ValueError(f"pad_slots: claims have {k} slots, more than {K}")
    rep = lambda a: np.concatenate([a, np.repeat(a[:, -1:], K - k, axis=1)], axis=1)  # noqa: E731
    return ReachClaims(c.centre, c.heading, rep(c.lo), rep(c.hi))


def _obb(ci, hi_, c, s, lo, hi):
    """Centre (.., 2), axis cos/sin and half extents of ``ci + R [lo, hi]``."""
    mx, my = 0.5 * (lo[..., 0] + hi[..., 0]), 0.5 * (lo[..., 1] + hi[..., 1])
    cx = ci[..., 0] + c * mx - s * my
    cy = ci[..., 1] + s * mx + c * my
    return cx, cy, 0.5 * (hi[..., 0] - lo[..., 0]), 0.5 * (hi[..., 1] - lo[..., 1])


def _boxes_overlap(ca, ha, la, ua, cb, hb, lb, ub, tol):
    """Separating-axis test of oriented boxes ``ca + R(ha) [la, ua]`` and ``cb + R(hb) [lb, ub]``
    (broadcast over leading axes); boxes closer than ``tol`` overlap, empty boxes never do."""
    ac, as_ = np.cos(ha), np.sin(ha)
    bc, bs = np.cos(hb), np.sin(hb)
    ax, ay, ahx, ahy = _obb(ca, ha, ac, as_, la, ua)
    bx, by, bhx, bhy = _obb(cb, hb, bc, bs, lb, ub)
    dx, dy = bx - ax, by - ay
    cc = np.abs(ac * bc + as_ * bs)
    ss = np.abs(ac * bs - as_ * bc)
    sep = np.abs(dx * ac + dy * as_) - (ahx + bhx * cc + bhy * ss) > tol
    sep |= np.abs(-dx * as_ + dy * ac) - (ahy + bhx * ss + bhy * cc) > tol
    sep |= np.abs(dx * bc + dy * bs) - (bhx + ahx * cc + ahy * ss) > tol
    sep |= np.abs(-dx * bs + dy * bc) - (bhy + ahx * ss + ahy * cc) > tol
    empty = ~((la <= ua).all(axis=-1) & (lb <= ub).all(axis=-1))
    return ~(sep | empty)


def claims_conflict(a: ReachClaims, i, b: ReachClaims, j, check: str = "timed",
                    tol: float = GEOMETRY_TOL) -> np.ndarray:
    """Whether claims ``a[i[t]]`` and ``b[j[t]]`` meet, for each pair ``t``.

    ``timed``: some ``k`` with ``S_k`` overlapping ``S_k``; ``union``: the bounding boxes (in
    each vehicle's segment frame) of all its slots overlap.  Boxes closer than ``tol`` conflict
    (separation must be positive, as elsewhere in the TM)."""
    i = np.atleast_1d(np.asarray(i, dtype=np.intp))
    j = np.atleast_1d(np.asarray(j, dtype=np.intp))
    if check == "timed":
        K = max(a.lo.shape[1], b.lo.shape[1])
        def sl(c, v):  # pad the shorter horizon with its last slot (it stands for every later step)
            lo, hi = c.lo[v], c.hi[v]
            pad = K - lo.shape[1]
            return (np.concatenate([lo, np.repeat(lo[:, -1:], pad, axis=1)], axis=1),
                    np.concatenate([hi, np.repeat(hi[:, -1:], pad, axis=1)], axis=1))
        la, ua = sl(a, i)
        lb, ub = sl(b, j)
        hit = _boxes_overlap(a.centre[i][:, None], a.heading[i][:, None], la, ua,
                             b.centre[j][:, None], b.heading[j][:, None], lb, ub, tol)
        return hit.any(axis=1)
    if check == "union":
        def hull(c, v):
            lo, hi = c.lo[v], c.hi[v]
            ok = (lo <= hi).all(axis=-1, keepdims=True)
            return np.where(ok, lo, np.inf).min(axis=1), np.where(ok, hi, -np.inf).max(axis=1)
        la, ua = hull(a, i)
        lb, ub = hull(b, j)
        return _boxes_overlap(a.centre[i], a.heading[i], la, ua, b.centre[j], b.heading[j], lb, ub, tol)
    raise ValueError(f"check must be 'timed' or 'union', got {check!r}")


def world_aabb(claims: ReachClaims) -> tuple[np.ndarray, np.ndarray]:
    """World bounding boxes (n, 2) of every vehicle's ``∪_k S_k`` (empty claims: inverted boxes)."""
    ok = (claims.lo <= claims.hi).all(axis=-1, keepdims=True)
    lo = np.where(ok, claims.lo, np.inf).min(axis=1)
    hi = np.where(ok, claims.hi, -np.inf).max(axis=1)
    c, s = np.abs(np.cos(claims.heading)), np.abs(np.sin(claims.heading))
    mid = claims.centre + rotate_pairs(0.5 * (lo + hi), claims.heading)
    half = 0.5 * (hi - lo)
    ext = np.column_stack([c * half[:, 0] + s * half[:, 1], s * half[:, 0] + c * half[:, 1]])
    return mid - ext, mid + ext


def candidate_pairs(lo_a, hi_a, lo_b, hi_b, tol: float = GEOMETRY_TOL) -> tuple[np.ndarray, np.ndarray]:
    """Pairs ``(i, j)`` whose world boxes come within ``tol`` (dense broad phase)."""
    m = ((lo_a[:, None, 0] <= hi_b[None, :, 0] + tol) & (lo_b[None, :, 0] <= hi_a[:, None, 0] + tol) &
         (lo_a[:, None, 1] <= hi_b[None, :, 1] + tol) & (lo_b[None, :, 1] <= hi_a[:, None, 1] + tol))
    return np.nonzero(m)


def pairwise_conflicts(claims: ReachClaims, check: str = "timed") -> tuple[np.ndarray, np.ndarray]:
    """All pairs ``i < j`` of ``claims`` that conflict (dense broad phase on the union boxes, then
    :func:`claims_conflict`; for lanes and tests)."""
    lo, hi = world_aabb(claims)
    i, j = candidate_pairs(lo, hi, lo, hi)
    keep = i < j
    i, j = i[keep], j[keep]
    if not len(i):
        return i, j
    hit = claims_conflict(claims, i, claims, j, check)
    return i[hit], j[hit]
