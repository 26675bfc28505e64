"""Classes built from SUMO vTypes (controllers.classes.vtype_class): SUMO's footprint, and a speed
bound that is the vType's own up to motorway speeds."""

import pytest

from controllers.classes import BRAKING_BUDGET_M, CITY_V_MAX, VTYPE_V_MAX, VTypeParams, builtin_classes, vtype_class, vtype_speed_cap


def _v(cls):
    return float(cls.model.z_bounds[1][0])


@pytest.mark.parametrize("max_speed, want", [(55.56, VTYPE_V_MAX), (27.78, 27.78), (8.0, 8.0)])
def test_a_vtype_class_keeps_its_max_speed_up_to_130_km_h(max_speed, want):
    """SUMO's passenger default (55.56 m/s) is capped at 36.11 m/s; a truck's 27.78 and a slow
    vType's 8 m/s are kept (a motorway demo's lanes allow 33.3 m/s: at the urban classes' 13.89
    its cars drove at 50 km/h).  The built-in urban classes stay at 13.89 m/s."""
    c = vtype_class(VTypeParams("passenger", 5.0, 1.8, 3.0, 4.5, max_speed))
    assert _v(c) == pytest.approx(want, abs=1e-4)  # the bound is rounded to 4 decimals
    assert (c.length, c.width) == (5.0, 1.8)
    assert VTYPE_V_MAX > CITY_V_MAX
    assert all(_v(builtin_classes()[n]) == CITY_V_MAX for n in ("car", "bus", "truck"))


@pytest.mark.parametrize("lanes, cap", [(13.9, 13.9), (8.33, 13.89), (33.33, 33.33), (83.33, VTYPE_V_MAX)])
def test_the_cap_is_the_fastest_lane_within_the_urban_and_motorway_bounds(lanes, cap):
    """A city network keeps the urban bound (on SUMO's grid6, lanes 13.9 m/s, every vType at 36.11
    m/s landed 18 vehicles in 180 s against 26: larger sets for speeds no lane allows); a
    motorway's fastest lane is the bound up to 130 km/h (A10KW has an 83.33 m/s lane)."""
    assert vtype_speed_cap(lanes) == pytest.approx(cap, abs=1e-12)
    c = vtype_class(VTypeParams("passenger", 5.0, 1.8, 3.0, 4.5, 55.56), vtype_speed_cap(lanes))
    assert _v(c) == pytest.approx(cap, abs=1e-4)
    with pytest.raises(ValueError, match="v_cap must be a speed > 0"):
        vtype_class(VTypeParams("passenger", 5.0, 1.8, 2.6, 4.5, 55.56), 0.0)


def test_a_slow_braking_vtype_is_bounded_by_its_braking_budget_and_its_sets_exist():
    """SUMO's truck vClass defaults (accel 1.3 m/s^2, maxSpeed 36.11 m/s): its comfortable
    deceleration is 1.04 m/s^2, and at 36.11 m/s its movement-authority set lay 633 m back, beyond
    the synthesis's 200 levels (A10KW's run failed with a SynthesisError).  Bounded by the braking
    budget it drives at most sqrt(2 * 1.04 * 300) = 24.98 m/s and its family is synthesised with
    the co-simulation's level bound (``AUTHORITY_MAX_LEVELS``)."""
    from controllers.settings import AUTHORITY_MAX_LEVELS, SynthesisSettings
    from controllers.synthesis import SynthesisError, synthesize

    c = vtype_class(VTypeParams("truck", 7.1, 2.4, 1.3, 4.0, 36.11), vtype_speed_cap(83.33))
    assert c.comfort_decel == pytest.approx(1.04)
    assert _v(c) == pytest.approx(24.9799, abs=1e-4) and _v(c) ** 2 / (2 * c.comfort_decel) <= BRAKING_BUDGET_M
    fam = synthesize(c.model, SynthesisSettings(authority_decel=c.comfort_decel, cache=False,
                                                max_levels=AUTHORITY_MAX_LEVELS))
    assert 200 < fam.N <= AUTHORITY_MAX_LEVELS  # 224: beyond the default bound, hence the co-simulation's
    unbounded = VTypeParams("truck", 7.1, 2.4, 1.3, 4.0, 36.11)
    import controllers.classes as classes
    budget = classes.BRAKING_BUDGET_M
    try:  # without the budget: 633 m back, and the default level bound fails (the A10KW run)
        classes.BRAKING_BUDGET_M = 1e9
        big = vtype_class(unbounded, vtype_speed_cap(83.33))
    finally:
        classes.BRAKING_BUDGET_M = budget
    assert _v(big) == pytest.approx(36.11)
    with pytest.raises(SynthesisError, match="max_levels=200"):
        synthesize(big.model, SynthesisSettings(authority_decel=big.comfort_decel, cache=False))
