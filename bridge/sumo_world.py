"""SUMO as the co-simulation's world: routes in, positions out, SUMO judges collisions.

:func:`run_sumo` runs a built-in scenario (``grid``, ``grid-large``), a
scenario TOML file, or a user's ``.sumocfg``: SUMO's routes become waypoints
at most the class's delta apart (junction-internal lanes included), every
vehicle is driven by its ST-MPC through :class:`bridge.cosim.Cosim`, and each
step the vehicles are pushed into SUMO with ``moveToXY``.  Junctions are the
co-simulation's conflict zones.  ``baseline=True`` runs the same demand driven
by SUMO itself (no override) for comparison.
"""

from __future__ import annotations

import sys
import time
import traceback
import weakref
from dataclasses import replace
from pathlib import Path

import numpy as np

from controllers.speed_limits import SpeedSettings
from bridge.cosim import Cosim, CosimSettings, VehicleSpec, Zone
from bridge.departure import DepartLanes, DepartPlan, depart_plan, first_edge_end
from bridge.groups import _headings as spec_headings
from bridge.interrupt import interrupt_behind
from bridge.pose import front_bumper, sumo_angle
from analysis.kpis import baseline_vehicle_table, read_tripinfo
from analysis.halts import HaltCounter
from analysis.mcap_log import observers_for
from analysis.outputs import StreamingOutputs, close_observers, write_run_tables
from analysis.safety import verdict
from bridge.scenarios import _write_summary
from bridge.signals import LinkSlots, route_stop_lines
from bridge.vehicle_stops import plan_stops
from bridge.stopping import RunLimit, route_file_departures, run_limit, stop_reason
from bridge.sumo_adapter import SumoAdapter, SumoError
from bridge.sumo_inputs import InputError, headless_config, net_turn_accel, parse_xml, prepare_inputs
from bridge.sumo_pedestrians import read_personinfo, read_persons, walk_regions
from bridge.waypoints import RouteError, load_net, trim_start, trim_start_index
from controllers.classes import VehicleClass, VTypeParams, builtin_classes, vtype_class, vtype_speed_cap
from controllers.tolerances import HOLD_TOL_M, HOLD_TOL_RAD, POSE_TOL_M
from bridge.body_fleet import FleetBodies
from bridge.sumo_body import BACK_M, RouteBody, window_starts
from tm.pedestrians import PedestrianRule, PedestrianSettings
from tm.settings import TMSettings, default_check
from tm.signals import SignalSettings

#: Gap between a departing vehicle's back and the start of its first lane (m).
DEPART_CLEARANCE_M = 0.5

#: SUMO's step length when a configuration sets none (s).
SUMO_DEFAULT_STEP_S = 1.0
#: SUMO's end beyond the co-simulation's window (s): muvsim, not SUMO's end, stops the run.
END_MARGIN_S = 60.0

#: Options of a user's ``.sumocfg`` run when the command line leaves them out.
SUMOCFG_DEFAULTS = {"tm": "optimal", "switching": "early", "disturbance": "random"}  # check: default_check

__all__ = ["SumoWorld", "junction_zones", "run_sumo"]


#: Padding rows a vehicle keeps per waypoint in :meth:`SumoWorld.claim_pads` (current and requested
#: waypoints, with room for a grant between lookups).
_PAD_ROWS_KEPT = 4
_NEVER = (1e18, 1e18, 0.0)  # pose of a vehicle not yet sent: far from any, so always moved


