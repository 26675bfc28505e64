"""The co-simulation loop: vehicles under ST-MPC, the traffic manager, and a world adapter.

The loop only talks to a :class:`World` adapter (the free plane, or SUMO
through :mod:`bridge.sumo_world`), to the controllers and to the traffic
manager.  One step (``Ts``) is:

1. every active vehicle computes its membership index ``l`` w.r.t. its
   current waypoint and, when it may switch (``terminal``: ``l = 0``;
   ``early``: its state lies in the next waypoint's domain), a request
   ``(l', r̄)`` w.r.t. the next waypoint;
2. the TM grants or denies the requests (:class:`tm.manager.TrafficManager`);
3. granted vehicles switch; every vehicle applies the terminal law or the
   QP of eq. (6) (:class:`controllers.stmpc.STMPC`, vectorised per class);
4. the plant steps with the disturbance policy; the index must strictly
   decrease until 0 and then stay 0 (tube invariant, counted otherwise);
5. vehicles at their last waypoint with ``l = 0`` arrive; waiting vehicles
   whose initial tube is free are admitted (condition (12));
6. the monitor checks footprints and claims; the world is pushed and stepped.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from controllers.classes import VehicleClass
from controllers.plant import DISTURBANCES, step as plant_step
from controllers.settings import ControllerSettings, SynthesisSettings
from controllers.stmpc import STMPC
from controllers.synthesis import synthesize
from controllers.tolerances import SWEEP_MARGIN
from tm.claims import Claims
from tm.manager import FleetState, TrafficManager
from tm.monitor import Monitor
from tm.settings import TMSettings

__all__ = ["Zone", "VehicleSpec", "CosimSettings", "World", "FreePlaneWorld", "Cosim", "VehicleRecord"]


@dataclass(frozen=True)
class VehicleSpec:
    """A vehicle to run: id, class name, waypoints (K, 2) at most delta apart, departure time;
    optionally the speed limit (m/s) of the lane under each waypoint (``speed_limits``, (K,)),
    for the controller to bound the vehicle's speed there."""

    id: str
    vclass: str
    waypoints: np.ndarray
    depart_s: float = 0.0
    speed_limits: np.ndarray | None = None

    @property
    def route_length_m(self) -> float:
        return float(np.linalg.norm(np.diff(self.waypoints, axis=0), axis=1).sum())


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


@dataclass(frozen=True)
class CosimSettings:
    """Options of one co-simulation run (validated)."""

    tm: TMSettings = field(default_factory=TMSettings)
    switching: str = "early"
    disturbance: str = "random"
    solver: str = "exact"
    seed: int = 0
    duration_s: float | None = None
    Ts: float = 0.1

    def __post_init__(self) -> None:
        ControllerSettings(solver=self.solver, switching=self.switching)  # validates both
        if self.disturbance not in DISTURBANCES:
            raise ValueError(f"CosimSettings.disturbance: must be one of {DISTURBANCES}, "
                             f"got {self.disturbance!r}")
        if self.duration_s is not None and not self.duration_s > 0:
            raise ValueError(f"CosimSettings.duration_s: must be > 0 s or None, got {self.duration_s}")


class World(Protocol):
    """What the loop needs from a simulator."""

    def insert(self, spec: VehicleSpec, vclass: VehicleClass) -> None: ...
    def push(self, ids: list[str], centre: np.ndarray, heading: np.ndarray) -> None: ...
    def finish(self, vid: str) -> None: ...
    def step(self) -> list[tuple[str, str]]: ...


class FreePlaneWorld:
    """No simulator: muvsim's own plant and geometric monitor are the whole world."""

    def insert(self, spec, vclass) -> None:
        pass

    def push(self, ids, centre, heading) -> None:
        pass

    def finish(self, vid) -> None:
        pass

    def step(self) -> list:
        return []


@dataclass
class VehicleRecord:
    """Per-vehicle KPI accumulator."""

    id: str
    vclass: str
    depart_s: float
    route_length_m: float
    admitted_s: float | None = None
    arrived_s: float | None = None
    denials: int = 0
    stop_episodes: int = 0
    stopped_steps: int = 0
    closest_m: float = np.inf
    speed_sum: float = 0.0
    steps: int = 0


