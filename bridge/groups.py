"""The active vehicles of one class as arrays (the co-simulation loop's per-class state)."""

from __future__ import annotations

import time

import numpy as np

from controllers import tolerances as tol
from controllers.classes import VehicleClass
from controllers.speed_limits import RouteSpeeds, bound_at, plan_steps, restart_slack
from controllers.stmpc import STMPC

__all__ = ["_Group", "_headings", "live_groups"]


#: Columns of a group's waypoint buffer: x, y, heading (the controller's frame), then the speed
#: tables of :mod:`controllers.speed_limits` (arc shifted per route so that it increases over the
#: buffer, gap bound, look-ahead speed, lane limit), then x, y, heading in the world (the same as
#: the first three for a road-frame plant; a path-frame plant's waypoints are ``(S_k, 0)``, heading 0).
_X, _Y, _H, _ARC, _BOUND, _ENV, _LANE, _WX, _WY, _WH = range(10)
_COLS = 10
#: Gap between the shifted arcs of two routes in a buffer (m): more than any look-ahead.
_ROUTE_GAP_M = 1.0e4


class _Group:
    """The active vehicles of one class, as arrays.

    ``slack_steps``: see :class:`controllers.speed_limits.SpeedSettings`; ``decel``: the
    look-ahead's comfort deceleration (m/s^2)."""

    def __init__(self, vclass: VehicleClass, ctl: STMPC, decel: float = 1.0, slack_steps: int = 3):
        self.vclass = vclass
        self.ctl = ctl
        self.decel = float(decel)
        self.slack_steps = int(slack_steps)
        # the speed a bound must lie below to bind: the class bound, or the fastest speed any of
        # its tubes allows if that is lower (the paper's sets: 6.56 m/s for the car)
        self.v_max = min(float(vclass.model.z_bounds[1][0]), float(getattr(ctl, "v_top", np.inf)))
        self.u_max = float(vclass.model.u_bounds[1][0])
        self._arc_next = 0.0
        n = vclass.model.n
        self.ids: list[str] = []
        self.X = np.zeros((0, n))
        self.k = np.zeros(0, dtype=np.intp)
        self.l = np.zeros(0, dtype=np.intp)
        self.W: list[np.ndarray] = []  # world waypoints and headings of each route
        self.H: list[np.ndarray] = []
        # every route's waypoints and headings in one buffer, so that the current (or next)
        # waypoints of all vehicles are one gather: row start[i] + k[i] of vehicle i
        self._wbuf = np.zeros((1024, _COLS))
        self._used = 0
        self.start = np.zeros(0, dtype=np.intp)
        self.K = np.zeros(0, dtype=np.intp)
        # per-vehicle accumulators (flushed into the VehicleRecords by Cosim)
        self.speed_sum = np.zeros(0)
        self.steps = np.zeros(0, dtype=np.intp)
        self.denied_last = np.zeros(0, dtype=bool)
        self.req_l = np.zeros(0, dtype=np.intp)  # request indices of the last TM state
        self.cap = np.zeros(0)                   # this step's speed bounds (m/s), see speed_caps
        self.excess = np.zeros(0)                # largest speed over the front's lane limit so far (m/s)
        self.k_end = np.zeros(0, dtype=np.intp)  # arrival waypoints (K - 1: at rest on the last; see arrived)
        self.binds = np.zeros(0, dtype=bool)     # whether some speed bound of the route lies below v_max
        self.pinned = np.zeros(0, dtype=bool)    # tube index at its fastest fall while a bound binds (request)

    def add(self, vid, W, H, x0, l0, speeds: RouteSpeeds | None = None, world=None, k_end: int | None = None,
            k0: int = 0):
        """Add a vehicle: waypoints ``W`` (K, 2) and headings ``H`` (K,) in the controller's frame,
        state ``x0``, index ``l0`` for its current waypoint ``k0``; ``world``: ``(W, H)`` in the world
        when the controller's frame is not (a path-frame plant), else the same; ``k_end``: its arrival
        waypoint (:attr:`bridge.cosim.VehicleSpec.arrive_k`; None: the last, reached at rest)."""
        K = len(W)
        Ww, Hw = (W, H) if world is None else world
        live = int(self.K.sum())
        if self._used + K > len(self._wbuf):
            if self._used > 2 * live + 4096:  # mostly removed routes: compact
                rows = np.concatenate([np.arange(s, s + k) for s, k in zip(self.start, self.K)]) \
                    if len(self.K) else np.zeros(0, dtype=np.intp)
                self._wbuf = np.vstack([self._wbuf[rows], np.zeros((max(1024, 2 * (live + K)), _COLS))])
                self.start = np.concatenate([[0], np.cumsum(self.K)[:-1]]).astype(np.intp) \
                    if len(self.K) else self.start
                self._used = live
            if self._used + K > len(self._wbuf):
                grow = max(len(self._wbuf), K)
                self._wbuf = np.vstack([self._wbuf, np.zeros((grow, _COLS))])
        rows = slice(self._used, self._used + K)
        self._wbuf[rows, :2] = W
        self._wbuf[rows, _H] = H
        self._wbuf[rows, _WX:_WY + 1] = Ww
        self._wbuf[rows, _WH] = Hw
        if speeds is None:  # no limits: the class bound everywhere
            arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(W, axis=0), axis=1))])
            self._wbuf[rows, _BOUND] = self._wbuf[rows, _ENV] = self._wbuf[rows, _LANE] = self.v_max
        else:
            arc = speeds.arc
            self._wbuf[rows, _BOUND], self._wbuf[rows, _ENV] = speeds.bound, speeds.env
            self._wbuf[rows, _LANE] = speeds.lane
        self._wbuf[rows, _ARC] = arc + self._arc_next  # increasing over the whole buffer
        self._arc_next += float(arc[-1]) + _ROUTE_GAP_M
        self.ids.append(vid)
        self.X = np.vstack([self.X, x0[None]])
        self.k = np.append(self.k, int(k0))
        self.l = np.append(self.l, l0)
        self.W.append(np.asarray(Ww, dtype=float))
        self.H.append(np.asarray(Hw, dtype=float))
        self.start = np.append(self.start, self._used)
        self.K = np.append(self.K, K)
        self._used += K
        self.speed_sum = np.append(self.speed_sum, 0.0)
        self.steps = np.append(self.steps, 0)
        self.denied_last = np.append(self.denied_last, False)
        self.req_l = np.append(self.req_l, 0)
        self.cap = np.append(self.cap, self.v_max)
        self.excess = np.append(self.excess, -np.inf)
        self.binds = np.append(self.binds, speeds is not None and
                               bool(np.min(speeds.bound) < self.v_max - tol.SPEED_BOUND_TOL))
        self.k_end = np.append(self.k_end, K - 1 if k_end is None else int(k_end))
        self.pinned = np.append(self.pinned, False)

    def remove(self, mask):
        keep = ~mask
        self.ids = [v for v, k in zip(self.ids, keep) if k]
        self.X, self.k, self.l = self.X[keep], self.k[keep], self.l[keep]
        self.W = [w for w, k in zip(self.W, keep) if k]
        self.H = [h for h, k in zip(self.H, keep) if k]
        self.start, self.K = self.start[keep], self.K[keep]
        self.speed_sum, self.steps = self.speed_sum[keep], self.steps[keep]
        self.denied_last, self.req_l = self.denied_last[keep], self.req_l[keep]
        self.cap, self.excess, self.binds = self.cap[keep], self.excess[keep], self.binds[keep]
        self.k_end, self.pinned = self.k_end[keep], self.pinned[keep]

    @property
    def at_last(self) -> np.ndarray:
        """Whether each vehicle's current waypoint is its route's last."""
        return self.k == self.K - 1

    def arrived(self) -> np.ndarray:
        """Which vehicles arrive now: at rest on their last waypoint (``l = 0`` there), or, with a
        run-out past their arrival waypoint ``k_end`` (:attr:`bridge.cosim.VehicleSpec.arrive_k`),
        once their stop point is at or past it and their position has passed it along the run-out's
        first segment (at whatever speed: SUMO's vehicles leave at their route's end at speed)."""
        done = (self.k_end == self.K - 1) & self.at_last & (self.l == 0)
        run = np.flatnonzero((self.k_end < self.K - 1) & (self.k >= self.k_end))
        if len(run):
            end = self._wbuf[self.start[run] + self.k_end[run]]
            h = self._wbuf[self.start[run] + self.k_end[run] + 1, _H]  # the run-out's first segment
            along = (self.X[run, 0] - end[:, _X]) * np.cos(h) + (self.X[run, 1] - end[:, _Y]) * np.sin(h)
            done[run[along >= 0.0]] = True
        return done

    def centres(self, offset=0):
        """Waypoints ``k + offset`` (clipped to the last), their headings, and whether they exist."""
        if not self.ids:
            return np.zeros((0, 2)), np.zeros(0), np.zeros(0, dtype=bool)
        row = self._wbuf[self.start + np.minimum(self.k + offset, self.K - 1)]
        return row[:, :2], row[:, _H], self.k + offset < self.K

    def world_centres(self, offset=0):
        """:meth:`centres` in the world (waypoints, headings of the segments arriving there)."""
        if not self.ids:
            return np.zeros((0, 2)), np.zeros(0), np.zeros(0, dtype=bool)
        row = self._wbuf[self.start + np.minimum(self.k + offset, self.K - 1)]
        return row[:, _WX:_WY + 1], row[:, _WH], self.k + offset < self.K

    def stop_points(self, ahead: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World waypoints ``idx = min(k + ahead, K - 1)`` (n, 2) of every vehicle, the headings of the
        segments arriving there (n,) and at the waypoint after it (``min(idx + 1, K - 1)``): the floats
        of ``W[i][idx]``, ``H[i][idx]`` and ``H[i][min(idx + 1, K - 1)]`` (the junction gate's stop
        points, :attr:`tm.junctions.JunctionFleet.stops`), all at once."""
        if not self.ids:
            return np.zeros((0, 2)), np.zeros(0), np.zeros(0)
        idx = np.minimum(self.k + ahead, self.K - 1)
        row = self._wbuf[self.start + idx]
        return row[:, _WX:_WY + 1], row[:, _WH], self._wbuf[self.start + np.minimum(idx + 1, self.K - 1), _WH]

    # ------------------------------------------------------------------ speed bounds
    def _along(self, X=None):
        """Centre arc (buffer-shifted) and along-road speed of every vehicle: the current
        waypoint's arc less the lead to it along its segment."""
        X = self.X if X is None else X
        row = self._wbuf[self.start + self.k]
        d = np.column_stack([np.cos(row[:, _H]), np.sin(row[:, _H])])
        lead = np.einsum("ij,ij->i", row[:, :2] - X[:, :2], d)
        return row[:, _ARC] - lead, np.einsum("ij,ij->i", X[:, 2:4], d)

    def _tables(self):
        b = self._wbuf[:self._used]
        return b[:, _ARC], b[:, _BOUND], b[:, _ENV], b[:, _LANE]

    def speed_caps(self, Ts: float, X=None) -> tuple[np.ndarray, np.ndarray]:
        """The speed bound with look-ahead at each front one step on (front + v Ts: where the front
        is when the next input's speed holds), and the lane limit under the front now."""
        s, v = self._along(X)
        arc, bound, env, lane = self._tables()
        first, last = self.start, self.start + self.K - 1
        front = s + 0.5 * self.vclass.length
        cap, _ = bound_at(arc, bound, env, lane, first, last, front + np.maximum(v, 0.0) * Ts, self.decel)
        _, lim = bound_at(arc, bound, env, lane, first, last, front, self.decel)
        return cap, lim

    def slack(self, Ts: float, offset: int, cap: np.ndarray, X=None) -> np.ndarray:
        """Extra tube levels (steps) each vehicle needs to come to rest at waypoint ``k + offset``
        keeping its speed bounds, over what it needs without them (plus ``slack_steps``);
        0 where no bound binds.  See :class:`controllers.speed_limits.SpeedSettings`."""
        out = np.zeros(len(self.ids), dtype=np.intp)
        r = np.flatnonzero(self.binds)  # routes without a bound below v_max need no slack
        if not len(r):
            return out
        s, v = self._along(X)
        first, last = self.start[r], self.start[r] + self.K[r] - 1
        stop = self._wbuf[first + np.minimum(self.k[r] + offset, self.K[r] - 1), _ARC]
        out[r] = self.bound_slack(self._tables(), first, last, s[r], v[r], stop, np.asarray(cap)[r], Ts)
        return out

    def bound_slack(self, tables, first, last, s, v, stop, cap, Ts: float) -> np.ndarray:
        """:meth:`slack` of vehicles of this class at centre arcs ``s`` with speeds ``v`` coming to rest
        at centre arcs ``stop``, on the routes of speed tables ``tables`` (``(arc, bound, env, lane)``,
        rows ``first .. last`` each; a group's buffer, or one route's :class:`RouteSpeeds` for a
        vehicle not yet in the group: admission's start, :meth:`bridge.cosim.Cosim._starts`),
        ``cap``: their speed bounds one step on (:meth:`speed_caps`); all of shape (V,)."""
        arc, bound, env, lane = tables
        half = 0.5 * self.vclass.length
        extra = np.zeros(len(s), dtype=np.intp)
        slower = np.zeros(len(s), dtype=bool)
        # A bound b at S (front arc) slows the plan only if b^2 + 2 a_c S < 2 a_c (stop + L/2): the
        # braking to the stop is slower there otherwise.  Then the look-ahead bound at the front
        # now lies below the braking speed to the stop now, so the plans are needed only there.
        now, _ = bound_at(arc, bound, env, lane, first, last, s + half, self.decel)
        need = np.flatnonzero(now ** 2 < 2.0 * self.decel * np.maximum(stop - s, 0.0) + tol.SPEED_BOUND_TOL)
        if len(need):
            with_caps, without, t_with, t_without = plan_steps(
                s[need], v[need], stop[need], arc, bound, env, lane, first[need], last[need], half, self.decel,
                self.u_max, self.v_max, Ts, seconds=True)
            extra[need] = with_caps - without
            # a bound binds where it slows the plan at all, not only by a whole step: rounded, a stretch
            # costing less than a step read as free, the request carried no slack and its grant was a
            # minimum-time tube the loop cannot widen (SUMO's grid6: topBottom.3, 12.71 m/s on an
            # 11.09 m/s lane, granted at its horizon 30 m past the lane's start)
            slower[need] = t_with > t_without + tol.PLAN_SLOWER_TOL_S
        bind = (extra > 0) | slower | (np.asarray(cap) < self.v_max - tol.SPEED_BOUND_TOL)
        return np.where(bind, np.maximum(extra, 0) + self.slack_steps, 0)

    # ------------------------------------------------------------------ requests (design.md §2, step 1)
    def request(self, Ts: float, switching: str, authority: bool) -> tuple[np.ndarray, np.ndarray, float]:
        """Whether each vehicle asks for its next waypoint, and the index ``l'`` it asks with (its
        membership index w.r.t. that waypoint plus the slack a binding speed bound needs); sets this
        step's speed bounds :attr:`cap` and request indices :attr:`req_l`.  Returns ``(may, l')`` and
        the seconds the indices took (``request_ms``)."""
        cen, hd, _ = self.centres()
        tr = time.perf_counter()
        nxt, nh, has = self.centres(1)
        lp = self.ctl.index(self.X, nxt, nh)
        t_index = time.perf_counter() - tr
        self.cap, _ = self.speed_caps(Ts)
        # a binding speed bound asks for a grant with slack (SpeedSettings.slack_steps) and
        # only for one whose tube lets the vehicle keep the bound (a stopped vehicle always asks)
        inside = lp <= self.ctl.N
        # at rest and denied: ask without slack (its claim would reach behind it: liveness)
        want = lp + restart_slack(self.slack(Ts, 1, self.cap), self.l, self.denied_last)
        may = self.ctl.may_request(self.X, cen, hd, lp, self.cap if authority else None)
        if authority:
            # its tube has no room left while a bound binds: it asks again, whatever its lead (else
            # the index, falling a level a step towards a stop point far ahead, drives it over the
            # bound: a lone bus 2.84 m/s over a 6.51 m/s stretch, tests/bridge/test_cosim_speed_limits.py)
            soon = self.pinned.copy()
            if soon.any():  # ... and within slack_steps levels it would force the vehicle over the bound
                r = np.flatnonzero(soon)
                soon[r] = ~self.ctl.cap_admits(self.X[r], cen[r], hd[r] if hd is not None else None,
                                               np.maximum(self.l[r] - 1 - self.slack_steps, 1), self.cap[r])
            may |= soon & inside
        may &= has
        may &= (want <= self.ctl.N) | (self.l == 0)
        lp = np.where(inside, np.minimum(want, self.ctl.N), lp)
        may &= self.ctl.cap_admits(self.X, nxt, nh, lp, self.cap) | (self.l == 0)
        self.req_l = lp
        if switching == "terminal":
            may &= self.l == 0
        return may, lp, t_index


def _headings(W: np.ndarray) -> np.ndarray:
    """Heading of the segment arriving at each waypoint (the first takes the first segment's)."""
    d = np.diff(W, axis=0)
    h = np.arctan2(d[:, 1], d[:, 0]) if len(d) else np.zeros(0)
    return np.concatenate([h[:1] if len(h) else [0.0], h])


def live_groups(groups: dict) -> list[_Group]:
    """The groups of ``groups`` (class -> :class:`_Group`, fleet order) that have vehicles, in order."""
    return [g for g in groups.values() if g.ids]
