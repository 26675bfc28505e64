"""``--seed`` draws the generated demand (randomTrips' seed), not only disturbances and tie-breaks."""

import json

from bridge.cli import main

SCENARIO = """
name = "tiny"
seed = 1
tm = "optimal"
check = "union"
switching = "early"
disturbance = "random"

[net]
type = "grid"
junctions = 3
spacing_m = 100.0
lanes = 1

[demand]
vehicles = 12
duration_s = 30.0
class_mix = { car = 0.8, bus = 0.1, truck = 0.1 }
"""


def _routes(tmp_path, label, *seed):
    """Generate the scenario's demand for a run (real randomTrips + duarouter) and return its routes."""
    toml = tmp_path / "tiny.toml"
    toml.write_text(SCENARIO)
    out = tmp_path / label
    args = ["run", str(toml), "--baseline", "sumo", "--duration", "1", "--quiet", "--out", str(out)]
    assert main(args + (["--seed", str(seed[0])] if seed else [])) == 0
    (f,) = out.glob("inputs/demand-*/routes.rou.xml")
    return f.read_bytes(), json.loads((out / "summary.json").read_text())


def test_seed_changes_the_demand_and_the_same_seed_repeats_it(tmp_path):
    a1, s1 = _routes(tmp_path, "a1", 1)
    a2, s2 = _routes(tmp_path, "a2", 2)
    b2, _ = _routes(tmp_path, "b2", 2)
    assert a1 != a2                       # another seed, other traffic
    assert a2 == b2                       # same seed, byte-identical demand
    assert (s1["seed"], s1["demand_seed"], s2["seed"], s2["demand_seed"]) == (1, 1, 2, 2)


def test_without_seed_the_scenario_seed_draws_the_demand(tmp_path):
    d, s = _routes(tmp_path, "d")
    a1, _ = _routes(tmp_path, "a1", 1)
    assert d == a1 and s["demand_seed"] == s["seed"] == 1
