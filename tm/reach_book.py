"""Reach-tightened claims of a whole fleet, per class (design.md §7): what the co-simulation loop
hands :meth:`tm.manager.TrafficManager.decide_reach`, the admission check and the monitor.

One :class:`~tm.reach.ReachModel` per movement-authority class; :meth:`ReachBook.claims` builds the
claims of several class groups (states, waypoints, headings, indices) in one call and
concatenates them in the order given (the order of the loop's :class:`~tm.manager.FleetState`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from controllers.authority import build_tables
from controllers.synthesis import SetFamily, rotate_pairs
from controllers.tolerances import GEOMETRY_TOL
from tm.path_claims import PathPlace, bare_model, path_reach_claims
from tm.reach import (ReachClaims, ReachModel, candidate_pairs, claims_conflict, reach_claims, reach_claims_many,
                      split_pad, world_aabb)

__all__ = ["ReachBook", "tube_escapes", "footprint_claims", "admit_reach"]


class ReachBook:
    """Claim models of the classes of a run.

    Parameters
    ----------
    families : mapping of str to SetFamily
        Movement-authority families (synthesised with ``authority_decel``).
    footprints : mapping of str to (length, width)
    """

    def __init__(self, families: Mapping[str, SetFamily], footprints: Mapping[str, tuple[float, float]]):
        missing = [c for c, f in families.items() if f.authority is None]
        if missing:
            raise ValueError(f"ReachBook: class(es) {missing} have no movement-authority family "
                             "(synthesise with SynthesisSettings.authority_decel)")
        self.models = {c: ReachModel.build(f, build_tables(f), *footprints[c]) for c, f in families.items()}
        #: the models without footprint (path-frame vehicles: the footprint is laid along the path)
        self.bare = {c: bare_model(m) for c, m in self.models.items()}

    @property
    def K(self) -> int:
        """The largest number of claim slots over the classes."""
        return max(m.K for m in self.models.values())

    def claims_of(self, cls: str, X, centre, heading, index, pad=None, place: PathPlace | None = None) -> ReachClaims:
        """Claims of vehicles of class ``cls`` (:func:`tm.reach.reach_claims`); with ``place``, of
        vehicles driven in path coordinates (``X``, ``centre``, ``heading`` in their frames:
        :func:`tm.path_claims.path_reach_claims`, drawn in the world frames of ``place``)."""
        m = self.models[cls]
        index = np.minimum(index, m.N)
        if place is None:
            return reach_claims(m, X, centre, heading, index, body_pad=pad)
        return path_reach_claims(m, self.bare[cls], X, centre, index, place, body_pad=pad)

    def claims(self, parts: Sequence[tuple]) -> ReachClaims:
        """Claims of groups ``(class, X (n, 4), centre (n, 2), heading (n,), index (n,)[, pad (n, 2)[,
        place]])``, concatenated (shorter horizons padded with their last slot); an empty claim set
        when every group is empty.  ``pad``: the footprint's extra half extents (``reach_claims``'
        ``body_pad``); ``place``: a :class:`~tm.path_claims.PathPlace` for path-frame vehicles."""
        parts = [p for p in parts if len(p[1])]
        if not parts:
            K = self.K
            return ReachClaims(np.zeros((0, 2)), np.zeros(0), np.zeros((0, K, 2)), np.zeros((0, K, 2)))
        if all(len(p) <= 6 or p[6] is None for p in parts):  # road frame: one set of arrays, written in place
            return reach_claims_many([(self.models[p[0]], p[1], p[2], p[3], np.minimum(p[4], self.models[p[0]].N),
                                       0.0, p[5] if len(p) > 5 else None) for p in parts])
        return ReachClaims.concat(*(self.claims_of(p[0], p[1], p[2], p[3], p[4], p[5] if len(p) > 5 else None,
                                                   p[6] if len(p) > 6 else None) for p in parts))


def footprint_claims(position, heading, length, width, K: int = 1, pad=None) -> ReachClaims:
    """The footprints now as claims (every slot the footprint, widened by ``pad`` (n, 2) or one-sided (n, 4) when given):
    what a new vehicle must miss when it appears, besides the others' claims from the next step on."""
    position = np.asarray(position, dtype=float).reshape(-1, 2)
    half = 0.5 * np.column_stack([np.asarray(length, dtype=float), np.asarray(width, dtype=float)])
    plo, phi = split_pad(pad, len(position)) if pad is not None else (0.0, 0.0)
    lo = np.repeat((-half - plo)[:, None, :], K, axis=1)
    hi = np.repeat((half + phi)[:, None, :], K, axis=1)
    return ReachClaims(position, np.asarray(heading, dtype=float), lo, hi)


