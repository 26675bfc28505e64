"""The liveness layer: junction zones, their tokens, corridors and exit slots.

The paper's traffic manager keeps vehicles apart but has no liveness rule: four
vehicles entering a junction together can each wait forever for another's hold
region.  :class:`JunctionGate` withholds requests (before the TM decides) so that
only a zone's token holders may ask for a switch into its guard, and blocks
admissions into a holder's corridor.  Safety is untouched: the TM still checks
every request.  Pure numpy, no simulator: the co-simulation loop
(:mod:`bridge.cosim`) hands it the fleet's current claim boxes, requests and routes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.tolerances import SWEEP_MARGIN
from tm.boxes import BoxGrid, GuardIndex, boxes_meet, corridor_hits, meets_any

__all__ = ["Zone", "ClassReach", "JunctionFleet", "JunctionGate"]


@dataclass(frozen=True)
class Zone:
    """A conflict zone (e.g. a junction) as an axis-aligned box ``lo <= p <= hi`` (m).

    Liveness rule (the paper's traffic manager has none): a vehicle may only
    *ask* for a switch whose new claim reaches the zone's guard region (the
    box enlarged by the largest claim radius of any class) while it holds one
    of the zone's tokens.  A vehicle's corridor is the union of boxes that hold
    every claim it can make from its current waypoint to its exit slot, the
    first waypoint where its hold region is clear of the guard.  Tokens are
    handed out in order of waiting to vehicles that have room for their
    largest claim at the exit slot and whose corridor misses every holder's
    corridor and every claim already in the guard; the first waiting vehicle
    whose corridor meets a holder's ends the round, so nobody overtakes it.  A
    token is released once the holder's claim has left the guard, and no
    vehicle is admitted into a holder's corridor.  Holders therefore never
    meet each other or a queue inside the guard: several cross at once when
    their paths are apart (opposite straight streams, right turns), and none
    stops inside the zone.  Safety is untouched: the traffic manager still
    checks every request.
    """

    name: str
    lo: tuple
    hi: tuple

    def __post_init__(self) -> None:
        lo, hi = np.asarray(self.lo, dtype=float), np.asarray(self.hi, dtype=float)
        if lo.shape != (2,) or hi.shape != (2,) or not np.all(np.isfinite(lo) & np.isfinite(hi)) \
                or np.any(lo > hi):
            raise ValueError(f"Zone {self.name!r}: lo and hi must be finite (x, y) pairs with lo <= hi, "
                             f"got lo={self.lo}, hi={self.hi}")


@dataclass(frozen=True, eq=False)
class ClassReach:
    """What the junction layer needs of a vehicle class: extents of its position sets.

    Parameters
    ----------
    hold : float
        ``max |P^0|`` (m): the hold region's radius without the footprint.
    big : ndarray, shape (2,)
        Per-axis ``max |P^{N-1}|`` (m): the largest claim a vehicle makes on its way.
    top : float
        ``max |P^N|`` (m): the largest set of the family.
    length, width : float
        Footprint (m).
    road_frame : bool
        Whether the position sets turn with the heading (else only the footprint turns).
    """

    hold: float
    big: np.ndarray
    top: float
    length: float
    width: float
    road_frame: bool

    @staticmethod
    def of(position_sets, length: float, width: float, road_frame: bool) -> ClassReach:
        """From a family's position sets ``P^0 .. P^N`` (vertex arrays, ``N >= 1``)."""
        if len(position_sets) < 2:
            raise ValueError(f"ClassReach.of: need the position sets P^0 .. P^N with N >= 1, "
                             f"got {len(position_sets)} set(s)")
        return ClassReach(hold=float(np.abs(position_sets[0]).max()),
                          big=np.abs(position_sets[len(position_sets) - 2]).max(axis=0),
                          top=float(np.abs(position_sets[-1]).max()),
                          length=float(length), width=float(width), road_frame=bool(road_frame))

    @property
    def hold_radius(self) -> float:
        """Radius of the hold region: ``max |P^0|`` plus the footprint's half diagonal."""
        return self.hold + 0.5 * float(np.hypot(self.length, self.width))

    def half_extent(self, heading: np.ndarray) -> np.ndarray:
        """Half extents (x, y) of the bounding box of the largest claim ``P^{N-1} ⊕ footprint``
        at each heading (shape (n, 2)): the position set turns with the heading in the road
        frame, only the footprint in the world frame."""
        P = self.big
        half = 0.5 * np.array([self.length, self.width])
        c, s = np.abs(np.cos(heading))[:, None], np.abs(np.sin(heading))[:, None]
        if self.road_frame:
            e = P + half
            return np.hstack([c * e[0] + s * e[1], s * e[0] + c * e[1]])
        return P + np.hstack([c * half[0] + s * half[1], s * half[0] + c * half[1]])


