"""Scenario files: built-ins, validation errors naming file, field and what is valid; SUMO configs."""

import textwrap

import pytest

from sumo_nets.scenario import (
    DEFAULT_CLASSES,
    ScenarioError,
    builtin_scenarios,
    load_scenario,
    materialise,
    read_sumocfg,
)

GOOD = """
name = "t"
seed = 2
duration_s = 60.0
tm = "greedy"
check = "timed"
switching = "terminal"

[net]
type = "grid"
junctions = 3
spacing_m = 100
lanes = 2
speed_mps = 13.89

[demand]
vehicles = 10
duration_s = 30.0
class_mix = { car = 1.0 }
"""


def write(tmp_path, text, name="s.toml"):
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return p


def test_builtin_grid_defaults():
    assert {"grid", "grid-large"} <= set(builtin_scenarios())
    s = load_scenario("grid")
    # check None: the run takes the controller's (timed with authority, union with paper)
    assert (s.name, s.seed, s.duration_s, s.tm, s.check, s.switching) == ("grid", 1, 300.0, "optimal", None,
                                                                          "early")
    assert (s.net.junctions, s.net.lanes, s.net.spacing_m) == (4, 2, 100.0)
    assert s.demand.vehicles == 150 and s.demand.duration_s == 300.0 and s.demand.seed == 1
    assert s.demand.mix == {"car": 0.8, "bus": 0.1, "truck": 0.1}
    assert s.class_of_vtype == {"car": "car", "bus": "bus", "truck": "truck"}
    large = load_scenario("grid-large")
    assert large.net.junctions == 10 and large.demand.vehicles >= 2000


def test_good_file_and_defaults(tmp_path):
    s = load_scenario(write(tmp_path, GOOD))
    assert (s.tm, s.check, s.switching, s.disturbance) == ("greedy", "timed", "terminal", "random")
    assert s.net.spacing_m == 100.0 and isinstance(s.net.spacing_m, float)
    assert s.demand.seed == 2  # defaults to the scenario seed
    assert s.demand.duration_s == 30.0
    # the name defaults to the file stem
    s2 = load_scenario(write(tmp_path, GOOD.replace('name = "t"\n', ""), "my-city.toml"))
    assert s2.name == "my-city"


@pytest.mark.parametrize("old, new, field, valid", [
    ('seed = 2', 'seed = 2\ncolour = "red"', "colour", "unknown key"),
    ('lanes = 2', 'lanes = 2\nwidth = 3', "net.width", "unknown key"),
    ('vehicles = 10', 'vehicles = 10\ncars = 3', "demand.cars", "unknown key"),
    ('junctions = 3', 'junctions = "3"', "net.junctions", "integer"),
    ('junctions = 3', 'junctions = 3.0', "net.junctions", "integer"),
    ('lanes = 2', 'lanes = true', "net.lanes", "integer"),
    ('spacing_m = 100', 'spacing_m = "far"', "net.spacing_m", "number"),
    ('tm = "greedy"', 'tm = 3', "tm", "'greedy', 'optimal'"),
    ('tm = "greedy"', 'tm = "fastest"', "tm", "'greedy', 'optimal'"),
    ('check = "timed"', 'check = "both"', "check", "'union', 'timed'"),
    ('switching = "terminal"', 'switching = "late"', "switching", "'terminal', 'early'"),
    ('seed = 2', 'seed = -1', "seed", ">= 0"),
    ('duration_s = 60.0', 'duration_s = 0', "duration_s", "> 0"),
    ('lanes = 2', 'lanes = 0', "net.lanes", ">= 1"),
    ('junctions = 3', 'junctions = 1', "net.junctions", ">= 2"),
    ('type = "grid"', 'type = "spider"', "net.type", "'grid'"),
    ('vehicles = 10', 'vehicles = -5', "demand.vehicles", ">= 1"),
    ('class_mix = { car = 1.0 }', 'class_mix = { car = -1.0 }', "demand.class_mix.car", ">= 0"),
    ('class_mix = { car = 1.0 }', 'class_mix = { plane = 1.0 }', "demand.class_mix.plane", "paper-a"),
    ('class_mix = { car = 1.0 }', 'class_mix = { car = 0.0 }', "demand.class_mix", "not all be zero"),
    ('class_mix = { car = 1.0 }', 'class_mix = "car"', "demand.class_mix", "table"),
])
def test_invalid_fields_name_file_field_and_valid_values(tmp_path, old, new, field, valid):
    assert old in GOOD
    path = write(tmp_path, GOOD.replace(old, new, 1))
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    msg = str(err.value)
    assert str(path) in msg
    assert f"{field}:" in msg
    assert valid in msg


def test_classes_are_checked_against_the_given_set(tmp_path):
    path = write(tmp_path, GOOD.replace("car = 1.0", "paper-a = 1.0"))
    assert load_scenario(path).demand.mix == {"paper-a": 1.0}
    with pytest.raises(ScenarioError, match=r"demand\.class_mix\.paper-a.*valid classes: car, van"):
        load_scenario(path, classes={"car", "van"})
    assert "paper-d" in DEFAULT_CLASSES