def tube_escapes(claims: ReachClaims, position, length, width, tol: float = GEOMETRY_TOL,
                 pad=None, body_heading=None) -> np.ndarray:
    """Which vehicles' positions ``x(t+1)`` lie outside the position part of their claim ``S_1(t)``
    (the box minus the footprint, ``tol`` given away): a tube escape, never expected.

    ``claims``: the claims in force after the decision of step ``t`` (the box of slot 1 was built
    with ``body_offset = 0``: half footprint ``(length, width) / 2`` in the segment frame, plus the
    ``body_pad`` the claims were built with, ``pad`` (n, 2) or (n, 4): :func:`tm.reach.split_pad`).

    ``body_heading`` (n,): the bodies' headings where they need not be the claims' (path-frame
    vehicles, :mod:`tm.path_claims`): the padded rectangle is then turned by the difference and its
    bounding box in the claim's frame is what the box must hold."""
    position = np.asarray(position, dtype=float).reshape(-1, 2)
    if len(position) != len(claims):
        raise ValueError(f"tube_escapes: {len(claims)} claims for {len(position)} positions")
    e = rotate_pairs(position - claims.centre, -claims.heading)
    half = 0.5 * np.column_stack([np.asarray(length, dtype=float), np.asarray(width, dtype=float)])
    half = np.broadcast_to(half, (len(position), 2))
    plo, phi = split_pad(pad, len(position)) if pad is not None else (np.zeros((len(position), 2)),) * 2
    blo, bhi = half + plo, half + phi  # the body's reach behind/right and ahead/left of its centre
    if body_heading is not None:
        d = np.asarray(body_heading, dtype=float) - claims.heading
        corners = np.stack([np.column_stack([-blo[:, 0], -blo[:, 1]]), np.column_stack([bhi[:, 0], -blo[:, 1]]),
                            np.column_stack([bhi[:, 0], bhi[:, 1]]), np.column_stack([-blo[:, 0], bhi[:, 1]])], axis=1)
        rc = rotate_pairs(corners.reshape(-1, 2), np.repeat(d, 4)).reshape(-1, 4, 2)
        blo, bhi = -rc.min(axis=1), rc.max(axis=1)
    lo, hi = claims.lo[:, 0] + blo, claims.hi[:, 0] - bhi
    return np.any((e < lo - tol) | (e > hi + tol), axis=1)


def admit_reach(current: ReachClaims, candidates: ReachClaims, check: str) -> np.ndarray:
    """Initial condition (12) with reach claims: candidates taken in order, each admitted iff its
    claims miss every claim of ``current`` (include the footprints now: :func:`footprint_claims`)
    and those of the candidates admitted before it."""
    C = len(candidates)
    admitted = np.zeros(C, dtype=bool)
    if not C:
        return admitted
    allc = ReachClaims.concat(current, candidates) if len(current) else candidates
    n = len(current)
    lo, hi = world_aabb(allc)
    i, j = candidate_pairs(lo[n:], hi[n:], lo, hi)
    keep = j != i + n
    i, j = i[keep], j[keep]
    hit = np.zeros(0, dtype=bool) if not len(i) else claims_conflict(allc, i + n, allc, j, check)
    i, j = i[hit], j[hit]
    blocked = np.zeros(C, dtype=bool)
    blocked[i[j < n]] = True
    for k in range(C):
        if blocked[k]:
            continue
        earlier = j[(i == k) & (j >= n) & (j < n + k)] - n
        admitted[k] = not admitted[earlier].any()
    return admitted
