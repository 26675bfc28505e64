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
* across: the reach's interval cut to the across range of ``T_y^{max(l_y + 1 - k, 0)}``, where
  ``l_y <= l`` is the across factor's own index: a movement-authority controller keeps the across
  factor in its own tube (:meth:`controllers.stmpc.STMPC.tube_levels`), ``x_y(t+k) ∈
  T_y^{max(l_y - k, 0)}``; one level more absorbs a tie at a level's boundary between the
  controller's and the claim's arithmetic.  (With ``T^{l-k}``'s range, the across extent of a
  cruising car's claims grew to +-0.95 m, a bus's to +-1.58 m: opposite inner lanes, 3.2 m
  apart, could not pass each other; issue 12, ``grid`` seed 1, bus 85 / car 71.)  A model
  without ``across`` (:class:`ReachModel`) uses ``T^{l-k}``'s range, as before;
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
from functools import cached_property

import numpy as np

from controllers.authority import AuthorityTables
from controllers.stmpc import FactorMembership
from controllers.synthesis import SetFamily, rotate_pairs
from controllers.tolerances import GEOMETRY_TOL, REACH_LOOKUP_MARGIN
from tm.boxes import ranges
from tm.geometry import broad_phase, rectangles
from tm.kernels import reach_boxes, timed_pairs_plain, timed_pairs_tight, union_bounds
from tm.slot_boxes import SlotBoxes

__all__ = ["ReachModel", "ReachClaims", "reach_claims", "reach_claims_many", "claims_conflict", "pairwise_conflicts",
           "world_aabb", "claim_polygons", "claim_polygons_of", "candidate_pairs", "pad_slots", "split_pad", "slot_aabb", "union_aabb",
           "PREFILTER_TOL_FACTOR"]