class SumoWorld:
    """The :class:`~bridge.cosim.World` adapter over a started :class:`SumoAdapter`."""

    def __init__(self, adapter: SumoAdapter, planned: dict, routes: dict, slots: LinkSlots | None = None,
                 net=None):
        self.adapter = adapter
        self.slots = slots  # the signalised links the routes cross (bridge.signals)
        self.planned = planned
        self.routes = routes
        self.net = net  # NetGeometry: SUMO's lane shapes for the bodies (bridge.sumo_body)
        self._body: dict[str, RouteBody] = {}
        self._fleet_bodies = FleetBodies()  # the same bodies, computed on together (bridge.body_fleet)
        self._sigma: dict[str, float] = {}  # vehicle -> arc position of its reference point
        self._pose: dict[str, tuple] = {}   # vehicle -> (front, angle, edge, lane) of this step
        self._pushed: dict[str, np.ndarray] = {}  # vehicles moved by the last push -> front sent
        self._pads: dict = {}               # vehicle -> PadTable (claims' padding)
        #: the tables in use by inputs (:meth:`_pad_key`): vehicles on the same route and lanes, of one
        #: class, share one (a flow's vehicles; SUMO's ``A10KW``: 44 distinct of 369 in 120 s), kept
        #: while a vehicle holds it
        self._pad_shared: weakref.WeakValueDictionary = weakref.WeakValueDictionary()
        self._arcs: dict[str, np.ndarray] = {}  # vehicle -> its waypoints' arc positions on its route
        self._top: dict[str, float] = {}    # vehicle -> furthest arc position reached
        self._j0: dict[str, int] = {}       # vehicle -> its padding window's first sample (claim_pads)
        self._pad_rows: dict[str, dict] = {}  # vehicle -> {k: (j0, last j0, padding row)} (claim_pads)
        #: changes whenever claim_pads may answer differently for the same vehicles and waypoints
        #: (bodies placed: windows moved; a route's padding registered): bridge.pad_memo keeps answers
        self.pads_version = 0
        self._sumo_arrived: set[str] = set()  # vehicles SUMO removed itself at their route's end
        #: Vehicle-steps whose reference point rolled back more than BACK_M or lay farther than
        #: OFFSET_MAX_M from its route (outside what the claims' padding covers).
        self.body_window_exits = 0
        #: Largest distance of a reference point from its route polyline so far (m).
        self.offset_max_m = 0.0
        #: Vehicle-steps whose front SUMO put farther than POSE_TOL_M from the one pushed.
        self.pose_mismatches = 0
        self.pose_mismatch_max_m = 0.0
        self.lengths: dict[str, float] = {}
        self.step_ms = 0.0
        self._sent: dict[str, list] = {}  # vehicle -> (x, y, heading) last sent by moveToXY
        self._held: set[str] = set()      # vehicles SUMO holds at speed 0 (see push)
        self._persons: tuple[list, np.ndarray] = ([], np.zeros((0, 2)))  # read after every step
        self._seen: set[str] = set()
        #: Fastest walking speed of any person so far (m/s; SUMO's person.getMaxSpeed).
        self.ped_speed_max = 0.0

    def route_body(self, vid: str) -> RouteBody | None:
        """SUMO's body along ``vid``'s route (None without the network's geometry)."""
        if self.net is None:
            return None
        b = self._body.get(vid)
        if b is None:
            pv = self.planned[vid]
            b = self._body[vid] = RouteBody(self.routes[vid], self.net, pv.length, pv.width)
            self._fleet_bodies.add(vid, b)
        return b

    def body_leans(self, spec: VehicleSpec) -> np.ndarray | None:
        """Body lean (rad) of each chord of ``spec``'s waypoints (:meth:`bridge.sumo_body.RouteBody.leans`:
        SUMO's body on a lane change lies along the lane, not the diagonal); None without the
        network's geometry."""
        if self.net is None:
            return None
        lean = self.route_body(spec.id).leans(spec.driven_waypoints, self._waypoint_arcs(spec))
        return np.concatenate([lean, np.zeros(len(spec.waypoints) - 1 - len(lean))])  # a run-out: straight

    def _waypoint_arcs(self, spec: VehicleSpec) -> np.ndarray:
        """Arc positions of ``spec``'s waypoints on its route polyline (kept per vehicle).  The
        waypoints are a run of the route's after a first point on the polyline (``trim_start``, and
        in authority mode cut before the route's end), whose arc positions the route knows: the search's hints
        (:meth:`RouteBody.project_along`); other waypoints are searched one after the other."""
        got = self._arcs.get(spec.id)
        if got is None:
            W = spec.driven_waypoints
            r = self.routes[spec.id]
            RW, RA = np.asarray(r.waypoints, dtype=float), np.asarray(r.arc_length, dtype=float)
            hint = None
            n = len(W) - 1
            for m in (np.flatnonzero((RW == W[1]).all(axis=1)).tolist() if len(W) >= 2 else []):
                if m + n <= len(RW) and np.array_equal(W[1:], RW[m:m + n]):
                    hint = np.concatenate([[RA[m] - float(np.hypot(*(W[1] - W[0])))], RA[m:m + n]])
                    break
            got = self._arcs[spec.id] = self.route_body(spec.id).project_along(W, hint)
        return got

    def register_pads(self, spec: VehicleSpec, box_lo, box_hi, frame: str = "road",
                      headings=None) -> np.ndarray | None:
        """Prepare the claims' padding of ``spec`` (:class:`bridge.sumo_body.PadTable`, ``frame`` its
        plant's) for positions in ``[box_lo, box_hi]`` of each waypoint's frame; returns the padding
        (4,) of a vehicle at rest on its first waypoint (None without the network's geometry).
        ``headings`` (K,): the bodies' headings on the chord arriving at each waypoint (a leaning
        path frame's, :class:`controllers.path.PathFrame`); the chords' own by default."""
        if self.net is None:
            return None
        t = self._pads.get(spec.id)
        if t is None:
            b = self.route_body(spec.id)
            W = spec.driven_waypoints  # a run-out past the arrival waypoint is never driven: no padding rows
            arc = self._waypoint_arcs(spec)
            H = spec_headings(W) if headings is None else np.asarray(headings, dtype=float)[:len(W)]
            key = _pad_key(self.routes[spec.id], b, arc, W, H, box_lo, box_hi, frame)
            t = self._pad_shared.get(key)
            if t is None:
                t = self._pad_shared[key] = b.pad_table(arc, W, H, box_lo, box_hi, frame)
            self._pads[spec.id] = t
            self._j0.pop(spec.id, None)
            self._pad_rows.pop(spec.id, None)
            self.pads_version += 1
        return self.entry_pads(spec.id, 0)

    def entry_pads(self, vid: str, k: int) -> np.ndarray | None:
        """The claims' padding (4,) of vehicle ``vid`` (not yet in the network: :meth:`register_pads`
        done) for its waypoint ``k``, for every position from its first waypoint on (a start further
        along, :mod:`bridge.departure`: a window from the route's start holds the one from there);
        None without a table."""
        t = self._pads.get(vid)
        if t is None:
            return None
        return t.pads(min(int(k), len(t.arc_k) - 1), t.arc_k[0] - BACK_M)

    def claim_pads(self, ids, k) -> np.ndarray | None:
        """The claims' padding (n, 4), one-sided (:meth:`bridge.sumo_body.PadTable.pads`), of vehicles
        ``ids`` for their waypoints ``k`` (n,), for the positions still ahead of them (from the
        furthest reference point reached, less :data:`~bridge.sumo_body.BACK_M`); None without the
        network's geometry.  :meth:`claim_pad_runs` without the runs; each run of one vehicle's many
        waypoints (the junction gate's paths, one or several vehicles' at once) in one go
        (:meth:`~bridge.sumo_body.PadTable.pads_many`)."""
        if self.net is None:
            return None
        ids = list(ids)
        n = len(ids)
        k = np.asarray(k).reshape(-1)
        same = np.array(ids[1:], dtype=object) == np.array(ids[:-1], dtype=object)
        if not same.any():  # no vehicle twice in a row
            return self.claim_pad_runs(ids, k)[0]
        out = np.zeros((n, 4))
        first = np.flatnonzero(np.r_[True, ~same])
        ends = np.r_[first[1:], n]
        runs = ends - first > 1
        single = first[~runs]
        starts = first[runs].tolist()
        for a, b, j0 in zip(starts, ends[runs].tolist(), self.pad_windows([ids[a] for a in starts]).tolist()):
            t = self._pads.get(ids[a])
            if t is not None:
                out[a:b] = t.pads_many(k[a:b], int(j0))
        if len(single):
            out[single] = self.claim_pad_runs([ids[i] for i in single.tolist()], k[single])[0]
        return out

    def pad_windows(self, ids) -> np.ndarray:
        """The first sample (int64, (n,)) of each vehicle's padding window (-1 without a table): the
        last one at or before its furthest reference point less ``BACK_M``
        (:func:`bridge.sumo_body.window_starts`), kept until that point moves."""
        pads, j0s = self._pads, self._j0
        out = np.fromiter((j0s.get(v, -2) for v in ids), dtype=np.int64, count=len(ids))
        miss = np.flatnonzero(out == -2)
        if len(miss):
            tabs = [pads.get(ids[i]) for i in miss.tolist()]
            todo = [(i, t) for i, t in zip(miss.tolist(), tabs) if t is not None]
            out[miss] = -1
            if todo:  # PadTable.window_start of the vehicles without one, all at once
                top = self._top
                sig = [top.get(ids[i], t.arc_k[0]) - BACK_M for i, t in todo]
                got = window_starts([t.grid for _, t in todo], sig)
                j0s.update(zip((ids[i] for i, _ in todo), got.tolist()))
                out[[i for i, _ in todo]] = got
        return out

    def claim_pad_runs(self, ids, k) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(pads, j_lo, j_hi)``: :meth:`claim_pads` (n, 4) and, per row, the window starts
        ``[j_lo, j_hi]`` (int64) it holds for (:meth:`pad_windows`: while a vehicle's window start
        stays in them and its ``k`` is the same, so is its row; ``-1, -1`` without a table).

        A row depends on the vehicle's table, ``k`` and the window's first sample ``j0``; ``j0``
        moves only when the furthest point reached passes a sample, ``k`` only at a grant, and the
        row (a suffix maximum) stays the same over long runs of ``j0``
        (:meth:`~bridge.sumo_body.PadTable.pads_run`).  Each vehicle keeps its last row per ``k``
        (:data:`_PAD_ROWS_KEPT` waypoints) with the run of ``j0`` it holds for, and its ``j0``
        until its furthest point moves: a step's many lookups (current and requested waypoints,
        the junction gate, the tube-escape check, the monitor's claims) read a table only when
        the padding may have changed."""
        pads, memo = self._pads, self._pad_rows
        n = len(ids)
        out = np.zeros((n, 4))
        j_lo = np.full(n, -1, dtype=np.int64)
        j_hi = np.full(n, -1, dtype=np.int64)
        kk = np.asarray(k).reshape(-1).tolist()
        for i, (v, j, ki) in enumerate(zip(ids, self.pad_windows(ids).tolist(), kk)):
            if j < 0:
                continue
            rows = memo.get(v)
            if rows is None:
                rows = memo[v] = {}
            got = rows.get(ki)
            if got is None or not got[0] <= j <= got[1]:
                row, j1 = pads[v].pads_run(ki, j)
                got = (j, j1, row)
                if ki not in rows and len(rows) >= _PAD_ROWS_KEPT:
                    del rows[min(rows)]  # waypoints left behind (a vehicle's k only grows)
                rows[ki] = got
            out[i] = got[2]
            j_lo[i], j_hi[i] = got[0], got[1]
        return out, j_lo, j_hi

    def _poses(self, ids, centre):
        """SUMO's bodies for reference points ``centre`` (see :mod:`bridge.sumo_body`), all vehicles at
        once (:class:`bridge.body_fleet.FleetBodies`); caches the front, angle and lane of each for
        :meth:`push`."""
        self.pads_version += 1  # the windows of the claims' padding move with the reference points
        bodies = [self.route_body(v) for v in ids]
        around = np.array([self._sigma.get(v, np.nan) for v in ids], dtype=float)
        sig, e = self._fleet_bodies.project(ids, centre, around)
        front, back, lane, corners = self._fleet_bodies.bodies(ids, sig, e)
        self._sigma.update(zip(ids, sig.tolist()))
        off = np.abs(e)
        self.offset_max_m = max(self.offset_max_m, float(off.max(initial=0.0)))
        cap = np.array([t.offset_max if (t := self._pads.get(v)) is not None else np.inf for v in ids])
        self.body_window_exits += int(np.sum(off > cap + 1e-9))  # off the padding's offsets
        prev = np.array([self._top.get(v, np.nan) for v in ids], dtype=float)
        top = np.where(np.isnan(prev), sig, prev)
        self.body_window_exits += int(np.sum(sig < top - BACK_M))  # rolled back past the padding's window
        top_new = np.maximum(top, sig)
        for v in (ids[i] for i in np.flatnonzero(top_new != prev).tolist()):  # NaN: new here
            self._j0.pop(v, None)  # its padding window moved: claim_pads reads the start anew
        self._top.update(zip(ids, top_new.tolist()))
        ax = front - back
        ang = sumo_angle(np.arctan2(ax[:, 1], ax[:, 0])).tolist()
        for v, b, f, a, k in zip(ids, bodies, front, ang, lane.tolist()):
            self._pose[v] = (f, a, b.edge[k], b.index[k])
        return corners

    def bodies(self, ids, centre, heading, length, width) -> np.ndarray | None:
        """The bodies SUMO will judge after the next push of these reference points (``(V, 4, 2)``,
        :mod:`bridge.sumo_body`); None without the network's geometry (then the monitor uses
        rectangles)."""
        if self.net is None:
            return None
        return self._poses(list(ids), np.asarray(centre, dtype=float).reshape(-1, 2))

    def insert(self, spec: VehicleSpec, vclass, k: int = 0) -> None:
        """Add ``spec``'s vehicle to SUMO with its centre on waypoint ``k``."""
        pv, r = self.planned[spec.id], self.routes[spec.id]
        self.lengths[spec.id] = pv.length
        W = np.asarray(spec.waypoints, dtype=float)[k:]
        if self.net is not None:
            self._sigma.pop(spec.id, None)
            self._poses([spec.id], W[:1])
            front, ang, edge, lane = self._pose.pop(spec.id)
            self.adapter.admit(pv, front, ang, depart_lane=r.depart_lane_index, hint_edge=edge, hint_lane=lane)
            return
        h0 = float(np.arctan2(*(W[1] - W[0])[::-1]))
        self.adapter.admit(pv, front_bumper(W[0], h0, pv.length), sumo_angle(h0),
                           depart_lane=r.depart_lane_index)

    def push(self, ids, centre, heading) -> None:
        """Move the vehicles whose pose changed (beyond :data:`HOLD_TOL_M` /
        :data:`HOLD_TOL_RAD` since it was last sent); hold the others still in SUMO.  With the
        network's geometry the front pushed is SUMO's body's (:meth:`bodies`, computed here when
        not yet this step)."""
        c = np.asarray(centre, dtype=float).reshape(-1, 2)
        h = np.asarray(heading, dtype=float).reshape(-1)
        last = np.array([self._sent.get(v, _NEVER) for v in ids], dtype=float).reshape(-1, 3)
        still = (np.hypot(c[:, 0] - last[:, 0], c[:, 1] - last[:, 1]) < HOLD_TOL_M) & \
            (np.abs(np.angle(np.exp(1j * (h - last[:, 2])))) < HOLD_TOL_RAD)
        hold = [v for v, s in zip(ids, still.tolist()) if s and v not in self._held]
        if hold:
            self.adapter.hold(hold)
            self._held.update(hold)
        mv = np.flatnonzero(~still)
        self._pushed = {}
        if not len(mv):
            self._pose = {}
            return
        mids = [ids[i] for i in mv.tolist()]
        release = [v for v in mids if v in self._held]
        if release:
            self.adapter.release(release)
            self._held.difference_update(release)
        if self.net is not None:
            todo = [i for i in mv.tolist() if ids[i] not in self._pose]
            if todo:
                self._poses([ids[i] for i in todo], c[todo])
            poses = [self._pose[v] for v in mids]
            fronts = np.array([p[0] for p in poses]).reshape(-1, 2)
            self.adapter.move(mids, fronts, [p[1] for p in poses], [p[2] for p in poses], [p[3] for p in poses])
            self._pushed = dict(zip(mids, fronts))
        else:
            lengths = np.array([self.lengths[v] for v in mids])
            self.adapter.move(mids, front_bumper(c[mv], h[mv], lengths), sumo_angle(h[mv]))
        self._sent.update(zip(mids, np.column_stack([c[mv], h[mv]]).tolist()))

    def link_states(self) -> np.ndarray | None:
        """SUMO's state letter of every signalised link in use, one byte per slot (None: no signals)."""
        return self.slots.states(self.adapter) if self.slots else None

    def link_time_to_red(self) -> np.ndarray | None:
        """Per slot, the time (s) until its link turns red (:meth:`bridge.signals.LinkSlots.time_to_red`)."""
        return self.slots.time_to_red(self.adapter) if self.slots else None

    def finish(self, vid: str) -> None:
        self._sent.pop(vid, None)
        self._held.discard(vid)
        self._sigma.pop(vid, None)
        self._body.pop(vid, None)
        self._fleet_bodies.remove(vid)
        self._pads.pop(vid, None)
        self._arcs.pop(vid, None)
        self._top.pop(vid, None)
        self._j0.pop(vid, None)
        self._pad_rows.pop(vid, None)
        if vid in self._sumo_arrived:  # SUMO ended the trip itself (its front at the route's end)
            self._sumo_arrived.discard(vid)
            return
        self.adapter.finish(vid)

    def check_poses(self) -> int:
        """Count the vehicles moved by the last push whose front SUMO has farther than
        :data:`~controllers.tolerances.POSE_TOL_M` from the front pushed, or off every lane (with
        ``keepRoute=3`` a front off the road stays there, and SUMO checks no collision for it)."""
        gone = set(self.adapter.arrived_ids())  # SUMO may end a trip itself (a front at its route's end)
        self._sumo_arrived |= gone & set(self._pushed)
        ids = [v for v in self._pushed if v not in gone]
        if not ids:
            return 0
        got = self.adapter.positions(ids)
        want = np.array([self._pushed[v] for v in ids]).reshape(-1, 2)
        d = np.hypot(*(got - want).T)
        off = np.array([lane == "" for lane in self.adapter.lane_ids(ids)])  # off every lane: unjudged
        n = int(np.sum((d > POSE_TOL_M) | off))
        self.pose_mismatches += n
        self.pose_mismatch_max_m = max(self.pose_mismatch_max_m, float(d.max(initial=0.0)))
        return n

    def step(self) -> list:
        t = time.perf_counter()
        self.adapter.step()
        self._pose = {}
        self.check_poses()
        api = self.adapter._need("persons")
        self._persons = read_persons(api)
        new = [p for p in self._persons[0] if p not in self._seen]
        if new:  # each new person's own walking speed (its vType's, times its speed factor)
            self._seen.update(new)
            self.ped_speed_max = max([self.ped_speed_max] + [float(api.person.getMaxSpeed(p)) for p in new])
        self.step_ms = (time.perf_counter() - t) * 1e3
        return [e.pair for e in self.adapter.collisions()]

    def pedestrians(self) -> tuple[list, np.ndarray]:
        """Every person's id and position ``(P, 2)`` after the last step (SUMO moves them)."""
        return self._persons


