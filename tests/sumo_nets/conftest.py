"""A small generated grid shared by the sumo_nets tests (generation is the slow part)."""

import pytest

from sumo_nets.generate import make_demand, make_grid

MIX = {"car": 0.6, "bus": 0.2, "truck": 0.2}


@pytest.fixture(scope="session")
def gen_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("sumo-nets")


@pytest.fixture(scope="session")
def small_net(gen_dir):
    return make_grid(gen_dir, junctions=3, spacing_m=100.0, lanes=2)


@pytest.fixture(scope="session")
def small_routes(small_net, gen_dir):
    return make_demand(small_net, gen_dir, seed=3, vehicles=30, duration_s=60.0, class_mix=MIX)
