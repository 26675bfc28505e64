"""tm/authority_reach.py: a movement-authority class's extents and the world boxes built from them
(the gate's scenes that use them: tests/tm/test_authority_gate.py).

``CAR``: ``T^0`` within 0.25 m along and 0.2 m across, claims within 1.0 m across, footprint
4 m x 1.8 m, δ = 1 m.  At heading east: hold box ±2.25 m along (T^0 + L/2), ±1.1 m across
(T^0 + W/2); claim box ±2.25 m along, ±1.9 m across (claims + W/2); corridor box ±2.75 m along
(δ/2 + T^0 + L/2), ±1.1 m across.  Every expected value below is worked out by hand.
"""

from types import SimpleNamespace

import numpy as np
import pytest

from tm.authority_reach import AuthorityReach

CAR = AuthorityReach(hold=0.25, hold_y=0.2, across=1.0, length=4.0, width=1.8, delta=1.0)
EAST, NORTH = np.array([0.0]), np.array([np.pi / 2])


def test_bad_extents_are_named():
    with pytest.raises(ValueError, match=r"AuthorityReach: extents must be finite and >= 0 m.*'across': -1.0"):
        AuthorityReach(hold=0.2, hold_y=0.2, across=-1.0, length=4.0, width=1.8, delta=1.0)
    with pytest.raises(ValueError, match=r"AuthorityReach: .*delta > 0"):
        AuthorityReach(hold=0.2, hold_y=0.2, across=1.0, length=4.0, width=1.8, delta=0.0)


def test_of_takes_the_hold_from_level_0_and_the_across_half_width_from_every_level():
    tables = SimpleNamespace(p_lo=np.array([-0.3, -5.0]), p_hi=np.array([0.25, 9.0]),
                             y_lo=np.array([-0.2, -1.2]), y_hi=np.array([0.1, 0.9]))
    r = AuthorityReach.of(tables, length=4.0, width=1.8, delta=1.0)
    assert (r.hold, r.hold_y, r.across) == (0.3, 0.2, 1.2)
    assert (r.length, r.width, r.delta) == (4.0, 1.8, 1.0)


def test_guard_reach_is_the_across_half_width_plus_half_the_diagonal():
    assert CAR.guard_reach == pytest.approx(1.0 + 0.5 * np.hypot(4.0, 1.8))


def test_half_extents_along_and_across_turn_with_the_heading():
    assert np.allclose(CAR.hold_half(EAST), [[2.25, 1.1]])
    assert np.allclose(CAR.hold_half(NORTH), [[1.1, 2.25]])
    assert np.allclose(CAR.claim_half(EAST), [[2.25, 1.9]])
    assert np.allclose(CAR.half_extent(EAST), [[2.75, 1.1]])
    # a waypoint between an east- and a north-bound segment: the hull of both
    assert np.allclose(CAR.hold_half(EAST, NORTH), [[2.25, 2.25]])
    # 45 degrees: each world axis sees (a + b) / sqrt(2)
    assert np.allclose(CAR.hold_half(np.array([np.pi / 4])), [[(2.25 + 1.1) / np.sqrt(2)] * 2])


def test_boxes_are_padded_one_sided_back_front_right_left():
    """Padding 1 m back, 2 m front, 0.5 m right, none left: heading east the hold box runs from
    2.25 + 1 behind to 2.25 + 2 ahead, 1.1 + 0.5 to the right (-y), 1.1 to the left; heading north
    right is +x.  Without padding the boxes are the half extents either side."""
    pad = np.array([[1.0, 2.0, 0.5, 0.0]])
    lo, hi = CAR.hold_box(pad, EAST)
    assert np.allclose(lo, [[-3.25, -1.6]]) and np.allclose(hi, [[4.25, 1.1]])
    lo, hi = CAR.hold_box(pad, NORTH)
    assert np.allclose(lo, [[-1.1, -3.25]]) and np.allclose(hi, [[1.6, 4.25]])
    lo, hi = CAR.claim_box(pad, EAST)
    assert np.allclose(lo, [[-3.25, -2.4]]) and np.allclose(hi, [[4.25, 1.9]])
    lo, hi = CAR.claim_box(np.zeros((1, 4)), EAST, NORTH)
    assert np.allclose(-lo, CAR.claim_half(EAST, NORTH)) and np.allclose(hi, CAR.claim_half(EAST, NORTH))


def test_re_exported_by_the_gate_module():
    from tm import authority_gate
    assert authority_gate.AuthorityReach is AuthorityReach