class _Group:
    """The active vehicles of one class, as arrays."""

    def __init__(self, vclass: VehicleClass, ctl: STMPC):
        self.vclass = vclass
        self.ctl = ctl
        n = vclass.model.n
        self.ids: list[str] = []
        self.X = np.zeros((0, n))
        self.k = np.zeros(0, dtype=np.intp)
        self.l = np.zeros(0, dtype=np.intp)
        self.W: list[np.ndarray] = []
        self.H: list[np.ndarray] = []
        # every route's waypoints and headings in one buffer, so that the current (or next)
        # waypoints of all vehicles are one gather: row start[i] + k[i] of vehicle i
        self._wbuf = np.zeros((1024, 3))
        self._used = 0
        self.start = np.zeros(0, dtype=np.intp)
        self.K = np.zeros(0, dtype=np.intp)
        # per-vehicle accumulators (flushed into the VehicleRecords by Cosim)
        self.speed_sum = np.zeros(0)
        self.steps = np.zeros(0, dtype=np.intp)
        self.denied_last = np.zeros(0, dtype=bool)
        self.req_l = np.zeros(0, dtype=np.intp)  # request indices of the last TM state

    def add(self, vid, W, H, x0, l0):
        K = len(W)
        live = int(self.K.sum())
        if self._used + K > len(self._wbuf):
            if self._used > 2 * live + 4096:  # mostly removed routes: compact
                rows = np.concatenate([np.arange(s, s + k) for s, k in zip(self.start, self.K)]) \
                    if len(self.K) else np.zeros(0, dtype=np.intp)
                self._wbuf = np.vstack([self._wbuf[rows], np.zeros((max(1024, 2 * (live + K)), 3))])
                self.start = np.concatenate([[0], np.cumsum(self.K)[:-1]]).astype(np.intp) \
                    if len(self.K) else self.start
                self._used = live
            if self._used + K > len(self._wbuf):
                grow = max(len(self._wbuf), K)
                self._wbuf = np.vstack([self._wbuf, np.zeros((grow, 3))])
        self._wbuf[self._used:self._used + K, :2] = W
        self._wbuf[self._used:self._used + K, 2] = H
        self.ids.append(vid)
        self.X = np.vstack([self.X, x0[None]])
        self.k = np.append(self.k, 0)
        self.l = np.append(self.l, l0)
        self.W.append(W)
        self.H.append(H)
        self.start = np.append(self.start, self._used)
        self.K = np.append(self.K, K)
        self._used += K
        self.speed_sum = np.append(self.speed_sum, 0.0)
        self.steps = np.append(self.steps, 0)
        self.denied_last = np.append(self.denied_last, False)
        self.req_l = np.append(self.req_l, 0)

    def remove(self, mask):
        keep = ~mask
        self.ids = [v for v, k in zip(self.ids, keep) if k]
        self.X, self.k, self.l = self.X[keep], self.k[keep], self.l[keep]
        self.W = [w for w, k in zip(self.W, keep) if k]
        self.H = [h for h, k in zip(self.H, keep) if k]
        self.start, self.K = self.start[keep], self.K[keep]
        self.speed_sum, self.steps = self.speed_sum[keep], self.steps[keep]
        self.denied_last, self.req_l = self.denied_last[keep], self.req_l[keep]

    @property
    def at_last(self) -> np.ndarray:
        """Whether each vehicle's current waypoint is its route's last."""
        return self.k == self.K - 1

    def centres(self, offset=0):
        """Waypoints ``k + offset`` (clipped to the last), their headings, and whether they exist."""
        if not self.ids:
            return np.zeros((0, 2)), np.zeros(0), np.zeros(0, dtype=bool)
        row = self._wbuf[self.start + np.minimum(self.k + offset, self.K - 1)]
        return row[:, :2], row[:, 2], self.k + offset < self.K


def _cells(lo: np.ndarray, hi: np.ndarray, cell: float):
    """Every (box, grid cell) pair of boxes no wider than ``cell``: at most 2 x 2 cells a box."""
    c0 = np.floor(lo / cell).astype(np.int64)
    c1 = np.floor(hi / cell).astype(np.int64)
    box, key = [], []
    for dx in (0, 1):
        for dy in (0, 1):
            ok = (c0[:, 0] + dx <= c1[:, 0]) & (c0[:, 1] + dy <= c1[:, 1])
            box.append(np.flatnonzero(ok))
            key.append((c0[ok, 0] + dx) * (1 << 32) + (c0[ok, 1] + dy))
    return np.concatenate(box), np.concatenate(key)


class _BoxGrid:
    """Boxes ``(lo[j], hi[j])`` bucketed on a uniform grid of square cells no smaller than the
    widest box (so a box covers at most 2 x 2 cells), for :meth:`pairs`."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray, cell: float):
        self.lo, self.hi, self.cell = lo, hi, cell
        box, key = _cells(lo, hi, cell)
        order = np.argsort(key, kind="stable")
        self.key, self.box = key[order], box[order]

    def pairs(self, q_lo: np.ndarray, q_hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(i, j)``: every query box ``i`` (no wider than the cell) that meets box ``j``
        (touching counts), each pair once.  Boxes sharing a cell are tested exactly on both
        axes; a pair is kept in one cell only, the one holding the larger of the two lower
        corners.  (A sweep along x alone met every vehicle of the same north-south road.)"""
        if not len(q_lo) or not len(self.lo):
            return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)
        qb, qk = _cells(q_lo, q_hi, self.cell)
        start = np.searchsorted(self.key, qk, side="left")
        count = np.searchsorted(self.key, qk, side="right") - start
        i = np.repeat(qb, count)
        k = np.repeat(qk, count)
        j = self.box[np.repeat(start - np.cumsum(count) + count, count) + np.arange(int(count.sum()))]
        lo, hi = self.lo, self.hi
        ok = (hi[j, 0] >= q_lo[i, 0]) & (lo[j, 0] <= q_hi[i, 0]) & (lo[j, 1] <= q_hi[i, 1]) & (hi[j, 1] >= q_lo[i, 1])
        i, j, k = i[ok], j[ok], k[ok]
        ref = np.floor(np.maximum(q_lo[i], lo[j]) / self.cell).astype(np.int64)
        once = ref[:, 0] * (1 << 32) + ref[:, 1] == k
        return i[once], j[once]


