"""Shared, session-scoped set families (synthesis is the slow part of these tests)."""

import numpy as np
import pytest

from controllers.classes import get_class
from controllers.models import drag_integrator, jerk_integrator
from controllers.settings import SynthesisSettings
from controllers.synthesis import synthesize

JERK = dict(v_max=13.89, a_max=4.0, j_max=40.0, d_max=0.01, delta=1.0)


@pytest.fixture(scope="session")
def settings(shared_set_cache):
    """Default synthesis settings on the suite's shared set cache (tests/conftest.py)."""
    return SynthesisSettings(cache_dir=shared_set_cache)


@pytest.fixture(scope="session")
def families(settings):
    """One family per model type: double integrator, drag, jerk."""
    return {
        "double": synthesize(get_class("paper-a").model, settings),
        "drag": synthesize(get_class("bus").model, settings),
        "jerk": synthesize(jerk_integrator(**JERK), settings),
    }


@pytest.fixture(params=["double", "drag", "jerk"])
def family(request, families):
    return families[request.param]


def rng_for(seed: int) -> np.random.Generator:
    return np.random.default_rng(seed)
