"""A small generated grid and demand shared by the SUMO-facing bridge tests."""

import subprocess
import sys
from pathlib import Path

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


TLS_ROUTES = """<routes>
  <vType id="car" length="5" width="1.8"/>
  <route id="e" edges="A1B1 B1C1"/><flow id="east" type="car" begin="0" end="48" period="8" route="e"/>
  <route id="w" edges="C1B1 B1A1"/><flow id="west" type="car" begin="2" end="48" period="8" route="w"/>
  <route id="n" edges="B0B1 B1B2"/><flow id="north" type="car" begin="4" end="48" period="8" route="n"/>
  <route id="s" edges="B2B1 B1B0"/><flow id="south" type="car" begin="6" end="48" period="8" route="s"/>
</routes>
"""


@pytest.fixture(scope="module")
def tls_cfg(tmp_path_factory):
    """A 3 x 3 grid whose centre B1 is a traffic light (SUMO's static 40 s program, 3 s yellow) and
    four streams crossing it (tests/bridge/test_sumo_signals.py, test_sweep.py)."""
    d = tmp_path_factory.mktemp("tls")
    subprocess.run([str(Path(sys.executable).parent / "netgenerate"), "--grid", "--grid.x-number", "3", "--grid.y-number", "3", "--grid.length", "80",
                    "--default.lanenumber", "1", "--tls.set", "B1", "--tls.cycle.time", "40",
                    "--tls.yellow.time", "3", "-o", str(d / "net.net.xml")], check=True, capture_output=True)
    (d / "demand.rou.xml").write_text(TLS_ROUTES)
    cfg = d / "tls.sumocfg"
    cfg.write_text('<configuration><input><net-file value="net.net.xml"/><route-files value="demand.rou.xml"/>'
                   '</input><time><begin value="0"/><end value="150"/><step-length value="0.1"/></time>'
                   '</configuration>')
    return cfg


@pytest.fixture
def netgenerate_grid(tmp_path):
    """A factory: ``make(x, y, length, lanes, name="net.net.xml")`` writes netgenerate's grid of
    ``x`` x ``y`` junctions, ``length`` m blocks and ``lanes`` lanes each way into the test's
    directory and returns its path."""
    def make(x: int, y: int, length: float, lanes: int, name: str = "net.net.xml") -> Path:
        out = tmp_path / name
        subprocess.run([str(Path(sys.executable).parent / "netgenerate"), "--grid", "--grid.x-number", str(x),
                        "--grid.y-number", str(y), "--grid.length", str(length), "--default.lanenumber", str(lanes),
                        "-o", str(out)], check=True, capture_output=True)
        return out
    return make