def run_out(W: np.ndarray, limits: np.ndarray, vc) -> tuple[np.ndarray, np.ndarray, int]:
    """Waypoints ``W`` (K, 2) with a straight run-out past their last along the last segment, long
    enough for the class to come to rest from its top speed at its comfort deceleration plus three
    waypoint gaps (so that the stop point never makes it brake for the route's end), waypoints
    ``delta`` apart at the last lane limit; returns them, their limits and the arrival index K - 1
    (:attr:`bridge.cosim.VehicleSpec.arrive_k`)."""
    W = np.asarray(W, dtype=float)
    d = W[-1] - W[-2]
    d = d / np.hypot(*d)
    delta = float(vc.model.delta)
    length = float(vc.v_max) ** 2 / (2.0 * float(vc.comfort_decel)) + 3.0 * delta
    steps = delta * np.arange(1, int(np.ceil(length / delta)) + 1)
    ext = W[-1] + steps[:, None] * d[None, :]
    lim = np.asarray(limits, dtype=float)
    return np.vstack([W, ext]), np.concatenate([lim, np.full(len(ext), lim[-1])]), len(W) - 1


def _pad_key(route, body: RouteBody, arc, W, H, box_lo, box_hi, frame: str) -> tuple:
    """Everything a :class:`bridge.sumo_body.PadTable` is built from: the route's polyline, its
    segments' lanes and whether they lie on them (its :class:`bridge.sumo_body.RouteBody`, with the
    network's lane shapes), the body's size, the waypoints, their arcs and headings, the box and the
    frame.  Equal keys, equal tables (a table's later lookups read only its own arrays)."""
    f = lambda a: np.ascontiguousarray(a, dtype=float).tobytes()  # noqa: E731
    return (frame, body.length, body.width, f(box_lo), f(box_hi), f(body.poly),
            np.asarray(route.segment_on_lane, dtype=bool).tobytes(), tuple(route.segment_lanes), f(arc), f(W), f(H))


