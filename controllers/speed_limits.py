"""Speed bounds along a route: lanes' speed limits and curve speeds, with braking look-ahead.

A speed limit is a traffic rule, not part of the guarantee: the ST-MPC applies the bound
these tables give as an extra bound on the along-road input, intersected with the tube's
feasible interval (:meth:`controllers.stmpc.STMPC.control`; the tube wins when they do not
meet).  This module only says *what* the bound is at a point of a route.

Profile
    Per gap ``j`` of a route (waypoints ``j-1 .. j``, arc ``[S_{j-1}, S_j]``) a limit
    ``lim_j``: the lower of the lane limits of its two waypoints (a lane change lies somewhere
    inside the gap, at most ``delta`` long, so the lower one holds on all of it), and in
    ``authority`` mode also the curve speed ``sqrt(a_lat / kappa)`` of both end waypoints.
    The limit holds for the vehicle's FRONT bumper, as in SUMO (a vehicle is on the lane its
    front is on): it must be at or below ``lim_j`` when its front enters gap ``j``.
Look-ahead
    ``env_j`` is the largest speed at ``S_{j-1}`` from which braking at the comfort
    deceleration ``a_c`` meets every limit from gap ``j`` on (one backward pass:
    ``env_j = min(lim_j, sqrt(env_{j+1}^2 + 2 a_c (S_j - S_{j-1})))``).  The bound at a front
    position ``s`` in gap ``j`` is ``min(lim_j, sqrt(env_{j+1}^2 + 2 a_c (S_j - s)))``.
Curvature
    ``kappa`` at a waypoint is the heading change of the polyline over the arc window
    ``[s - w, s + w]`` divided by its length (``w = SpeedSettings.curve_window_m``; the heading
    taken linear between segment midpoints): a kink of a few degrees between two long straight
    pieces is a gentle curve, not a sharp one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.search_kernel import search_clipped
from controllers.settings import SettingsError

__all__ = ["SpeedSettings", "RouteSpeeds", "route_speeds", "curvature", "bound_at", "free_flow_time", "plan_steps"]


@dataclass(frozen=True)
class SpeedSettings:
    """How lane limits and curve speeds bound a vehicle's speed (validated).

    Parameters
    ----------
    lane_limits : bool
        Bound the speed by the lanes' speed limits (both controller modes).
    curves : bool
        Bound the speed by ``sqrt(lat_accel / kappa)`` (``authority`` mode only: the paper's
        sets hold ~5 m/s, below any curve speed of a road).
    lat_accel : float
        Lateral acceleration ``a_lat`` (m/s^2, 0 < a_lat <= 10) of the curve speed; 2.0 is the
        usual comfort figure for cars (buses and trucks share it).  A run on a SUMO network may
        take the network's own instead (``--lat-accel net``, :meth:`from_options`): the one its
        turn speeds were built with, which SUMO's drivers drive.
    curve_window_m : float
        Half-width ``w`` (m, > 0) of the arc window over which curvature is measured.
    slack_steps : int
        Tube levels (>= 0) kept on top of the extra time a binding bound costs.  The tube's
        levels are minimum-time sets and the paper re-minimises the index every step, so a
        vehicle must progress as if it drove at the class's speed bound; below a low limit the
        tube then forces it above the limit (measured: 3 m/s lane, 6.0 m/s).  Any index ``l``
        with ``x in T^l`` is a valid tube, so where a bound binds the loop keeps
        ``l = max(l_min, min(l_prev - 1, l_min + extra + slack_steps))`` (still strictly
        decreasing, claims grow accordingly) and asks for a grant with that much slack
        (none for a vehicle at rest whose last request was denied: :func:`restart_slack`).
        A vehicle whose index already falls by that one level a step while a bound binds, and
        whose tube would within ``slack_steps`` levels no longer let it keep the bound, asks for
        its next waypoint whatever its lead (``bridge.groups._Group.request``): the grant's
        fresh slack is what keeps a bus braking for a slow junction lane under its limit.
    """

    lane_limits: bool = True
    curves: bool = True
    lat_accel: float = 2.0
    curve_window_m: float = 4.0
    slack_steps: int = 3

    def __post_init__(self) -> None:
        for k in ("lane_limits", "curves"):
            if not isinstance(getattr(self, k), bool):
                raise SettingsError(f"SpeedSettings.{k}: must be True or False, got {getattr(self, k)!r}")
        a = self.lat_accel
        if isinstance(a, bool) or not isinstance(a, (int, float)) or not 0 < a <= 10:
            raise SettingsError(f"SpeedSettings.lat_accel: must be a lateral acceleration in (0, 10] m/s^2, "
                                f"got {a!r}")
        n = self.slack_steps
        if isinstance(n, bool) or not isinstance(n, int) or n < 0:
            raise SettingsError(f"SpeedSettings.slack_steps: must be an integer >= 0, got {n!r}")
        w = self.curve_window_m
        if isinstance(w, bool) or not isinstance(w, (int, float)) or not 0 < w < np.inf:
            raise SettingsError(f"SpeedSettings.curve_window_m: must be a distance > 0 m, got {w!r}")

    @classmethod
    def from_options(cls, opts, network_lat_accel: float | None = None) -> "SpeedSettings":
        """From command-line options ``speed_limits`` (``obey`` / ``ignore``) and ``lat_accel``
        (m/s^2, 0 turns curve speeds off; absent: the class default, 2.0).  ``lat_accel = "net"``:
        ``network_lat_accel``, the lateral acceleration the network's own turn speeds were built
        with (a SUMO network's ``limitTurnSpeed``, :func:`bridge.sumo_inputs.net_turn_accel`;
        SUMO's drivers drive those speeds), else the default.  Not the default: on SUMO's
        ``fokr_bs_demo`` it landed 20 vehicles in 180 s against 37 (README, Known limits)."""
        mode = getattr(opts, "speed_limits", None) or "obey"
        if mode not in ("obey", "ignore"):
            raise SettingsError(f"--speed-limits: must be 'obey' or 'ignore', got {mode!r}")
        a = getattr(opts, "lat_accel", None)
        if a == "net":  # (a network's value past the valid range is taken at its end)
            a = min(float(network_lat_accel), 10.0) if network_lat_accel else None
        if a is None:
            a = cls.lat_accel
        return cls(lane_limits=mode == "obey", curves=a > 0, lat_accel=a if a > 0 else cls.lat_accel)


def restart_slack(slack: np.ndarray, index: np.ndarray, denied_last: np.ndarray) -> np.ndarray:
    """The slack a request asks for: ``slack``, but none for a vehicle at rest at its stop point
    (``index == 0``) whose last request was denied.

    A request with slack claims more than the vehicle holds, behind it as well (the larger level
    ``T^{l+s}`` of the new stop point keeps the reach's backward, negative-velocity part): for a
    car at rest, ~0.4 m behind its hold box ``T^0 ⊕ footprint`` with 3 levels of slack; with
    none, at most 0.01 m over 400 sampled states of ``T^0`` (car, bus, truck; 0.1 m for a car
    at rest at ``T^0``'s rear end; ``tests/tm/test_restart.py`` has the cycle).  A follower
    stopped closer than that behind it can never move (its leader stands in its way), so the leader's request would be
    denied for ever (measured on ``grid``, authority, seed 1: 11 cars in one such queue until
    the 894 s cap).  From rest, the tube of the minimal index needs no slack to keep a speed
    bound for the first waypoint (the vehicle starts at 0 m/s); the slack comes back with the
    next requests.

    Parameters
    ----------
    slack : ndarray of int, shape (n,)
    index : ndarray of int, shape (n,)
        The vehicles' current membership indices ``l``.
    denied_last : ndarray of bool, shape (n,)
        Whether each vehicle's request was denied in the last step.
    """
    slack = np.asarray(slack, dtype=np.intp)
    return np.where((np.asarray(index) == 0) & np.asarray(denied_last, dtype=bool), 0, slack)


@dataclass(frozen=True)
class RouteSpeeds:
    """Per-waypoint tables of one route (arrays of shape (K,); row ``j >= 1`` is gap ``j``).

    Attributes
    ----------
    arc : ndarray
        Arc length of each waypoint along the waypoint polyline (m), from 0.
    lane : ndarray
        Lane limit of gap ``j`` (row 0 repeats row 1): what the KPI compares with.
    bound : ndarray
        Limit of gap ``j`` the controller holds: ``lane`` and, if asked, curve speeds.
    env : ndarray
        Look-ahead speed at the start of gap ``j`` (see the module notes).
    """

    arc: np.ndarray
    lane: np.ndarray
    bound: np.ndarray
    env: np.ndarray


def curvature(W: np.ndarray, window_m: float, straight: np.ndarray | None = None) -> np.ndarray:
    """Curvature (1/m, >= 0) of the polyline ``W`` (K, 2) at each waypoint over ``[s - w, s + w]``.

    ``straight`` (K,) bool: waypoints on a straight connection (see :func:`route_speeds`); the
    heading changes at a segment touching one (either end waypoint) are left out, so the turns of
    such a connection's shape, and its kinks where it meets the lanes, count as no curve."""
    W = np.asarray(W, dtype=float)
    d = np.diff(W, axis=0)
    seg = np.linalg.norm(d, axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    if len(W) < 3:
        return np.zeros(len(W))
    h = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    # heading as a continuous function of arc: each segment's heading at its midpoint, linear in
    # between (exact for a uniformly sampled circle), held at the ends
    mid = 0.5 * (arc[:-1] + arc[1:])
    lo = np.clip(arc - window_m, 0.0, arc[-1])
    hi = np.clip(arc + window_m, 0.0, arc[-1])
    turn = np.abs(np.interp(hi, mid, h) - np.interp(lo, mid, h))
    if straight is not None and np.any(straight):
        st = np.asarray(straight, dtype=bool)
        on = st[:-1] | st[1:]  # segment j (W[j] -> W[j+1]) touches a straight connection
        dh = np.diff(h)  # the turn between segments j and j+1, over [mid_j, mid_{j+1}]
        cut = (on[:-1] | on[1:]) & (dh != 0.0)
        if cut.any():  # only the windows that see a cut turn change (elsewhere: bit for bit as before)
            h_eff = h[0] + np.concatenate([[0.0], np.cumsum(np.where(cut, 0.0, dh))])
            turn_eff = np.abs(np.interp(hi, mid, h_eff) - np.interp(lo, mid, h_eff))
            sees = np.zeros(len(W), dtype=bool)
            for a, b in zip(mid[:-1][cut], mid[1:][cut]):
                sees |= (lo < b) & (hi > a)
            turn = np.where(sees, turn_eff, turn)
    span = np.maximum(hi - lo, 1e-9)
    return turn / span


def route_speeds(W: np.ndarray, limits: np.ndarray | None, v_max: float, decel: float,
                 lat_accel: float | None = None, window_m: float = 4.0, apply_lanes: bool = True,
                 straight: np.ndarray | None = None) -> RouteSpeeds:
    """The tables of one route.

    Parameters
    ----------
    W : ndarray, shape (K, 2)
        Waypoints (K >= 2).
    limits : ndarray, shape (K,), or None
        Lane speed limit under each waypoint (m/s, > 0); None: no lane limits.
    v_max : float
        The class's speed bound (m/s); limits above it change nothing.
    decel : float
        Comfort deceleration ``a_c`` of the look-ahead (m/s^2, > 0).
    lat_accel : float or None
        ``a_lat`` of the curve speed; None: no curve speeds.
    window_m : float
        Curvature window half-width (m).
    apply_lanes : bool
        Whether ``bound`` holds the lane limits (``lane`` always does: the KPI measures against
        them even when the controller ignores them).
    straight : ndarray of bool, shape (K,), optional
        Waypoints on the internal lanes of a straight connection (SUMO's direction ``s``): no
        curve speed from their shape (:func:`curvature`).  SUMO's drivers keep the lane's speed
        through them (netconvert lowers only turning connections' speeds): a node where a road's
        lane count changes bends its lanes sideways by a lane width over a few metres, and the
        curve speed there was ~5 m/s on a 13.89 m/s road (SUMO's ``cross`` demo).

    Raises
    ------
    ValueError
        On limits that are not finite and > 0, or of the wrong length.
    """
    W = np.asarray(W, dtype=float)
    K = len(W)
    if K < 2:
        raise ValueError(f"route_speeds: need >= 2 waypoints, got {K}")
    if not decel > 0:
        raise ValueError(f"route_speeds: decel must be > 0 m/s^2, got {decel}")
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(W, axis=0), axis=1))])
    pt = np.full(K, float(v_max))
    if limits is not None:
        lim = np.asarray(limits, dtype=float)
        if lim.shape != (K,):
            raise ValueError(f"speed_limits: expected one limit per waypoint ({K},), got shape {lim.shape}")
        if not np.all(np.isfinite(lim) & (lim > 0)):
            i = int(np.flatnonzero(~(np.isfinite(lim) & (lim > 0)))[0])
            raise ValueError(f"speed_limits: must be finite and > 0 m/s, waypoint {i} has {lim[i]!r}")
        pt = np.minimum(pt, lim)
    lane = np.empty(K)
    lane[1:] = np.minimum(pt[:-1], pt[1:])
    lane[0] = lane[1]
    bound = lane.copy() if apply_lanes else np.full(K, float(v_max))
    if lat_accel is not None:
        if straight is not None and np.shape(straight) != (K,):
            raise ValueError(f"straight: expected one flag per waypoint ({K},), got shape {np.shape(straight)}")
        kap = curvature(W, window_m, straight)
        with np.errstate(divide="ignore"):
            vc = np.where(kap > 0, np.sqrt(lat_accel / np.maximum(kap, 1e-300)), np.inf)
        bound[1:] = np.minimum(bound[1:], np.minimum(vc[:-1], vc[1:]))
        bound[0] = bound[1]
    env = np.empty(K)
    nxt = np.inf
    for j in range(K - 1, 0, -1):  # backward pass (once per route)
        nxt = min(bound[j], np.sqrt(nxt ** 2 + 2.0 * decel * (arc[j] - arc[j - 1])))
        env[j] = nxt
    env[0] = env[1]
    for a in (arc, lane, bound, env):
        a.setflags(write=False)
    return RouteSpeeds(arc=arc, lane=lane, bound=bound, env=env)


