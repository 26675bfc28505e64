"""Reuse of reach claims from one step to the next (design.md §7 "Cost").

Not granted, claims only shrink: a vehicle that keeps its waypoint ``c`` has
``S_k(t+1) ⊆ S_{k+1}(t)`` (:mod:`tm.reach`), so the claims in force after the decision of step
``t``, shifted by one slot (:meth:`~tm.reach.ReachClaims.shift`), are a sound outer bound of its
fresh claims at ``t + 1``: a decision on them is conservative (it never grants what the fresh
claims would refuse).  :class:`ClaimCache` keeps every vehicle's claims in force and hands out the
shifted ones where the premises of that inclusion are checked to hold; fresh claims otherwise.

A cached row is reused at step ``t + 1`` iff every one of these holds (else: fresh claims):

* it was stored at step ``t`` (the step just before) for a vehicle of the same id and class;
* the vehicle was not granted at ``t`` (a grant gives new claims; computed fresh), unless its
  requested claims were committed with the grant (:meth:`ClaimCache.commit`): then they are its
  claims in force, and its new waypoint, index and pad are the ones checked below;
* its waypoint and segment heading are the stored ones (bit-for-bit);
* its index dropped: ``min(l(t+1), N) <= max(min(l(t), N) - 1, 0)`` (the tube invariant);
* its footprint padding (``body_pad`` of :func:`~tm.reach.reach_claims`, e.g. SUMO's bodies,
  :class:`bridge.sumo_body.PadTable`) did not grow: the pad the stored claims were built with is
  ``>=`` the pad needed now, elementwise (any shape per vehicle): a claim only grows with its pad,
  so the shifted claims, built with the larger pad, contain the fresh ones with the smaller;
* its state moved within one step of physics: ``x(t+1)`` (segment frame, both factors) lies in the
  interval hull ``A x(t) ± r_1`` of ``Reach_1(x(t))`` (within ``tol``).  Together with the index this
  is what the inclusion rests on; it also implies ``x(t+1) ∈ S_1(t)`` (no tube escape).

Vehicles that leave drop out of the cache (rows are matched by id); new ones get fresh claims.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from controllers.synthesis import rotate_pairs
from controllers.tolerances import GEOMETRY_TOL
from tm.path_claims import PathPlace
from tm.reach import ReachClaims, pad_slots
from tm.slot_boxes import SlotBoxes
from tm.reach_book import ReachBook

__all__ = ["ClaimCache", "CacheStats", "REASONS"]

#: Why a vehicle's cached claims were not reused (keys of :attr:`CacheStats.fresh_by_reason`).
REASONS = ("new", "stale", "granted", "waypoint", "index", "pad", "reach")


@dataclass
class CacheStats:
    """Counts over the cache's life: rows reused (shifted), rows taken from claims offered for the same
    state (:meth:`ClaimCache.offer`), rows computed fresh (by the first failing reason)."""

    reused: int = 0
    fresh: int = 0
    offered: int = 0

    def __post_init__(self) -> None:
        self.fresh_by_reason = dict.fromkeys(REASONS, 0)


@dataclass(frozen=True, eq=False)
class _Entry:
    """What the cache holds about the fleet of one step (rows in the fleet's order)."""

    t: int
    ids: tuple
    row: dict | None     # id -> row (built when a later step's ids differ)
    cls: np.ndarray      # (n,) class names
    X: np.ndarray        # (n, 4)
    centre: np.ndarray   # (n, 2)
    heading: np.ndarray  # (n,)
    index: np.ndarray    # (n,) capped at the class's N
    pad: np.ndarray | None  # (n, ...) the footprint padding the claims were built with (None: none)
    claims: ReachClaims | None = None   # the claims handed out (in force for those not granted)
    granted: np.ndarray | None = None   # granted rows whose claims in force are not held (fresh next step)
    new: ReachClaims | None = None      # the granted rows' claims in force (their requested ones), K slots
    new_pos: np.ndarray | None = None   # (n,) row of ``new`` of each row (-1: its claims are ``claims``)


class ClaimCache:
    """Claims in force per vehicle, reused one step later as ``S_{k+1}(t)`` (see the module docstring).

    Parameters
    ----------
    book : ReachBook
        The claim models of the run's classes.
    tol : float
        Slack (m, m/s) of the reach test: the plant's ``A x + B u + d`` and the closed-form ``A x ± r_1``
        round differently by ~1e-13.

    Use: :meth:`current` for every vehicle's claims at step ``t``, then :meth:`commit` with the
    decision's result.  A step without :meth:`commit` leaves nothing to reuse at ``t + 1``.
    """

    def __init__(self, book: ReachBook, tol: float = GEOMETRY_TOL):
        self.book = book
        self.tol = float(tol)
        self.K = book.K
        self.stats = CacheStats()
        #: (n,) which rows of the last :meth:`current` took shifted claims
        self.last_reused = np.zeros(0, dtype=bool)
        self._last: _Entry | None = None     # committed at its step
        self._pending: _Entry | None = None  # handed out by current(), not yet committed
        self._offer: _Entry | None = None    # fresh claims of a step's state, offered before current()
        self._reach1 = {c: (m.Ak_al[1], m.r_al[1], m.Ak_ac[1], m.r_ac[1]) for c, m in book.models.items()}
        for c, m in book.models.items():
            for name, Ak, r in (("along", m.Ak_al, m.r_al), ("across", m.Ak_ac, m.r_ac)):
                # x(t+1) ∈ A x(t) ± r_1 gives A^k x(t+1) ± r_k ⊆ A^{k+1} x(t) ± r_{k+1} iff |A^k| r_1 <= r_{k+1} - r_k
                grow = np.einsum("kij,j->ki", np.abs(Ak[:-1]), r[1])
                if np.any(grow > r[1:] - r[:-1] + 1e-12):
                    raise ValueError(f"ClaimCache: class {c!r}, {name} factor: the reach radii do not nest "
                                     "(|A^k| r_1 > r_(k+1) - r_k): shifted claims would not bound fresh ones")

    def reset(self) -> None:
        """Forget every cached claim."""
        self._last = self._pending = self._offer = None

    def offer(self, t: int, parts, claims: ReachClaims) -> None:
        """Fresh claims of the fleet's state at step ``t`` computed elsewhere (e.g. by the monitor at
        the end of step ``t - 1``), rows as ``parts`` (see :meth:`current`): :meth:`current` at step
        ``t`` hands them out as they are when its parts are the same (ids, classes, states, waypoints,
        indices, bit for bit), instead of shifted or recomputed claims."""
        parts = [p for p in parts if len(p[1])]
        ids = tuple(v for p in parts for v in p[1])
        if len(claims) != len(ids):
            raise ValueError(f"ClaimCache.offer: {len(claims)} claims for {len(ids)} vehicles")
        self._offer = _Entry(t, ids, None, *self._stack(parts), pad_slots(claims, self.K))

    def _stack(self, parts):
        cls = np.concatenate([np.full(len(p[1]), p[0], dtype=object) for p in parts])
        with_pad = [len(p) > 6 and p[6] is not None for p in parts]
        if any(with_pad) and not all(with_pad):
            raise ValueError("ClaimCache: either every part has a pad (7th item) or none has")
        pad = np.concatenate([np.asarray(p[6], dtype=float).reshape(len(p[1]), -1) for p in parts]) \
            if all(with_pad) else None
        X = np.vstack([np.asarray(p[2], dtype=float) for p in parts])
        centre = np.vstack([np.asarray(p[3], dtype=float) for p in parts])
        heading = np.concatenate([np.asarray(p[4], dtype=float) for p in parts])
        index = np.concatenate([np.minimum(np.asarray(p[5], dtype=np.intp), self.book.models[p[0]].N)
                                for p in parts])
        return cls, X, centre, heading, index, pad

    @staticmethod
    def _places(parts) -> PathPlace | None:
        """The parts' path places (8th item, :class:`tm.path_claims.PathPlace`), concatenated, or
        None; path-frame vehicles' claims are built in their frames and drawn in the places'."""
        with_place = [len(p) > 7 and p[7] is not None for p in parts]
        if not any(with_place):
            return None
        if not all(with_place):
            raise ValueError("ClaimCache: either every part has a path place (8th item) or none has")
        return PathPlace.concat(*(p[7] for p in parts))

    def _offered(self, t, ids, cls, X, centre, heading, index, pad) -> ReachClaims | None:
        o, self._offer = self._offer, None
        if o is None or o.t != t or o.ids != ids:
            return None
        same = (np.array_equal(o.cls, cls) and np.array_equal(o.X, X) and np.array_equal(o.centre, centre)
                and np.array_equal(o.heading, heading) and np.array_equal(o.index, index)
                and ((o.pad is None and pad is None) or (o.pad is not None and pad is not None
                                                         and np.array_equal(o.pad, pad))))
        return o.claims if same else None

    def current(self, t: int, parts: Sequence[tuple[str, Sequence[str], np.ndarray, np.ndarray, np.ndarray,
                                                     np.ndarray]]) -> ReachClaims:
        """Every vehicle's claims at step ``t`` for its current waypoint, in the order of ``parts``.

        Parameters
        ----------
        t : int
            The step (consecutive integers; reuse needs the previous step committed).
        parts : sequence of (class, ids, X (n, 4), centre (n, 2), heading (n,), index (n,)[, pad (n, ...)[, place]])
            As :meth:`tm.reach_book.ReachBook.claims`, with the vehicles' ids; ``pad``: the
            footprint padding (``body_pad`` of :func:`~tm.reach.reach_claims`, passed on as it is),
            in every part or in none; ``place``: path-frame vehicles' :class:`~tm.path_claims.PathPlace`
            (``X``, ``centre``, ``heading`` are then path coordinates: the reach test and the waypoint
            check work on them; the claims are drawn in the places' world frames).

        Returns
        -------
        ReachClaims
            ``K = book.K`` slots, slot boxes (:attr:`~tm.reach.ReachClaims.slot_boxes`) attached.
        """
        parts = [p for p in parts if len(p[1])]
        for c, pid, *arrays in parts:
            arrays = [a for a in arrays if a is not None]
            if c not in self.book.models:
                raise ValueError(f"ClaimCache.current: class {c!r} has no claim model; known: {sorted(self.book.models)}")
            lens = [len(a) for a in arrays]
            if any(k != len(pid) for k in lens):
                raise ValueError(f"ClaimCache.current: class {c!r}: {len(pid)} ids but X, centre, heading, index "
                                 f"have {lens} rows")
        ids = tuple(v for p in parts for v in p[1])
        if not parts:
            K = self.K
            self._pending = None
            self.last_reused = np.zeros(0, dtype=bool)
            return ReachClaims(np.zeros((0, 2)), np.zeros(0), np.zeros((0, K, 2)), np.zeros((0, K, 2)))
        cls, X, centre, heading, index, pad = self._stack(parts)
        place = self._places(parts)
        n = len(ids)
        given = self._offered(t, ids, cls, X, centre, heading, index, pad)
        if given is not None:
            given.slot_boxes  # noqa: B018  (attached now: the decision and the next shift use them)
            self.last_reused = np.zeros(n, dtype=bool)
            self.stats.offered += n
            self._pending = _Entry(t, ids, None, cls, X, centre, heading, index, pad, given)
            return given
        reuse, j = self._reusable(t, ids, cls, X, centre, heading, index, pad)
        r = np.flatnonzero(reuse)
        lo, hi, boxes = np.empty((n, self.K, 2)), np.empty((n, self.K, 2)), np.empty((4, n, self.K))
        # path-frame claims carry their slots as unions of boxes (ReachClaims.tight): kept alike
        pieces = []  # (rows, SlotBoxes of those rows)
        if len(r) and place is not None:
            old_t = self._last.claims.slot_union().shift()
            keep = r
            if self._last.new is not None:
                q = self._last.new_pos[j[r]]
                if (q >= 0).any():
                    pieces.append((r[q >= 0], self._last.new.slot_union().shift().pad(self.K).take(q[q >= 0])))
                    keep = r[q < 0]
            pieces.append((keep, old_t.take(j[keep])))
        if len(r):  # slot k <- slot k + 1 of the stored claims, the last one kept (ReachClaims.shift)
            old = self._last.claims
            g_lo, g_hi, g_b = old.lo, old.hi, old.slot_boxes
            if ids != self._last.ids:  # whole rows first (a gather mixed with slices is ~30x slower)
                src = np.where(reuse, j, 0)
                g_lo, g_hi, g_b = g_lo[src], g_hi[src], np.take(g_b, src, axis=1)
            for dst, g in ((lo, g_lo), (hi, g_hi)):
                dst[:, :-1] = g[:, 1:]
                dst[:, -1] = g[:, -1]
            boxes[:, :, :-1] = g_b[:, :, 1:]
            boxes[:, :, -1] = g_b[:, :, -1]
            if self._last.new is not None:  # rows granted at t - 1: their requested claims, shifted
                q = self._last.new_pos[j[r]]
                dst, q = r[q >= 0], q[q >= 0]
                if len(dst):
                    nw = self._last.new
                    nb = nw.slot_boxes
                    for a, g in ((lo, nw.lo), (hi, nw.hi)):
                        a[dst, :-1] = g[q, 1:]
                        a[dst, -1] = g[q, -1]
                    for p in range(4):
                        boxes[p, dst, :-1] = nb[p, q, 1:]
                        boxes[p, dst, -1] = nb[p, q, -1]
        f = np.flatnonzero(~reuse)
        for c in dict.fromkeys(cls[f].tolist()):
            g = f[cls[f] == c]
            fresh = pad_slots(self.book.claims_of(c, X[g], centre[g], heading[g], index[g],
                                                  None if pad is None else pad[g],
                                                  None if place is None else place.take(g)), self.K)
            lo[g], hi[g] = fresh.lo, fresh.hi
            if place is not None:
                pieces.append((g, fresh.slot_union()))
            fb = fresh.slot_boxes
            for q in range(4):  # per plane: a scatter along the middle axis is slow
                boxes[q, g] = fb[q]
        self.last_reused = reuse
        self.stats.reused += len(r)
        self.stats.fresh += len(f)
        out = (ReachClaims(centre, heading, lo, hi) if place is None
               else ReachClaims(place.centre, place.heading, lo, hi,
                                SlotBoxes.assemble(n, self.K, pieces)))._with_boxes(boxes)
        if pad is not None and len(r):  # a shifted row keeps the (larger) pad it was built with
            pad = pad.copy()
            pad[r] = self._last.pad[j[r]]
        self._pending = _Entry(t, ids, None, cls, X, centre, heading, index, pad, out)
        return out

    def commit(self, granted: np.ndarray, requesting: np.ndarray | None = None,
               requested: ReachClaims | None = None, req_index: np.ndarray | None = None,
               req_pad: np.ndarray | None = None) -> None:
        """Record the decision of the step of the last :meth:`current`: ``granted`` (n,) (e.g.
        ``decision.go``).  The claims in force of the vehicles not granted are the ones
        :meth:`current` handed out (a decision keeps them).

        Without ``requested`` the granted ones are not reused (fresh claims next step).  With it,
        their claims in force are their requested ones and are reused next step under the same
        premises (their new waypoint, segment heading, index and pad are then the ones checked):
        ``requesting`` (n,) the rows that requested (``granted`` among them), ``requested`` the
        claims of those rows in their order (e.g. the ones the decision took, centred on the
        requested waypoints), ``req_index`` (their requested indices) and ``req_pad`` (their pads,
        in the shape of :meth:`current`'s, if the parts had pads).
        """
        e = self._pending
        if e is None:
            self._last = None
            return
        granted = np.asarray(granted, dtype=bool)
        n = len(e.ids)
        if granted.shape != (n,):
            raise ValueError(f"ClaimCache.commit: granted must have shape ({n},), got {granted.shape}")
        if requested is None or not granted.any():
            self._last = _Entry(e.t, e.ids, e.row, e.cls, e.X, e.centre, e.heading, e.index, e.pad, e.claims,
                                granted)
            self._pending = None
            return
        requesting = np.asarray(requesting, dtype=bool)
        rq = np.flatnonzero(requesting)
        if requesting.shape != (n,) or len(requested) != len(rq) or np.any(granted & ~requesting):
            raise ValueError(f"ClaimCache.commit: requesting must be ({n},) bool covering granted, and requested "
                             f"one row per requester ({int(requesting.sum())}), got {requesting.shape} and "
                             f"{len(requested)}")
        if req_index is None or len(req_index) != len(rq):
            raise ValueError("ClaimCache.commit: req_index must give one index per requester")
        if (req_pad is None) != (e.pad is None):
            raise ValueError("ClaimCache.commit: req_pad must be given iff the current parts had pads")
        g = np.flatnonzero(granted)
        sub = np.flatnonzero(granted[rq])  # the granted rows among the requesters
        new = pad_slots(requested.take(sub), self.K)
        centre, heading, index = e.centre.copy(), e.heading.copy(), e.index.copy()
        centre[g], heading[g] = new.centre, new.heading
        cap = np.array([self.book.models[c].N for c in e.cls[g].tolist()], dtype=np.intp)
        index[g] = np.minimum(np.asarray(req_index, dtype=np.intp)[sub], cap)
        pad = e.pad
        if pad is not None:
            pad = pad.copy()
            pad[g] = np.asarray(req_pad, dtype=float).reshape(len(rq), -1)[sub]
        pos = np.full(n, -1, dtype=np.intp)
        pos[g] = np.arange(len(g))
        self._last = _Entry(e.t, e.ids, e.row, e.cls, e.X, centre, heading, index, pad, e.claims,
                            np.zeros(n, dtype=bool), new, pos)
        self._pending = None

    # ------------------------------------------------------------------ the premises
    def _reusable(self, t, ids, cls, X, centre, heading, index, pad) -> tuple[np.ndarray, np.ndarray]:
        """Which rows may take their shifted cached claims, and their cached rows (-1: none)."""
        n = len(ids)
        last = self._last
        fail = np.zeros(n, dtype=np.intp)  # 0: reusable, else 1 + position of the first failing reason
        if last is None or last.claims is None or last.t != t - 1:
            j = np.full(n, -1, dtype=np.intp)
            fail[:] = 1 + (REASONS.index("new") if last is None else REASONS.index("stale"))
            self._count(fail)
            return np.zeros(n, dtype=bool), j
        if ids == last.ids:
            j = np.arange(n, dtype=np.intp)
        else:
            if last.row is None:
                object.__setattr__(last, "row", dict(zip(last.ids, range(len(last.ids)))))
            get = last.row.get
            j = np.fromiter((get(v, -1) for v in ids), dtype=np.intp, count=n)
        have = j >= 0
        js = np.where(have, j, 0)

        def mark(bad, reason):
            fail[(fail == 0) & bad] = 1 + REASONS.index(reason)

        mark(~have | (last.cls[js] != cls), "new")
        mark(last.granted[js], "granted")
        mark(np.any(last.centre[js] != centre, axis=1) | (last.heading[js] != heading), "waypoint")
        mark(index > np.maximum(last.index[js] - 1, 0), "index")
        if pad is None or last.pad is None:  # claims with a pad never stand for claims without, nor back
            mark(np.full(n, (pad is None) != (last.pad is None)), "pad")
        elif pad.shape[1:] != last.pad.shape[1:]:
            mark(np.ones(n, dtype=bool), "pad")
        else:
            mark(~(last.pad[js] >= pad).all(axis=1), "pad")
        ok = fail == 0
        if ok.any():
            mark(~self._within_one_step(cls, X, centre, heading, last.X[js], ok), "reach")
        self._count(fail)
        return fail == 0, j

    def _within_one_step(self, cls, X, centre, heading, X0, rows) -> np.ndarray:
        """Rows ``rows`` whose ``x(t+1)`` lies in ``A x(t) ± r_1`` (segment frame, both factors)."""
        out = np.zeros(len(X), dtype=bool)
        off = np.hstack([centre, np.zeros((len(X), 2))])
        for c in dict.fromkeys(cls[rows].tolist()):
            g = np.flatnonzero(rows & (cls == c))
            A_al, r_al, A_ac, r_ac = self._reach1[c]
            E1 = rotate_pairs(X[g] - off[g], -heading[g])
            E0 = rotate_pairs(X0[g] - off[g], -heading[g])
            d_al = np.abs(E1[:, [0, 2]] - E0[:, [0, 2]] @ A_al.T) <= r_al + self.tol
            d_ac = np.abs(E1[:, [1, 3]] - E0[:, [1, 3]] @ A_ac.T) <= r_ac + self.tol
            out[g] = d_al.all(axis=1) & d_ac.all(axis=1)
        return out

    def _count(self, fail: np.ndarray) -> None:
        counts = np.bincount(fail, minlength=len(REASONS) + 1)
        for r, k in zip(REASONS, counts[1:].tolist()):
            self.stats.fresh_by_reason[r] += k