def junction_zones(net_path) -> list[Zone]:
    """Every junction where two or more edges enter and some of its links conflict, as a zone (its
    shape's bounding box).

    A junction whose right-of-way matrix lists no foes (every ``<request>``'s ``foes`` all zeros:
    SUMO found no two of its links crossing or merging, pedestrian crossings included) is no zone:
    its movements run side by side, and a token would only serialise them.  On SUMO's ``ramp`` the
    on-ramp's lane joins the motorway at ``gneJ4`` as a lane of its own; as a zone, ramp vehicles
    waited at its entry line for the right lane's stream to leave the guard, and the right lane for
    them (README, Known limits).  A junction without a matrix (no ``<request>``) stays a zone."""
    root = parse_xml(net_path).getroot()
    zones = []
    for j in root.iter("junction"):
        if j.get("type") in ("internal", "dead_end"):
            continue
        inc = [e for e in (j.get("incLanes") or "").split() if e]
        edges = {lane.rsplit("_", 1)[0] for lane in inc}
        shape = j.get("shape")
        if len(edges) < 2 or not shape or _conflict_free(j):
            continue
        pts = np.array([[float(c) for c in p.split(",")[:2]] for p in shape.split()])
        zones.append(Zone(j.get("id"), tuple(pts.min(axis=0)), tuple(pts.max(axis=0))))
    return zones