@dataclass(frozen=True, eq=False)
class JunctionFleet:
    """The fleet as the junction layer sees it, rows in the TM's fleet order.

    Parameters
    ----------
    ids : list of str
    family : ndarray of str, shape (n,)
        Class name of each row (a key of the gate's classes).
    claim_lo, claim_hi : ndarray, shape (n, 2)
        Bounding boxes of the current claims.
    parts : tuple of (list of ndarray, list of ndarray, ndarray)
        Routes in consecutive runs of rows (e.g. one per vehicle class): each part's
        waypoints ``(K, 2)``, the headings of the segments arriving at them ``(K,)``, and
        the current waypoint index of each of its rows.
    pads : callable or None
        ``pads(rows, idx)``: the one-sided padding ``(back, front, right, left)`` (m, shape
        (m, 4)) the claims of fleet row ``rows[i]`` add to its footprint at its route's waypoint
        ``idx[i]`` (``rows``, ``idx`` int arrays (m,); SUMO's bodies, :mod:`bridge.sumo_body`);
        None: no padding.
    claim_polygons : callable or None
        ``claim_polygons(rows)``: oriented boxes (M, 4, 2), counter-clockwise, and the position in
        ``rows`` (int array) of the row each is of (M,), non-decreasing: the union of a row's boxes holds
        every current claim of that row (:func:`tm.reach.claim_polygons_of`); None: only the world
        boxes ``claim_lo, claim_hi`` are known.
    stops : callable or None
        ``stops(ahead) -> (W (n, 2), H_in (n,), H_out (n,), pads (n, 4))``: every row's waypoint
        ``idx = min(k + ahead, K - 1)``, the headings at ``idx`` and ``min(idx + 1, K - 1)`` and the
        padding there, the very floats :meth:`route` and :meth:`pad_rows` give, for the whole fleet
        at once (:meth:`stop_table`); None: taken row by row.
    """

    ids: list
    family: np.ndarray
    claim_lo: np.ndarray
    claim_hi: np.ndarray
    parts: tuple
    pads: object = None
    claim_polygons: object = None
    stops: object = None

    def __post_init__(self) -> None:
        # each row's part and place in it, for :meth:`route` (asked for millions of times a run)
        at = []
        for W, H, k in self.parts:
            at.extend((W, H, k, i) for i in range(len(k)))
        object.__setattr__(self, "_at", at)
        object.__setattr__(self, "_stop_tables", {})  # ahead -> stop_table(ahead)

    def stop_table(self, ahead: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
        """:attr:`stops` ``(ahead)``, asked once per fleet and ``ahead``, its padding checked as
        :meth:`pad_rows` checks it; None without :attr:`stops`."""
        if self.stops is None:
            return None
        got = self._stop_tables.get(ahead)
        if got is None:
            W, H_in, H_out, p = self.stops(ahead)
            n = len(self.ids)
            p = np.asarray(p, dtype=float)
            if p.shape != (n, 4) or not np.all(np.isfinite(p) & (p >= 0)):
                raise ValueError(f"JunctionFleet.stops: need finite pads >= 0 of shape ({n}, 4), got shape {p.shape}")
            got = self._stop_tables[ahead] = (np.asarray(W, dtype=float).reshape(n, 2),
                                              np.asarray(H_in, dtype=float).reshape(n),
                                              np.asarray(H_out, dtype=float).reshape(n), p)
        return got

    def pad(self, row: int, idx: np.ndarray) -> np.ndarray:
        """The padding (m, 4) ``(back, front, right, left)`` of row ``row`` at waypoints ``idx``
        (zeros without :attr:`pads`)."""
        idx = np.asarray(idx, dtype=np.intp).reshape(-1)
        return self.pad_rows(np.full(len(idx), row, dtype=np.intp), idx)

    def pad_rows(self, rows: np.ndarray, idx: np.ndarray) -> np.ndarray:
        """The padding (m, 4) of rows ``rows[i]`` at their waypoints ``idx[i]`` (zeros without
        :attr:`pads`)."""
        rows = np.asarray(rows, dtype=np.intp).reshape(-1)
        idx = np.asarray(idx, dtype=np.intp).reshape(-1)
        if self.pads is None or not len(idx):
            return np.zeros((len(idx), 4))
        p = np.asarray(self.pads(rows, idx), dtype=float)
        if p.shape != (len(idx), 4) or not np.all(np.isfinite(p) & (p >= 0)):
            bad = sorted({self.ids[r] for r in rows.tolist()})
            raise ValueError(f"JunctionFleet.pads: vehicle(s) {bad}: need finite pads >= 0 of shape "
                             f"({len(idx)}, 4), got shape {p.shape}")
        return p

    def route(self, row: int) -> tuple[np.ndarray, np.ndarray, int]:
        """``(waypoints, headings, current waypoint index)`` of fleet row ``row``."""
        if 0 <= row < len(self._at):
            W, H, k, i = self._at[row]
            return W[i], H[i], int(k[i])
        p = row
        for W, H, k in self.parts:
            if p < len(k):
                return W[p], H[p], int(k[p])
            p -= len(k)
        raise IndexError(f"JunctionFleet.route: row {row} beyond the fleet's {len(self.ids)} rows")


class JunctionGate:
    """Tokens of the zones (see :class:`Zone`), their holders' corridors, and the queues.

    Parameters
    ----------
    zones : list of Zone
    classes : mapping of str to ClassReach
        Every class a fleet row may name.  The guard of each zone is the zone enlarged by
        the largest claim radius of any class (``max |P^N|`` plus half the footprint diagonal).
    through : mapping of str to collection of str, optional
        Vehicle id -> the names of the zones its route passes through (a SUMO route: the
        junctions its edges start and end at, :meth:`bridge.waypoints.NetGeometry.route_junctions`).
        A zone its route does not pass through is none of its business here: it never waits for
        that zone's token, and its claims in that zone's guard do not hold the zone's candidates
        back (the traffic manager still checks them against everyone's).  A vehicle left out (and
        every vehicle when None) belongs to every zone whose guard it reaches, as before.  Without
        it the guard, a box around the junction, catches roads that only pass by: on SUMO's
        ``A10KW`` the two on-ramp merges ``21432413`` and ``32500343`` lie beside the opposite
        carriageway, whose vehicles waited for their tokens and held them (README, Known limits).
    """

    #: Whether a waiter may take a token past one that a holder blocks (earlier in the order) when
    #: its corridor misses that one's: it cannot delay it then.  Off: the first blocked waiter ends
    #: the round.
    pass_blocked = False
    #: Whether a vehicle that wants several zones' tokens in one round keeps them only if it gets every
    #: one (:class:`tm.authority_gate.AuthorityGate`): then one that a claim in its corridor holds
    #: back in one zone takes no token in another either (it would give it back at once, and might
    #: have taken it from a waiter that could have used it, every round).
    all_or_none = False

    def __init__(self, zones, classes: dict, through: dict | None = None):
        self.zones = list(zones)
        self.classes = dict(classes)
        names: dict[str, list[int]] = {}
        for z, zone in enumerate(self.zones):
            names.setdefault(zone.name, []).append(z)
        #: vehicle id -> the zone indices its route passes through (absent: every zone, see ``through``)
        self.through: dict[str, frozenset[int]] = {
            vid: frozenset(z for name in zs for z in names.get(name, ())) for vid, zs in (through or {}).items()}
        radius = self.guard_radius(self.classes.values())
        self.lo = np.array([z.lo for z in self.zones], dtype=float).reshape(-1, 2) - radius
        self.hi = np.array([z.hi for z in self.zones], dtype=float).reshape(-1, 2) + radius
        self.guards = GuardIndex(self.lo, self.hi)
        #: per zone: holder id -> (its route key, its corridor boxes lo, hi) through the guard;
        #: tokens go to several vehicles at once only while their corridors are disjoint
        self.holders: list[dict[str, tuple]] = [{} for _ in self.zones]
        #: (zone, vehicle) -> the step since which it waits for the zone's token
        self.wait: dict[tuple[int, str], int] = {}
        self._meet: dict = {}  # (route key, route key) -> whether the two corridors meet
        self._routes: dict = {}  # (vehicle, zone, waypoint) -> (key, exit slot box or None, corridor lo, hi)
        #: vehicle -> zones whose token it gave back (:meth:`give_back`): it must ask for it again
        self.given_back: dict[str, set[int]] = {}
        #: vehicles standing at a red light this step (:meth:`give_back`)
        self.standing: set[str] = set()
        #: over the run: tokens handed out, given back at red lights, and requests withheld for want of one
        self.tokens_granted = 0
        self.tokens_given_back = 0
        self.requests_withheld = 0
        #: this step's withheld requesters -> the holders of the tokens they wait for (none: something
        #: else held the hand-out back, e.g. a claim in the corridor or no room at the exit slot;
        #: :mod:`analysis.waits`)
        self.waiting_on: dict[str, list[str]] = {}

    @staticmethod
    def guard_radius(classes) -> float:
        """How far the guard reaches beyond the zone (m): the largest claim radius of any class
        (``max |P^N|`` plus half the footprint diagonal; centred claims reach backwards too)."""
        return max((c.top + 0.5 * np.hypot(c.length, c.width) for c in classes), default=0.0)

    def passes(self, ids, zs: np.ndarray) -> np.ndarray:
        """Whether vehicle ``ids[i]``'s route passes through zone ``zs[i]`` (bool (n,); see ``through``:
        a vehicle left out passes through every zone)."""
        through = self.through
        zs = np.asarray(zs, dtype=np.intp).reshape(-1)
        if not through:
            return np.ones(len(zs), dtype=bool)
        return np.array([vid not in through or z in through[vid] for vid, z in zip(ids, zs.tolist())],
                        dtype=bool).reshape(-1)

    def give_back(self, ids) -> None:
        """The vehicles ``ids`` stand at a red light this step (replaces the last call's set):
        they give their tokens back.

        A holder that cannot move would otherwise keep every vehicle whose corridor meets its
        own out of the zone, for as long as it stands (a red light: the whole green phase of the
        crossing streams).  Its requests into the zone's guard then need the token again, even
        with its current claim already in the guard.  A standing vehicle's claim in the guard
        blocks a token only for a vehicle whose route runs into it (a waypoint of its corridor
        inside that claim's box: the queue behind it), not for one whose corridor box merely
        brushes it (the next lane, whose light is green)."""
        self.standing = set(ids)
        for vid in ids:
            for z, hs in enumerate(self.holders):
                if vid in hs:
                    del hs[vid]
                    self.given_back.setdefault(vid, set()).add(z)
                    self.tokens_given_back += 1

    # ------------------------------------------------------------------ requests
    def withhold(self, t: int, fleet: JunctionFleet, requesting: np.ndarray, new_lo: np.ndarray,
                 new_hi: np.ndarray) -> np.ndarray:
        """Release tokens, hand out new ones, and say which requests may be made.

        Parameters
        ----------
        t : int
            The step (orders the waiting).
        fleet : JunctionFleet
        requesting : ndarray of bool, shape (n,)
            Which rows ask for a switch.
        new_lo, new_hi : ndarray, shape (number of requests, 2)
            Bounding boxes of the claims the requests would make, in row order.

        Returns
        -------
        ndarray of bool, shape (n,)
            The requests that stay: every request but those whose new claim reaches a
            guard its current claim is not in, without that zone's token.
        """
        return self._withhold(t, fleet, self._rows_by_id(fleet), requesting, new_lo, new_hi)

    @staticmethod
    def _rows_by_id(fleet: JunctionFleet) -> dict[str, int]:
        """Vehicle id -> its row in ``fleet`` (the last row, should an id repeat)."""
        return dict(zip(fleet.ids, range(len(fleet.ids))))

    def _withhold(self, t: int, fleet: JunctionFleet, pos: dict[str, int], requesting: np.ndarray,
                  new_lo: np.ndarray, new_hi: np.ndarray) -> np.ndarray:
        """:meth:`withhold` with ``pos`` (:meth:`_rows_by_id` of ``fleet``) built by the caller, who
        may use it for its own work in the same step (:meth:`tm.authority_gate.AuthorityGate.withhold`)."""
        self._release(fleet, pos)
        req = np.array(requesting, dtype=bool)
        r = np.flatnonzero(req)
        self.waiting_on = {}
        if not len(r):
            return req
        wz, wrow = self._wanting(fleet, r, new_lo, new_hi)
        allowed = self._hand_out(t, fleet, pos, wz, wrow)
        req[wrow[~allowed]] = False   # only a zone's holders may ask into its guard
        self.requests_withheld += len(np.unique(wrow[~allowed]))
        for z, row in zip(wz[~allowed].tolist(), wrow[~allowed].tolist()):
            vid = fleet.ids[row]
            self.waiting_on.setdefault(vid, []).extend(h for h in self.holders[z] if h != vid)
        wait = self.wait
        for key in [k for k in wait if k[1] not in pos or k[1] in self.holders[k[0]]]:
            wait.pop(key, None)
        for vid in [v for v, zs in self.given_back.items() if v not in pos or not zs]:
            del self.given_back[vid]
        return req

    def _wanting(self, fleet: JunctionFleet, r: np.ndarray, new_lo: np.ndarray,
                 new_hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(zone, row)`` pairs of requesters ``r`` that need the zone's token unless they hold it,
        grouped by zone, rows ascending: the new claim reaches a guard the current claim is not
        in, or a guard whose token the vehicle gave back (:meth:`give_back`)."""
        cur_lo, cur_hi, ids = fleet.claim_lo, fleet.claim_hi, fleet.ids
        # (requester, zone) pairs whose new claim reaches a guard its current claim is not in
        ni, nz = self.guards.pairs(new_lo, new_hi)
        ci, cz = self.guards.pairs(cur_lo[r], cur_hi[r])
        Z = len(self.zones)
        fresh = ~np.isin(ni * Z + nz, ci * Z + cz) & self.passes([ids[i] for i in r[ni].tolist()], nz)
        if self.given_back:  # a token given back is needed again, from inside the guard too
            again = np.array([z in self.given_back.get(ids[i], ()) for i, z in zip(r[ni].tolist(), nz.tolist())],
                             dtype=bool).reshape(-1)
            fresh |= again
        want = np.sort(nz[fresh] * len(r) + ni[fresh])             # grouped by zone, rows ascending
        wz, wrow = want // len(r), r[want % len(r)]
        return wz, wrow

    def _hand_out(self, t: int, fleet: JunctionFleet, pos: dict, wz: np.ndarray,
                  wrow: np.ndarray) -> np.ndarray:
        """Hand out tokens to the pairs ``(wz, wrow)`` (from :meth:`_wanting`) that wait for one;
        returns which pairs may ask (holders, and the vehicles given a token now)."""
        cur_lo, cur_hi, ids = fleet.claim_lo, fleet.claim_hi, fleet.ids
        n = len(ids)
        if len(self._routes) > 100_000:  # stale (vehicle, waypoint) keys: start over
            self._routes.clear()
        wait = self.wait
        holder_keys = np.array(sorted(z * n + pos[h] for z, hs in enumerate(self.holders) for h in hs),
                               dtype=np.intp)
        is_holder = np.isin(wz * n + wrow, holder_keys)
        allowed = is_holder.copy()
        P = np.flatnonzero(~is_holder)  # (zone, candidate) pairs that need a token
        if len(P):
            routes = [self.route_through(fleet, i, z) for z, i in zip(wz[P].tolist(), wrow[P].tolist())]
            c_len = np.array([len(rt[2]) for rt in routes])
            c_lo = np.vstack([rt[2] for rt in routes])
            c_hi = np.vstack([rt[3] for rt in routes])
            cell = max(float((cur_hi - cur_lo).max()), float((c_hi - c_lo).max())) + SWEEP_MARGIN
            claims_grid = BoxGrid(cur_lo, cur_hi, cell)
            # room for the largest claim at the exit slot (the corridor's last box): no other
            # vehicle's current claim there
            has_slot = np.array([rt[1] is not None for rt in routes])
            blocked_exit = np.zeros(len(P), dtype=bool)
            if has_slot.any():
                qs = np.flatnonzero(has_slot)
                s_lo = np.array([routes[q][1][0] for q in qs])
                s_hi = np.array([routes[q][1][1] for q in qs])
                qi, bj = claims_grid.pairs(s_lo, s_hi)
                # (nor a vehicle whose route does not pass through the zone: it never drives onto its
                # exit road, and its claim's box is there only beside it: ``through``)
                other = (bj != wrow[P[qs[qi]]]) & self.passes([ids[j] for j in bj.tolist()], wz[P[qs[qi]]])
                other[other] = self._slot_taken(fleet, [routes[q][0] for q in qs[qi[other]].tolist()], bj[other])
                blocked_exit[qs[qi[other]]] = True
            first = np.r_[0, np.cumsum(c_len)]
            zP = wz[P]
            # claims already in the guard that are not a holder's ("intruders"), by zone
            gi_, gz_ = self.guards.pairs(cur_lo, cur_hi)
            # (a vehicle whose route does not pass through the zone is none of its business: ``through``)
            keep = ~np.isin(gz_ * n + gi_, holder_keys) & self.passes([ids[i] for i in gi_.tolist()], gz_)
            stand = np.array([ids[i] in self.standing for i in gi_.tolist()], dtype=bool).reshape(-1)
            o = np.argsort(gz_[keep & ~stand], kind="stable")
            blocked_intr = self._intruder_hits(fleet, [rt[0] for rt in routes], zP, wrow[P], first, c_lo, c_hi,
                                               gz_[keep & ~stand][o], gi_[keep & ~stand][o])
            if (keep & stand).any():  # standing at a red: only routes running into its claim
                o = np.argsort(gz_[keep & stand], kind="stable")
                blocked_intr |= self._standing_hits(fleet, zP, wrow[P], first, c_lo, c_hi,
                                                    gz_[keep & stand][o], gi_[keep & stand][o])
            # In order of waiting, per zone: a candidate with room beyond the zone (do not block
            # the box: a holder stuck in a queue inside the guard would stall everyone) gets a
            # token if its corridor misses every holder's, so holders never meet inside the
            # guard, and misses the claims already in the guard.  The first candidate whose
            # corridor meets a holder's ends the round (nobody overtakes it into the zone, so it
            # is served once those holders have left).
            cid = [ids[i] for i in wrow[P].tolist()]
            stuck = np.isin(wrow[P], wrow[P][blocked_intr])
            since = np.array([wait.setdefault((z, v), t) for z, v in zip(zP.tolist(), cid)])
            # candidates by zone, then by waiting, then by id; those without room at the exit slot
            # are skipped (unless they follow holders on their path: :meth:`_follows`)
            order = np.lexsort((np.array(cid, dtype=object).astype(str), since, zP))
            z_prev, blocked = -1, []  # corridors of the waiters that a holder blocks, this round
            for q in order.tolist():
                z = int(zP[q])
                if z != z_prev:
                    z_prev, blocked, holders = z, [], self.holders[z]
                key_q, _, lo_q, hi_q = routes[q]
                row_q = int(wrow[P[q]])
                if blocked and not (self.pass_blocked and
                                    not any(self.corridors_meet(key_q, lo_q, hi_q, *b) for b in blocked)):
                    continue
                # a claim it cannot pass stands in its corridor (through this zone, or through another
                # it wants this round and must have too: ``all_or_none``): it waits for that one to
                # move, not for the holders, and holds nobody back
                if blocked_intr[q] or (self.all_or_none and stuck[q]):
                    continue
                meet = [h for h, c in holders.items() if self.corridors_meet(key_q, lo_q, hi_q, *c)
                        and not self._passable(fleet, pos, t, h, row_q, z)]
                follows = (blocked_exit[q] or meet) and self._follows(fleet, pos, row_q, z, meet)
                if blocked_exit[q] and not follows:
                    continue
                if meet and not follows and not self._after(fleet, pos, row_q, z, meet):
                    if not all(self._stalled(t, h) for h in meet):  # else it holds nobody back
                        blocked.append((key_q, lo_q, hi_q))
                    continue
                # (not to a waiter that cannot pass a claim in its corridor, through this zone or one
                # chained to it: it takes no token meanwhile)
                if self._yields(fleet, row_q, z, wrow[P[(zP == z) & ~stuck]]):
                    continue
                holders[cid[q]] = (key_q, lo_q, hi_q)
                allowed[P[q]] = True
                self.tokens_granted += 1
                if cid[q] in self.given_back:
                    self.given_back[cid[q]].discard(z)
        return allowed

    def _intruder_hits(self, fleet: JunctionFleet, keys: list, zq: np.ndarray, rq: np.ndarray, first: np.ndarray,
                       c_lo: np.ndarray, c_hi: np.ndarray, zs: np.ndarray, rs: np.ndarray) -> np.ndarray:
        """Which candidates (zone ``zq``, row ``rq``, route key ``keys[q]``, corridor boxes
        ``c_lo[first[q]:first[q+1]]``) have a claim in their corridor that is already in the guard
        and no holder's (rows ``rs`` of zones ``zs``, sorted by zone; :meth:`_hand_out`): here, any
        claim whose world box meets a corridor box."""
        return corridor_hits(zq, rq, first, c_lo, c_hi, zs, rs, fleet.claim_lo, fleet.claim_hi)

    def _slot_taken(self, fleet: JunctionFleet, keys: list, rows: np.ndarray) -> np.ndarray:
        """Whether each candidate's exit slot (its route key, :meth:`route_through`), whose box meets
        the world box of row ``rows[i]``'s current claims, is taken by them: here, always."""
        return np.ones(len(rows), dtype=bool)

    def _standing_hits(self, fleet: JunctionFleet, zq: np.ndarray, rq: np.ndarray, first: np.ndarray,
                       c_lo: np.ndarray, c_hi: np.ndarray, zs: np.ndarray, rs: np.ndarray) -> np.ndarray:
        """Which candidates (zone ``zq``, row ``rq``, corridor boxes ``c_lo[first[q]:first[q+1]]``)
        cannot pass the vehicles standing at a red light in the guard (zone ``zs``, row ``rs``, sorted
        by zone): a waypoint of the corridor lies inside one's current claim box (its queue runs into
        it); a corridor that merely brushes it (the next lane, whose light is green) is let through."""
        mid = 0.5 * (c_lo + c_hi)  # the corridor's waypoints
        return corridor_hits(zq, rq, first, mid, mid, zs, rs, fleet.claim_lo, fleet.claim_hi)

    def _passable(self, fleet: JunctionFleet, pos: dict, t: int, holder: str, row: int, z: int) -> bool:
        """Whether candidate row ``row``, whose corridor through zone ``z`` meets holder ``holder``'s,
        may take the token beside it all the same (never, here: it waits for the holder)."""
        return False

    def _stalled(self, t: int, holder: str) -> bool:
        """Whether holder ``holder`` counts as stalled at step ``t`` (never, here).  A waiter whose
        corridor meets only stalled holders' waits for them without holding later waiters back
        (:meth:`_hand_out`): it cannot go before they do, and one of those may be what they wait for."""
        return False

    def _yields(self, fleet: JunctionFleet, row: int, z: int, waiters: np.ndarray) -> bool:
        """Whether row ``row``, next in line for zone ``z``'s token, lets the other ``waiters`` of
        ``z`` (rows) go first this round (never, here)."""
        return False

    def _after(self, fleet: JunctionFleet, pos: dict, row: int, z: int, holders: list) -> bool:
        """Whether row ``row`` may take zone ``z``'s token although its corridor meets the corridors
        of the holders ``holders``, to go after them (never, here: it waits for them to release it)."""
        return False

    def _follows(self, fleet: JunctionFleet, pos: dict, row: int, z: int, leaders: list) -> bool:
        """Whether row ``row`` may take zone ``z``'s token although its corridor meets the corridors
        of the holders ``leaders`` or its exit slot has no room (never, here: a candidate whose
        corridor meets a holder's waits for it)."""
        return False

    def _release(self, fleet: JunctionFleet, pos: dict) -> None:
        """Release tokens whose holder's current claim has left the guard (or who is gone)."""
        cur_lo, cur_hi = fleet.claim_lo, fleet.claim_hi
        held = [(z, pos.get(h, -1), h) for z, hs in enumerate(self.holders) for h in hs]
        if held:
            hz = np.array([z for z, _, _ in held], dtype=np.intp)
            hi_ = np.array([i for _, i, _ in held], dtype=np.intp)
            gone = hi_ < 0
            inside = np.all(cur_lo[hi_] <= self.hi[hz], axis=1) & np.all(cur_hi[hi_] >= self.lo[hz], axis=1)
            for n in np.flatnonzero(gone | ~inside).tolist():
                del self.holders[held[n][0]][held[n][2]]

    # ------------------------------------------------------------------ corridors
    def route_through(self, fleet: JunctionFleet, row: int, z: int):
        """``(key, slot, lo, hi)``: the exit slot and corridor of fleet row ``row`` through zone
        ``z``'s guard, and their cache key ``(vehicle id, z, current waypoint)``.

        Cached per (vehicle, zone, current waypoint): they depend on the route only.  The
        exit slot is the box that must be free beyond the guard (see below), or
        None when the route ends inside the guard or does not cross it.  The corridor is the
        union of boxes ``(lo[i], hi[i])`` that hold every claim the vehicle can make from its
        current waypoint up to the slot (each waypoint's box of ``P^{N-1}`` plus the
        footprint at the waypoint's heading; claims are ``P^{l-1}``, ``l <= N``, nested).

        The slot waypoint is the first one whose hold-region box (the class's largest ``P^0``
        extent plus its footprint's half diagonal) misses the guard: a holder at rest there
        has left the guard and releases the token.  The slot box is the corridor's last box:
        room for the largest claim the holder may need around that waypoint on its way there.
        (Room for the hold region alone is not enough: the symmetric sets claim as much road
        ahead of the waypoint as behind it, so a holder got stuck one waypoint short of the
        slot, its claim still in the guard, behind a queue that waited for the next junction;
        on ``grid``, 600 s, seed 1 that gridlocked the network with 46 of 150 vehicles
        arrived, against 90 with this box and one token per junction.)
        """
        W, H, k = fleet.route(row)
        key = (fleet.ids[row], z, k)
        found = self._routes.get(key)
        if found is not None:
            return found
        cls = self.classes[fleet.family[row]]
        r0 = cls.hold_radius
        lo_z, hi_z = self.lo[z], self.hi[z]
        Wk = W[k + 1:]
        inside = (Wk[:, 0] - r0 <= hi_z[0]) & (Wk[:, 0] + r0 >= lo_z[0]) & \
            (Wk[:, 1] - r0 <= hi_z[1]) & (Wk[:, 1] + r0 >= lo_z[1])
        last, exits = min(k + 1, len(W) - 1), False
        if inside.any():  # else the route does not cross the guard beyond here
            first_in = int(np.argmax(inside))
            out = np.nonzero(~inside[first_in:])[0]
            exits = len(out) > 0  # else the route ends inside the guard: it arrives there
            last = k + 1 + first_in + int(out[0]) if exits else len(W) - 1
        idx = np.arange(k, last + 1)
        r1 = cls.half_extent(H[idx])
        corr_lo, corr_hi = W[idx] - r1, W[idx] + r1
        slot = (corr_lo[-1], corr_hi[-1]) if exits else None
        self._routes[key] = found = (key, slot, corr_lo, corr_hi)
        return found

    def corridors_meet(self, key_a, lo_a, hi_a, key_b, lo_b, hi_b) -> bool:
        """Whether two corridors meet (cached per pair of route keys: they are fixed)."""
        pair = (key_a, key_b)
        hit = self._meet.get(pair)
        if hit is None:
            if len(self._meet) > 200_000:  # stale keys: start over
                self._meet.clear()
            hit = self._meet[pair] = boxes_meet(lo_a, hi_a, lo_b, hi_b)
        return hit

    # ------------------------------------------------------------------ admissions
    def admissible(self, ok: np.ndarray, family: np.ndarray, centre: np.ndarray,
                   heading: np.ndarray, boxes: tuple | None = None) -> np.ndarray:
        """``ok`` without the new vehicles whose largest claim (``P^{N-1}`` plus the footprint)
        at their first waypoint ``centre`` would meet a token holder's corridor.

        ``family``, ``centre``, ``heading``: class name, first waypoint and first heading of
        each candidate (rows of ``ok``); ``boxes``: ``(lo, hi)`` (rows, 2) more boxes each candidate
        covers (its claims when it starts moving; inverted: none)."""
        ok = np.asarray(ok, dtype=bool)
        held = [c for hs in self.holders for c in hs.values()]
        if not held or not ok.any():
            return ok
        h_lo = np.vstack([c[1] for c in held])
        h_hi = np.vstack([c[2] for c in held])
        q = np.flatnonzero(ok)
        r = np.vstack([self.classes[family[i]].half_extent(heading[i:i + 1]) for i in q.tolist()])
        lo, hi = centre[q] - r, centre[q] + r
        if boxes is not None:
            lo, hi = np.minimum(lo, boxes[0][q]), np.maximum(hi, boxes[1][q])
        meet = meets_any(lo, hi, h_lo, h_hi)
        ok = ok.copy()
        ok[q[meet]] = False
        return ok