#: The per-slot world bounding boxes that pre-filter the ``timed`` check are compared with
#: ``PREFILTER_TOL_FACTOR * tol``: two oriented boxes that the separating-axis test with ``tol``
#: calls overlapping have world boxes within ``sqrt(2) tol`` (grow one box by ``tol`` along its own
#: axes: the grown box meets the other, and its world box is at most ``(|cos| + |sin|) tol`` larger),
#: so the pre-filter never drops a pair the test would report.
PREFILTER_TOL_FACTOR = 2.0


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
    across : FactorMembership, optional
        The across factor's own membership index (its levels ``T_y^m``): the claims' across extent
        follows it (module notes).  None: the joint index's levels, as for any controller.
    """

    Ak_al: np.ndarray
    Ak_ac: np.ndarray
    r_al: np.ndarray
    r_ac: np.ndarray
    tables: AuthorityTables
    length: float
    width: float
    across: FactorMembership | None = None

    @property
    def N(self) -> int:
        return self.tables.N

    @property
    def K(self) -> int:
        """Claim slots: ``k = 1 .. K`` (the last one stands for every later step)."""
        return self.N + 2

    @classmethod
    def build(cls, family: SetFamily, tables: AuthorityTables, length: float, width: float) -> "ReachModel":
        """Powers and radii of both factors of ``family`` (road frame, 2-D factors), and the across
        factor's own index: for vehicles driven by :class:`controllers.stmpc.STMPC` in
        ``authority`` mode, which keeps that factor in its own tube."""
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
        across = FactorMembership.of(next(f for f in family.factors if 1 in f.states))
        return cls(tables=tables, length=float(length), width=float(width), across=across, **out)


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
    tight : SlotBoxes, optional
        The slots as unions of oriented boxes (path-frame vehicles, :mod:`tm.path_claims`: one box
        per path segment, where the waypoint's frame bounds a curve coarsely), inside ``lo, hi``.
        When given, the ``timed`` check and :attr:`slot_boxes` use them; the ``union`` check,
        :func:`world_aabb` and the drawings use ``lo, hi``.
    """

    centre: np.ndarray
    heading: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    tight: SlotBoxes | None = None

    def __len__(self) -> int:
        return len(self.centre)

    @cached_property
    def slot_boxes(self) -> np.ndarray:
        """World bounding boxes of every slot, ``(4, n, K)``: ``x_lo, x_hi, y_lo, y_hi`` (empty
        slots inverted: ``+inf, -inf``); computed on first use, carried by :meth:`shift`,
        :meth:`take` and :meth:`concat` when present."""
        if self.tight is not None:
            out, U = self.tight.aabb_union()
            self.__dict__.setdefault("union_bounds", U)  # the same pass: kept for union_aabb
            return out
        return slot_aabb(self.centre, self.heading, self.lo, self.hi)

    @cached_property
    def union_bounds(self) -> np.ndarray:
        """Per vehicle, the bounds over its slots' world bounding boxes (:attr:`slot_boxes`), ``(n, 4)``:
        ``x_lo, x_hi, y_lo, y_hi`` (inverted when every slot is empty); computed with the slot boxes
        where they are (:func:`reach_claims_many`, :meth:`SlotBoxes.aabb_union`), else on first use."""
        b = self.slot_boxes
        if "union_bounds" in self.__dict__:  # set by slot_boxes just now
            return self.__dict__["union_bounds"]
        if not b.shape[2]:
            return np.tile([np.inf, -np.inf, np.inf, -np.inf], (b.shape[1], 1))
        return union_bounds(np.ascontiguousarray(b))

    def slot_union(self) -> SlotBoxes:
        """The slots as unions of boxes: :attr:`tight`, or the claims' own boxes (one per slot)."""
        if self.tight is not None:
            return self.tight
        return SlotBoxes.from_frames(self.centre, self.heading, self.lo, self.hi)

    def _with_boxes(self, boxes, union=None) -> "ReachClaims":
        if boxes is not None:
            self.__dict__["slot_boxes"] = boxes  # the cached_property's slot (frozen dataclass)
        if union is not None:
            self.__dict__["union_bounds"] = union
        return self

    def _boxes(self) -> np.ndarray | None:
        return self.__dict__.get("slot_boxes")

    def shift(self) -> "ReachClaims":
        """``S_{k+1}(t)`` as the claims for ``t + 1`` (reuse for vehicles not granted):
        drop slot 1, repeat the last (``T^0``, every later step)."""
        sh = lambda a: np.concatenate([a[:, 1:], a[:, -1:]], axis=1)  # noqa: E731
        b = self._boxes()
        return ReachClaims(self.centre, self.heading, sh(self.lo), sh(self.hi),
                           None if self.tight is None else self.tight.shift())._with_boxes(
            None if b is None else np.concatenate([b[:, :, 1:], b[:, :, -1:]], axis=2))

    def take(self, idx) -> "ReachClaims":
        b, u = self._boxes(), self.__dict__.get("union_bounds")
        return ReachClaims(self.centre[idx], self.heading[idx], self.lo[idx], self.hi[idx],
                           None if self.tight is None else self.tight.take(idx))._with_boxes(
            None if b is None else np.take(b, idx, axis=1), None if u is None else u[idx])

    @staticmethod
    def concat(*parts: "ReachClaims") -> "ReachClaims":
        K = max(p.lo.shape[1] for p in parts)
        def pad(a, axis=1):  # pad with the last slot (it stands for every later step)
            extra = K - a.shape[axis]
            if not extra:
                return a
            last = a[:, -1:] if axis == 1 else a[:, :, -1:]
            return np.concatenate([a, np.repeat(last, extra, axis=axis)], axis=axis)
        boxes = [p._boxes() for p in parts]
        tight = None
        if any(p.tight is not None for p in parts):
            tight = SlotBoxes.concat(*(p.slot_union().pad(K) for p in parts))
        out = ReachClaims(np.concatenate([p.centre for p in parts]), np.concatenate([p.heading for p in parts]),
                          np.concatenate([pad(p.lo) for p in parts]), np.concatenate([pad(p.hi) for p in parts]),
                          tight)
        if all(b is not None for b in boxes):
            out._with_boxes(np.concatenate([pad(b, axis=2) for b in boxes], axis=1))
        return out

    def polygons(self) -> np.ndarray:
        """Corners (n, 4, 2), counter-clockwise, of each vehicle's claim as drawn (MCAP ``--log
        full``): the box in its segment frame holding every non-empty slot, ``∪_k S_k``'s bounding
        box (what the ``union`` check compares), in the world.  A vehicle without a non-empty slot
        is its centre, four times."""
        lo, hi = _hull(self.lo, self.hi)
        none = ~np.all(lo <= hi, axis=1)
        lo, hi = np.where(none[:, None], 0.0, lo), np.where(none[:, None], 0.0, hi)
        C = np.stack([lo, np.column_stack([hi[:, 0], lo[:, 1]]), hi, np.column_stack([lo[:, 0], hi[:, 1]])], axis=1)
        n = len(self.centre)
        world = rotate_pairs(C.reshape(4 * n, 2), np.repeat(self.heading, 4)).reshape(n, 4, 2)
        return self.centre[:, None, :] + world

    def world_corners(self, i: int, k: int) -> np.ndarray:
        """Corners (4, 2) of box ``S_k`` of vehicle ``i`` in the world (``k >= 1``)."""
        lo, hi = self.lo[i, k - 1], self.hi[i, k - 1]
        C = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
        return self.centre[i] + rotate_pairs(C, self.heading[i])