def _corridor_hits(zone_q, row_q, first, c_lo, c_hi, zone_b, row_b, b_lo, b_hi) -> np.ndarray:
    """Per query ``q``: whether one of its corridor boxes ``first[q]:first[q + 1]`` meets a box
    ``row_b[k]`` of its own zone (``zone_b`` ascending), other than its own row ``row_q[q]``.

    Candidates and the boxes of their zone are paired by ``searchsorted`` on the zone, then
    each pair's corridor boxes are tested against its box (touching counts)."""
    hits = np.zeros(len(zone_q), dtype=bool)
    if not len(zone_b) or not len(zone_q):
        return hits
    s = np.searchsorted(zone_b, zone_q, side="left")
    cnt = np.searchsorted(zone_b, zone_q, side="right") - s
    q = np.repeat(np.arange(len(zone_q)), cnt)
    k = np.repeat(s - np.cumsum(cnt) + cnt, cnt) + np.arange(int(cnt.sum()))
    j = row_b[k]
    # the corridor's bounding box first: most pairs of a zone are far apart
    cb_lo = np.minimum.reduceat(c_lo, first[:-1], axis=0)
    cb_hi = np.maximum.reduceat(c_hi, first[:-1], axis=0)
    near = (j != row_q[q]) & np.all((cb_lo[q] <= b_hi[j]) & (cb_hi[q] >= b_lo[j]), axis=1)
    q, j = q[near], j[near]
    if not len(q):
        return hits
    n_box = first[q + 1] - first[q]
    qq = np.repeat(q, n_box)
    jj = np.repeat(j, n_box)
    bb = np.repeat(first[q] - np.cumsum(n_box) + n_box, n_box) + np.arange(int(n_box.sum()))
    meet = np.all((c_lo[bb] <= b_hi[jj]) & (c_hi[bb] >= b_lo[jj]), axis=1)
    hits[qq[meet]] = True
    return hits


def _boxes_meet(lo1: np.ndarray, hi1: np.ndarray, lo2: np.ndarray, hi2: np.ndarray) -> bool:
    """Whether any box ``(lo1[i], hi1[i])`` meets any box ``(lo2[j], hi2[j])`` (touching counts)."""
    return bool(np.any(np.all((lo1[:, None, :] <= hi2[None]) & (hi1[:, None, :] >= lo2[None]), axis=2)))


def _headings(W: np.ndarray) -> np.ndarray:
    """Heading of the segment arriving at each waypoint (the first takes the first segment's)."""
    d = np.diff(W, axis=0)
    h = np.arctan2(d[:, 1], d[:, 0]) if len(d) else np.zeros(0)
    return np.concatenate([h[:1] if len(h) else [0.0], h])


