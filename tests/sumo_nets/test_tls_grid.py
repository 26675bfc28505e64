"""sumo_nets.tls_grid: the signalised city grid made by SUMO's own tools, run by plain sumo."""

import subprocess
import xml.etree.ElementTree as ET

import pytest

from sumo_nets.sumo_tools import binary
from sumo_nets.tls_grid import TlsGridSettings, make_tls_grid


@pytest.fixture(scope="module")
def tls_cfg(tmp_path_factory):
    return make_tls_grid(tmp_path_factory.mktemp("tlsgrid"))


def test_the_grid_has_traffic_lights_and_the_demand_is_the_requested_trips(tls_cfg):
    net = ET.parse(tls_cfg.with_name("tlsgrid.net.xml")).getroot()
    tls = net.findall("tlLogic")
    assert len(tls) >= 4  # --tls.guess signalises the inner junctions of a 4 x 4 grid (12 measured)
    assert {j.get("type") for j in net.findall("junction") if j.get("id") in {t.get("id") for t in tls}} == \
        {"traffic_light"}
    trips = ET.parse(tls_cfg.with_name("tlsgrid.rou.xml")).getroot().findall("trip")
    # randomTrips -e 180 -p 2: departures 0, 2, ..., 178 (--validate drops only unroutable ones; none in a grid)
    assert [float(t.get("depart")) for t in trips] == [2.0 * i for i in range(90)]
    cfg = ET.parse(tls_cfg).getroot()
    assert cfg.find("input/net-file").get("value") == "tlsgrid.net.xml"
    assert cfg.find("input/route-files").get("value") == "tlsgrid.rou.xml"
    assert cfg.find("time/end").get("value") == "180"


def test_plain_sumo_runs_the_configuration(tls_cfg, tmp_path):
    info = tmp_path / "tripinfo.xml"
    proc = subprocess.run([str(binary("sumo")), "-c", str(tls_cfg), "--end", "60", "--no-step-log",
                           "--tripinfo-output", str(info)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "collision" not in proc.stderr.lower()
    assert ET.parse(info).getroot().findall("tripinfo")  # some trips finish in the first minute


def test_the_same_settings_give_the_same_demand(tls_cfg, tmp_path):
    other = make_tls_grid(tmp_path)
    strip = lambda p: [ET.tostring(e) for e in ET.parse(p).getroot()]  # noqa: E731 - the header holds a date
    assert strip(other.with_name("tlsgrid.rou.xml")) == strip(tls_cfg.with_name("tlsgrid.rou.xml"))


@pytest.mark.parametrize("kwargs, field", [(dict(junctions=1), "junctions"), (dict(lanes=0), "lanes"),
                                           (dict(seed=-1), "seed"), (dict(end_s=0), "end_s"),
                                           (dict(period_s="2"), "period_s")])
def test_bad_settings_name_the_field(kwargs, field):
    with pytest.raises(ValueError, match=f"TlsGridSettings.{field}"):
        TlsGridSettings(**kwargs)
