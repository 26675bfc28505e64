"""Family table: validation, nesting detection and prefix hulls."""

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from tests.tm.helpers import box, nested_family
from tm.families import FamilyError, build_family_table


def test_nested_family_stores_levels_as_hulls():
    fam = nested_family(np.random.default_rng(1), 5, "poly")
    t = build_family_table({"a": fam, "b": [box(1, 1)]})
    assert t.nested.tolist() == [True, True]
    assert t.keys == ("a", "b") and t.n_levels.tolist() == [5, 1] and t.offset.tolist() == [0, 5]
    for l, P in enumerate(fam):
        assert np.array_equal(t.hulls[l, :len(P)], P)         # H^l = P^l exactly
    assert np.array_equal(t.family_index(["b", "a", "b"]), [1, 0, 1])


def test_non_nested_family_gets_the_hull_of_the_union():
    fam = [box(1, 1), box(3, 0.5), box(0.5, 3)]                # crossing bars: not nested
    t = build_family_table({"x": fam})
    assert not t.nested[0]
    H2 = t.hulls[2]
    pts = np.vstack(fam)
    assert ConvexHull(H2).volume == pytest.approx(ConvexHull(pts).volume, rel=1e-12)
    assert np.allclose(t.lo[2], [-3, -3]) and np.allclose(t.hi[2], [3, 3])


@pytest.mark.parametrize("families, needle", [
    ({}, "non-empty"),
    ({"a": []}, "at least one level"),
    ({"a": [box(1, 1)[::-1]]}, "counter-clockwise"),
    ({"a": [np.zeros((3, 3))]}, "(k, 2)"),
    ({"a": [np.array([[0, 0], [np.nan, 1], [1, 1]])]}, "finite"),
])
def test_invalid_families_are_rejected(families, needle):
    with pytest.raises(FamilyError) as err:
        build_family_table(families)
    assert needle in str(err.value)


def test_unknown_key_is_named():
    t = build_family_table({"car": [box(1, 1)]})
    with pytest.raises(FamilyError, match="'bus'"):
        t.family_index(["car", "bus"])
