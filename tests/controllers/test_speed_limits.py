"""Speed bounds (controllers.speed_limits) and the speed cap of STMPC.control: the tube always wins."""

import numpy as np
import pytest
from hypothesis import given, settings as hsettings, strategies as st

from controllers import tolerances as tol
from controllers.classes import get_class
from controllers.settings import ControllerSettings, SettingsError, SynthesisSettings
from controllers.speed_limits import SpeedSettings, bound_at, curvature, free_flow_time, route_speeds
from controllers.stmpc import STMPC
from controllers.synthesis import rotate_pairs, synthesize


@pytest.fixture(scope="module")
def ctls(shared_set_cache):
    """car (double integrator) and bus (drag integrator) in both modes, exact and daqp."""
    out = {}
    for c in ("car", "bus"):
        vc = get_class(c)
        for mode in ("paper", "authority"):
            fam = synthesize(vc.model, SynthesisSettings(cache_dir=shared_set_cache,
                                                         authority_decel=vc.comfort_decel if mode == "authority"
                                                         else None))
            out[c, mode] = {s: STMPC(fam, ControllerSettings(mode=mode, solver=s)) for s in ("exact", "daqp")}
    return out


def _nominal_in_tube(ctl, E, U_road, l):
    """Whether A e + B u lies in T~^{l-1} for every factor (road-frame error rows)."""
    ok = np.ones(len(E), dtype=bool)
    nxt = E @ ctl.model.A.T + U_road @ ctl.model.B.T
    for t in ctl._tables:
        for i in range(len(E)):
            ok[i] &= np.all(t.Ht[l[i] - 1] @ nxt[i, t.states] <= t.ht[l[i] - 1] + 1e-7)
    return ok, nxt


@hsettings(max_examples=30, deadline=None)
@given(c=st.sampled_from(["car", "bus"]), mode=st.sampled_from(["paper", "authority"]),
       solver=st.sampled_from(["exact", "daqp"]), seed=st.integers(0, 10 ** 6), cap=st.floats(0.0, 20.0))
def test_a_cap_never_breaks_the_tube_and_holds_where_the_tube_admits_it(ctls, c, mode, solver, seed, cap):
    """States sampled in T^l (l = 1..N), any cap in [0, 20] m/s: the QP is never infeasible, the
    nominal successor always lies in T~^{l-1} (the guarantee), and |v+| <= cap (QP_FEAS_TOL)
    wherever cap_admits says some tube input allows it; elsewhere v+ is the tube's end nearest
    the cap (checked against the unbounded answer: never further from the cap)."""
    ctl = ctls[c, mode][solver]
    fam = ctl.family
    rng = np.random.default_rng(seed)
    E = np.vstack([fam.sample(l, 1, rng) for l in rng.integers(1, fam.N + 1, 12)])
    H = rng.uniform(-np.pi, np.pi, len(E))
    X = rotate_pairs(E, H)
    C = np.zeros((len(E), 2))
    l = ctl.index(X, C, H)
    keep = l >= 1
    X, E, H, C, l = X[keep], E[keep], H[keep], C[keep], l[keep]
    caps = np.full(len(X), cap)
    U = ctl.control(X, C, l, heading=H, v_cap=caps)
    ok, nxt = _nominal_in_tube(ctl, E, rotate_pairs(U, -H), l)
    assert ok.all()
    adm = ctl.cap_admits(X, C, H, l, caps)
    v = nxt[:, 2]
    assert np.all(np.abs(v[adm]) <= cap + 1e-6)
    free = ctl.control(X, C, l, heading=H)
    v_free = (E @ ctl.model.A.T + rotate_pairs(free, -H) @ ctl.model.B.T)[:, 2]
    over = lambda w: np.maximum(np.abs(w) - cap, 0.0)  # noqa: E731
    assert np.all(over(v[~adm]) <= over(v_free[~adm]) + 1e-6)
    # exact (clipped 1-D minimiser, the tube's end when the cap misses it) and daqp (cap rows, or
    # the re-solve tracking the cap) give the same input: strictly convex, unique optimum
    other = ctls[c, mode]["daqp" if solver == "exact" else "exact"]
    assert np.abs(other.control(X, C, l, heading=H, v_cap=caps) - U).max() < tol.SOLVER_AGREEMENT_TOL


def test_look_ahead_reaches_the_limit_at_the_entry_braking_at_a_c():
    """A 5 m/s stretch from 150 m on a 13.89 m/s road: at the front position where the stretch
    begins the bound is 5, 20 m before it sqrt(25 + 2 a_c 20) (one gap of delta: the gap holding
    the lane change counts as slow), and nowhere does the envelope ask for more than a_c."""
    W = np.column_stack([np.arange(0.0, 301.0, 3.0), np.zeros(101)])
    lim = np.where(W[:, 0] >= 150.0, 5.0, 13.89)
    rs = route_speeds(W, lim, 13.89, 2.5)
    first, last = np.array([0]), np.array([len(W) - 1])
    cap = lambda s: bound_at(rs.arc, rs.bound, rs.env, rs.lane, first, last, np.array([s]), 2.5)[0][0]  # noqa
    assert cap(147.0) == pytest.approx(5.0) and cap(200.0) == pytest.approx(5.0)
    assert cap(127.0) == pytest.approx(np.sqrt(25 + 2 * 2.5 * 20.0))
    assert cap(10.0) == pytest.approx(13.89)
    e = rs.env[1:]
    assert np.all(e[:-1] ** 2 <= e[1:] ** 2 + 2 * 2.5 * 3.0 + 1e-9)
    # free flow at the limits the front is under (front 2.5 m ahead of the centre)
    assert free_flow_time(rs.arc, rs.lane, 2.5) == pytest.approx(
        (147.0 - 2.5) / 13.89 + (300.0 - 144.5) / 5.0, rel=1e-9)


