"""controllers.search_kernel.search_clipped against numpy's clipped searchsorted, on random buffers."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from controllers.search_kernel import search_clipped


@settings(max_examples=300, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), R=st.integers(0, 60), n=st.integers(0, 40), dup=st.booleans(),
       side=st.sampled_from(["left", "right"]))
def test_same_as_numpy(seed, R, n, dup, side):
    rng = np.random.default_rng(seed)
    a = np.sort(rng.integers(0, 10, R).astype(float) if dup else rng.normal(size=R) * 10)
    pool = np.r_[a, rng.normal(size=5) * 12, [np.nan, np.inf, -np.inf]]
    x = pool[rng.integers(0, len(pool), n)] if len(pool) else np.zeros(n)
    lo = rng.integers(0, R + 1, n)
    hi = rng.integers(0, R + 1, n)  # lo > hi too: numpy's clip takes hi
    want = np.clip(np.searchsorted(a, x, side=side), lo, hi)
    got = search_clipped(a, x, lo, hi, side)
    assert got.dtype == np.intp and np.array_equal(got, want)
    col = np.stack([a, -a], axis=1)[:, 0]  # a strided column, searched in place
    assert np.array_equal(search_clipped(col, x, lo, hi, side), want)


def test_scalar_bounds_and_checks():
    a = np.arange(10.0)
    x = np.array([-1.0, 3.0, 3.5, 20.0])
    assert np.array_equal(search_clipped(a, x, 2, 8, "right"), np.clip(np.searchsorted(a, x, "right"), 2, 8))
    with pytest.raises(ValueError):
        search_clipped(a, x, -1, 8)
    with pytest.raises(ValueError):
        search_clipped(a, x, 0, 11)
    with pytest.raises(ValueError):
        search_clipped(a, x, 0, 5, "middle")


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), R=st.integers(0, 40), dup=st.booleans(), right=st.booleans())
def test_bisect_is_searchsorted_of_the_slice(seed, R, dup, right):
    """The compiled scalar search (shared by search_clipped and bridge.body_kernels.sample_range) gives
    numpy's answer on the slice ``a[b0:b1]`` plus ``b0``, NaN last (``b1``); exact integers, no tolerance."""
    from controllers.search_kernel import bisect

    rng = np.random.default_rng(seed)
    a = np.sort(rng.integers(0, 6, R).astype(float) if dup else rng.normal(size=R) * 10)
    b0, b1 = sorted(rng.integers(0, R + 1, 2).tolist())
    side = "right" if right else "left"
    for v in np.r_[a, rng.normal(size=4) * 12, [np.nan, np.inf, -np.inf]]:
        want = int(np.searchsorted(a[b0:b1], v, side=side)) + b0
        assert bisect(a, float(v), b0, b1, right) == want
