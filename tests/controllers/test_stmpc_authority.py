"""Movement-authority ST-MPC (design.md §7): the cost drives at v_des, the tube of eq. (6) and the
request rule keep the guarantee.

One vehicle alone on a straight 600 m road, waypoints delta apart, every request granted.
"""

import numpy as np
import pytest
from hypothesis import given, settings as hsettings, strategies as st

from controllers import tolerances as tol
from controllers.classes import get_class
from controllers.plant import step
from controllers.settings import ControllerSettings, SettingsError, SynthesisSettings
from controllers.stmpc import STMPC
from controllers.synthesis import rotate_pairs, synthesize

URBAN = ("car", "bus", "truck")


@pytest.fixture(scope="module")
def fams(shared_set_cache):
    cache = shared_set_cache
    return {c: synthesize(get_class(c).model, SynthesisSettings(authority_decel=get_class(c).comfort_decel,
                                                                cache_dir=cache)) for c in URBAN}


def drive(fam, policy, seed, grant=None, length=600.0, steps=900, heading=0.0, v_cap=None):
    """Drive along a straight at ``heading``; returns along speeds, index log and violations.

    ``grant(t)``: whether the request at step t is granted (default: always).  Checks after
    every step that the index strictly decreased (or stayed 0), the eq. (5) invariant."""
    m = fam.model
    ctl = STMPC(fam, ControllerSettings(mode="authority"))
    rng = np.random.default_rng(seed)
    d = np.array([np.cos(heading), np.sin(heading)])
    wp = np.arange(0.0, length + 1e-9, m.delta)[:, None] * d
    hd = np.full(1, heading)
    X = np.zeros((1, m.n))
    k = 0
    l = ctl.index(X, wp[[0]], hd)
    speeds, pos, bad, requests = [], [], 0, 0
    for t in range(steps):
        if k + 1 < len(wp):
            lp = ctl.index(X, wp[[k + 1]], hd)
            if ctl.may_request(X, wp[[k]], hd, lp, v_cap)[0]:
                requests += 1
                assert lp[0] <= ctl.N
                if grant is None or grant(t):
                    k, l = k + 1, lp
        U = ctl.control(X, wp[[k]], l, heading=hd, v_cap=v_cap)
        assert np.all(np.abs(rotate_pairs(U, -hd)) <= m.u_bounds[1] + 1e-9)  # bounds hold in the road frame
        X, _ = step(m, X, U, wp[[k]], policy, rng, heading=hd)
        ln = ctl.index(X, wp[[k]], hd)
        bad += int(not (ln[0] < l[0] or (l[0] == 0 and ln[0] == 0)))
        l = ln
        speeds.append(float(X[0, 2:4] @ d))
        pos.append(float(X[0, :2] @ d))
    drive.pos = np.array(pos)
    return np.array(speeds), bad, requests, ctl.lead(X, wp[[k]], hd)[0]


@pytest.mark.parametrize("policy", ["none", "random", "adversarial"])
@pytest.mark.parametrize("c", URBAN)
def test_cruise_at_the_speed_bound_on_a_straight(fams, c, policy):
    """Every request granted: the car cruises >= 13.5 m/s (the issue's target; today 5.0), bus and
    truck reach v̄ = 13.89 within 2 d̄ = 0.01 m/s (the tube keeps A x + B u one disturbance
    inside the speed bound)."""
    speeds, bad, _, _ = drive(fams[c], policy, seed=1)
    assert bad == 0
    cruise = np.median(speeds[(drive.pos > 300) & (drive.pos < 500)])  # after the start, before the end
    assert cruise >= (13.5 if c == "car" else 13.89 - 0.01)
    assert speeds.max() <= 13.89 + 1e-9


@pytest.mark.parametrize("cap", [11.0, 13.0])
def test_speed_cap_is_tracked(fams, cap):
    """A lane limit given as v_cap (with the authority shortened to its braking distance) is
    where the car settles: median within 0.05 m/s (the disturbance moves v by <= 0.005 a step;
    measured 0.001-0.002).  Known limit: below ~11 m/s the tube, which must shrink one level a
    step and whose levels are minimum-time sets for v̄, pushes the car above the cap (3 -> 6.0,
    8 -> 8.5 m/s measured) when the index is re-minimised every step, as here; the co-simulation
    loop keeps tube slack where a bound binds (tests/bridge/test_cosim_speed_limits.py)."""
    speeds, bad, _, _ = drive(fams["car"], "random", seed=2, v_cap=np.array([cap]))
    assert bad == 0
    assert abs(np.median(speeds[(drive.pos > 150) & (drive.pos < 500)]) - cap) < 0.05


@hsettings(max_examples=25, deadline=None)
@given(c=st.sampled_from(URBAN), policy=st.sampled_from(["random", "adversarial"]), seed=st.integers(0, 10 ** 6),
       heading=st.floats(-np.pi, np.pi), pattern=st.lists(st.booleans(), min_size=5, max_size=40))
