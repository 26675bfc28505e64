"""A small generated grid and demand shared by the SUMO-facing bridge tests."""

import pytest

from sumo_nets.generate import make_demand, make_grid, sumocfg_for


@pytest.fixture(scope="session")
def sumo_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("bridge-sumo")


@pytest.fixture(scope="session")
def grid_net(sumo_dir):
    """3 x 3 junctions, 2 lanes each way, internal junction lanes, approach stubs."""
    return make_grid(sumo_dir, junctions=3, spacing_m=100.0, lanes=2)


@pytest.fixture(scope="session")
def grid_routes(grid_net, sumo_dir):
    return make_demand(grid_net, sumo_dir, seed=5, vehicles=20, duration_s=40.0,
                       class_mix={"car": 0.5, "bus": 0.25, "truck": 0.25})


@pytest.fixture(scope="session")
def grid_cfg(grid_routes):
    return sumocfg_for(grid_routes)