class Cosim:
    """One co-simulation run.

    Parameters
    ----------
    classes : mapping of str to VehicleClass
        Every class a spec may name.
    specs : list of VehicleSpec
    settings : CosimSettings
    world : World, optional
        Defaults to :class:`FreePlaneWorld`.
    synthesis : SynthesisSettings, optional
    """

    def __init__(self, classes, specs, settings: CosimSettings, world=None,
                 synthesis: SynthesisSettings | None = None, zones: list[Zone] | None = None,
                 observers: list | None = None):
        self.settings = settings
        #: Objects with ``on_step(sim, state, decision, row)``, called at the end of every
        #: step (``state``: the FleetState the TM decided on, or None with no vehicle;
        #: ``decision``: the TM's Decision or None; ``row``: the step's KPI row).
        #: Loggers (MCAP) and KPI accumulators attach here.
        self.observers = list(observers or [])
        self.world = world or FreePlaneWorld()
        used = sorted({s.vclass for s in specs})
        missing = [c for c in used if c not in classes]
        if missing:
            raise ValueError(f"vehicle class(es) {missing} unknown; valid: {sorted(classes)}")
        self.classes = {c: classes[c] for c in used}
        for s in specs:
            W = np.asarray(s.waypoints, dtype=float)
            if W.ndim != 2 or W.shape[1] != 2 or len(W) < 2:
                raise ValueError(f"vehicle {s.id}: waypoints must be (K >= 2, 2), got {W.shape}")
            gaps = np.linalg.norm(np.diff(W, axis=0), axis=1)
            model = self.classes[s.vclass].model
            delta = model.delta
            if np.any(gaps > delta + 1e-9):
                i = int(np.argmax(gaps))
                raise ValueError(f"vehicle {s.id}: waypoints {i} and {i + 1} are {gaps[i]:.3f} m apart; "
                                 f"class {s.vclass!r} needs at most delta = {delta} m")
            if model.frame == "road" and len(W) > 2:
                h = _headings(W)[1:]
                turn = np.degrees(np.abs((np.diff(h) + np.pi) % (2 * np.pi) - np.pi))
                if np.any(turn > model.turn_max_deg + 1e-6):
                    i = int(np.argmax(turn))
                    raise ValueError(
                        f"vehicle {s.id}: its route turns by {turn[i]:.1f} deg at waypoint {i + 1}; class "
                        f"{s.vclass!r} (road frame) accepts at most {model.turn_max_deg} deg between segments")
        if len({s.id for s in specs}) != len(specs):
            raise ValueError("vehicle ids must be unique")
        cs = ControllerSettings(solver=settings.solver, switching=settings.switching)
        self.families = {c: synthesize(vc.model, synthesis) for c, vc in self.classes.items()}
        self.groups = {c: _Group(vc, STMPC(self.families[c], cs)) for c, vc in self.classes.items()}
        self.tm = TrafficManager(settings.tm, {c: f.position_sets for c, f in self.families.items()},
                                 rotating=[c for c, vc in self.classes.items() if vc.model.frame == "road"])
        self.monitor = Monitor(settings.tm.check)
        self.pending = sorted(specs, key=lambda s: (s.depart_s, s.id))
        self._heading0: dict[str, float] = {}
        self.records = {s.id: VehicleRecord(s.id, s.vclass, s.depart_s, s.route_length_m) for s in specs}
        self.rng = np.random.default_rng(settings.seed)
        self.t = 0
        self.step_rows: list[dict] = []
        self.invariant_violations = 0
        self.constraint_violations = 0
        self.collisions_world: set = set()
        self.last_decision = None
        # zones: guard boxes (core enlarged by the largest claim radius), token holders, queues
        radius = max(float(np.abs(f.position_sets[-1]).max()) + 0.5 * np.hypot(self.classes[c].length,
                                                                              self.classes[c].width)
                     for c, f in self.families.items()) if self.families else 0.0
        self.zones = list(zones or [])
        self.zone_lo = np.array([z.lo for z in self.zones], dtype=float).reshape(-1, 2) - radius
        self.zone_hi = np.array([z.hi for z in self.zones], dtype=float).reshape(-1, 2) + radius
        # per zone: holder id -> (its route key, its corridor boxes lo, hi) through the guard;
        # tokens go to several vehicles at once only while their corridors are disjoint
        self.zone_holders: list[dict[str, tuple]] = [{} for _ in self.zones]
        self._meet: dict = {}  # (route key, route key) -> whether the two corridors meet
        self.zone_wait: dict[tuple[int, str], int] = {}
        order = np.argsort(self.zone_lo[:, 0], kind="stable")  # guards by lower x, for _zone_pairs
        self._zone_order = order
        self._zone_x_sorted = self.zone_lo[order, 0]
        self._zone_width_x = float((self.zone_hi[:, 0] - self.zone_lo[:, 0]).max()) if self.zones else 0.0
        self._group_list: list = []  # non-empty groups in fleet order and their first rows, set by _gate
        self._group_start = np.zeros(1, dtype=np.intp)
        self._exit_slot: dict = {}  # (vehicle, zone, waypoint) -> (exit slot box or None, corridor lo, hi)
        self._ms_request = self._ms_gate = 0.0  # this step's request indices and junction tokens

    # -------------------------------------------------------------- state
    def _fleet(self, with_requests: bool):
        ids, fam, C, L, H, Ln, Wd = [], [], [], [], [], [], []
        RQ, RC, RL, RH = [], [], [], []
        for c, g in self.groups.items():
            if not g.ids:
                continue
            cen, hd, _ = g.centres()
            ids += g.ids
            fam += [c] * len(g.ids)
            C.append(cen)
            L.append(g.l)
            H.append(hd)
            Ln.append(np.full(len(g.ids), g.vclass.length))
            Wd.append(np.full(len(g.ids), g.vclass.width))
            if with_requests:
                tr = time.perf_counter()
                nxt, nh, has = g.centres(1)
                lp = g.ctl.index(g.X, nxt, nh)
                self._ms_request += (time.perf_counter() - tr) * 1e3
                g.req_l = lp
                may = has & (lp <= g.ctl.N)
                if self.settings.switching == "terminal":
                    may &= g.l == 0
                RQ.append(may)
                RC.append(nxt)
                RL.append(np.minimum(lp, g.ctl.N))
                RH.append(nh)
        if not ids:
            return None
        cat = np.concatenate
        kw = {}
        if with_requests:
            kw = dict(requesting=cat(RQ), req_centre=np.vstack(RC), req_index=cat(RL), req_heading=cat(RH))
        state = FleetState(ids=ids, family=np.array(fam), centre=np.vstack(C), index=cat(L), heading=cat(H),
                           length=cat(Ln), width=cat(Wd), **kw)
        if with_requests and self.zones:
            tg = time.perf_counter()
            state = self._gate(state)
            self._ms_gate += (time.perf_counter() - tg) * 1e3
        return state

    def _zone_pairs(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(i, z)``: every box ``i`` (``lo, hi`` of shape (n, 2)) that meets zone guard ``z``.

        Guards sorted by their lower x: box ``i`` can only meet the guards whose lower x lies
        in ``[lo_x - widest guard, hi_x]`` (a ``searchsorted`` range); those candidate pairs
        are then tested on both axes.  Pairs sorted by ``i``.
        """
        zx = self._zone_x_sorted
        start = np.searchsorted(zx, lo[:, 0] - self._zone_width_x - SWEEP_MARGIN, side="left")
        count = np.maximum(np.searchsorted(zx, hi[:, 0], side="right") - start, 0)
        i = np.repeat(np.arange(len(lo)), count)
        q = np.repeat(start - np.cumsum(count) + count, count) + np.arange(int(count.sum()))
        z = self._zone_order[q]
        zl, zh = self.zone_lo, self.zone_hi
        ok = (lo[i, 0] <= zh[z, 0]) & (hi[i, 0] >= zl[z, 0]) & (lo[i, 1] <= zh[z, 1]) & (hi[i, 1] >= zl[z, 1])
        return i[ok], z[ok]

    def _claim_half_extent(self, vclass: VehicleClass, level: int, heading: np.ndarray) -> np.ndarray:
        """Half extents (x, y) of the bounding box of the largest claim ``P^level ⊕ footprint``
        of ``vclass`` at each heading (shape (n, 2)): the position set turns with the heading
        in the road frame, only the footprint in the world frame."""
        P = np.abs(self.families[vclass.name].position_sets[level]).max(axis=0)
        half = 0.5 * np.array([vclass.length, vclass.width])
        c, s = np.abs(np.cos(heading))[:, None], np.abs(np.sin(heading))[:, None]
        if vclass.model.frame == "road":
            e = P + half
            return np.hstack([c * e[0] + s * e[1], s * e[0] + c * e[1]])
        return P + np.hstack([c * half[0] + s * half[1], s * half[0] + c * half[1]])

    def _route_through(self, vid: str, row: int, z: int):
        """``(key, slot, lo, hi)``: the exit slot and corridor of ``vid`` (fleet row ``row``)
        through zone ``z``'s guard, and their cache key ``(vid, z, current waypoint)``.

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
        gi = int(np.searchsorted(self._group_start, row, side="right")) - 1
        g, j = self._group_list[gi], row - int(self._group_start[gi])
        k = int(g.k[j])
        key = (vid, z, k)
        found = self._exit_slot.get(key)
        if found is not None:
            return found
        W, H = g.W[j], g.H[j]
        r0 = float(np.abs(self.families[g.vclass.name].position_sets[0]).max()) \
            + 0.5 * float(np.hypot(g.vclass.length, g.vclass.width))
        lo_z, hi_z = self.zone_lo[z], self.zone_hi[z]
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
        r1 = self._claim_half_extent(g.vclass, len(self.families[g.vclass.name].position_sets) - 2, H[idx])
        corr_lo, corr_hi = W[idx] - r1, W[idx] + r1
        slot = (corr_lo[-1], corr_hi[-1]) if exits else None
        self._exit_slot[key] = found = (key, slot, corr_lo, corr_hi)
        return found

    def _corridors_meet(self, key_a, lo_a, hi_a, key_b, lo_b, hi_b) -> bool:
        """Whether two corridors meet (cached per pair of route keys: they are fixed)."""
        pair = (key_a, key_b)
        hit = self._meet.get(pair)
        if hit is None:
            if len(self._meet) > 200_000:  # stale keys: start over
                self._meet.clear()
            hit = self._meet[pair] = _boxes_meet(lo_a, hi_a, lo_b, hi_b)
        return hit

    def _gate(self, state: FleetState) -> FleetState:
        """Withhold requests into a zone guard whose token another vehicle holds (see :class:`Zone`)."""
        cur = self.tm.claims(state)
        cur_lo, cur_hi = cur.aabb()
        pos = dict(zip(state.ids, range(len(state.ids))))
        # release tokens whose holder's current claim has left the guard (or who is gone)
        held = [(z, pos.get(h, -1), h) for z, hs in enumerate(self.zone_holders) for h in hs]
        if held:
            hz = np.array([z for z, _, _ in held], dtype=np.intp)
            hi_ = np.array([i for _, i, _ in held], dtype=np.intp)
            gone = hi_ < 0
            inside = np.all(cur_lo[hi_] <= self.zone_hi[hz], axis=1) & np.all(cur_hi[hi_] >= self.zone_lo[hz], axis=1)
            for n in np.flatnonzero(gone | ~inside).tolist():
                del self.zone_holders[held[n][0]][held[n][2]]
        req = state.requesting.copy()
        r = np.flatnonzero(req)
        if not len(r):
            return state
        new = Claims(cur.table, cur.family[r], state.req_centre[r], state.req_index[r], state.req_heading[r],
                     cur.length[r], cur.width[r])
        new_lo, new_hi = new.aabb()
        # (requester, zone) pairs whose new claim reaches a guard its current claim is not in
        ni, nz = self._zone_pairs(new_lo, new_hi)
        ci, cz = self._zone_pairs(cur_lo[r], cur_hi[r])
        Z = len(self.zones)
        fresh = ~np.isin(ni * Z + nz, ci * Z + cz)
        want = np.sort(nz[fresh] * len(r) + ni[fresh])             # grouped by zone, rows ascending
        wz, wrow = want // len(r), r[want % len(r)]
        self._group_list = [g for g in self.groups.values() if g.ids]
        self._group_start = np.cumsum([0] + [len(g.ids) for g in self._group_list[:-1]])
        if len(self._exit_slot) > 100_000:  # stale (vehicle, waypoint) keys: start over
            self._exit_slot.clear()
        ids, wait, t, n = state.ids, self.zone_wait, self.t, len(state.ids)
        holder_keys = np.array(sorted(z * n + pos[h] for z, hs in enumerate(self.zone_holders) for h in hs),
                               dtype=np.intp)
        is_holder = np.isin(wz * n + wrow, holder_keys)
        allowed = is_holder.copy()
        P = np.flatnonzero(~is_holder)  # (zone, candidate) pairs that need a token
        if len(P):
            routes = [self._route_through(ids[i], i, z) for z, i in zip(wz[P].tolist(), wrow[P].tolist())]
            c_len = np.array([len(rt[2]) for rt in routes])
            c_lo = np.vstack([rt[2] for rt in routes])
            c_hi = np.vstack([rt[3] for rt in routes])
            cell = max(float((cur_hi - cur_lo).max()), float((c_hi - c_lo).max())) + SWEEP_MARGIN
            claims_grid = _BoxGrid(cur_lo, cur_hi, cell)
            # room for the largest claim at the exit slot (the corridor's last box): no other
            # vehicle's current claim there
            has_slot = np.array([rt[1] is not None for rt in routes])
            blocked_exit = np.zeros(len(P), dtype=bool)
            if has_slot.any():
                qs = np.flatnonzero(has_slot)
                s_lo = np.array([routes[q][1][0] for q in qs])
                s_hi = np.array([routes[q][1][1] for q in qs])
                qi, bj = claims_grid.pairs(s_lo, s_hi)
                other = bj != wrow[P[qs[qi]]]
                blocked_exit[qs[qi[other]]] = True
            first = np.r_[0, np.cumsum(c_len)]
            zP = wz[P]
            # claims already in the guard that are not a holder's ("intruders"), by zone
            gi_, gz_ = self._zone_pairs(cur_lo, cur_hi)
            keep = ~np.isin(gz_ * n + gi_, holder_keys)
            o = np.argsort(gz_[keep], kind="stable")
            blocked_intr = _corridor_hits(zP, wrow[P], first, c_lo, c_hi,
                                          gz_[keep][o], gi_[keep][o], cur_lo, cur_hi)
            # In order of waiting, per zone: a candidate with room beyond the zone (do not block
            # the box: a holder stuck in a queue inside the guard would stall everyone) gets a
            # token if its corridor misses every holder's, so holders never meet inside the
            # guard, and misses the claims already in the guard.  The first candidate whose
            # corridor meets a holder's ends the round (nobody overtakes it into the zone, so it
            # is served once those holders have left).
            cid = [ids[i] for i in wrow[P].tolist()]
            since = np.array([wait.setdefault((z, v), t) for z, v in zip(zP.tolist(), cid)])
            # candidates with room, by zone, then by waiting, then by id (the others are skipped)
            viable = np.flatnonzero(~blocked_exit)
            order = viable[np.lexsort((np.array(cid, dtype=object)[viable].astype(str), since[viable], zP[viable]))]
            z_prev, stop = -1, False
            for q in order.tolist():
                z = int(zP[q])
                if z != z_prev:
                    z_prev, stop, holders = z, False, self.zone_holders[z]
                if stop:
                    continue
                key_q, _, lo_q, hi_q = routes[q]
                if any(self._corridors_meet(key_q, lo_q, hi_q, *h) for h in holders.values()):
                    stop = True
                    continue
                if blocked_intr[q]:
                    continue
                holders[cid[q]] = (key_q, lo_q, hi_q)
                allowed[P[q]] = True
        req[wrow[~allowed]] = False   # only a zone's holders may ask into its guard
        for key in [k for k in wait if k[1] not in pos or k[1] in self.zone_holders[k[0]]]:
            wait.pop(key, None)
        return FleetState(ids=state.ids, family=state.family, centre=state.centre, index=state.index,
                          heading=state.heading, length=state.length, width=state.width, requesting=req,
                          req_centre=state.req_centre, req_index=state.req_index, req_heading=state.req_heading)

    # -------------------------------------------------------------- one step
    def step(self) -> dict:
        s = self.settings
        t_s = self.t * s.Ts
        row = {"t_s": round(t_s, 6)}
        tt = time.perf_counter()
        self._ms_request = self._ms_gate = 0.0
        state = self._fleet(with_requests=True)
        n_req = n_go = 0
        ms_tm = ms_decide = 0.0
        if state is not None:
            td = time.perf_counter()
            dec = self.tm.decide(state)
            ms_decide = (time.perf_counter() - td) * 1e3
            self.last_decision = dec
            ms_tm = (time.perf_counter() - tt) * 1e3
            n_req, n_go = int(state.requesting.sum()), int(dec.go.sum())
            o = 0  # the fleet state concatenates the non-empty groups in order
            for c, g in self.groups.items():
                if not g.ids:
                    continue
                sl = slice(o, o + len(g.ids))
                o += len(g.ids)
                gmask = np.asarray(dec.go[sl], dtype=bool)
                rmask = np.asarray(state.requesting[sl], dtype=bool)
                if gmask.any():  # the request index of the new waypoint becomes the index
                    g.k[gmask] += 1
                    g.l[gmask] = g.req_l[gmask]
                denied = rmask & ~gmask
                for i in np.nonzero(denied)[0]:
                    rec = self.records[g.ids[i]]
                    rec.denials += 1
                    rec.stopped_steps += 1
                    if not g.denied_last[i]:
                        rec.stop_episodes += 1
                g.denied_last = denied
            row["edges"] = int(len(dec.edges))
        # controls and plant
        tc = time.perf_counter()
        for c, g in self.groups.items():
            if not g.ids:
                continue
            m = g.vclass.model
            cen, hd, _ = g.centres()
            U = g.ctl.control(g.X, cen, g.l, ids=g.ids, heading=hd)
            g.X, _ = plant_step(m, g.X, U, cen, s.disturbance, self.rng, heading=hd)
            l_new = g.ctl.index(g.X, cen, hd)
            bad = ~((l_new < g.l) | ((g.l == 0) & (l_new == 0)))
            self.invariant_violations += int(bad.sum())
            z = g.ctl.error(g.X, cen, hd)[:, 2:]  # constraints hold in the model's frame
            self.constraint_violations += int(np.sum(np.any((z > m.z_bounds[1] + 1e-7) |
                                                            (z < m.z_bounds[0] - 1e-7), axis=1)))
            g.l = l_new
            g.speed_sum += np.linalg.norm(g.X[:, 2:4], axis=1)
            g.steps += 1
        ms_ctl = (time.perf_counter() - tc) * 1e3
        self.t += 1
        t_next = self.t * s.Ts
        # arrivals
        for c, g in self.groups.items():
            if not g.ids:
                continue
            done = g.at_last & (g.l == 0)
            if done.any():
                self._flush(g, done)
                for i in np.nonzero(done)[0]:
                    self.records[g.ids[i]].arrived_s = t_next
                    self.world.finish(g.ids[i])
                g.remove(done)
        # admissions (condition (12)) against the claims of the vehicles now in the network
        admitted = self._admit(t_next)
        # monitor and world
        tw = time.perf_counter()
        cur = self._fleet(with_requests=False)
        if cur is not None:
            pos = np.vstack([g.X[:, :2] for g in self.groups.values() if g.ids])
            ms = self.monitor.step(cur.ids, pos, cur.heading, cur.length, cur.width,
                                   claims=self.tm.claims(cur))
            self.world.push(list(cur.ids), pos, cur.heading)
            if np.isfinite(ms.min_separation) and ms.closest_pair:
                for v in ms.closest_pair:
                    r = self.records[v]
                    r.closest_m = min(r.closest_m, ms.min_separation)
            row.update(footprint_overlaps=ms.footprint_overlaps, claim_violations=ms.claim_violations,
                       min_separation_m=ms.min_separation)
        for pair in self.world.step():
            self.collisions_world.add(tuple(sorted(pair)))
        row.update(active=0 if cur is None else len(cur.ids), requests=n_req, grants=n_go,
                   denials=n_req - n_go, admitted=admitted, tm_ms=round(ms_tm, 4),
                   tm_decide_ms=round(ms_decide, 4), request_ms=round(self._ms_request, 4),
                   gate_ms=round(self._ms_gate, 4),
                   controller_ms=round(ms_ctl, 4), world_ms=round((time.perf_counter() - tw) * 1e3, 4))
        self.step_rows.append(row)
        for obs in self.observers:
            obs.on_step(self, state, self.last_decision if state is not None else None, row)
        return row

    def _first_heading(self, sp: VehicleSpec) -> float:
        h = self._heading0.get(sp.id)
        if h is None:
            W = np.asarray(sp.waypoints[:2], dtype=float)
            h = self._heading0[sp.id] = float(_headings(W)[0])
        return h

    def _admit(self, t_s: float) -> int:
        n_ready = 0  # pending is sorted by departure: the ready ones are a prefix
        while n_ready < len(self.pending) and self.pending[n_ready].depart_s <= t_s + 1e-9:
            n_ready += 1
        ready = self.pending[:n_ready]
        if not ready:
            return 0
        cur = self._fleet(with_requests=False)
        cand = FleetState(
            ids=[sp.id for sp in ready], family=np.array([sp.vclass for sp in ready]),
            centre=np.array([sp.waypoints[0] for sp in ready]), index=np.zeros(len(ready), dtype=np.intp),
            heading=np.array([self._first_heading(sp) for sp in ready]),
            length=np.array([self.classes[sp.vclass].length for sp in ready]),
            width=np.array([self.classes[sp.vclass].width for sp in ready]))
        if cur is None:  # empty network: an empty state
            cur = FleetState(ids=[], family=np.array([], dtype=str), centre=np.zeros((0, 2)),
                             index=np.zeros(0, dtype=np.intp), heading=np.zeros(0), length=np.zeros(0),
                             width=np.zeros(0))
        else:
            # A new vehicle appears NOW: it must miss where the others are now (P^l), not only
            # their claims from the next step on (P^{l-1}).  Claims of index l+1 are P^l.
            top = np.zeros(len(cur.family), dtype=np.intp)
            for c, f in self.families.items():
                top[cur.family == c] = f.N
            cur = FleetState(ids=cur.ids, family=cur.family, centre=cur.centre,
                             index=np.minimum(cur.index + 1, top), heading=cur.heading, length=cur.length,
                             width=cur.width)
        ok = self.tm.admit(cur, cand)
        held = [c for hs in self.zone_holders for c in hs.values()]
        ok = np.asarray(ok, dtype=bool)
        if held and ok.any():  # nor into a junction holder's corridor (see _gate)
            h_lo = np.vstack([c[1] for c in held])
            h_hi = np.vstack([c[2] for c in held])
            q = np.flatnonzero(ok)
            r = np.vstack([self._claim_half_extent(self.classes[ready[i].vclass],
                                                   len(self.families[ready[i].vclass].position_sets) - 2,
                                                   cand.heading[i:i + 1]) for i in q.tolist()])
            lo, hi = cand.centre[q] - r, cand.centre[q] + r
            meet = np.any(np.all((lo[:, None, :] <= h_hi[None]) & (hi[:, None, :] >= h_lo[None]), axis=2), axis=1)
            ok = ok.copy()
            ok[q[meet]] = False
        n = 0
        for sp, a in zip(ready, ok):
            if not a:
                continue
            g = self.groups[sp.vclass]
            W = np.asarray(sp.waypoints, dtype=float)
            x0 = g.vclass.model.equilibrium(W[0])
            H = _headings(W)
            g.add(sp.id, W, H, x0, int(g.ctl.index(x0[None], W[:1], H[:1])[0]))
            self.records[sp.id].admitted_s = t_s
            self.world.insert(sp, g.vclass)
            n += 1
        if n:
            keep = [i for i, a in enumerate(ok) if not a] + list(range(n_ready, len(self.pending)))
            self.pending = [self.pending[i] for i in keep]
        return n

    def _flush(self, g: _Group, mask=None) -> None:
        """Move the group's per-vehicle accumulators (rows ``mask``) into the records."""
        rows = np.arange(len(g.ids)) if mask is None else np.nonzero(mask)[0]
        for i in rows:
            rec = self.records[g.ids[i]]
            rec.speed_sum += float(g.speed_sum[i])
            rec.steps += int(g.steps[i])
            g.speed_sum[i] = 0.0
            g.steps[i] = 0

    def flush_records(self) -> None:
        """Bring every :class:`VehicleRecord` up to date (called at the end of :meth:`run`;
        call it before reading ``records`` after stepping by hand)."""
        for g in self.groups.values():
            if g.ids:
                self._flush(g)

    # -------------------------------------------------------------- run
    @property
    def done(self) -> bool:
        return not self.pending and not any(g.ids for g in self.groups.values())

    def run(self, max_steps: int, progress=None) -> None:
        """Step until every vehicle has arrived, ``duration_s`` or ``max_steps``."""
        if self.t == 0:
            self._admit(0.0)
        limit = max_steps
        if self.settings.duration_s is not None:
            limit = min(limit, int(round(self.settings.duration_s / self.settings.Ts)))
        try:
            while self.t < limit and not self.done:
                self.step()
                if progress is not None:
                    progress(self)
        finally:
            self.flush_records()
