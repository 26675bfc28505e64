"""The broad phase pads boxes by GEOMETRY_TOL: pairs closer than the tolerance are candidates,
so the narrow phase (which counts gaps below the tolerance as contact) ever sees them."""

import numpy as np
import pytest

from controllers.tolerances import GEOMETRY_TOL
from tm.geometry import broad_phase
from tm.monitor import footprint_overlaps, footprint_polygons


@pytest.mark.parametrize("x0", [0.0, 123.456])
@pytest.mark.parametrize("axis", [0, 1])
def test_boxes_closer_than_the_tolerance_are_a_pair(x0, axis):
    # gap 0.5 tol: a pair (the tolerance says "closer than tol touches"); 2 tol: none.
    # Coordinates up to ~100 m have a resolution of ~1.4e-14 m, far below the gaps tested.
    lo = np.array([[x0, x0], [x0, x0]])
    hi = lo + 1.0
    for gap, expected in ((0.5 * GEOMETRY_TOL, 1), (2.0 * GEOMETRY_TOL, 0)):
        lo2, hi2 = lo.copy(), hi.copy()
        lo2[1, axis] = hi[0, axis] + gap
        hi2[1, axis] = lo2[1, axis] + 1.0
        i, j = broad_phase(lo2, hi2, GEOMETRY_TOL)
        assert len(i) == expected, (gap, i, j)


def test_monitor_counts_footprints_closer_than_the_tolerance():
    """End to end through the monitor's footprint check: two cars end to end with a gap of half
    the tolerance count as an overlap; with twice the tolerance they do not."""
    for gap, expected in ((0.5 * GEOMETRY_TOL, 1), (2.0 * GEOMETRY_TOL, 0)):
        pos = np.array([[10.0, 5.0], [10.0 + 5.0 + gap, 5.0]])
        polys = footprint_polygons(pos, np.zeros(2), np.full(2, 5.0), np.full(2, 1.8))
        i, _ = footprint_overlaps(polys)
        assert len(i) == expected, gap