def test_missing_tables_and_bad_toml(tmp_path):
    no_demand = write(tmp_path, GOOD.split("[demand]")[0])
    with pytest.raises(ScenarioError, match=r"s\.toml: net/demand: .*\[demand\]"):
        load_scenario(no_demand)
    bad = write(tmp_path, "name = \n", "bad.toml")
    with pytest.raises(ScenarioError, match=r"bad\.toml: not valid TOML"):
        load_scenario(bad)
    with pytest.raises(ScenarioError, match="does not exist"):
        load_scenario(tmp_path / "nope.toml")
    with pytest.raises(ScenarioError, match="unknown scenario 'nope'.*grid"):
        load_scenario("nope")


def test_builtin_names_win_over_same_named_directories(tmp_path, monkeypatch):
    (tmp_path / "grid").mkdir()
    monkeypatch.chdir(tmp_path)
    assert load_scenario("grid").name == "grid"


def test_materialise_is_cached(tmp_path):
    s = load_scenario(write(tmp_path, GOOD))
    files = materialise(s, tmp_path / "work")
    assert files.net.is_file() and files.sumocfg.is_file() and len(files.routes) == 1
    assert files.routes[0].is_file()
    assert materialise(s, tmp_path / "work") == files
    cfg = read_sumocfg(files.sumocfg)
    assert cfg.net == files.net.resolve() and cfg.routes == (files.routes[0].resolve(),)


CFG = """<configuration>
    <input>
        <net-file value="{net}"/>
        <route-files value="{routes}"/>
    </input>
</configuration>
"""


def test_read_sumocfg_resolves_relative_paths(tmp_path):
    (tmp_path / "nets").mkdir()
    (tmp_path / "nets" / "a.net.xml").write_text("<net/>")
    (tmp_path / "r1.rou.xml").write_text("<routes/>")
    (tmp_path / "r2.rou.xml").write_text("<routes/>")
    cfg_path = tmp_path / "c.sumocfg"
    cfg_path.write_text(CFG.format(net="nets/a.net.xml", routes="r1.rou.xml,r2.rou.xml"))
    cfg = read_sumocfg(cfg_path)
    assert cfg.net == (tmp_path / "nets" / "a.net.xml").resolve()
    assert cfg.routes == ((tmp_path / "r1.rou.xml").resolve(), (tmp_path / "r2.rou.xml").resolve())
    # a scenario may point at it, relative to the TOML file
    scen = write(tmp_path, 'sumocfg = "c.sumocfg"\n[vtype_classes]\nDEFAULT_VEHTYPE = "car"\n')
    s = load_scenario(scen)
    assert s.sumocfg == cfg_path.resolve() and s.net is None and s.class_of_vtype == {"DEFAULT_VEHTYPE": "car"}
    assert load_scenario(cfg_path).sumocfg == cfg_path.resolve()
    assert s.class_for("DEFAULT_VEHTYPE") == "car"
    assert (s.class_for("myBus", "bus"), s.class_for("lorry", "trailer"), s.class_for("truck", "bus")) == (
        "bus", "truck", "truck")
    with pytest.raises(ScenarioError, match=r"s\.toml: vtype_classes\.boat: vType 'boat' \(vClass 'ship'\)"):
        s.class_for("boat", "ship")
    assert materialise(s, tmp_path).net == cfg.net


def test_read_sumocfg_errors(tmp_path):
    with pytest.raises(ScenarioError, match=r"missing\.sumocfg: SUMO configuration does not exist"):
        read_sumocfg(tmp_path / "missing.sumocfg")
    bad = tmp_path / "bad.sumocfg"
    bad.write_text("<configuration><input>")
    with pytest.raises(ScenarioError, match=r"bad\.sumocfg: not a well-formed"):
        read_sumocfg(bad)
    no_net = tmp_path / "nonet.sumocfg"
    no_net.write_text("<configuration><input/></configuration>")
    with pytest.raises(ScenarioError, match=r"nonet\.sumocfg: no <net-file"):
        read_sumocfg(no_net)
    gone = tmp_path / "gone.sumocfg"
    gone.write_text(CFG.format(net="x.net.xml", routes=""))
    with pytest.raises(ScenarioError, match=r"gone\.sumocfg: net-file 'x\.net\.xml' does not exist"):
        read_sumocfg(gone)
    scen = write(tmp_path, 'sumocfg = "gone.sumocfg"\n', "g.toml")
    with pytest.raises(ScenarioError, match=r"gone\.sumocfg: net-file"):
        load_scenario(scen)


def test_sumocfg_and_generated_net_exclude_each_other(tmp_path):
    (tmp_path / "a.net.xml").write_text("<net/>")
    (tmp_path / "c.sumocfg").write_text(CFG.format(net="a.net.xml", routes=""))
    both = write(tmp_path, 'sumocfg = "c.sumocfg"\n' + GOOD, "both.toml")
    with pytest.raises(ScenarioError, match=r"both\.toml: sumocfg: .*either"):
        load_scenario(both)