def _conflict_free(junction) -> bool:
    """Whether a ``<junction>`` element's right-of-way matrix has requests and lists no foes."""
    foes = [r.get("foes") or "" for r in junction.iter("request")]
    return bool(foes) and not any("1" in f for f in foes)


def _classes_for(scenario, demand, classes, source=None):
    """The muvsim class of every vehicle: the scenario's mapping, or for a user's .sumocfg a
    vType named like a class, else its SUMO vClass (``VCLASS_TO_CLASS``); any other vClass
    (bicycle, pedestrian, ...) is refused by name, never driven as a car."""
    from sumo_nets.scenario import VCLASS_TO_CLASS, ScenarioError

    out = {}
    for pv in demand.vehicles:
        if scenario is not None:
            name = scenario.class_for(pv.type_id, pv.vclass)
        elif pv.type_id in ("car", "bus", "truck"):
            name = pv.type_id
        elif pv.vclass in VCLASS_TO_CLASS:
            name = VCLASS_TO_CLASS[pv.vclass]
        else:
            raise ScenarioError(
                f"{source or 'the demand'}: vehicle {pv.id!r}: vType {pv.type_id!r} has vClass {pv.vclass!r}, "
                f"which muvsim cannot drive (it has no class for it); valid vClasses: "
                f"{', '.join(sorted(VCLASS_TO_CLASS))} (or a vType named car, bus or truck)")
        if name not in classes:
            raise ValueError(f"vehicle {pv.id}: vType {pv.type_id!r} maps to unknown class {name!r}")
        out[pv.id] = name
    return out


def _vtype_classes(demand, max_lane_speed: float) -> tuple[dict[str, VehicleClass], dict[str, str]]:
    """One class per distinct vType parameter set (SUMO's own values, the speed capped by
    :func:`controllers.classes.vtype_speed_cap` of the network's fastest lane), and each
    vehicle's class."""
    classes: dict[str, VehicleClass] = {}
    of_type: dict[str, str] = {}
    cap = vtype_speed_cap(max_lane_speed)
    for tid, t in demand.types.items():
        p = VTypeParams(t.vclass, t.length, t.width, t.accel, t.decel, t.max_speed)
        if p.name not in classes:
            classes[p.name] = vtype_class(p, cap)
        of_type[tid] = p.name
    return classes, {pv.id: of_type[pv.type_id] for pv in demand.vehicles}


def _check_drivable(vid: str, W, vclass: VehicleClass) -> None:
    """Raise RouteError when the waypoints break the class's turn bound (as Cosim checks it)."""
    m = vclass.model
    W = np.asarray(W, dtype=float)
    if m.frame != "road" or len(W) <= 2:
        return
    d = np.diff(W, axis=0)
    h = np.arctan2(d[:, 1], d[:, 0])
    turn = np.degrees(np.abs((np.diff(h) + np.pi) % (2 * np.pi) - np.pi))
    if np.any(turn > m.turn_max_deg + 1e-6):
        i = int(np.argmax(turn))
        raise RouteError(f"vehicle {vid!r}: its route turns by {turn[i]:.1f} deg at waypoint {i + 1}; class "
                         f"{vclass.name!r} accepts at most {m.turn_max_deg} deg between segments")


def _report_undrivable(out: Path, undrivable: dict, begin: float) -> None:
    """Rows ``status = undrivable`` with the reason in vehicles.csv (driven vehicles: ``driven``)."""
    import pandas as pd

    path = out / "vehicles.csv"
    df = pd.read_csv(path) if path.exists() else pd.DataFrame()
    if "status" not in df.columns:
        df["status"] = "driven"
    if "reason" not in df.columns:
        df["reason"] = ""
    rows = pd.DataFrame([{"id": vid, "departure_s": pv.depart_s - begin, "status": "undrivable", "reason": why}
                         for vid, (pv, why) in undrivable.items()])
    pd.concat([df, rows], ignore_index=True).to_csv(path, index=False)


