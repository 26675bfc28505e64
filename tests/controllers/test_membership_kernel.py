"""The compiled index search (controllers/membership_kernel.py) against the numpy search it
replaced: the same binary search over the levels with ``_Polar.inside`` as the test (the angles,
the sector lookup, the row and MEMBERSHIP_TOL).  Exact equality, on states sampled in every level,
just outside the boundaries (scaled by ``1 + 1e-7``) and far outside (N + 1), for the joint index,
each factor's own index and :class:`controllers.stmpc.FactorMembership`."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from controllers.classes import get_class
from controllers.settings import ControllerSettings, SynthesisSettings
from controllers.stmpc import STMPC, FactorMembership, _factor_inside, _nested_index
from controllers.synthesis import rotate_pairs, synthesize


@pytest.fixture(scope="module")
def car_authority(shared_set_cache):
    cls = get_class("car")
    return synthesize(cls.model, SynthesisSettings(cache_dir=shared_set_cache, authority_decel=cls.comfort_decel))


def _states(fam, rng, scale):
    X = np.vstack([fam.sample(l, 4, rng) for l in range(fam.N + 1)]) * scale
    C = rng.normal(size=(len(X), 2)) * 30
    H = rng.uniform(-np.pi, np.pi, size=len(X))
    X = rotate_pairs(X, H)
    X[:, :2] += C
    return X, C, H


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**31 - 1), scale=st.sampled_from([1.0, 1.0 + 1e-7, 1.05, 40.0]))
def test_compiled_index_equals_the_numpy_search(car_authority, seed, scale):
    rng = np.random.default_rng(seed)
    ctl = STMPC(car_authority, ControllerSettings(mode="authority"))
    assert ctl._stack is not None  # the car's factors have sector tables: the compiled path is taken
    X, C, H = _states(car_authority, rng, scale)
    E = ctl.error(X, C, H)
    want = _nested_index(lambda lev: ctl._inside(E, lev), len(E), ctl.N, ctl._steps)
    got = ctl.index(X, C, H)
    assert np.array_equal(got, want)
    assert len(np.unique(got)) > 2 or scale == 40.0  # many levels met (N + 1 only far outside)
    for f, t in enumerate(ctl._tables):
        Ef = E[:, t.states]
        want_f = _nested_index(lambda lev: _factor_inside(t, Ef, lev), len(E), ctl.N, ctl._steps)
        assert np.array_equal(ctl.factor_index(E, f), want_f)
        fm = FactorMembership.of(car_authority.factors[f])
        assert np.array_equal(fm.index(E), want_f)


def test_outside_every_level_is_n_plus_one(car_authority):
    ctl = STMPC(car_authority, ControllerSettings(mode="authority"))
    X = np.array([[0.0, 0.0, 0.0, 0.0], [0.0, 500.0, 0.0, 0.0]])
    assert ctl.index(X, np.zeros((2, 2)), np.zeros(2)).tolist() == [0, ctl.N + 1]
