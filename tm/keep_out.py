"""Keep-out: nobody comes to stand in the claims a junction-token holder still has to make to leave
the guard (the movement-authority liveness layer, :mod:`tm.authority_gate`, module notes "room for
the claims' width").

:class:`KeepOut` withholds the requests whose requested stop point's standing box (the padded
:meth:`tm.authority_reach.AuthorityReach.hold_box`) meets a holder's wide path from its stop point on
while the current one does not; of two holders kept out of each other's path so, one goes
(:meth:`KeepOut._mutual`).  Composed into :class:`tm.authority_gate.AuthorityGate`, which hands
it the holders and its own path and route helpers.  Liveness only: the traffic manager checks every
claim.  Pure numpy, no simulator.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np

from tm.authority_reach import AuthorityReach
from tm.boxes import ranges
from tm.gate_paths import standing_boxes
from tm.junctions import JunctionFleet

__all__ = ["KeepOut"]


class KeepOut:
    """The keep-out rule of the movement-authority junction layer (module notes).

    Parameters
    ----------
    classes : mapping of str to AuthorityReach
        The vehicle classes' extents.

    Attributes
    ----------
    margin : float
        How far a requester's standing box may lie beyond its current claim box (m): its stop
        point moves by at most δ, plus the largest hold box and a padding allowance; requesters
        farther from a holder's path are not looked at.
    """

    def __init__(self, classes: Mapping[str, AuthorityReach]):
        self.classes = classes
        #: over the run: holders let go into each other's paths (:meth:`_mutual`)
        self.mutual_released = 0
        #: the last call's withheld vehicles -> the holders whose paths they were kept out of (ids)
        self.kept_from: dict[str, list[str]] = {}
        self.margin = max((c.delta + c.hold + 0.5 * np.hypot(c.length, c.width) for c in classes.values()),
                          default=0.0) + 10.0

    def apply(self, fleet: JunctionFleet, req: np.ndarray, holders: Sequence[dict],
              wide_paths: Callable, on_routes: Callable,
              after: Mapping[str, set] | None = None) -> tuple[np.ndarray, int]:
        """Withhold the requests whose requested stop point's standing box
        (:meth:`AuthorityReach.hold_box`, padded) meets a zone ``z`` holder's wide path (``wide_paths``)
        from its stop point on while their current one does not: of vehicles without ``z``'s
        token, and of those on the holder's route (its queue, ``z`` holders that follow it through
        included), for which the path counts from the waypoint after the holder's stop point (a
        queue closes up to the holder, not into the claims its turn swings back).  Other ``z``
        holders are exempt (their corridors miss this one's), but not one that took the token after
        this one (``after``).  Nobody comes to stand in claims a
        holder still has to make to leave the guard.  (It does not help against one that stood
        there before the token was handed out: a hand-out rule refusing the token then, tried on
        ``grid`` seed 1, refused every waiter of a busy junction, each standing in another's wide
        path: 94 of 150 arrived.)

        Parameters
        ----------
        fleet : JunctionFleet
        req : ndarray of bool, shape (n,)
            The requests that stay so far.
        holders : sequence of dict
            Per zone, its token holders (ids; :attr:`tm.junctions.JunctionGate.holders`).
        wide_paths : callable
            ``(fleet, [(row, zone, first), ...]) -> [(lo, hi) or None, ...]``: holders' paths from
            waypoint ``first`` on (:meth:`tm.authority_gate.AuthorityGate._wide_paths`).
        on_routes : callable
            ``(fleet, rows, js, ahead) -> bool array``: whether row ``js[i]`` has its stop point
            ``+ ahead`` on row ``rows[i]``'s route, each pair ``i``
            (:meth:`tm.gate_paths.GatePaths.on_routes`).
        after : mapping of str to set of str, optional
            Holder id -> the holders whose paths it keeps out of although it holds their zone's token
            too: it took the token after them (:meth:`tm.authority_gate.AuthorityGate._after`).

        Returns
        -------
        out : ndarray of bool, shape (n,)
        withheld : int
            How many requests were withheld here.
        """
        ids = fleet.ids
        pos = dict(zip(ids, range(len(ids))))
        after = after or {}
        self.kept_from = {}
        r = np.flatnonzero(req)
        if not len(r):
            return req, 0
        out = req.copy()
        # the holders' paths and the requesters near each (by their claims' boxes, all at once) ...
        asks, owner = [], []
        for z, hs in enumerate(holders):
            for h in list(hs):
                row = pos.get(h)
                if row is not None:
                    asks.append((row, z, fleet.route(row)[2]))
                    owner.append((hs, row))
        paths = [(hs, row, *path) for (hs, row), path in zip(owner, wide_paths(fleet, asks)) if path is not None]
        if not paths:
            return out, 0
        m_box = np.array([len(p[2]) for p in paths], dtype=np.intp)  # each path's boxes, one run each in L_lo
        s_box = np.cumsum(m_box) - m_box
        L_lo = np.concatenate([p[2] for p in paths])
        L_hi = np.concatenate([p[3] for p in paths])
        p_lo = np.minimum.reduceat(L_lo, s_box, axis=0) - self.margin   # (P, 2)
        p_hi = np.maximum.reduceat(L_hi, s_box, axis=0) + self.margin
        c_lo, c_hi = fleet.claim_lo[r], fleet.claim_hi[r]
        close = ((c_lo[None, :, 0] <= p_hi[:, None, 0]) & (c_lo[None, :, 1] <= p_hi[:, None, 1]) &
                 (c_hi[None, :, 0] >= p_lo[:, None, 0]) & (c_hi[None, :, 1] >= p_lo[:, None, 1]))  # (P, R)
        h_row = np.array([p[1] for p in paths], dtype=np.intp)
        # (path, requester) pairs, path by path, requesters ascending (not the holder itself)
        pt, pr = np.nonzero(close)
        pj = r[pr]
        keep = pj != h_row[pt]
        pt, pj = pt[keep], pj[keep]
        if not len(pt):
            return out, 0
        # ... their standing boxes asked for, computed once; which of them meet each path's boxes ...
        a_lo, a_hi = self._standing_by_row(fleet, np.unique(pj), ahead=1)
        pb, bb = self._pair_boxes(pt, m_box, s_box)
        hit1 = self._meet(a_lo, a_hi, pj[pb], L_lo[bb], L_hi[bb])  # the asked-for box against each box of the path
        first = np.cumsum(m_box[pt]) - m_box[pt]
        asks = np.logical_or.reduceat(hit1, first)  # it meets the path somewhere
        if not asks.any():
            return out, 0
        hit1 = hit1[np.repeat(asks, m_box[pt])]
        pt, pj = pt[asks], pj[asks]
        # ... the current standing boxes of those alone ...
        n_lo, n_hi = self._standing_by_row(fleet, np.unique(pj), ahead=0)
        pb, bb = self._pair_boxes(pt, m_box, s_box)
        hit0 = self._meet(n_lo, n_hi, pj[pb], L_lo[bb], L_hi[bb])
        # ... then pair by pair: on the holder's route (its queue), the path after the holder's stop
        # point counts (its first box left out); off it, the zone's other holders are exempt unless
        # they took the token after this one (``after``)
        queue = on_routes(fleet, h_row[pt], pj, ahead=1)
        first = np.cumsum(m_box[pt]) - m_box[pt]
        counts = ~(queue[pb] & (bb == s_box[pt][pb]))
        h1 = np.logical_or.reduceat(hit1 & counts, first)
        h0 = np.logical_or.reduceat(hit0 & counts, first)
        co = {t: {pos[v] for v in paths[t][0] if v in pos and ids[paths[t][1]] not in after.get(v, ())}
              for t in set(pt.tolist())}
        exempt = np.array([not q and j in co[t] for t, j, q in zip(pt.tolist(), pj.tolist(), queue.tolist())],
                          dtype=bool).reshape(-1)
        hit = h1 & ~h0 & ~exempt
        by: dict[int, set[int]] = {}  # withheld row -> the holders' rows that withheld it (:meth:`_mutual`)
        for t, j in zip(pt[hit].tolist(), pj[hit].tolist()):
            by.setdefault(j, set()).add(paths[t][1])
        if not by:
            return out, 0
        out[list(by)] = False
        n_withheld = len(by) - self._mutual(ids, by, out)
        self.kept_from = {ids[j]: [ids[h] for h in sorted(hs)] for j, hs in by.items() if not out[j]}
        return out, n_withheld

    @staticmethod
    def _pair_boxes(pt: np.ndarray, m_box: np.ndarray, s_box: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every (pair, box of the pair's path) combination: the pair ``pb`` and the box's index ``bb``
        into the paths' boxes (path ``t``'s: ``s_box[t] .. s_box[t] + m_box[t] - 1``), pair by pair."""
        n = m_box[pt]
        return np.repeat(np.arange(len(pt)), n), ranges(s_box[pt], n)

    @staticmethod
    def _meet(lo: np.ndarray, hi: np.ndarray, rows: np.ndarray, b_lo: np.ndarray, b_hi: np.ndarray) -> np.ndarray:
        """Whether box ``(lo[rows[i]], hi[rows[i]])`` meets box ``(b_lo[i], b_hi[i])``, each ``i`` (touching
        counts; :func:`tm.boxes.box_pairs_meet` of one pair)."""
        return np.all((lo[rows] <= b_hi) & (hi[rows] >= b_lo), axis=1)

    def _mutual(self, ids: list, by: dict[int, set[int]], out: np.ndarray) -> int:
        """Let one of each pair of holders kept out of each other's wide path go: each holds a token
        of its own zone and its next stop point would stand in the other's path, so each would wait
        for the other to move first, for good (SUMO's ``fkk_in``: ``1_left.0`` leaving ``gneJ21`` and
        ``2_right.0`` leaving ``gneJ220``, two junctions 3 m apart whose exits merge).  The one whose
        id sorts first goes, unless a holder that is not its partner keeps it out too; its current
        standing box misses the other's path (else it would not have been kept out), so the other
        can follow once it has moved on.  Returns how many were let go (:attr:`mutual_released`)."""
        freed = 0
        for j, hs in by.items():
            partners = {h for h in hs if j in by.get(h, ())}
            if not partners or hs - partners or out[j]:
                continue
            if all(ids[j] < ids[h] for h in partners):
                out[j] = True
                freed += 1
        self.mutual_released += freed
        return freed

    def _standing_by_row(self, fleet: JunctionFleet, rows: np.ndarray, ahead: int) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`standing_boxes` of ``rows`` placed at their rows of the fleet, (len(fleet.ids), 2) each
        (NaN at the other rows)."""
        lo, hi = np.full((2, len(fleet.ids), 2), np.nan)
        lo[rows], hi[rows] = self.standing_boxes(fleet, rows, ahead)
        return lo, hi

    def standing_boxes(self, fleet: JunctionFleet, rows: np.ndarray, ahead: int) -> tuple[np.ndarray, np.ndarray]:
        """:func:`tm.gate_paths.standing_boxes` of this rule's classes."""
        return standing_boxes(self.classes, fleet, rows, ahead)
