"""The junction liveness layer for movement-authority vehicles (design.md §7, "Liveness with the
new claims").

In ``--controller authority`` mode a vehicle's current waypoint ``c`` is its stop point (its
movement authority) and its claims ``S_k`` are reach-tightened: they run from where the vehicle is
to a little past ``c`` and no longer reach backwards as the paper's centred sets do.  The tokens,
waiting order, corridors and exit-slot room of :class:`tm.junctions.JunctionGate` stay; what
changes is where they apply:

* **guard**: the zone enlarged by the claims' across half-width (``max |y|`` over the across
  factor's levels) plus half the footprint's diagonal, per class (:attr:`AuthorityReach.guard_reach`);
  the gate's shared guard boxes, :meth:`AuthorityGate.guard_radius`, take the largest over the
  fleet's classes, and every rule below is on them, for every class;
* **entry line**: without the zone's token a vehicle may not move its stop point to a waypoint
  whose hold box ``T^0 ⊕ footprint`` meets the shared guard -- its stop point stays behind the
  guard's edge less the ``T^0`` extent and ``L/2`` (:meth:`AuthorityGate.intervals`).  The shared
  guard, not the class's own: a holder's claims reach up to its own class's guard, so a car that
  stopped at its own (smaller) guard's line could stand inside a truck holder's claim -- the truck
  waited for the car to move and the car for the truck's token (issue 12, ``grid`` seed 1: truck
  29 / car 12, bus 111 / car 139);
* **exit slot**: the first waypoint after the entry whose hold box misses the guard again.  With
  the token the stop point may move up to it (and on, outside the guard, without one); the token
  is handed out only with room there for the stopped vehicle: no other vehicle's claim on the
  slot's hold box.  Where the slot's world box meets another vehicle's claims, their oriented boxes decide
  (:meth:`AuthorityGate._slot_taken`, :attr:`JunctionFleet.claim_polygons`): on a road not along an
  axis the world boxes of opposite lanes overlap;
* **room for the claims' width** (:class:`tm.keep_out.KeepOut`):
  the exit slot's hold box is narrower than the claims a holder makes on its way there (the
  claims' across half-width plus ``W/2`` and the body padding across, ``T^0 + L/2`` past the slot
  along), and the opposite approach's first waiter stands at its entry line right beside the exit
  slot: a bus holder's claims up its exit road met that car's standing box, the traffic manager
  denied them, and the car waited for the bus's token (issue 12, ``grid`` seed 1: bus 85 / car 71
  at A0, bus 93 / car 79 at B2).  So while the token is held nobody without it moves its stop
  point so that its standing box enters the holder's remaining wide path (a vehicle already
  standing there at the hand-out is not covered).  A vehicle of the holder's own queue (on its
  lanes), even one that holds the token too (it follows the holder through, :meth:`_follows`),
  may close up to the holder's current box, not into the boxes of its path ahead: at a turn's
  start those swing back over the arm the queue stands on (a long vehicle's body padding, SUMO's
  bent body in the turn's frame: bus 111 at D0, ``grid`` seed 1, right pad 5.6 m; car 124, given
  the token behind it, closed up to 3.5 m and the bus's next claims met its standing box, for
  good: 9 of 150 never arrived; with this rule all 150 arrive).
  Kept in the gate rather than moving every entry line back by
  the largest such reach (about ``L + 2 T^0 + pad + δ``, 16 m for a bus): only the approaches
  beside a holder's exit road wait, and only while it holds the token;
* **yield at the hand-out** (:meth:`AuthorityGate._yields`): the next in line lets the zone's
  other waiters go first when its wide path beyond its stop point meets one of them standing at
  its stop point and that one's path misses its own: that one does not move until it has the
  token, and the candidate's claims through the zone would meet it (``grid`` seed 2: bus 84 took
  C1's token to turn left beside bus 80 at its entry line and never moved again);
* **standing at a red** (:meth:`AuthorityGate._standing_hits`): a vehicle standing at a red light
  in the guard (:meth:`JunctionGate.give_back`) holds back a candidate whose corridor beyond its stop
  point (oriented boxes, padded) meets its hold box, not only one whose waypoints run into its claim:
  with the token it would stand in the zone until the light turns green (SUMO's ``fkk_in``, whose
  lights change only by hand: for good), and such a waiter is no one's reason to yield
  (:meth:`_yields`): it takes no token meanwhile, through this zone or one chained to it;
* **intruders** (:meth:`AuthorityGate._intruder_hits`): a claim in the guard that is no holder's holds
  a candidate back only where it meets the candidate's corridor ahead of its stop point (not the box
  at it, which reaches over the car queued behind), as padded oriented boxes where the world boxes
  meet (lanes side by side on a road not along an axis);
* **stalled holders** (:meth:`AuthorityGate._passable`): a holder whose stop point has not moved
  for :attr:`~AuthorityGate.stall_steps` steps holds back a candidate only where the candidate's
  corridor meets its standing box, not its whole corridor, and a waiter held back by stalled
  holders alone no longer holds later waiters back: one of them may be what the holders wait for;
* **corridor**: what the vehicle can hold while its stop point moves from where it is to the
  exit slot: boxes around those waypoints, ``δ/2 + T^0`` along plus ``L/2`` (a position lies
  within ``δ/2`` of a waypoint), ``T^0`` plus ``W/2`` across.  Across, this is the hold region,
  not the moving claims' half-width: two holders' moving claims are time-indexed and the traffic
  manager lets one pass the other (opposite or parallel lanes); what can block a holder for ever
  is another one stopped in its path.  (With the moving claims' width, ``max |y|`` of every level
  plus ``W/2``, adjacent lanes' corridors meet: on ``grid``, 300 s, seeds 1 / 2: 88 / 77 of 150
  arrived, against 104 / 97 with this width.)  Two corridors meet when their world boxes do and,
  for through movements, their oriented boxes too, padded by SUMO's body reach
  (:meth:`AuthorityGate.corridors_meet`): on a road not along an axis the world boxes of lanes side
  by side overlap;
* **chained zones** (:meth:`AuthorityGate._wanting`, :meth:`AuthorityGate._hand_out`): where a
  route enters the next zone's guard at or before the exit slot of the one it enters now, it
  cannot stop between them outside both; it asks for both tokens at once and gets both or
  neither, and one that a claim in its corridor holds back in one of them takes no token in the
  other that round (:attr:`JunctionGate.all_or_none`: it took one and gave it back every round, and
  the next in line for both lost that one to it and gave back the other).  Waiting for the second
  at its entry line while holding the first, two vehicles crossing such a pair in opposite
  directions each held one token and waited for the other's, for good (SUMO's ``fkk_in``:
  ``3_right.0`` and ``1_right.0`` at ``276184048`` and ``gneJ21``, 5 m between the guards);
* **release** (:meth:`AuthorityGate._release`): once the holder's stop point has reached the exit
  slot of the interval the token was handed out for, when every ``S_k`` (the bounding box of their
  union) has left the shared guard -- the guard of the entry line: a class's own, smaller one
  released a car's token at the step it was handed out (its claim, from where it is to its stop
  point at the entry line, not yet in the car's guard), and the car drove through the zone without
  one;
* **corridors cut behind the holder** (:meth:`AuthorityGate._trim`): each step a holder's corridor
  loses the boxes before the first one its current claim meets, so a crossing stream may take the
  token once the holder is past the conflict, not only once it has left the guard;
* **ordered entry** (:meth:`AuthorityGate._after`): a candidate whose corridor meets holders'
  takes the token after them when its standing box misses every holder's wide path from that
  one's stop point on; then it keeps out of those paths (:class:`tm.keep_out.KeepOut`, which
  exempts the zone's other holders but not the ones a vehicle came after) until each holder lets
  the token go.  It comes up to the conflict while the holders cross it instead of waiting at the
  entry line, and the next one behind it follows.  Every vehicle stands clear of the paths of
  the holders before it, so the first holder never finds a later one standing in its path.  Not for a
  vehicle that wants several zones this round or holds another zone's token: on SUMO's
  ``fkk_in`` (junctions 3-5 m apart) one took ``gneJ21``'s token after ``1_left.0`` with
  ``gneJ220``'s, and ``1_left.0`` waited for it to pass ``gneJ220``: 8 of 114 arrived in 180 s
  (24 before the rule, 32 with it and this exception).  A holder whose route ends in the guard
  has no path to keep out of: a candidate waits for it;
* **queues** (:meth:`AuthorityGate._follows`): a vehicle on the same lanes behind a holder takes a
  token too when the exit road has room for all of them; and a later waiter passes one that a
  holder blocks when its corridor misses that one's (``pass_blocked``: it cannot delay it).

Pure numpy, no simulator; safety stays with the traffic manager, which checks every request.
"""