def bound_at(arc: np.ndarray, bound: np.ndarray, env: np.ndarray, lane: np.ndarray, first: np.ndarray,
             last: np.ndarray, s: np.ndarray, decel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The speed bound with look-ahead, and the lane limit, at front positions ``s`` (vectorised).

    Parameters
    ----------
    arc, bound, env, lane : ndarray, shape (R,)
        Tables of many routes stacked in one buffer, ``arc`` increasing over the whole buffer
        (each route's arcs shifted by an offset).
    first, last : ndarray of int, shape (V,)
        Each vehicle's first and last row in the buffer.
    s : ndarray, shape (V,)
        Front positions in the buffer's (shifted) arc.
    decel : ndarray, shape (V,) or float

    Returns
    -------
    cap : ndarray, shape (V,)
        ``min(lim_j, sqrt(env_{j+1}^2 + 2 a_c (S_j - s)))`` for the gap ``j`` holding ``s``.
    lane_limit : ndarray, shape (V,)
        Lane limit of that gap.
    """
    # first row with arc > s: gap j holds s (searched in each vehicle's own rows)
    s = np.asarray(s, dtype=float)
    j = search_clipped(arc, s.reshape(-1), np.asarray(first) + 1, last, "right").reshape(s.shape)
    nxt = np.minimum(j + 1, last)
    more = j < last
    ahead = np.maximum(arc[j] - s, 0.0)
    look = np.where(more, np.sqrt(env[nxt] ** 2 + 2.0 * decel * ahead), np.inf)
    return np.minimum(bound[j], look), lane[j]


def free_flow_time(arc: np.ndarray, lane: np.ndarray, front_offset: float) -> float:
    """Free-flow time (s) of a route whose centre runs ``arc[0] .. arc[-1]`` at the limit its front
    is under (``lane``: per gap, row 0 unused; the front is ``front_offset`` m ahead, beyond the end
    under the last gap's limit)."""
    arc = np.asarray(arc, dtype=float)
    lane = np.asarray(lane, dtype=float)
    a0, a1 = float(arc[0]), float(arc[-1])
    # front-gap j covers centre positions [S_{j-1} - off, S_j - off); the last one extends to +inf
    lo = arc[:-1] - front_offset
    hi = np.concatenate([arc[1:-1], [np.inf]]) - front_offset
    lo[0] = -np.inf
    length = np.clip(np.minimum(hi, a1) - np.maximum(lo, a0), 0.0, None)
    return float(np.sum(length / lane[1:]))


def plan_steps(s0: np.ndarray, v0: np.ndarray, stop: np.ndarray, arc, bound, env, lane, first, last,
               front_offset, decel, accel: float, v_max: float, Ts: float,
               samples: int = 24, seconds: bool = False) -> tuple[np.ndarray, ...]:
    """Steps (ceil, >= 0) a vehicle at centre arc ``s0`` with speed ``v0`` needs to come to rest at
    ``stop`` (centre arc), accelerating at ``accel`` and braking at ``decel`` at the end: driving
    at the bound with look-ahead (:func:`bound_at`, front ``front_offset`` m ahead), and at
    ``v_max`` alone (the difference is what the bounds cost).

    Midpoint rule on ``ds / v(s)`` over ``samples`` pieces; the last piece, where ``v -> 0``, is
    integrated exactly for the final braking (``sqrt(2 ds / a_c)``).  Vectorised over vehicles.

    Returns
    -------
    with_bounds, without : ndarray of int, shape (V,)
    t_with, t_without : ndarray of float, shape (V,)
        Only with ``seconds``: the two plans' durations (s) before rounding up to steps.
    """
    s0 = np.asarray(s0, dtype=float)
    V = len(s0)
    stop = np.asarray(stop, dtype=float)
    span = np.maximum(stop - s0, 0.0)
    ds = span / samples
    mid = s0[:, None] + ds[:, None] * (np.arange(samples) + 0.5)[None, :]          # (V, M)
    cap, _ = bound_at(arc, bound, env, lane, np.repeat(first, samples), np.repeat(last, samples),
                      (mid + front_offset).ravel(), decel)
    a_c = np.asarray(decel, dtype=float)
    brake = np.sqrt(2.0 * a_c * np.maximum(stop[:, None] - mid, 0.0))
    free = np.minimum(np.minimum(brake, v_max),
                      np.sqrt(np.maximum(v0, 0.0)[:, None] ** 2 + 2.0 * accel * (mid - s0[:, None])))
    last_piece = np.sqrt(2.0 * ds / a_c)
    out, secs = [], []
    for v in (np.minimum(free, cap.reshape(V, samples)), free):
        t = np.sum(ds[:, None] / np.maximum(v[:, :-1], 1e-3), axis=1) + last_piece
        out.append(np.ceil(t / Ts).astype(np.intp))
        secs.append(t)
    return (out[0], out[1], secs[0], secs[1]) if seconds else (out[0], out[1])
