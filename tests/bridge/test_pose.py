"""SUMO pose conventions: front bumper, angle clockwise from north in degrees."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from bridge.pose import centre_from_front, front_bumper, heading_from_sumo_angle, sumo_angle


def test_conventions():
    # east-bound: heading 0 -> SUMO 90 deg; north-bound: pi/2 -> 0; west: pi -> 270; south: -pi/2 -> 180
    np.testing.assert_allclose(sumo_angle([0.0, np.pi / 2, np.pi, -np.pi / 2]), [90.0, 0.0, 270.0, 180.0])
    np.testing.assert_allclose(front_bumper([[0.0, 0.0]], [np.pi / 2], [5.0]), [[0.0, 2.5]], atol=1e-12)
    np.testing.assert_allclose(front_bumper([[1.0, 2.0], [0.0, 0.0]], [0.0, np.pi], [12.0, 5.0]),
                               [[7.0, 2.0], [-2.5, 0.0]], atol=1e-12)


@given(st.floats(-100, 100), st.floats(-100, 100), st.floats(-np.pi, np.pi), st.floats(0.5, 20))
def test_round_trip(x, y, th, length):
    f = front_bumper([[x, y]], [th], [length])
    np.testing.assert_allclose(centre_from_front(f, [th], [length]), [[x, y]], atol=1e-9)
    back = heading_from_sumo_angle(sumo_angle(th))
    assert abs((back - th + np.pi) % (2 * np.pi) - np.pi) < 1e-9
    assert 0 <= sumo_angle(th) < 360
