"""Where a movement-authority vehicle will pass and stand near a junction: its wide path through a
zone (the boxes that hold every claim it can make while its stop point moves to the exit slot) and
its padded hold box at rest at its stop point, in world boxes and as oriented boxes, cached per
vehicle, zone and stop point; and the two hand-out rules that are questions of those paths alone:
whether a candidate queues behind holders on the same lanes with room beyond the exit slot
(:meth:`GatePaths.follows`) and whether it lets a waiter go first (:meth:`GatePaths.yields`)
(:mod:`tm.authority_gate`, module notes: "room for the claims' width", "yield at the hand-out",
"standing at a red", "queues").  Pure numpy, no simulator.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from tm.authority_reach import AuthorityReach
from tm.boxes import boxes_meet, ranges
from tm.guard_spans import GuardSpans
from tm.junctions import JunctionFleet

__all__ = ["GatePaths", "standing_boxes"]

_UNSET = object()  # not kept yet (:meth:`GatePaths.wide_paths`; None is a kept answer)
#: waypoints per run of a route whose bounding box :meth:`GatePaths.on_routes` tests first
_CHUNK = 16


class GatePaths:
    """Wide paths and standing boxes of a fleet's vehicles, cached, and the queue and yield rules
    on them (module notes).

    Parameters
    ----------
    classes : mapping of str to AuthorityReach
        Every class a fleet row may name.
    spans : GuardSpans
        The vehicles' route intervals through the guards (where a path ends: the exit slot).
    """

    def __init__(self, classes: Mapping[str, AuthorityReach], spans: GuardSpans):
        self.classes = classes
        self.spans = spans
        self._wide: dict = {}  # (vehicle, zone, waypoint, first) -> its wide path (:meth:`wide_path`)
        #: (vehicle, zone, waypoint) -> its wide path beyond its stop point as oriented boxes (:meth:`wide_polygons`)
        self._wide_poly: dict = {}
        self._stand_memo: tuple = (None, {})  # (fleet, row -> standing box) (:meth:`standing`)
        #: vehicle -> (its route, the bounding boxes of the route's runs of waypoints) (:meth:`_chunks`)
        self._route_chunks: dict = {}
        #: (vehicle, its path's entry and exit slot, leader, the leader's) -> whether they are the same lanes
        #: (:meth:`follows`; the paths are pieces of the routes, which never change)
        self._lanes: dict = {}

    def wide_path(self, fleet: JunctionFleet, row: int, z: int, first: int):
        """Boxes ``(lo, hi)`` (m, 2) that hold every claim of row ``row`` while its stop point moves
        from waypoint ``first`` to zone ``z``'s exit slot and rests there: at each of those waypoints
        :meth:`tm.authority_reach.AuthorityReach.claim_box` (``T^0`` plus ``L/2`` along, the claims'
        across half-width plus ``W/2`` across, the route's padding there).  None when the route does not leave the
        guard from there (it arrives inside) or the stop point is past the slot."""
        return self.wide_paths(fleet, [(row, z, first)])[0]

    def path_idx(self, fleet: JunctionFleet, row: int, z: int, first: int,
                 to_end: bool = False) -> np.ndarray | None:
        """The waypoints of row ``row``'s path through zone ``z`` from waypoint ``first`` to the exit
        slot (:meth:`wide_path`, :meth:`wide_polygons`); None when the route does not leave the guard
        from there (``to_end``: then to the route's last waypoint, in the guard) or the stop point is
        past the slot."""
        k = fleet.route(row)[2]
        span = self.spans.span_of(fleet, row, z, k + 1) or self.spans.span_of(fleet, row, z, k)
        if span is None or not (span[2] or to_end) or first > span[1]:
            return None
        return np.arange(max(first, 0), span[1] + 1)

    def wide_paths(self, fleet: JunctionFleet, asks: list) -> list:
        """:meth:`wide_path` of each ``(row, z, first)`` of ``asks``, kept per (vehicle, zone, stop
        point, first); those not kept yet computed together (their boxes one class at a time)."""
        if len(self._wide) > 100_000:  # stale keys: start over
            self._wide.clear()
        out, todo = [], []
        for row, z, first in asks:
            W, H, k = fleet.route(row)
            key = (fleet.ids[row], z, k, first)
            found = self._wide.get(key, _UNSET)
            if found is _UNSET:
                idx = self.path_idx(fleet, row, z, first)
                if idx is None:
                    found = self._wide[key] = None
                else:
                    todo.append((len(out), key, row, W, H, idx))
            out.append(found)
        for c in sorted({fleet.family[t[2]] for t in todo}):
            mine = [t for t in todo if fleet.family[t[2]] == c]
            pad = fleet.pad_rows(np.concatenate([np.full(len(idx), row) for _, _, row, _, _, idx in mine]),
                                 np.concatenate([idx for *_, idx in mine]))  # one lookup for all
            lo, hi = self.classes[c].claim_box(
                pad, np.concatenate([H[idx] for *_, H, idx in mine]),
                np.concatenate([H[np.minimum(idx + 1, len(H) - 1)] for *_, H, idx in mine]))
            o = 0
            for n, key, _, W, _, idx in mine:
                m = len(idx)
                out[n] = self._wide[key] = (W[idx] + lo[o:o + m], W[idx] + hi[o:o + m])
                o += m
        return out

    def standing(self, fleet: JunctionFleet, row: int) -> tuple[np.ndarray, np.ndarray]:
        """World box ``(lo, hi)`` (2,) of row ``row`` at rest at its stop point (padded hold box);
        kept for the fleet it was asked for (a step's rounds ask for the same waiters often)."""
        memo = self._stand_memo
        if memo[0] is not fleet:
            memo = self._stand_memo = (fleet, {})
        got = memo[1].get(row)
        if got is None:
            got = memo[1][row] = self.standing_box(fleet, row)
        return got

    def standing_many(self, fleet: JunctionFleet, rows: np.ndarray) -> None:
        """Keep :meth:`standing` of every row of ``rows`` not kept yet for ``fleet``, computed together
        (one padding lookup, the boxes one class at a time; each the floats :meth:`standing_box` gives)."""
        memo = self._stand_memo
        if memo[0] is not fleet:
            memo = self._stand_memo = (fleet, {})
        todo = [r for r in dict.fromkeys(np.asarray(rows, dtype=np.intp).reshape(-1).tolist()) if r not in memo[1]]
        if not todo:
            return
        lo, hi = standing_boxes(self.classes, fleet, np.array(todo, dtype=np.intp), 0)
        for i, r in enumerate(todo):
            memo[1][r] = (lo[i], hi[i])

    def at_stop(self, fleet: JunctionFleet, row: int) -> tuple:
        """Row ``row``'s class, stop point ``W[k]`` (1, 2), padding there (1, 4) and the stop point's
        arriving and leaving headings (1,) each: what its hold box at rest is drawn from."""
        W, H, k = fleet.route(row)
        idx = np.array([k])
        return (self.classes[fleet.family[row]], W[idx], fleet.pad(row, idx), H[idx],
                H[np.minimum(idx + 1, len(H) - 1)])

    def standing_box(self, fleet: JunctionFleet, row: int) -> tuple[np.ndarray, np.ndarray]:
        cls, w, pad, h_in, h_out = self.at_stop(fleet, row)
        lo, hi = cls.hold_box(pad, h_in, h_out)
        return w[0] + lo[0], w[0] + hi[0]

    def beyond_meets(self, fleet: JunctionFleet, row: int, z: int, box) -> bool:
        """Whether row ``row``'s wide path through zone ``z`` beyond its stop point meets ``box``."""
        path = self.wide_path(fleet, row, z, fleet.route(row)[2] + 1)
        if path is None:
            return False
        return boxes_meet(path[0], path[1], np.asarray(box[0])[None], np.asarray(box[1])[None])

    def wide_polygons(self, fleet: JunctionFleet, row: int, z: int) -> np.ndarray | None:
        """Row ``row``'s wide path through zone ``z`` beyond its stop point (the boxes of
        :meth:`wide_path` from the next waypoint on, to the route's end where it ends in the guard)
        as oriented boxes (h n, 4, 2), each waypoint's at its arriving and leaving headings; None when
        no waypoint is left there."""
        W, H, k = fleet.route(row)
        key = (fleet.ids[row], z, k)
        found = self._wide_poly.get(key, _UNSET)
        if found is _UNSET:
            if len(self._wide_poly) > 100_000:  # stale keys: start over
                self._wide_poly.clear()
            idx = self.path_idx(fleet, row, z, k + 1, to_end=True)
            found = None
            if idx is not None:
                found = self.classes[fleet.family[row]].corridor_polygons(W[idx], fleet.pad(row, idx), H[idx],
                                                                          H[np.minimum(idx + 1, len(H) - 1)])
            self._wide_poly[key] = found
        return found

    def standing_polygons(self, fleet: JunctionFleet, row: int) -> np.ndarray:
        """Row ``row`` at rest at its stop point: its padded hold box as oriented boxes (2, 4, 2), at
        the stop point's arriving and leaving headings."""
        cls, w, pad, h_in, h_out = self.at_stop(fleet, row)
        return cls.hold_polygons(w, pad, h_in, h_out)

    def on_route(self, fleet: JunctionFleet, row: int, j: np.ndarray, ahead: int = 0) -> np.ndarray:
        """Which rows ``j`` have their requested stop point (``k + ahead``) on row ``row``'s route
        (within ``0.6 δ`` of one of its waypoints: the same lanes, ahead of it or behind)."""
        j = np.asarray(j, dtype=np.intp).reshape(-1)
        return self.on_routes(fleet, np.full(len(j), row, dtype=np.intp), j, ahead)

    def on_routes(self, fleet: JunctionFleet, rows: np.ndarray, j: np.ndarray, ahead: int = 0) -> np.ndarray:
        """:meth:`on_route` of pairs: whether row ``j[i]``'s requested stop point (``k + ahead``) lies
        on row ``rows[i]``'s route (within ``0.6 δ`` of one of its waypoints), all pairs at once.

        Only the runs of :data:`_CHUNK` waypoints whose bounding box, widened by the tolerance (and a
        rounding's slack), holds the point are measured (:meth:`_chunks`): a waypoint within ``0.6 δ``
        lies within it on either axis.  A route with a NaN waypoint is measured whole (its minimum
        distance NaN, as a direct minimum makes it)."""
        rows = np.asarray(rows, dtype=np.intp).reshape(-1)
        j = np.asarray(j, dtype=np.intp).reshape(-1)
        out = np.zeros(len(j), dtype=bool)
        if not len(j):
            return out
        table = fleet.stop_table(ahead)
        if table is not None:  # the whole fleet's stop points (JunctionFleet.stops)
            pts = table[0][j]
        else:
            pts = np.empty((len(j), 2))
            for n, jj in enumerate(j.tolist()):
                Wj, _, kj = fleet.route(jj)
                pts[n] = Wj[min(kj + ahead, len(Wj) - 1)]
        fam = np.asarray(fleet.family)[j]
        tol = np.empty(len(j))
        for c in np.unique(fam).tolist():
            tol[fam == c] = 0.6 * self.classes[c].delta
        u, inv = np.unique(rows, return_inverse=True)
        Ws = [fleet.route(r)[0] for r in u.tolist()]
        ch = [self._chunks(fleet, fleet.ids[r], W) for r, W in zip(u.tolist(), Ws)]
        whole = np.array([c is None for c in ch], dtype=bool)
        if whole.any():  # NaN in the route: every waypoint, as a direct minimum takes them
            for t in np.flatnonzero(whole[inv]).tolist():
                W = Ws[inv[t]]
                out[t] = np.hypot(W[:, 0] - pts[t, 0], W[:, 1] - pts[t, 1]).min() <= tol[t]
        c_lo = np.concatenate([c[0] for c in ch if c is not None] or [np.zeros((0, 2))])
        c_hi = np.concatenate([c[1] for c in ch if c is not None] or [np.zeros((0, 2))])
        cnt = np.array([0 if c is None else len(c[0]) for c in ch], dtype=np.intp)
        n_c = cnt[inv]  # each pair's route's chunks, and their places in c_lo
        pc = np.repeat(np.arange(len(j)), n_c)
        cc = ranges((np.cumsum(cnt) - cnt)[inv], n_c)
        slack = tol * (1.0 + 1e-9) + 1e-9
        near = np.all((c_lo[cc] - slack[pc, None] <= pts[pc]) & (pts[pc] <= c_hi[cc] + slack[pc, None]), axis=1)
        pc, cc = pc[near], cc[near]
        if not len(pc):
            return out
        first = (cc - (np.cumsum(cnt) - cnt)[inv][pc]) * _CHUNK  # each chunk's first waypoint in its route
        seg = [Ws[inv[p]][f:f + _CHUNK] for p, f in zip(pc.tolist(), first.tolist())]
        m = np.array([len(s) for s in seg], dtype=np.intp)
        W = np.concatenate(seg)
        p = np.repeat(pc, m)
        d = np.hypot(W[:, 0] - pts[p, 0], W[:, 1] - pts[p, 1])
        out[p[d <= tol[p]]] = True
        return out

    def _chunks(self, fleet: JunctionFleet, vid: str, W: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """Bounding boxes ``(lo, hi)`` (C, 2) of vehicle ``vid``'s route ``W``'s runs of :data:`_CHUNK`
        waypoints (:meth:`on_routes`), kept per vehicle while its route is the same array (the entry
        holds it); None when a waypoint is NaN.  The vehicles no longer in ``fleet`` are dropped once
        the kept ones are many more than it."""
        got = self._route_chunks.get(vid)
        if got is None or got[0] is not W:
            if len(self._route_chunks) > 2 * len(fleet.ids) + 1000:  # vehicles gone
                live = set(fleet.ids)
                self._route_chunks = {v: c for v, c in self._route_chunks.items() if v in live}
            C = -(-len(W) // _CHUNK)
            if np.isnan(W).any():
                box = None
            else:
                pad = np.concatenate([W, np.repeat(W[-1:], C * _CHUNK - len(W), axis=0)]).reshape(C, _CHUNK, 2)
                box = (pad.min(axis=1), pad.max(axis=1))
            got = self._route_chunks[vid] = (W, box)
        return got[1]

    def follows(self, fleet: JunctionFleet, pos: dict, row: int, z: int, leaders: list) -> bool:
        """A queue through the junction: row ``row`` may take zone ``z``'s token although its
        corridor meets the holders ``leaders``' (or their claims fill its exit slot) when each of
        them drives the same path through the zone (every waypoint of its path from entry to exit
        slot within ``0.6 δ`` of theirs: the same lanes) ahead of it, and the road from its exit
        slot on has room for them all and for it: the hold boxes at the waypoints from the slot
        over ``sum_j ceil(((L_j + L) / 2 + hold_j + hold) / δ)`` more meet no claim but theirs.
        Then none of them can stop inside the guard: nobody else enters that road but through this
        zone's exit slot, which every other candidate's corridor meets."""
        W, H, k = fleet.route(row)
        span = self.spans.span_of(fleet, row, z, k + 1)
        if span is None or not span[2]:
            return False
        cls = self.classes[fleet.family[row]]
        mine = W[span[0]:span[1] + 1]
        tol = 0.6 * cls.delta
        rows, m = [], 0
        if len(self._lanes) > 100_000:  # stale keys: start over
            self._lanes.clear()
        for h in leaders:
            j = pos.get(h)
            if j is None:
                return False
            Wj, _, kj = fleet.route(j)
            sj = self.spans.span_of(fleet, j, z, kj + 1) or self.spans.span_of(fleet, j, z, kj)  # as :meth:`path_idx`
            if sj is None or sj[1] < sj[0]:
                return False
            key = (fleet.ids[row], span[0], span[1], h, sj[0], sj[1])  # both paths: routes only
            same = self._lanes.get(key)
            if same is None:
                theirs = Wj[sj[0]:sj[1] + 1]
                d = np.linalg.norm(mine[:, None, :] - theirs[None, :, :], axis=2).min(axis=1)
                same = self._lanes[key] = not d.max() > tol
            if not same:
                return False
            c = self.classes[fleet.family[j]]
            rows.append(j)
            m += int(np.ceil((0.5 * (c.length + cls.length) + c.hold + cls.hold) / cls.delta))
        x = span[1]
        idx = np.arange(x, min(x + m, len(W) - 1) + 1)
        half = cls.hold_half(H[idx], H[np.minimum(idx + 1, len(H) - 1)])
        lo, hi = W[idx] - half, W[idx] + half
        near = np.flatnonzero(np.all((fleet.claim_lo <= hi.max(axis=0)) & (fleet.claim_hi >= lo.min(axis=0)), axis=1))
        near = near[~np.isin(near, [row] + rows)]  # the queue's own claims do not count
        near = near[self.spans.passes([fleet.ids[j] for j in near.tolist()], np.full(len(near), z))]  # nor passers-by
        c_lo, c_hi = fleet.claim_lo[near], fleet.claim_hi[near]
        return not np.any(np.all((lo[:, None, :] <= c_hi[None]) & (hi[:, None, :] >= c_lo[None]), axis=2))

    def yields(self, fleet: JunctionFleet, row: int, z: int, waiters: np.ndarray) -> bool:
        """Row ``row`` lets the other waiters of zone ``z`` go first when its wide path beyond its stop
        point (:meth:`wide_path`: the claims it will make through the zone, padded) meets the box of
        one of them standing at its stop point, and that one's path does not meet ``row``'s (then
        that one goes first: a vehicle waiting at its entry line does not move until it has the
        token, and a holder whose next claims meet it would stand inside the guard for good --
        ``grid`` seed 2: bus 84 took C1's token to turn left beside bus 80 waiting at its entry line,
        and never moved again).  Vehicles on ``row``'s own route (its queue) do not count.

        Only when the waiters it would let go first lead, yielding in turn, to one that yields to
        nobody (who will take the token): where they only lead round a cycle (``grid`` seed 1 with
        path-frame plants: the four approaches of one zone, each the next one's target, waited for
        ever, 33 of 150 never arrived), nobody on it yields and the first in line takes the token."""
        waiters = np.array([int(j) for j in waiters], dtype=np.intp)
        if len(waiters) < 2:
            return False
        targets: dict[int, list[int]] = {}

        def of(r: int) -> list[int]:
            if r not in targets:
                targets[r] = self.targets(fleet, r, z, waiters[waiters != r])
            return targets[r]

        seen, todo = {row}, list(of(row))
        while todo:  # does a chain of targets from row end at a waiter that yields to nobody?
            j = todo.pop()
            if j in seen:
                continue
            seen.add(j)
            nxt = of(j)
            if not nxt:
                return True
            todo.extend(nxt)
        return False

    def targets(self, fleet: JunctionFleet, row: int, z: int, others: np.ndarray) -> list[int]:
        """The rows among ``others`` (not on ``row``'s route) that ``row`` would let go first
        (:meth:`yields`): its wide path beyond its stop point meets their standing box and theirs
        misses its own."""
        if not len(others):
            return []
        mine = self.standing(fleet, row)
        on = self.on_route(fleet, row, others)
        return [int(j) for j, q in zip(others.tolist(), on.tolist())
                if not q and self.beyond_meets(fleet, row, z, self.standing(fleet, j))
                and not self.beyond_meets(fleet, j, z, mine)]


def standing_boxes(classes: Mapping[str, AuthorityReach], fleet: JunctionFleet, rows: np.ndarray,
                   ahead: int) -> tuple[np.ndarray, np.ndarray]:
    """World boxes ``(lo, hi)`` (n, 2) of ``rows`` standing (padded :meth:`AuthorityReach.hold_box`)
    at their waypoints ``k + ahead`` (the route's last at most): ``0`` at their stop points, ``1``
    at the ones they ask for; ``classes``: the vehicle classes' extents (:class:`GatePaths`,
    :class:`tm.keep_out.KeepOut`)."""
    n = len(rows)
    if not n:
        return np.zeros((0, 2)), np.zeros((0, 2))
    table = fleet.stop_table(ahead)
    if table is not None:  # the whole fleet's, at once (JunctionFleet.stops)
        Wp, Ha, Hb, pad = (a[rows] for a in table)
    else:
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
        b_lo[m], b_hi[m] = classes[c].hold_box(pad[m], Ha[m], Hb[m])
    return Wp + b_lo, Wp + b_hi
