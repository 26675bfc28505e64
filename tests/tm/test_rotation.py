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


OFF_CENTRE = [np.array([[-1.0, -0.3], [4.0, -0.3], [4.0, 0.5], [-1.0, 0.5]]),   # boxes not centred on 0
              np.array([[-2.0, -0.6], [6.0, -0.6], [6.0, 0.7], [-2.0, 0.7]])]
OCTAGON = [np.array([[1, 0], [0.7, 0.7], [0, 1], [-0.7, 0.7], [-1, 0], [-0.7, -0.7], [0, -1], [0.7, -0.7]]) * r
           for r in (1.0, 2.0)]


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**31 - 1), st.sampled_from(["union", "timed"]))
def test_oriented_box_fast_path_agrees_with_polygon_sat_and_lp(seed, check):
    """Claims of rotating families whose sets are rectangles take a closed-form four-axis test
    (tm.claims._obb_overlap); it must give the polygon separating-axis answer on every pair, and
    the LP answer on the first 150 pairs (random continuous positions: none is within the LP's
    tolerance of touching)."""
    from tm.claims import claim_conflicts
    from tm.geometry import intersect_sat

    rng = np.random.default_rng(seed)
    table = build_family_table({"road": BOX, "off": OFF_CENTRE, "oct": OCTAGON}, rotating=["road", "off", "oct"])
    assert table.hull_box[:5].all() and not table.hull_box[5:].any()
    n = 40
    fam = rng.integers(0, 3, n)
    idx = np.minimum(rng.integers(0, 3, n), table.n_levels[fam] - 1)
    c = Claims(table, fam, rng.uniform(0, 25, (n, 2)), idx, rng.uniform(-np.pi, np.pi, n),
               rng.uniform(2, 12, n), rng.uniform(1.5, 2.6, n))
    i, j = np.triu_indices(n, 1)
    got = claim_conflicts(c, i, j, check)
    if check == "union":
        P = c.polygons()
        want = intersect_sat(P[i], P[j])
    else:
        want = np.zeros(len(i), dtype=bool)
        for k in range(1, int(max(idx.max(), 1)) + 1):
            Pk = c.polygons_at(k)
            want |= (np.maximum(np.maximum(idx[i], idx[j]), 1) >= k) & intersect_sat(Pk[i], Pk[j])
    assert np.array_equal(got, want)
    if check == "union":
        lp = np.array([intersect_lp(P[a], P[b]) for a, b in zip(i[:150], j[:150])])
        assert np.array_equal(got[:150], lp)
