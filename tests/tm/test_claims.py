"""Claims: polygons against a scipy reference, bounding boxes, union vs timed conflicts.

Tolerance: claim polygons are compared through support functions to 1e-9 m
(sums of O(10) m coordinates, round-off ~1e-14).
"""

import numpy as np
from hypothesis import given, settings, strategies as st

from tests.tm.helpers import box, nested_family, ref_claim_polygon
from tm.claims import Claims, claim_conflicts, conflicting_pairs
from tm.families import build_family_table
from tm.geometry import intersect_sat

DIRS = np.stack([np.cos(np.linspace(0, 2 * np.pi, 61)), np.sin(np.linspace(0, 2 * np.pi, 61))], axis=1)


def make_claims(table, fam, centre, index, heading, length, width):
    f = np.asarray(fam)
    return Claims(table, f, np.asarray(centre, float).reshape(-1, 2), np.asarray(index),
                  np.asarray(heading, float), np.asarray(length, float), np.asarray(width, float))


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.sampled_from(["box", "poly"]))
def test_claim_polygons_match_reference_and_boxes_contain_every_timed_polygon(seed, kind):
    rng = np.random.default_rng(seed)
    fam = nested_family(rng, 6, kind)
    table = build_family_table({"f": fam})
    n = 8
    c = make_claims(table, np.zeros(n, int), rng.normal(size=(n, 2)) * 10, rng.integers(0, 6, n),
                    rng.uniform(-4, 4, n), rng.uniform(0, 5, n), rng.uniform(0, 2, n))
    polys = c.polygons()
    lo, hi = c.aabb()
    for v in range(n):
        ref = ref_claim_polygon(fam, c.centre[v], max(c.index[v] - 1, 0), c.heading[v], c.length[v], c.width[v])
        assert np.allclose((polys[v] @ DIRS.T).max(0), (ref @ DIRS.T).max(0), atol=1e-9)
        for k in range(1, 8):
            Pk = c.polygons_at(k)[v]
            ref_k = ref_claim_polygon(fam, c.centre[v], max(c.index[v] - k, 0), c.heading[v],
                                      c.length[v], c.width[v])
            assert np.allclose((Pk @ DIRS.T).max(0), (ref_k @ DIRS.T).max(0), atol=1e-9)
            assert np.all(Pk >= lo[v] - 1e-9) and np.all(Pk <= hi[v] + 1e-9)


def test_timed_is_less_conservative_only_without_nesting():
    """Family "cross" is not nested: P^0 a vertical bar, P^1 a horizontal bar.  Claim a
    (l = 2, centre 0) is in P^1 at k = 1 and in P^0 at k = 2; its union claim is the hull of
    the cross, which contains (1.5, 1.5) (the hull edge is x + y = 3.2).  A small vehicle b
    of family "dot" sits at (1.5, 1.5): union sees a conflict, timed (the bars) does not."""
    table = build_family_table({"cross": [box(0.2, 3.0), box(3.0, 0.2), box(3.0, 3.0)],
                                "dot": [box(0.1, 0.1)]})
    c = make_claims(table, [0, 1], [[0, 0], [1.5, 1.5]], [2, 0], [0, 0], [0.1, 0.1], [0.1, 0.1])
    assert claim_conflicts(c, [0], [1], "union")[0]
    assert not claim_conflicts(c, [0], [1], "timed")[0]
    # the nested family with the same outer set: both checks see the conflict
    nested = build_family_table({"cross": [box(0.2, 0.2), box(3.0, 3.0), box(3.0, 3.0)],
                                 "dot": [box(0.1, 0.1)]})
    c2 = make_claims(nested, [0, 1], [[0, 0], [1.5, 1.5]], [2, 0], [0, 0], [0.1, 0.1], [0.1, 0.1])
    assert claim_conflicts(c2, [0], [1], "union")[0] and claim_conflicts(c2, [0], [1], "timed")[0]


def test_timed_finds_a_conflict_at_a_later_step():
    """Not nested: P^0 a long bar, P^1 small.  Claim a (l = 2) meets b only at k = 2."""
    table = build_family_table({"bar": [box(3.0, 0.2), box(0.2, 0.2), box(0.2, 0.2)],
                                "dot": [box(0.1, 0.1)]})
    c = make_claims(table, [0, 1], [[0, 0], [2.5, 0]], [2, 0], [0, 0], [0.1, 0.1], [0.1, 0.1])
    k1 = c.polygons_at(1)
    assert not intersect_sat(k1[:1], k1[1:])[0]                # not at k = 1 ...
    assert claim_conflicts(c, [0], [1], "timed")[0]            # ... but at k = 2
    far = make_claims(table, [0, 1], [[0, 0], [3.5, 0]], [2, 0], [0, 0], [0.1, 0.1], [0.1, 0.1])
    assert not claim_conflicts(far, [0], [1], "timed")[0]


def test_conflicting_pairs_mask():
    table = build_family_table({"x": [box(1, 1)]})
    c = make_claims(table, [0, 0, 0], [[0, 0], [1.5, 0], [3.0, 0]], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0])
    i, j = conflicting_pairs(c)
    assert list(zip(i, j)) == [(0, 1), (1, 2)]
    i, j = conflicting_pairs(c, mask=[True, False, False])
    assert list(zip(i, j)) == [(0, 1)]
