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
from tm.boxes import box_pairs_meet
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
        self.margin = max((c.delta + c.hold + 0.5 * np.hypot(c.length, c.width) for c in classes.values()),
                          default=0.0) + 10.0

    def apply(self, fleet: JunctionFleet, req: np.ndarray, holders: Sequence[dict],
              wide_paths: Callable, on_route: Callable,
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
        on_route : callable
            ``(fleet, row, rows, ahead) -> bool array``: which ``rows`` have their stop point ``+ ahead``
            on ``row``'s route (:meth:`tm.authority_gate.AuthorityGate._on_route`).
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
        p_lo = np.array([p[2].min(axis=0) for p in paths]) - self.margin   # (P, 2)
        p_hi = np.array([p[3].max(axis=0) for p in paths]) + self.margin
        c_lo, c_hi = fleet.claim_lo[r], fleet.claim_hi[r]
        close = ((c_lo[None, :, 0] <= p_hi[:, None, 0]) & (c_lo[None, :, 1] <= p_hi[:, None, 1]) &
                 (c_hi[None, :, 0] >= p_lo[:, None, 0]) & (c_hi[None, :, 1] >= p_lo[:, None, 1]))  # (P, R)
        todo = []
        for (hs, row, lo, hi), m in zip(paths, close):
            near = r[m]
            near = near[near != row]
            if len(near):
                todo.append((hs, row, lo, hi, near))
        if not todo:
            return out, 0
        # ... their standing boxes asked for, computed once; then holder by holder, which asked-for
        # boxes meet the path ...
        every = np.unique(np.concatenate([t[4] for t in todo]))
        a_lo, a_hi = self._standing_by_row(fleet, every, ahead=1)
        met = []
        for hs, row, lo, hi, near in todo:
            hit1 = box_pairs_meet(a_lo[near], a_hi[near], lo, hi)  # the asked-for box against each box of the path
            asks = hit1.any(axis=1)  # the asked-for box meets the path somewhere
            if asks.any():
                met.append((hs, row, lo, hi, near[asks], hit1[asks]))
        if not met:
            return out, 0
        # ... the current standing boxes of those alone ...
        askers = np.unique(np.concatenate([t[4] for t in met]))
        n_lo, n_hi = self._standing_by_row(fleet, askers, ahead=0)
        n_withheld = 0
        by: dict[int, set[int]] = {}  # withheld row -> the holders' rows that withheld it
        # ... then holder by holder (each withheld request's holders noted, :meth:`_mutual`)
        for hs, row, lo, hi, near, hit1 in met:
            co = set(pos[v] for v in hs if v in pos and ids[row] not in after.get(v, ()))
            hit0 = box_pairs_meet(n_lo[near], n_hi[near], lo, hi)
            queue = on_route(fleet, row, near, ahead=1)
            withheld = []
            for j, h0, h1, q in zip(near.tolist(), hit0, hit1, queue.tolist()):
                if q:
                    h0, h1 = h0[1:], h1[1:]  # its queue: the path after the holder's stop point
                elif j in co:
                    continue
                if h1.any() and not h0.any():
                    withheld.append(j)
            for j in withheld:
                by.setdefault(j, set()).add(row)
            if withheld:
                n_withheld += int(out[withheld].sum())
                out[withheld] = False
        n_withheld -= self._mutual(ids, by, out)
        return out, n_withheld

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
        """World boxes ``(lo, hi)`` (n, 2) of ``rows`` standing (padded :meth:`AuthorityReach.hold_box`)
        at their waypoints ``k + ahead`` (the route's last at most): ``0`` at their stop points, ``1``
        at the ones they ask for."""
        n = len(rows)
        if not n:
            return np.zeros((0, 2)), np.zeros((0, 2))
        routes = [fleet.route(j) for j in rows.tolist()]
        k = np.array([r[2] for r in routes], dtype=np.intp)
        last = np.array([len(r[0]) - 1 for r in routes], dtype=np.intp)
        idx = np.minimum(k + ahead, last)
        nxt = np.minimum(idx + 1, last)
        Wp = np.array([r[0][i] for r, i in zip(routes, idx.tolist())], dtype=float).reshape(n, 2)
        Ha = np.array([r[1][i] for r, i in zip(routes, idx.tolist())], dtype=float)
        Hb = np.array([r[1][i] for r, i in zip(routes, nxt.tolist())], dtype=float)
        pad = fleet.pad_rows(rows, idx)
        b_lo, b_hi = np.empty((n, 2)), np.empty((n, 2))
        fam = np.asarray(fleet.family)[rows]
        for c in np.unique(fam).tolist():
            m = fam == c
            b_lo[m], b_hi[m] = self.classes[c].hold_box(pad[m], Ha[m], Hb[m])
        return Wp + b_lo, Wp + b_hi