def reach_claims(rm: ReachModel, X: np.ndarray, centre: np.ndarray, heading: np.ndarray,
                 index: np.ndarray, body_offset=0.0, body_pad=None, boxes: bool = True) -> ReachClaims:
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
    body_pad : ndarray (n, 2) or (n, 4), optional
        How far (m) the simulator's body may reach beyond the footprint rectangle centred on the
        position (e.g. SUMO's lane-following body around turns, :meth:`bridge.sumo_body.PadTable.pads`):
        ``(along, across)`` on both sides, or one-sided ``(back, front, right, left)``
        (:func:`split_pad`); added to the footprint's half extents on those sides.
    boxes : bool
        Attach the slots' world bounding boxes (:attr:`ReachClaims.slot_boxes`) now, computed with
        the boxes (:func:`tm.kernels.reach_boxes`); False where they are not wanted (path-frame
        claims are drawn from these boxes of path coordinates, :mod:`tm.path_claims`), else
        computed on first use.
    """
    return reach_claims_many([(rm, X, centre, heading, index, body_offset, body_pad)], boxes)


def reach_claims_many(groups, boxes: bool = True) -> ReachClaims:
    """:func:`reach_claims` of several groups ``(rm, X, centre, heading, index, body_offset,
    body_pad)``, concatenated in order (as :meth:`ReachClaims.concat`: the longer horizon over the
    groups, shorter ones padded with their last slot), written in place: one set of arrays."""
    ins = [_reach_inputs(*g) for g in groups]
    n = sum(len(centre) for _, centre, _ in ins)
    K_out = max((g[0].K for g in groups), default=1)
    lo, hi = np.empty((n, K_out, 2)), np.empty((n, K_out, 2))
    W = np.empty((4, n if boxes else 0, K_out))
    U = np.empty((n if boxes else 0, 4))
    row0 = 0
    for args, centre, _ in ins:
        reach_boxes(*args, lo, hi, W, U, row0, boxes)
        row0 += len(centre)
    if len(ins) == 1:
        centre, heading = ins[0][1], ins[0][2]
    else:
        centre, heading = np.concatenate([i[1] for i in ins]), np.concatenate([i[2] for i in ins])
    out = ReachClaims(centre, heading, lo, hi)
    return out._with_boxes(W, U) if boxes else out


def _reach_inputs(rm: ReachModel, X, centre, heading, index, body_offset=0.0, body_pad=None) -> tuple:
    """``(args, centre, heading)``: the arguments of :func:`tm.kernels.reach_boxes` for one group
    (validated), up to ``sin_h``, and the group's waypoints and headings as arrays."""
    X = np.asarray(X, dtype=float)
    centre = np.ascontiguousarray(centre, dtype=float)
    heading = np.ascontiguousarray(heading, dtype=float)
    index = np.ascontiguousarray(index, dtype=np.intp)
    n, K, T = len(X), rm.K, rm.tables
    if np.any(index > rm.N) or np.any(index < 0):
        raise ValueError(f"reach_claims: index must lie in 0 .. N = {rm.N}, got {index.min()} .. {index.max()}")
    E = rotate_pairs(X - np.hstack([centre, np.zeros((n, 2))]), -heading)  # segment frame, error
    off = np.broadcast_to(np.asarray(body_offset, dtype=float), (n,))
    c, s = np.abs(np.cos(off)), np.abs(np.sin(off))
    fx = 0.5 * (rm.length * c + rm.width * s)
    fy = 0.5 * (rm.length * s + rm.width * c)
    fx_lo, fx_hi, fy_lo, fy_hi = fx, fx, fy, fy
    if body_pad is not None:
        plo, phi = split_pad(body_pad, n)
        fx_lo, fy_lo, fx_hi, fy_hi = fx + plo[:, 0], fy + plo[:, 1], fx + phi[:, 0], fy + phi[:, 1]
    # the across factor's own tube, one level of slack (module notes); without it, T^{l-k}'s range
    ly = index if rm.across is None else np.minimum(rm.across.index(E) + 1, index)
    # per slot k = 1 .. K-1: the reach's intervals (centre A^k e, radius r_k per factor) cut to
    # T^{max(l-k, 0)}'s, the tables read just outside the velocity bounds (REACH_LOOKUP_MARGIN:
    # ties at grid points); the last slot T^0 whole; then the footprint (tm.kernels.reach_boxes)
    feet = tuple(np.ascontiguousarray(f, dtype=float) for f in (fx_lo, fx_hi, fy_lo, fy_hi))
    return (E, index, np.ascontiguousarray(ly, dtype=np.intp), rm.Ak_al[1:], rm.Ak_ac[1:], rm.r_al[1:], rm.r_ac[1:],
            T.v_lo, T.v_hi, T.p_lo, T.p_hi, T.y_lo, T.y_hi, T.G, T.H, float(T.w0), float(T.dw), REACH_LOOKUP_MARGIN,
            *feet, K, centre, np.cos(heading), np.sin(heading)), centre, heading


def split_pad(pad, n: int) -> tuple[np.ndarray, np.ndarray]:
    """A footprint padding as ``(lo, hi)`` (n, 2) each: how far beyond the rectangle's low sides
    (back, right) and high sides (front, left) of the segment frame.  ``pad`` is (n, 2) ``(along,
    across)``, both sides alike, or (n, 4) one-sided ``(back, front, right, left)``."""
    p = np.asarray(pad, dtype=float)
    if p.size not in (2 * n, 4 * n) or p.ndim > 2 or (p.ndim == 2 and p.shape[0] != n):
        raise ValueError(f"body_pad: need (n, 2) or (n, 4) for n = {n} vehicles, got shape {p.shape}")
    p = p.reshape(n, -1) if n else p.reshape(0, 2)
    if np.any(p < 0) or not np.all(np.isfinite(p)):
        raise ValueError("body_pad must be finite and >= 0")
    if p.shape[1] == 2:
        return p, p
    return p[:, [0, 2]], p[:, [1, 3]]


def pad_slots(c: ReachClaims, K: int) -> ReachClaims:
    """``c`` with ``K`` slots: a shorter horizon is padded with its last slot (every later step)."""
    k = c.lo.shape[1]
    if k == K:
        return c
    if k > K:
        raise ValueError(f"pad_slots: claims have {k} slots, more than {K}")
    rep = lambda a: np.concatenate([a, np.repeat(a[:, -1:], K - k, axis=1)], axis=1)  # noqa: E731
    b = c._boxes()
    return ReachClaims(c.centre, c.heading, rep(c.lo), rep(c.hi),
                       None if c.tight is None else c.tight.pad(K))._with_boxes(
        None if b is None else np.concatenate([b, np.repeat(b[:, :, -1:], K - k, axis=2)], axis=2))


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


def _timed_conflicts(a: ReachClaims, i, b: ReachClaims, j, tol: float) -> np.ndarray:
    """``timed`` check: per pair, the slots in order, the world bounding boxes
    (:attr:`ReachClaims.slot_boxes`, padded by :data:`PREFILTER_TOL_FACTOR` ``tol``) first and the
    separating-axis test on the slots whose boxes meet, up to the first that meets
    (:mod:`tm.kernels`); slots past a shorter horizon are its last slot."""
    if not len(i):
        return np.zeros(0, dtype=bool)
    i, j = np.ascontiguousarray(i, dtype=np.intp), np.ascontiguousarray(j, dtype=np.intp)
    pad = PREFILTER_TOL_FACTOR * tol
    A, B = a.slot_boxes, b.slot_boxes
    La, Lb = a.lo.shape[1], b.lo.shape[1]
    if a.tight is None and b.tight is None:
        return timed_pairs_plain(A, B, a.centre, np.cos(a.heading), np.sin(a.heading), a.lo, a.hi, b.centre,
                                 np.cos(b.heading), np.sin(b.heading), b.lo, b.hi, i, j, tol, pad)
    sa, sb = a.slot_union(), b.slot_union()
    return timed_pairs_tight(A, B, La, sa.centre, np.cos(sa.heading), np.sin(sa.heading), sa.half, sa.start,
                             sa.count, Lb, sb.centre, np.cos(sb.heading), np.sin(sb.heading), sb.half, sb.start,
                             sb.count, i, j, tol, pad)


def claims_conflict(a: ReachClaims, i, b: ReachClaims, j, check: str = "timed",
                    tol: float = GEOMETRY_TOL) -> np.ndarray:
    """Whether claims ``a[i[t]]`` and ``b[j[t]]`` meet, for each pair ``t``.

    ``timed``: some ``k`` with ``S_k`` overlapping ``S_k``; ``union``: the bounding boxes (in
    each vehicle's segment frame) of all its slots overlap.  Boxes closer than ``tol`` conflict
    (separation must be positive, as elsewhere in the TM)."""
    i = np.atleast_1d(np.asarray(i, dtype=np.intp))
    j = np.atleast_1d(np.asarray(j, dtype=np.intp))
    if check == "timed":
        return _timed_conflicts(a, i, b, j, tol)
    if check == "union":
        la, ua = _hull(a.lo[i], a.hi[i])
        lb, ub = _hull(b.lo[j], b.hi[j])
        return _boxes_overlap(a.centre[i], a.heading[i], la, ua, b.centre[j], b.heading[j], lb, ub, tol)
    raise ValueError(f"check must be 'timed' or 'union', got {check!r}")


def _hull(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Segment-frame bounding boxes (n, 2) of the non-empty slots of ``lo, hi`` (n, K, 2) (no slot:
    inverted); per coordinate, as a reduction over the slot axis of (n, K, 2) is slow."""
    ok = (lo[..., 0] <= hi[..., 0]) & (lo[..., 1] <= hi[..., 1])
    out_lo = np.stack([np.where(ok, lo[..., d], np.inf).min(axis=1) for d in (0, 1)], axis=1)
    out_hi = np.stack([np.where(ok, hi[..., d], -np.inf).max(axis=1) for d in (0, 1)], axis=1)
    return out_lo, out_hi


def slot_aabb(centre, heading, lo, hi) -> np.ndarray:
    """World bounding boxes ``(4, n, K)`` (``x_lo, x_hi, y_lo, y_hi``) of boxes ``centre + R(heading)
    [lo, hi]`` (lo, hi (n, K, 2)); empty boxes inverted (``+inf, -inf``)."""
    return _slot_aabb_planar(centre, heading, lo[..., 0], hi[..., 0], lo[..., 1], hi[..., 1])


def _slot_aabb_planar(centre, heading, l0, h0, l1, h1) -> np.ndarray:
    """:func:`slot_aabb` from the corners' coordinates, each (n, K)."""
    n, K = l0.shape
    c, s = np.cos(heading)[:, None], np.sin(heading)[:, None]
    ac, as_ = np.abs(c), np.abs(s)
    out = np.empty((4, n, K))
    with np.errstate(invalid="ignore"):  # empty boxes (inf, -inf): fixed below
        mx = l0 + h0
        mx *= 0.5
        my = l1 + h1
        my *= 0.5
        hx = h0 - l0
        hx *= 0.5
        hy = h1 - l1
        hy *= 0.5
        wx = c * mx
        wx -= s * my
        wx += centre[:, :1]
        wy = s * mx
        wy += c * my
        wy += centre[:, 1:]
        ex = ac * hx
        ex += as_ * hy
        ey = as_ * hx
        ey += ac * hy
        np.subtract(wx, ex, out=out[0])
        np.add(wx, ex, out=out[1])
        np.subtract(wy, ey, out=out[2])
        np.add(wy, ey, out=out[3])
        empty = ~((hx >= 0) & (hy >= 0))
    if empty.any():
        out[0][empty] = out[2][empty] = np.inf
        out[1][empty] = out[3][empty] = -np.inf
    return out


def union_aabb(claims: ReachClaims) -> tuple[np.ndarray, np.ndarray]:
    """World bounding boxes (n, 2) of the union of every vehicle's slot boxes (inverted when all are
    empty): inside :func:`world_aabb`, enough for the ``timed`` check (a conflict is a slot overlap)."""
    U = claims.union_bounds
    return U[:, [0, 2]], U[:, [1, 3]]


def world_aabb(claims: ReachClaims) -> tuple[np.ndarray, np.ndarray]:
    """World bounding boxes (n, 2) of every vehicle's ``∪_k S_k`` (empty claims: inverted boxes)."""
    lo, hi = _hull(claims.lo, claims.hi)
    c, s = np.abs(np.cos(claims.heading)), np.abs(np.sin(claims.heading))
    mid = claims.centre + rotate_pairs(0.5 * (lo + hi), claims.heading)
    half = 0.5 * (hi - lo)
    ext = np.column_stack([c * half[:, 0] + s * half[:, 1], s * half[:, 0] + c * half[:, 1]])
    return mid - ext, mid + ext


def claim_polygons(claims: ReachClaims, row: int) -> np.ndarray:
    """Oriented boxes (m, 4, 2), counter-clockwise from the front right corner
    (:func:`tm.geometry.rectangles`), whose union is vehicle ``row``'s ``∪_k S_k``: the boxes of its
    slots (:meth:`ReachClaims.slot_union`), each once (:func:`claim_polygons_of` of one row)."""
    return claim_polygons_of(claims, np.array([row], dtype=np.intp))[0]


def claim_polygons_of(claims: ReachClaims, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`claim_polygons` of several rows at once: the boxes (M, 4, 2) and the position in
    ``rows`` of the row each is of (M,), non-decreasing."""
    rows = np.asarray(rows, dtype=np.intp).reshape(-1)
    u = claims.slot_union()
    st, ct = u.start[rows], u.count[rows]                   # (m, K)
    owner = np.repeat(np.arange(len(rows)), ct.sum(axis=1))
    box = ranges(st.ravel(), ct.ravel())
    # each box once per row (a slot's box may stand for several steps)
    q = max(len(u.centre), 1)
    key = np.unique(owner.astype(np.int64) * q + box)
    owner, box = (key // q).astype(np.intp), (key % q).astype(np.intp)
    polys = u.centre[box][:, None, :] + rectangles(u.heading[box], 2.0 * u.half[box, 0], 2.0 * u.half[box, 1])
    return polys, owner


def candidate_pairs(lo_a, hi_a, lo_b, hi_b, tol: float = GEOMETRY_TOL) -> tuple[np.ndarray, np.ndarray]:
    """Pairs ``(i, j)`` whose world boxes come within ``tol`` (dense broad phase)."""
    m = ((lo_a[:, None, 0] <= hi_b[None, :, 0] + tol) & (lo_b[None, :, 0] <= hi_a[:, None, 0] + tol) &
         (lo_a[:, None, 1] <= hi_b[None, :, 1] + tol) & (lo_b[None, :, 1] <= hi_a[:, None, 1] + tol))
    return np.nonzero(m)


def pairwise_conflicts(claims: ReachClaims, check: str = "timed") -> tuple[np.ndarray, np.ndarray]:
    """All pairs ``i < j`` of ``claims`` that conflict (grid broad phase on the union boxes, then
    :func:`claims_conflict`; the monitor, ``verify``, lanes and tests)."""
    lo, hi = world_aabb(claims)
    empty = ~(lo <= hi).all(axis=1)
    lo, hi = np.where(empty[:, None], 0.0, lo), np.where(empty[:, None], 0.0, hi)  # never hit (narrow phase)
    i, j = broad_phase(lo, hi, PREFILTER_TOL_FACTOR * GEOMETRY_TOL)
    if not len(i):
        return i, j
    hit = claims_conflict(claims, i, claims, j, check)
    return i[hit], j[hit]