def run_sumo(target: str, out: Path, opts, observers_extra: list | None = None) -> dict:
    """Run a SUMO scenario (built-in name, scenario TOML or .sumocfg) and write its outputs.

    ``observers_extra``: more :class:`~bridge.cosim.Cosim` observers (``on_step(sim, state,
    decision, row)``), called before the run's own outputs; e.g. a test recording the decisions."""
    from sumo_nets.scenario import ScenarioError, load_scenario, materialise, read_sumocfg

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    summary: dict = {"scenario": str(target), "complete": False, "baseline": opts.baseline or "muvsim"}
    _write_summary(out, summary)
    t0 = time.perf_counter()
    sim = None
    world = None
    undrivable: dict = {}
    observers: list = []
    adapter = SumoAdapter()
    try:
        begin, cfg = 0.0, None
        if str(target).endswith(".sumocfg"):
            scenario = None
            cfg = read_sumocfg(target)
            # a copy plain sumo loads (no gui-only options); opened with the GUI as it is
            sumocfg = cfg.path if opts.gui else headless_config(cfg.path, out / "inputs" / cfg.path.name)
            net = cfg.net
            # the configuration's own seed, begin and end, as plain `sumo -c` runs it
            seed = cfg.run_seed if opts.seed is None else opts.seed
            begin = cfg.begin_s
            routes_in, additional = cfg.routes, cfg.additional
            # the run's window as plain `sumo -c` runs it: --duration, else the configuration's
            # end - begin; with neither, until every vehicle of the demand arrived (at most the cap)
            if opts.duration or cfg.duration_s:
                duration = opts.duration or cfg.duration_s
                limit = RunLimit(duration, False, duration)
                expand_end = begin + duration
            else:
                deps = [d - begin for d in route_file_departures(list(routes_in) + list(additional))]
                limit = run_limit(deps, None)
                duration = limit.duration_s
                expand_end = begin + limit.window_s + 1.0  # every departure of the files, none cut at the edge
            tm, switching, disturbance = (getattr(opts, k) or SUMOCFG_DEFAULTS[k]
                                          for k in ("tm", "switching", "disturbance"))
            check = opts.check or default_check(getattr(opts, "controller", "paper"))
        else:
            scenario = load_scenario(target)
            if opts.seed is not None and scenario.demand is not None:  # --seed draws the demand too
                scenario = replace(scenario, demand=replace(scenario.demand, seed=opts.seed))
            files = materialise(scenario, out / "inputs")
            sumocfg, net = files.sumocfg, files.net
            seed = scenario.seed if opts.seed is None else opts.seed
            routes_in, additional = files.routes, ()
            if scenario.demand is not None:
                summary["demand_seed"] = scenario.demand.seed
            tm = opts.tm or scenario.tm
            check = opts.check or scenario.check or default_check(getattr(opts, "controller", "paper"))
            switching = opts.switching or scenario.switching
            disturbance = opts.disturbance or scenario.disturbance
        signals = SignalSettings(mode=getattr(opts, "signals", None) or "obey")
        # curve speeds; --lat-accel net: the lateral acceleration the network's turn speeds were built with
        speed = SpeedSettings.from_options(
            opts, net_turn_accel(net) if getattr(opts, "lat_accel", None) == "net" else None)
        summary.update(seed=seed, begin_s=begin,
                       options=dict(tm=tm, check=check, switching=switching, disturbance=disturbance,
                                    solver=opts.solver, duration_s=opts.duration, signals=signals.mode,
                                    controller=getattr(opts, "controller", "paper"),
                                    claim_cache=getattr(opts, "claim_cache", None) or "on",
                                    frame=getattr(opts, "frame", None) or "auto",
                                    arrival=getattr(opts, "arrival", None) or "stop",
                                    speed_limits=getattr(opts, "speed_limits", None) or "obey",
                                    lat_accel=speed.lat_accel if speed.curves else 0.0))
        _write_summary(out, summary)
        tripinfo = out / "tripinfo.xml"
        inputs = None
        if cfg is not None:
            inputs = prepare_inputs(cfg.routes, cfg.additional, out / "inputs")
        if opts.baseline == "sumo":
            planned = None
            if cfg is None:
                planned = _planned_demand(routes_in, additional)
                deps = [pv.depart_s for pv in planned.vehicles] if planned is not None \
                    else route_file_departures(routes_in)
                limit = run_limit(deps, opts.duration)
            return _run_baseline(adapter, sumocfg, tripinfo, seed, limit, out, summary, t0,
                                 None if planned is None else len(planned), cfg=cfg, inputs=inputs)
        if cfg is not None:
            # SUMO's own expansion of the demand, with the baseline's seed and step
            demand = adapter.expand_demand(sumocfg, inputs, begin_s=begin, end_s=expand_end, seed=seed,
                                           step_length=cfg.step_length_s or SUMO_DEFAULT_STEP_S,
                                           work_dir=out / "inputs")
            demand = adapter.start(sumocfg, tripinfo_path=tripinfo, seed=seed, gui=opts.gui, demand=demand,
                                   inputs=inputs, preflight=False,
                                   extra_args=["--begin", f"{begin:.10g}",
                                               "--end", f"{begin + duration + END_MARGIN_S:.10g}"])
            classes, cls_of = _vtype_classes(demand, load_net(net).max_lane_speed)
        else:
            demand = adapter.start(sumocfg, tripinfo_path=tripinfo, seed=seed, gui=opts.gui)
            limit = run_limit([pv.depart_s for pv in demand.vehicles], opts.duration)
            duration = limit.duration_s
            classes = builtin_classes()
            cls_of = _classes_for(scenario, demand, classes)
        geo = load_net(net)
        routes, specs, undrivable = {}, [], {}
        stops_skipped: list[str] = []  # planned stops a vehicle cannot serve (messages)
        lanes = DepartLanes(seed)  # departLane keywords: the lane SUMO would pick
        slots = LinkSlots()
        authority = getattr(opts, "controller", "paper") == "authority"
        for pv in demand.vehicles:
            c = cls_of[pv.id]
            try:
                m = classes[c].model
                lane = pv.depart_lane if pv.depart_lane is not None else \
                    lanes.pick(pv.edges[0], pv.depart_lane_rule, geo.start_lanes(pv.edges, pv.vclass)
                               if pv.depart_lane_rule is not None else {})
                r = geo.route(pv.edges, m.delta, vclass=pv.vclass, vehicle_id=pv.id, depart_lane=lane,
                              turn_max_deg=m.turn_max_deg if m.frame == "road" else None)
                # depart with the whole body on the first lane (SUMO's departPos="base"), not
                # with its back half in the junction behind it
                s0 = 0.5 * classes[c].length + DEPART_CLEARANCE_M
                W = trim_start(r, s0)
                _check_drivable(pv.id, W, classes[c])
                kept = trim_start_index(r, s0)
                limits = geo.speed_limits(r)[kept]
                straight = geo.straight_through(r)[kept]
                arc = r.arc_length[kept].astype(float)
                arc[0] = min(max(s0, 0.0), 0.5 * r.length_m)  # trim_start's first point
                arrive_k = None
                if authority:
                    # stop with the whole body on the last lane: SUMO clamps a front bumper pushed
                    # past a dead end back onto the lane (measured: a 0.3 m overlap with a close follower)
                    n = max(int(np.sum(arc <= r.length_m - s0)), 2)
                    W, limits, arc, straight = W[:n], limits[:n], arc[:n], straight[:n]
                plan = None
                if authority:
                    edge_end = first_edge_end(r)
                    plan = depart_plan(arc, classes[c].length, edge_end, pv.depart_pos_m, pv.depart_speed_mps,
                                       first_lane_m=edge_end)
                lines = route_stop_lines(geo, r, arc, slots)
                stops, left = plan_stops(pv.id, arc, [geo.route_arc_at(r, st.lane, st.end_pos_m) for st in pv.stops],
                                         pv.stops, classes[c].length, begin)
                stops_skipped.extend(left)
                if plan is not None and stops and plan.stop_max > stops[0].k:  # it must not start past its stop
                    plan = DepartPlan(min(plan.k, stops[0].k), plan.speed, stops[0].k)
                if authority and summary["options"]["arrival"] == "pass" and geo.ends_at_boundary(pv.edges[-1]):
                    W, limits, arrive_k = run_out(W, limits, classes[c])
                    straight = np.concatenate([straight, np.zeros(len(W) - len(straight), dtype=bool)])
            except RouteError as exc:  # one vehicle never ends the run: reported, the rest run
                undrivable[pv.id] = (pv, str(exc))
                continue
            routes[pv.id] = r
            specs.append(VehicleSpec(id=pv.id, vclass=c, waypoints=W, depart_s=pv.depart_s - begin,
                                     speed_limits=limits, stop_lines=lines, arrive_k=arrive_k, depart=plan, stops=stops,
                                     straight=straight if straight.any() else None,
                                     junctions=geo.route_junctions(pv.edges)))
        summary["vehicles_undrivable"] = len(undrivable)
        for why in stops_skipped:  # a stop SUMO's own run would not serve either: said, not hidden
            print(f"muvsim: warning: {why}; it is left out", file=sys.stderr)
        world = SumoWorld(adapter, {pv.id: pv for pv in demand.vehicles if pv.id in routes}, routes, slots=slots,
                          net=geo)
        settings = CosimSettings(tm=TMSettings(policy=tm, check=check, seed=seed), switching=switching,
                                 disturbance=disturbance, solver=opts.solver, seed=seed, duration_s=duration,
                                 signals=signals, controller=getattr(opts, "controller", "paper"),
                                 speed=speed,
                                 claim_cache=summary["options"]["claim_cache"] == "on",
                                 frame=summary["options"]["frame"])
        observers = [HaltCounter()] + observers_for(out, getattr(opts, "log", None) or "none",
                                                    {"scenario": str(target), "seed": seed, **summary["options"]})
        observers += list(observers_extra or [])
        observers.append(StreamingOutputs(out, dict(summary)))  # last: the row is complete by then
        peds = PedestrianRule(PedestrianSettings(enabled=getattr(opts, "pedestrians", None) != "ignore"),
                              walk_regions(net), settings.Ts)
        summary["options"]["pedestrians"] = "guard" if peds.settings.enabled else "ignore"
        sim = Cosim(classes, specs, settings, world=world, zones=junction_zones(net), observers=observers,
                    pedestrians=peds, crossings=walk_regions(net, functions=("crossing",)))
        bar = None
        if not getattr(opts, "quiet", False):
            from tqdm import tqdm
            bar = tqdm(total=int(round(duration / settings.Ts)), unit="step", file=sys.stderr,
                       mininterval=1.0, leave=False)

        def progress(s):
            if bar is not None:
                bar.update(1)
                if s.t % 50 == 0:
                    bar.set_postfix(active=sum(len(g.ids) for g in s.groups.values()),
                                    waiting=len(s.pending))

        sim.run(int(round(duration / settings.Ts)) + 1, progress=progress)
        if bar is not None:
            bar.close()
        summary["complete"] = True
    except KeyboardInterrupt:
        summary["interrupted"] = True  # written below; the caller says where it stopped
        raise
    except (ScenarioError, RouteError, SumoError, InputError) as exc:
        summary["error"] = f"{type(exc).__name__}: {exc}"
    except Exception as exc:
        if interrupt_behind(exc):  # a Ctrl-C that came back wrapped (bridge.interrupt)
            summary["interrupted"] = True
            raise KeyboardInterrupt from exc
        summary.update(error=f"{type(exc).__name__}: {exc}", traceback=traceback.format_exc(limit=6))
    finally:
        try:
            adapter.close()
        except Exception:  # pragma: no cover - a dead SUMO
            pass
        log_errors = close_observers(observers)
        if log_errors:
            summary["log_error"] = "; ".join(log_errors)
        wall = time.perf_counter() - t0
        summary["wall_s"] = round(wall, 3)
        if sim is not None:
            figures = write_run_tables(out, sim, out / "tripinfo.xml")
            summary.update(figures)
            summary.update(
                collisions_sumo=len(sim.collisions_world),
                pose_mismatches=world.pose_mismatches if world is not None else 0,
                pose_mismatch_max_m=round(world.pose_mismatch_max_m, 6) if world is not None else 0.0,
                route_offset_max_m=round(world.offset_max_m, 4) if world is not None else 0.0,
                red_violations=sim.red_violations, signal_withheld=sim.signal_book.withheld,
                vehicle_stops=sum(len(sp.stops) for sp in specs), vehicle_stops_served=sim.filters.stops.served,
                vehicle_stops_missed=len(stops_skipped) + sim.filters.stops.passed,
                pedestrian_conflicts=len(sim.pedestrian_conflicts),
                pedestrian_withheld=sim.pedestrian_withheld, crossing_withheld=sim.crossing_withheld,
                pedestrian_speed_bound_mps=round(sim.pedestrians.v_max, 4),
                vehicles_total=figures["vehicles"],
                stop_reason=stop_reason(limit, figures["vehicles"], figures["vehicles_arrived"],
                                        figures["simulated_s"]),
                rtf=round(sim.t * sim.settings.Ts / wall, 3) if wall > 0 else None)
            if sim.claim_cache is not None:  # rows of current claims: offered, shifted, computed fresh
                st = sim.claim_cache.stats
                summary.update(claim_cache_offered=st.offered, claim_cache_reused=st.reused,
                               claim_cache_fresh=st.fresh)
            if undrivable:
                _report_undrivable(out, undrivable, begin)
                summary["vehicles_total"] = figures["vehicles"] + len(undrivable)
            summary.update(_persons_table(out, out / "tripinfo.xml"))
            summary.update(verdict(summary))
        _write_summary(out, summary)
    return summary