def test_curvature_and_curve_speed_of_a_circle():
    """R = 20 m sampled every ~3 m: kappa within 5 % of 1/R (chord sampling), so the curve
    bound is sqrt(a_lat R) within 2.5 %; a straight has none."""
    t = np.linspace(0.0, np.pi / 2, 12)
    W = np.column_stack([20 * np.cos(t), 20 * np.sin(t)])
    k = curvature(W, 4.0)
    assert np.all(np.abs(k[2:-2] * 20.0 - 1.0) < 0.05)
    rs = route_speeds(W, None, 13.89, 2.5, lat_accel=2.0)
    assert np.all(np.abs(rs.bound[3:-3] / np.sqrt(2.0 * 20.0) - 1.0) < 0.025)
    assert np.all(rs.lane == 13.89)
    S = np.column_stack([np.arange(0.0, 30.0, 3.0), np.zeros(10)])
    assert np.all(curvature(S, 4.0) == 0.0)


def _s_bend_then_turn():
    """A straight, an S-bend shifting 2.6 m sideways over ~8 m (SUMO's ``cross`` demo, node ``m3``:
    the lanes of a straight connection), a straight, then a 90 degree turn of R = 20 m: waypoints
    and which lie on the S-bend."""
    a = np.column_stack([np.arange(0.0, 30.0, 3.0), np.zeros(10)])
    s_bend = np.array([[30.0, 0.0], [32.5, 0.3], [34.1, 1.3], [35.7, 2.3], [38.2, 2.6]])
    b = np.column_stack([np.arange(41.2, 80.0, 3.0), np.full(13, 2.6)])
    t = np.linspace(0.0, np.pi / 2, 12)[1:]
    turn = np.column_stack([b[-1, 0] + 20.0 * np.sin(t), 2.6 + 20.0 * (1.0 - np.cos(t))])
    W = np.vstack([a, s_bend, b, turn])
    straight = np.zeros(len(W), dtype=bool)
    straight[len(a):len(a) + len(s_bend)] = True
    return W, straight


def test_a_straight_connection_has_no_curve_speed_and_a_turn_keeps_its_own():
    """The S-bend of a straight connection: ~5 m/s as a curve (the speed ``cross``'s cars crawled
    at through every lane-count node); flagged straight, the lane's 13.89 m/s all along it, while
    the turn later on the same route keeps its curve speed exactly (sqrt(a_lat R) within 2.5 %, as
    the circle alone) and a route without flags is unchanged bit for bit."""
    W, straight = _s_bend_then_turn()
    lim = np.full(len(W), 13.89)
    plain = route_speeds(W, lim, 13.89, 2.5, lat_accel=2.0)
    free = route_speeds(W, lim, 13.89, 2.5, lat_accel=2.0, straight=straight)
    near = slice(7, 18)  # the S-bend and 4 m on either side
    assert plain.bound[near].min() < 6.0
    assert np.all(free.bound[near] == 13.89)
    turn = slice(len(W) - 8, len(W) - 3)
    assert np.array_equal(free.bound[turn], plain.bound[turn])
    assert np.all(np.abs(free.bound[turn] / np.sqrt(2.0 * 20.0) - 1.0) < 0.025)
    none = route_speeds(W, lim, 13.89, 2.5, lat_accel=2.0, straight=np.zeros(len(W), dtype=bool))
    assert np.array_equal(none.bound, plain.bound) and np.array_equal(none.env, plain.env)
    with pytest.raises(ValueError, match="one flag per waypoint"):
        route_speeds(W, lim, 13.89, 2.5, lat_accel=2.0, straight=straight[:-1])


def test_settings_and_bad_limits_are_refused():
    with pytest.raises(SettingsError, match="lat_accel"):
        SpeedSettings(lat_accel=0.0)
    with pytest.raises(SettingsError, match="slack_steps"):
        SpeedSettings(slack_steps=-1)
    with pytest.raises(SettingsError, match="curve_window_m"):
        SpeedSettings(curve_window_m=float("inf"))
    W = np.column_stack([np.arange(0.0, 9.0, 3.0), np.zeros(3)])
    with pytest.raises(ValueError, match="waypoint 1"):
        route_speeds(W, np.array([5.0, 0.0, 5.0]), 13.89, 2.5)
    with pytest.raises(ValueError, match="one limit per waypoint"):
        route_speeds(W, np.array([5.0, 5.0]), 13.89, 2.5)
    assert tol.SPEED_BOUND_TOL > 0


def test_lat_accel_from_the_option_the_network_or_the_default():
    """``--lat-accel A`` is A (0: curves off); ``--lat-accel net`` the network's own turn
    acceleration (a SUMO network's ``limitTurnSpeed``, taken at the valid range's end past it), the
    default 2.0 where it records none; without the option 2.0 whatever the network says."""
    from types import SimpleNamespace as NS

    assert SpeedSettings.from_options(NS(lat_accel="net"), 5.5).lat_accel == 5.5
    assert SpeedSettings.from_options(NS(lat_accel="net"), None).lat_accel == SpeedSettings.lat_accel == 2.0
    assert SpeedSettings.from_options(NS(lat_accel="net"), 25.0).lat_accel == 10.0
    assert SpeedSettings.from_options(NS(lat_accel=None), 5.5).lat_accel == 2.0
    assert SpeedSettings.from_options(NS(lat_accel=3.0), 5.5).lat_accel == 3.0
    assert not SpeedSettings.from_options(NS(lat_accel=0.0), 5.5).curves
    assert SpeedSettings.from_options(NS()).lat_accel == 2.0  # options without the field at all
