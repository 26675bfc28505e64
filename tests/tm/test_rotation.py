"""Road-frame families: claims turn with the heading (sets and footprint alike)."""

import numpy as np
from hypothesis import given, settings, strategies as st

from tm.claims import Claims
from tm.families import build_family_table
from tm.geometry import intersect_lp

BOX = [np.array([[-a, -b], [a, -b], [a, b], [-a, b]]) for a, b in ((0.5, 0.2), (3.0, 0.4), (8.0, 0.6))]


def _rot(P, h):
    c, s = np.cos(h), np.sin(h)
    return P @ np.array([[c, s], [-s, c]])


@settings(max_examples=60, deadline=None)
@given(st.floats(-np.pi, np.pi), st.integers(1, 2), st.floats(1.0, 6.0), st.floats(0.5, 2.5))
def test_rotated_claim_is_the_rotated_set_plus_the_footprint(h, l, length, width):
    table = build_family_table({"road": BOX, "world": BOX}, rotating=["road"])
    c = Claims(table, np.array([0, 1]), np.zeros((2, 2)), np.array([l, l]), np.array([h, h]),
               np.array([length, length]), np.array([width, width]))
    P = c.polygons()
    rect = np.array([[-length / 2, -width / 2], [length / 2, -width / 2], [length / 2, width / 2],
                     [-length / 2, width / 2]])
    want_road = _rot(BOX[l - 1], h)[:, None, :] + _rot(rect, h)[None]
    want_world = BOX[l - 1][:, None, :] + _rot(rect, h)[None]
    D = np.column_stack([np.cos(np.linspace(0, 2 * np.pi, 72)), np.sin(np.linspace(0, 2 * np.pi, 72))])
    for got, want in ((P[0], want_road.reshape(-1, 2)), (P[1], want_world.reshape(-1, 2))):
        # equal convex sets have equal support functions (1e-9 m: round-off of a few sums)
        assert np.allclose((D @ got.T).max(axis=1), (D @ want.T).max(axis=1), atol=1e-9)
    lo, hi = c.aabb()
    assert np.all(lo[0] <= P[0].min(axis=0) + 1e-9) and np.all(hi[0] >= P[0].max(axis=0) - 1e-9)


def test_lane_neighbours_conflict_only_when_the_sets_are_not_rotated():
    """Two cars side by side in adjacent lanes of a north-bound road (3.2 m apart): with sets in the
    road frame (long along, narrow across) their claims are disjoint; the same sets read in world
    axes (long across the lanes) overlap.  Checked by LP."""
    for rotating, overlap in ((["car"], False), ([], True)):
        table = build_family_table({"car": BOX}, rotating=rotating)
        c = Claims(table, np.array([0, 0]), np.array([[0.0, 0.0], [3.2, 0.0]]), np.array([2, 2]),
                   np.array([np.pi / 2, np.pi / 2]), np.array([5.0, 5.0]), np.array([1.8, 1.8]))
        P = c.polygons()
        assert intersect_lp(P[0], P[1]) == overlap