def _persons_table(out: Path, tripinfo: Path) -> dict:
    """persons.csv (SUMO's personinfo: one row per person that finished) and the summary's figures:
    pedestrians' delay is the walks' ``timeLoss``."""
    try:
        df = read_personinfo(tripinfo)
    except Exception:  # no tripinfo written (SUMO failed early): no persons figures
        return {}
    df.to_csv(out / "persons.csv", index=False)
    done = df["arrival_s"].notna()
    return {"persons_arrived": int(done.sum()),
            "mean_person_delay_s": float(df.loc[done, "walk_time_loss_s"].mean()) if done.any() else None,
            "mean_person_travel_time_s": float(df.loc[done, "duration_s"].mean()) if done.any() else None}


def _planned_demand(routes, additional):
    """The demand of routed route files as muvsim reads it (None for trips/flows or unreadable files)."""
    from bridge.demand import DemandError, needs_routing, read_demand

    if not routes or needs_routing(routes):
        return None
    try:
        return read_demand(list(routes), type_files=list(additional))
    except DemandError:
        return None


def _run_baseline(adapter: SumoAdapter, sumocfg, tripinfo, seed, limit, out, summary, t0,
                  demand_size: int | None = None, *, cfg=None, inputs=None) -> dict:
    """The same demand driven by SUMO's own drivers (no muvsim control), until ``limit``.

    A user's ``.sumocfg`` (``cfg``) runs as ``sumo -c`` runs it over the window
    ``begin .. begin + duration``: its own step length and seed, its inputs (output
    elements of additional files dropped, ``inputs``).  Only trips SUMO finished inside the
    window are arrivals (undeparted and unfinished ones written by
    ``tripinfo-output.write-undeparted/-unfinished`` are not); free flow is SUMO's
    ``duration - timeLoss`` (lanes' speed limits, the vType's maxSpeed), so delay = timeLoss >= 0.
    Generated scenarios keep muvsim's 0.1 s step and the class speed bound.
    ``vehicles_total`` is the demand's size when known (routed route files), else the
    vehicles of SUMO's demand inside the window.
    """
    if cfg is not None:
        res = adapter.run_native(sumocfg, duration_s=limit.duration_s, seed=seed, tripinfo_path=tripinfo,
                                 begin_s=cfg.begin_s, step_length=cfg.step_length_s,
                                 extra_args=inputs.args("expansion") if inputs is not None else ())
    else:
        res = adapter.run_native(sumocfg, duration_s=limit.duration_s, seed=seed, tripinfo_path=tripinfo,
                                 step_length=0.1)
    wall = time.perf_counter() - t0
    ti = read_tripinfo(tripinfo)
    finished = (ti["depart_s"] >= 0) & (ti["arrival_s"] >= 0)
    vehicles = baseline_vehicle_table(ti[finished].reset_index(drop=True),
                                      {c: vc.v_max for c, vc in builtin_classes().items()})
    if cfg is not None:
        vehicles["free_flow_s"] = vehicles["travel_time_s"] - vehicles["sumo_time_loss_s"]
        vehicles["delay_s"] = vehicles["sumo_time_loss_s"]
        vehicles["vclass"] = ti.loc[finished, "vtype"].to_numpy()
        for c in ("departure_s", "admitted_s", "arrival_s"):  # times from the window's begin, as muvsim's
            vehicles[c] = vehicles[c] - cfg.begin_s
    vehicles.to_csv(out / "vehicles.csv", index=False)
    arrived = vehicles["arrival_s"].notna()
    summary.update(complete=True, steps=res["steps"], simulated_s=res["simulated_s"],
                   collisions_sumo=len(res["collision_pairs"]), vehicles_arrived=int(arrived.sum()),
                   vehicles_unfinished=int((~finished).sum()),
                   halt_episodes=int(vehicles["halt_episodes"].sum()),  # SUMO's waitingCount, finished trips
                   mean_travel_time_s=float(vehicles["travel_time_s"].mean()) if arrived.any() else None,
                   mean_delay_s=float(vehicles["delay_s"].mean()) if arrived.any() else None,
                   throughput_vph=round(float(arrived.sum()) * 3600.0 / res["simulated_s"], 3)
                   if res["simulated_s"] else None,
                   rtf=round(res["simulated_s"] / wall, 3), wall_s=round(wall, 3))
    total = demand_size if demand_size is not None else res.get("vehicles_in_window")
    if total is not None:
        summary["vehicles_total"] = int(total)
        summary["stop_reason"] = stop_reason(limit, summary["vehicles_total"], summary["vehicles_arrived"],
                                             res["simulated_s"])
    summary.update(_persons_table(out, tripinfo))
    _write_summary(out, summary)
    return summary