from __future__ import annotations

import numpy as np

from tm.authority_reach import AuthorityReach
from tm.boxes import boxes_meet, corridor_hits, polygon_sets_meet, polygons_meet, ranges
from tm.gate_boxes import GateBoxes
from tm.gate_paths import GatePaths
from tm.guard_spans import GuardSpans
from tm.junctions import JunctionFleet, JunctionGate
from tm.keep_out import KeepOut
from tm.stalls import StallClock

__all__ = ["AuthorityReach", "AuthorityGate"]  # AuthorityReach: re-exported from tm.authority_reach


def corridors_ahead(first: np.ndarray, c_lo: np.ndarray, c_hi: np.ndarray):
    """The corridors ``c_lo[first[q]:first[q+1]]`` (and ``c_hi``) without the box at each one's
    current waypoint where more follow (:meth:`AuthorityGate._intruder_hits`): ``(first2, lo2, hi2)``."""
    n = np.diff(first)
    keep = np.ones(len(c_lo), dtype=bool)
    keep[first[:-1][n > 1]] = False
    return np.r_[0, np.cumsum(n - (n > 1))], c_lo[keep], c_hi[keep]


class AuthorityGate(JunctionGate):
    """:class:`tm.junctions.JunctionGate` with the movement-authority rules (module notes).

    Parameters
    ----------
    zones : list of Zone
    classes : mapping of str to AuthorityReach
        Every class a fleet row may name.
    through : mapping of str to collection of str, optional
        Vehicle id -> the names of the zones its route passes through (:class:`tm.junctions.JunctionGate`):
        only their guards give its route intervals (:meth:`intervals`, :meth:`entry_limit`).

    The fleet's ``claim_lo``, ``claim_hi`` are the world bounding boxes of every vehicle's
    ``∪_k S_k`` (:func:`tm.reach.world_aabb`); :meth:`withhold` ignores the new claims' boxes
    (the rules are on the stop points).
    """

    pass_blocked = True
    all_or_none = True
    #: Judge the intruders of a candidate's corridor on the corridor ahead of it, as oriented boxes
    #: where world boxes meet (:meth:`_intruder_hits`); off: every corridor box, as world boxes.
    oriented_intruders = True
    #: cut the holders' corridors behind them each step (:meth:`_trim`)
    trim_corridors = True
    #: steps a holder's stop point must stay put before a candidate whose corridor meets its corridor
    #: but not its standing box may take the token beside it (:meth:`_passable`; 10 s at 0.1 s
    #: steps); None: never
    stall_steps: int | None = 100
    #: Chained zones asked for together, all or none (module notes); off: one zone at a time.
    chain = True
    #: A candidate whose corridor meets holders' takes the token after them, kept out of every holder's
    #: wide path until that one lets the token go (:meth:`_after`); off: it waits for them to let it go.
    ordered_entry = True
    #: Corridors whose headings spread over at most this many degrees (through movements) are compared
    #: as oriented boxes where their world boxes meet (:meth:`corridors_meet`); a turning one keeps its
    #: world boxes, whose slack at the turn stands in for the body's swing (with oriented boxes on turns
    #: too, ``grid`` seed 5 locked with 27 of 150 in the network).
    oriented_turn_max_deg: float = 15.0

    def __init__(self, zones, classes: dict, through: dict | None = None):
        super().__init__(zones, classes, through)
        #: every vehicle's route intervals through the guards (cached per vehicle)
        self.spans = GuardSpans(self.guards, self.classes, self.passes)
        #: their wide paths through the zones and standing boxes (cached)
        self.paths = GatePaths(self.classes, self.spans)
        #: the oriented boxes of the routes' corridors and exit slots (:meth:`route_through`,
        #: :meth:`corridors_meet`, :meth:`_slot_taken`, :meth:`_intruder_hits`)
        self.boxes = GateBoxes(self.classes)
        #: over the run: requests withheld because their stop point would stand in a holder's path
        #: (:meth:`_keep_out`)
        self.wide_withheld = 0
        #: over the run: token hand-outs deferred because the candidate's path meets a waiter (:meth:`_yields`)
        self.yielded = 0
        #: how long each holder's stop point has stayed put (:meth:`_note_still`)
        self._still = StallClock()
        #: over the run: candidates' corridors let past a stalled holder's standing box (:meth:`_passable`)
        self.stalled_passed = 0
        #: over the run: token hand-outs deferred because the candidate's wide path meets a vehicle standing
        #: at a red in the guard (:meth:`_standing_hits`)
        self.red_yielded = 0
        #: over the run: holders' corridors cut behind them (:meth:`_trim`)
        self.corridors_cut = 0
        #: (zone, vehicle) -> the exit slot of the interval the token was handed out for: kept while the
        #: holder's stop point has not reached it (:meth:`_release`)
        self.pending: dict[tuple[int, str], int] = {}
        #: over the run: token hand-outs taken back because a zone chained to it could not be handed
        #: out in the same round (:meth:`_hand_out`)
        self.chain_revoked = 0
        #: the keep-out rule (:meth:`_keep_out`)
        self.keep_out = KeepOut(self.classes)
        #: (zone, holder) -> the zone's holders it took the token after (:meth:`_after`), and whose wide
        #: paths it keeps out of while they hold it
        self.after: dict[tuple[int, str], set[str]] = {}
        #: over the run: tokens handed out after holders whose corridors the candidate's meets (:meth:`_after`)
        self.ordered_granted = 0
        self._chained: set[int] = set()  # rows that want several zones' tokens this round (:meth:`_hand_out`)
        self._offered: set[tuple[int, str]] = set()  # (zone, vehicle) taking a token after holders this round

    @property
    def slots_freed(self) -> int:
        """Over the run: exit slots whose world box met another vehicle's claims but whose oriented box
        did not (:meth:`_slot_taken`)."""
        return self.boxes.slots_freed

    @staticmethod
    def guard_radius(classes) -> float:
        """The largest :attr:`AuthorityReach.guard_reach` of the classes (m)."""
        return max((c.guard_reach for c in classes), default=0.0)

    def intervals(self, fleet: JunctionFleet, row: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Row ``row``'s route intervals through the guards (:meth:`tm.guard_spans.GuardSpans.intervals`)."""
        return self.spans.intervals(fleet, row)

    def entry_limit(self, W: np.ndarray, H: np.ndarray, vclass: str, vid: str | None = None) -> int:
        """The furthest stop point without a token on a route (:meth:`tm.guard_spans.GuardSpans.entry_limit`)."""
        return self.spans.entry_limit(W, H, vclass, vid)

    def stop_limit(self, fleet: JunctionFleet, row: int) -> int:
        """The furthest waypoint row ``row``'s stop point may reach without a zone token it does not
        hold: one before the first entry beyond its requested stop point ``k + 1`` of an interval
        whose token it does not hold (or gave back), else the route's last waypoint."""
        zs, e, _, _ = self.intervals(fleet, row)
        W, _, k = fleet.route(row)
        vid = fleet.ids[row]
        back = self.given_back.get(vid, ())
        limit = len(W) - 1
        for z, en in zip(zs.tolist(), e.tolist()):
            if en > k + 1 and (vid not in self.holders[z] or z in back):
                limit = min(limit, en - 1)
        return limit

    def _wanting(self, fleet: JunctionFleet, r: np.ndarray, new_lo: np.ndarray,
                 new_hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(zone, row)`` pairs of requesters ``r`` that need the zone's token unless they hold it,
        grouped by zone, rows ascending: the requested stop point ``k + 1`` lies in one of the
        zone's intervals (entry to exit slot) and the current one does not, or the vehicle gave
        the zone's token back (:meth:`give_back`)."""
        ids = fleet.ids
        self.spans.prune(ids)
        cnt, (z, e, x) = self.spans.gather(fleet, r)
        if not cnt.sum():
            return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)
        row = np.repeat(r, cnt)
        k = np.concatenate([np.asarray(kk, dtype=np.intp) for _, _, kk in fleet.parts])[row]
        on = (e <= k + 1) & (k + 1 <= x)
        fresh = on & (k < e)
        if self.given_back:  # a token given back is needed again, from inside the guard too
            fresh |= on & np.array([zz in self.given_back.get(ids[i], ()) for i, zz in zip(row.tolist(), z.tolist())],
                                   dtype=bool).reshape(-1)
        wz, wr = z[fresh], row[fresh]
        # chained zones: the intervals that begin at or before the exit slot of one entered now
        # (and so on along the route) are wanted with it, all or none (:meth:`_hand_out`)
        extra_z, extra_r = [], []
        chained = np.flatnonzero(fresh & self.chain)
        if len(chained):
            owner = np.repeat(np.arange(len(r)), cnt)  # each interval's requester (its place in r)
            for f, n_i, rw, ef, xf in zip(chained.tolist(), owner[chained].tolist(), row[chained].tolist(),
                                          e[chained].tolist(), x[chained].tolist()):
                held = ids[rw]
                reach = xf
                for ej, zj, xj in self.spans.entry_runs(fleet, rw):
                    if ej <= ef:  # the intervals that begin after this one, in order
                        continue
                    if ej > reach:
                        break
                    if held not in self.holders[zj]:
                        extra_z.append(zj)
                        extra_r.append(rw)
                    reach = max(reach, xj)
        if extra_z:  # without duplicates (a zone met by two chains of one row)
            wz, wr = np.r_[wz, extra_z].astype(np.intp), np.r_[wr, extra_r].astype(np.intp)
            m = int(wr.max()) + 1
            key = np.unique(wz * m + wr)
            wz, wr = key // m, key % m
        o = np.lexsort((wr, wz))
        return wz[o], wr[o]

    def _hand_out(self, t: int, fleet: JunctionFleet, pos: dict, wz: np.ndarray,
                  wrow: np.ndarray) -> np.ndarray:
        """:meth:`JunctionGate._hand_out`, all or none per vehicle: a vehicle that wants several
        tokens this round (chained zones, :meth:`_wanting`) keeps those handed out now only if
        it has every one; else they go back (it keeps its place in the waiting order).  Tokens
        kept are :attr:`pending` until the holder's stop point reaches the interval's exit slot."""
        ids = fleet.ids
        if self.trim_corridors:
            self._trim(fleet, pos)
        before = [set(h) for h in self.holders]
        rows, n_wants = np.unique(wrow, return_counts=True)
        self._chained = set(rows[n_wants > 1].tolist())  # they want several zones this round (:meth:`_after`)
        self._offered = set()
        if self.ordered_entry:  # the waiters' standing boxes, asked for by :meth:`_after`, all at once
            self.paths.standing_many(fleet, wrow)
        allowed = super()._hand_out(t, fleet, pos, wz, wrow)
        if not len(wrow):
            return allowed
        short = np.unique(wrow[~allowed])
        new = np.array([ids[r] not in before[z] for z, r in zip(wz.tolist(), wrow.tolist())], dtype=bool)
        back = new & allowed & np.isin(wrow, short)
        for z, r in zip(wz[back].tolist(), wrow[back].tolist()):
            del self.holders[z][ids[r]]
            self.tokens_granted -= 1
            self.chain_revoked += 1
        allowed &= ~back
        kept = new & allowed
        for z, v in self._offered:  # ordered entry: counted when kept, forgotten when not (a yield, the chain)
            if v in self.holders[z]:
                self.ordered_granted += 1
            else:
                self.after.pop((z, v), None)
        for z, r in zip(wz[kept].tolist(), wrow[kept].tolist()):
            span = self.spans.span_of(fleet, r, z, fleet.route(r)[2] + 1)
            if span is not None:
                self.pending[(z, ids[r])] = span[1]
        return allowed

    def _trim(self, fleet: JunctionFleet, pos: dict) -> None:
        """Cut every holder's corridor (kept from its hand-out) to its boxes from the first one its
        current claim box meets: the boxes before that lie behind it.

        A holder's stop point only moves on along its route, and its current claim's world box holds
        its body and the hold box at its stop point, so every place it may yet come to stand lies in
        the boxes kept; a candidate whose corridor misses them can neither block it nor be blocked
        by it inside the guard, as with the whole corridor (:class:`tm.junctions.Zone`).  Without
        the cut a holder kept the conflict points it had passed until it left the guard: on SUMO's
        ``fokr_bs_demo`` a bicycle crossing junction ``38`` (68 m by 65 m) held every crossing
        stream back for the 12 s it took.  The cut corridor gets its own key (the oriented boxes of
        :meth:`corridors_meet` cut alike)."""
        cur_lo, cur_hi = fleet.claim_lo, fleet.claim_hi
        todo = [(hs, h, c, pos[h]) for hs in self.holders for h, c in hs.items() if h in pos and len(c[1]) >= 2]
        if not todo:
            return
        # every holder's first corridor box that its current claim box meets, all at once
        n = np.array([len(c[1]) for _, _, c, _ in todo], dtype=np.intp)
        start = np.cumsum(n) - n
        j = np.repeat(np.array([t[3] for t in todo], dtype=np.intp), n)
        lo = np.concatenate([c[1] for _, _, c, _ in todo])
        hi = np.concatenate([c[2] for _, _, c, _ in todo])
        meets = np.all((lo <= cur_hi[j]) & (hi >= cur_lo[j]), axis=1)
        first = np.minimum.reduceat(np.where(meets, np.arange(len(j)) - np.repeat(start, n), n.max()), start)
        for t in np.flatnonzero((first > 0) & (first < n)).tolist():
            hs, h, (key, lo, hi), _ = todo[t]
            i0 = int(first[t])
            cut = (*key[:3], key[3] + i0 if len(key) > 3 else i0)
            self.boxes.cut(key, cut, i0, len(lo))
            hs[h] = (cut, lo[i0:], hi[i0:])
            self.corridors_cut += 1

    def _release(self, fleet: JunctionFleet, pos: dict) -> None:
        """:meth:`JunctionGate._release`, except the tokens :attr:`pending`: kept until the holder's
        stop point has reached the exit slot of the interval the token was handed out for (then
        released as any other once its claim has left the guard), or the holder is gone.

        Whether a claim meets the guard says nothing of where the holder stands on its route: a
        claim's box follows the vehicle's speed and heading, and one that had just reached the
        guard left it again as the vehicle braked into a bend (SUMO's ``fkk_in``, ``3_right.0``
        between ``276184048`` and ``gneJ21``, 5 m apart: handed both tokens at once, it lost the
        second 0.2 s after its claim first touched that guard, stood between the zones for good,
        and ``2_left.0``, the other way, stood beside it waiting for the first).  Without a stop
        point in the interval, the claim of a vehicle at the entry line (its hold box clear of
        the guard) gave the token back the step after the hand-out whenever the manager denied
        the switch, and the vehicle queued again behind every waiter."""
        keep = {}
        for (z, v), x in list(self.pending.items()):
            i = pos.get(v, -1)
            if i < 0 or v not in self.holders[z] or fleet.route(i)[2] >= x:
                del self.pending[(z, v)]
            else:
                keep[(z, v)] = self.holders[z].pop(v)
        super()._release(fleet, pos)
        for (z, v), c in keep.items():
            self.holders[z][v] = c

    def _follows(self, fleet: JunctionFleet, pos: dict, row: int, z: int, leaders: list) -> bool:
        """A queue through the junction (module notes, "queues"): :meth:`GatePaths.follows`."""
        return self.paths.follows(fleet, pos, row, z, leaders)

    def _yields(self, fleet: JunctionFleet, row: int, z: int, waiters: np.ndarray) -> bool:
        """Row ``row`` lets the other waiters of zone ``z`` go first (module notes, "yield at the
        hand-out"): :meth:`GatePaths.yields`, counted in :attr:`yielded`."""
        out = self.paths.yields(fleet, row, z, waiters)
        self.yielded += int(out)
        return out

    def _after(self, fleet: JunctionFleet, pos: dict, row: int, z: int, holders: list) -> bool:
        """Row ``row`` takes zone ``z``'s token after the holders ``holders`` whose corridors its own
        meets (module notes, "ordered entry") when it stands clear of every holder's wide path from
        that one's stop point on (:meth:`GatePaths.wide_path`; a holder whose route ends in the guard
        has none, and is waited for): it then keeps out of those paths until each holder lets the
        token go (:meth:`_keep_out`), so it never stands where an earlier holder still has to pass,
        and comes up to the conflict while they cross it instead of waiting at the entry line."""
        vid = fleet.ids[row]
        if not self.ordered_entry or row in self._chained or any(
                vid in hs for zz, hs in enumerate(self.holders) if zz != z):
            return False
        box = self.paths.standing(fleet, row)
        b_lo, b_hi = np.asarray(box[0])[None], np.asarray(box[1])[None]
        meet = set(holders)
        for h in self.holders[z]:
            h_row = pos.get(h)
            if h_row is None:
                continue
            path = self.paths.wide_path(fleet, h_row, z, fleet.route(h_row)[2])
            if path is None:
                if h in meet:
                    return False
                continue
            if boxes_meet(path[0], path[1], b_lo, b_hi):
                return False
        self.after[(z, vid)] = set(self.holders[z])
        self._offered.add((z, vid))
        return True

    def _prune_after(self) -> None:
        """Forget the :attr:`after` entries of vehicles that no longer hold the zone's token, and the
        holders there that let it go."""
        for (z, v), hs in list(self.after.items()):
            hs.intersection_update(self.holders[z])
            if v not in self.holders[z] or not hs:
                del self.after[(z, v)]

    # ------------------------------------------------------------------ the moving claims' width
    def withhold(self, t: int, fleet: JunctionFleet, requesting: np.ndarray, new_lo: np.ndarray,
                 new_hi: np.ndarray) -> np.ndarray:
        """:meth:`JunctionGate.withhold`, then the holders' paths kept clear (:meth:`_keep_out`)."""
        pos = self._rows_by_id(fleet)  # one id -> row map for the step's stall clock and tokens
        self._note_still(t, fleet, pos)
        req = self._withhold(t, fleet, pos, requesting, new_lo, new_hi)
        return self._keep_out(fleet, req)

    def _keep_out(self, fleet: JunctionFleet, req: np.ndarray) -> np.ndarray:
        """The requests that stay after :class:`tm.keep_out.KeepOut` (the holders' wide paths kept
        clear of vehicles coming to stand in them), counted as withheld."""
        self._prune_after()
        after: dict[str, set[str]] = {}
        for (_, v), hs in self.after.items():
            after.setdefault(v, set()).update(hs)
        out, n = self.keep_out.apply(fleet, req, self.holders, self.paths.wide_paths, self.paths.on_routes, after)
        for v, hs in self.keep_out.kept_from.items():
            self.waiting_on.setdefault(v, []).extend(hs)
        self.requests_withheld += n
        self.wide_withheld += n
        return out

    def _note_still(self, t: int, fleet: JunctionFleet, pos: dict[str, int]) -> None:
        """Every holder's stop point at step ``t``, for :meth:`_stalled` (``pos``: vehicle id -> row
        in ``fleet``, :meth:`JunctionGate._rows_by_id`)."""
        self._still.note(t, ((h, fleet.route(pos[h])[2]) for hs in self.holders for h in hs if h in pos))

    def _stalled(self, t: int, holder: str) -> bool:
        """Whether holder ``holder``'s stop point has stayed put for :attr:`stall_steps` steps."""
        n = self._still.still_for(t, holder)
        return self.stall_steps is not None and n is not None and n >= self.stall_steps

    def _corridor_meets(self, fleet: JunctionFleet, row: int, z: int, box) -> bool:
        """Whether row ``row``'s corridor through zone ``z`` (:meth:`route_through`) meets ``box``
        ``(lo, hi)``, its boxes taken at each waypoint's arriving
        and leaving headings apart (their union, not the hull the corridor keeps: at a turn's
        corner that square reaches a body length sideways both ways)."""
        _, _, c_lo, _ = self.route_through(fleet, row, z)
        W, H, k = fleet.route(row)
        idx = k + np.arange(len(c_lo))
        cls = self.classes[fleet.family[row]]
        b_lo, b_hi = np.asarray(box[0])[None], np.asarray(box[1])[None]
        return any(boxes_meet(W[idx] - r, W[idx] + r, b_lo, b_hi)
                   for r in (cls.half_extent(H[idx]), cls.half_extent(H[np.minimum(idx + 1, len(H) - 1)])))

    def _intruder_hits(self, fleet: JunctionFleet, keys: list, zq: np.ndarray, rq: np.ndarray, first: np.ndarray,
                       c_lo: np.ndarray, c_hi: np.ndarray, zs: np.ndarray, rs: np.ndarray) -> np.ndarray:
        """:meth:`JunctionGate._intruder_hits` on the corridor ahead of the candidate: without the box
        at its current waypoint (where there are more), and as oriented boxes, padded by SUMO's body
        reach (:meth:`AuthorityReach.corridor_polygons`), where a world box meets the claim's.

        The box at the current waypoint reaches ``δ/2 + T^0 + L/2`` behind it, over the front of the
        vehicle queued right behind (claims no longer reach backwards: the candidate never stands
        there again), and the next box holds all of it ahead of the waypoint.  World boxes of roads
        not along an axis overlap lanes side by side.  SUMO's ``fokr_bs_demo``: two cars standing
        side by side at a red light inside junction ``38`` gave their tokens back; at green each one's
        corridor met the other's claim box (world boxes at 14 degrees), and one's also met the car
        queued behind it, for good."""
        if not self.oriented_intruders:
            return super()._intruder_hits(fleet, keys, zq, rq, first, c_lo, c_hi, zs, rs)
        first2, lo2, hi2 = corridors_ahead(first, c_lo, c_hi)
        hits = corridor_hits(zq, rq, first2, lo2, hi2, zs, rs, fleet.claim_lo, fleet.claim_hi)
        if fleet.claim_polygons is None or not hits.any():
            return hits
        # the (candidate, claim of its zone) pairs whose world boxes meet, all at once ...
        qs = np.flatnonzero(hits)
        s = np.searchsorted(zs, zq[qs], "left")
        cnt = np.searchsorted(zs, zq[qs], "right") - s
        pq, pj = np.repeat(np.arange(len(qs)), cnt), rs[ranges(s, cnt)]
        keep = pj != rq[qs][pq]
        pq, pj = pq[keep], pj[keep]
        a, nb = first2[qs][pq], (first2[qs + 1] - first2[qs])[pq]
        bb = ranges(a, nb)
        jj = np.repeat(pj, nb)
        near = np.all((lo2[bb] <= fleet.claim_hi[jj]) & (hi2[bb] >= fleet.claim_lo[jj]), axis=1)
        if len(pq):
            near = np.logical_or.reduceat(near, np.cumsum(nb) - nb)
        pq, pj = pq[near], pj[near]
        hits[qs] = False
        if not len(pq):
            return hits
        # ... then whether some oriented box of a candidate's corridor ahead meets some of each such
        # claim's, every pair in one compiled pass (each claim's boxes computed once)
        uq, q_of = np.unique(pq, return_inverse=True)
        mine = [self.boxes.ahead(fleet, int(rq[qs[q]]), keys[qs[q]], len(self._routes[keys[qs[q]]][2]))
                for q in uq.tolist()]
        p_cnt = np.array([len(m) for m in mine], dtype=np.intp)
        uj, j_of = np.unique(pj, return_inverse=True)
        Q, q_owner = fleet.claim_polygons(uj)
        q_cnt = np.bincount(q_owner, minlength=len(uj))
        meet = polygon_sets_meet(np.concatenate(mine), (np.cumsum(p_cnt) - p_cnt)[q_of], p_cnt[q_of],
                                 Q, (np.cumsum(q_cnt) - q_cnt)[j_of], q_cnt[j_of])
        hits[qs[pq[meet]]] = True
        return hits

    def _slot_taken(self, fleet: JunctionFleet, keys: list, rows: np.ndarray) -> np.ndarray:
        """:meth:`JunctionGate._slot_taken` with oriented boxes: an exit slot whose world box meets
        the world box of another vehicle's claims is taken only when the slot's padded hold box and
        that vehicle's claims (:attr:`JunctionFleet.claim_polygons`) meet as oriented boxes.  On a
        road not along an axis the world boxes of opposite lanes overlap: on SUMO's ``fkk_in`` a car
        turning right onto the diagonal ``-148050455#0`` never found its exit slot free while a queue
        stood on ``148050455#0`` beside it, and with it waited every vehicle behind."""
        return ~self.boxes.slot_free(fleet, keys, rows)

    def _standing_hits(self, fleet: JunctionFleet, zq: np.ndarray, rq: np.ndarray, first: np.ndarray,
                       c_lo: np.ndarray, c_hi: np.ndarray, zs: np.ndarray, rs: np.ndarray) -> np.ndarray:
        """:meth:`JunctionGate._standing_hits`, and a candidate whose wide path beyond its stop point
        (:meth:`GatePaths.wide_polygons`: the claims it will make through the zone, padded, as oriented boxes)
        meets the oriented hold box of a vehicle standing at a red in the guard cannot pass it either:
        the traffic manager would deny those claims for as long as the light stays red, and the
        candidate would stand inside the guard with the token, holding back every waiter whose
        corridor meets its own (SUMO's ``fkk_in``, whose lights change only by hand: bicycle
        ``4_left.1`` took ``gneJ21``'s token to turn left past the front of car ``4_right.0`` at its
        red, stopped 0.7 m short of its bumper's line and held the token for the rest of the run).
        A route that ends in the guard counts to its end: on the generated ``tlsgrid`` car 29, whose
        route ends at its lane's end beside junction ``B1``, took the token behind car 27 standing at
        the red (its corridor's last waypoint 0.08 m clear of 27's claim box, its hold box there 2.6 m
        into it); when the light turned green 27 waited for that token and 29 for 27, for good."""
        hits = super()._standing_hits(fleet, zq, rq, first, c_lo, c_hi, zs, rs)
        for q in np.flatnonzero(~hits).tolist():
            z, row = int(zq[q]), int(rq[q])
            near = rs[(zs == z) & (rs != row)]
            if not len(near):
                continue
            mine = self.paths.wide_polygons(fleet, row, z)
            if mine is None:
                continue
            lo, hi = mine.min(axis=(0, 1)), mine.max(axis=(0, 1))
            near = near[np.all((fleet.claim_lo[near] <= hi) & (fleet.claim_hi[near] >= lo), axis=1)]
            if any(polygons_meet(mine, self.paths.standing_polygons(fleet, int(j))) for j in near.tolist()):
                hits[q] = True
                self.red_yielded += 1
        return hits

    def _passable(self, fleet: JunctionFleet, pos: dict, t: int, holder: str, row: int, z: int) -> bool:
        """A candidate may take the token beside a holder whose corridor its own meets when that
        holder is stalled (:meth:`_stalled`: its stop point has not moved for :attr:`stall_steps`
        steps) and its standing box (:meth:`GatePaths.standing`: it is at rest at its stop point) misses the
        candidate's corridor: the holder is not about to take that road, and the candidate may be
        what it waits for (the corridor as :meth:`_corridor_meets` takes it).  With :meth:`_stalled`
        in :meth:`JunctionGate._hand_out` (a waiter held back by stalled holders alone holds nobody
        back), bench_scale's 6 x 6 grid lands 277 of 330 (none after 450 s), 252 without (issue 12).  It does
        not free two buses standing side by side at their entry lines, each turning away from the
        other: either one's rear swings into the other's lane (D5: 247 holding the token, 318 beside
        it; 318 let past 247 stalls the same way, README Known limits).  Liveness only: the traffic
        manager checks every claim as before."""
        h_row = pos.get(holder)
        if h_row is None or not self._stalled(t, holder):
            return False
        if self._corridor_meets(fleet, row, z, self.paths.standing(fleet, h_row)):
            return False
        self.stalled_passed += 1
        return True

    def route_through(self, fleet: JunctionFleet, row: int, z: int):
        """``(key, slot, lo, hi)``: exit slot and corridor of row ``row`` through zone ``z``'s guard.

        The corridor holds a box around every waypoint from the current one ``k`` to the exit
        slot (:meth:`AuthorityReach.half_extent`); the slot box is the hold box ``T^0 ⊕
        footprint`` at the exit slot (room for the stopped vehicle only: the claims no longer
        reach backwards), None when the route ends inside the guard.  Cached per (vehicle, zone,
        current waypoint)."""
        W, H, k = fleet.route(row)
        key = (fleet.ids[row], z, k)
        found = self._routes.get(key)
        if found is not None:
            return found
        cls = self.classes[fleet.family[row]]
        span = self.spans.span_of(fleet, row, z, k + 1)
        last, exits = (span[1], span[2]) if span is not None else (min(k + 1, len(W) - 1), False)
        idx = np.arange(k, last + 1)
        nxt = np.minimum(idx + 1, len(H) - 1)
        r1 = cls.half_extent(H[idx], H[nxt])
        corr_lo, corr_hi = W[idx] - r1, W[idx] + r1
        slot = None
        if exits:
            h = cls.hold_half(H[last:last + 1], H[nxt[-1]:nxt[-1] + 1])[0]
            slot = (W[last] - h, W[last] + h)
        self._routes[key] = found = (key, slot, corr_lo, corr_hi)
        self.boxes.note_route(key, cls, W, H, idx, nxt, fleet.pad(row, idx), exits, self.oriented_turn_max_deg)
        return found

    def corridors_meet(self, key_a, lo_a, hi_a, key_b, lo_b, hi_b) -> bool:
        """Whether two corridors meet: their world boxes (:meth:`JunctionGate.corridors_meet`), then
        their oriented boxes (:meth:`AuthorityReach.corridor_polygons`: each waypoint's box at its
        arriving and leaving headings, padded by SUMO's body reach there; separating axes, touching
        counts), cached per pair of route keys.  On a road that does not run along an axis the world
        boxes of two lanes side by side overlap: on ``A10KW``'s diagonal motorway every vehicle
        through a merge took the one token in turn, whatever its lane (40 arrived in 180 s; 71 with
        the oriented boxes, README).  Only through movements (:attr:`oriented_turn_max_deg`); a turning
        corridor, or one whose boxes are not kept (dropped with the route cache), is taken as its
        world boxes."""
        return (super().corridors_meet(key_a, lo_a, hi_a, key_b, lo_b, hi_b)
                and self.boxes.corridors_meet(key_a, key_b))