def test_index_strictly_decreases_under_any_grant_pattern(fams, c, policy, seed, heading, pattern):
    """Random and adversarial disturbances, grants following an arbitrary pattern (long runs of
    denials included): the index strictly decreases every step the waypoint stays, every request
    is inside T^{N_L}, and a denied vehicle stops at its waypoint (lead >= -T^0 extent)."""
    grant = (lambda t: pattern[(t // 7) % len(pattern)])
    speeds, bad, _, lead = drive(fams[c], policy, seed, grant=grant, length=300.0, steps=300, heading=heading)
    assert bad == 0


def test_deny_all_stops_at_the_first_waypoint(fams):
    """Nothing granted: the vehicle never passes its stop point (the tube ends in T^0(c))."""
    speeds, bad, requests, lead = drive(fams["car"], "adversarial", 5, grant=lambda t: False, steps=200)
    assert bad == 0 and requests > 0
    assert lead > -0.1 and abs(speeds[-1]) < 0.1  # T^0 spans a few cm for these disturbances


@pytest.mark.parametrize("c", ["car", "bus"])
def test_solvers_agree_on_the_authority_cost(fams, c):
    """exact (clipped 1-D minimiser per factor) vs daqp within SOLVER_AGREEMENT_TOL (1e-5: strictly
    convex 1-variable problems, unique optimum), proxsuite within PROXSUITE_AGREEMENT_TOL."""
    fam = fams[c]
    rng = np.random.default_rng(7)
    X = np.vstack([fam.sample(l, 3, rng) for l in range(1, fam.N + 1)])
    C = np.zeros((len(X), 2))
    H = rng.uniform(-np.pi, np.pi, len(X))
    X = rotate_pairs(X, H)  # sample in the road frame, state in the world
    cap = rng.uniform(2.0, 20.0, len(X))
    out = {}
    for solver in ("exact", "daqp", "proxsuite"):
        ctl = STMPC(fam, ControllerSettings(solver=solver, mode="authority"))
        out[solver] = ctl.control(X, C, ctl.index(X, C, H), heading=H, v_cap=cap)
    assert np.abs(out["daqp"] - out["exact"]).max() < tol.SOLVER_AGREEMENT_TOL
    assert np.abs(out["proxsuite"] - out["exact"]).max() < tol.PROXSUITE_AGREEMENT_TOL
    paper = STMPC(fam, ControllerSettings(solver="exact")).control(X, C, ctl.index(X, C, H), heading=H)
    assert np.abs(paper - out["exact"]).max() > 0.1  # the cost did change


def test_authority_mode_needs_an_authority_family(shared_set_cache):
    paper = synthesize(get_class("car").model, SynthesisSettings(cache_dir=shared_set_cache))
    with pytest.raises(ValueError, match="authority_decel"):
        STMPC(paper, ControllerSettings(mode="authority"))
    with pytest.raises(SettingsError, match="ControllerSettings.mode"):
        ControllerSettings(mode="fast")
    with pytest.raises(SettingsError, match="standoff"):
        ControllerSettings(standoff=-1.0)


def _across_steps(fam, mode, policy, seed, n=40):
    """One plant step of ``n`` random states (every level, random headings, waypoint kept) under
    ``mode``; returns the across factor's own index before and after."""
    ctl = STMPC(fam, ControllerSettings(mode=mode))
    rng = np.random.default_rng(seed)
    E = np.vstack([fam.sample(int(l), 1, rng) for l in rng.integers(1, fam.N + 1, n)])
    H = rng.uniform(-np.pi, np.pi, n)
    C = rng.uniform(-50.0, 50.0, (n, 2))
    X = rotate_pairs(E, H) + np.hstack([C, np.zeros((n, 2))])
    l = ctl.index(X, C, H)
    ly = ctl.factor_index(ctl.error(X, C, H), ctl._across)
    U = ctl.control(X, C, l, heading=H)
    Xn, _ = step(fam.model, X, U, C, policy, rng, heading=H)
    return l, ly, ctl.factor_index(ctl.error(Xn, C, H), ctl._across), ctl.index(Xn, C, H)


@hsettings(max_examples=25, deadline=None)
@given(c=st.sampled_from(URBAN), policy=st.sampled_from(["random", "adversarial"]), seed=st.integers(0, 2 ** 31))
def test_authority_keeps_the_across_factor_in_its_own_tube(fams, c, policy, seed):
    """Authority mode: the across factor's own index ``l_y <= l`` drops by one each step or stays 0,
    whatever the disturbance (so ``x_y(t+k) ∈ T_y^{max(l_y - k, 0)}``: what tm.reach's across extent
    relies on), and the joint index still strictly drops (eq. (5))."""
    l, ly, ly_next, l_next = _across_steps(fams[c], "authority", policy, seed)
    assert np.all(ly <= l)
    assert np.all(ly_next <= np.maximum(ly - 1, 0)), (ly, ly_next)
    assert np.all((l_next < l) | ((l == 0) & (l_next == 0)))


def test_paper_mode_does_not_keep_the_across_tube(fams):
    """The property above is the authority controller's doing: eq. (6) alone (paper mode, the
    joint level for every factor) lets the across index grow on some of the same samples."""
    grew = 0
    for seed in range(5):
        _, ly, ly_next, _ = _across_steps(fams["car"], "paper", "adversarial", seed)
        grew += int(np.sum(ly_next > np.maximum(ly - 1, 0)))
    assert grew > 0
