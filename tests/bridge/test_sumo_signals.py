"""Traffic lights on real SUMO: a red is never passed with ``--signals obey`` (SUMO's own view of
every vehicle against its next light, each step), vehicles still arrive, and ``--signals ignore``
passes reds (and ``red_violations`` counts them).

The network is written by the test (netgenerate: a 3 x 3 grid, one traffic light at the centre
``B1`` with SUMO's static program of 17 s green, 3 s yellow per direction), the demand four
crossing streams through it.
"""

import json
import subprocess
import sys
from pathlib import Path

import pytest

import bridge.sumo_world as sumo_world
from bridge.cli import main

ROUTES = """<routes>
  <vType id="car" length="5" width="1.8"/>
  <route id="e" edges="A1B1 B1C1"/><flow id="east" type="car" begin="0" end="48" period="8" route="e"/>
  <route id="w" edges="C1B1 B1A1"/><flow id="west" type="car" begin="2" end="48" period="8" route="w"/>
  <route id="n" edges="B0B1 B1B2"/><flow id="north" type="car" begin="4" end="48" period="8" route="n"/>
  <route id="s" edges="B2B1 B1B0"/><flow id="south" type="car" begin="6" end="48" period="8" route="s"/>
</routes>
"""


@pytest.fixture(scope="module")
def tls_cfg(tmp_path_factory):
    d = tmp_path_factory.mktemp("tls")
    subprocess.run([str(Path(sys.executable).parent / "netgenerate"), "--grid", "--grid.x-number", "3", "--grid.y-number", "3", "--grid.length", "80",
                    "--default.lanenumber", "1", "--tls.set", "B1", "--tls.cycle.time", "40",
                    "--tls.yellow.time", "3", "-o", str(d / "net.net.xml")], check=True, capture_output=True)
    (d / "demand.rou.xml").write_text(ROUTES)
    cfg = d / "tls.sumocfg"
    cfg.write_text('<configuration><input><net-file value="net.net.xml"/><route-files value="demand.rou.xml"/>'
                   '</input><time><begin value="0"/><end value="150"/><step-length value="0.1"/></time>'
                   '</configuration>')
    return cfg


class RedWatch:
    """SUMO's view, every step: a vehicle whose next light (tls, link) was ahead of it and red at
    the previous step and is behind it now crossed the stop line on red."""

    def __init__(self):
        self.prev = {}
        self.crossed_red = []
        self.crossed = 0
        self.red_seen = 0

    def on_step(self, sim, state, decision, row):
        api = sim.world.adapter._api
        now = {}
        for v in api.vehicle.getIDList():
            ahead = {(t, i): s for t, i, _, s in api.vehicle.getNextTLS(v)}
            for key, s in self.prev.get(v, {}).items():
                if key not in ahead:
                    self.crossed += 1
                    if s in "rRu":
                        self.crossed_red.append((sim.t, v, key))
            self.red_seen += sum(s in "rRu" for s in ahead.values())
            now[v] = ahead
        self.prev = now

    def close(self):
        pass


def _run(cfg, out, monkeypatch, *extra):
    watch = RedWatch()
    base = sumo_world.observers_for
    monkeypatch.setattr(sumo_world, "observers_for", lambda *a, **k: base(*a, **k) + [watch])
    rc = main(["run", str(cfg), "--out", str(out), "--quiet", "--log", "none", "--duration", "120", *extra])
    return rc, json.loads((out / "summary.json").read_text()), watch


def test_red_light_never_passed_and_vehicles_arrive(tls_cfg, tmp_path, monkeypatch):
    rc, s, watch = _run(tls_cfg, tmp_path / "obey", monkeypatch)
    assert rc == 0 and s["complete"], s.get("error")
    assert s["options"]["signals"] == "obey"
    assert watch.red_seen > 0 and watch.crossed > 0   # the light was red for some, and lines were crossed
    assert watch.crossed_red == []                    # SUMO's own view: no line crossed on red
    assert s["red_violations"] == 0 and s["signal_withheld"] > 0
    assert s["collisions_sumo"] == 0 and s["collisions_geometric"] == 0 and s["invariant_violations"] == 0
    assert s["vehicles_arrived"] >= 10, s              # liveness: every stream gets through


def test_red_light_never_passed_authority(tls_cfg, tmp_path, monkeypatch):
    """The same with ``--controller authority``: no line crossed on red (SUMO's view), every
    stream gets through, no collision, and the junction tokens are used and given back at red."""
    rc, s, watch = _run(tls_cfg, tmp_path / "authority", monkeypatch, "--controller", "authority")
    assert rc == 0 and s["complete"], s.get("error")
    assert watch.red_seen > 0 and watch.crossed > 0 and watch.crossed_red == []
    assert s["red_violations"] == 0 and s["signal_withheld"] > 0
    assert s["collisions_sumo"] == 0 and s["collisions_geometric"] == 0 and s["safe"] is True, s
    assert s["zones_ignored"] == 0 and s["junction_tokens"] > 0 and s["junction_given_back"] > 0
    assert s["vehicles_arrived"] >= 10, s


def test_signals_ignore_passes_reds_and_counts_them(tls_cfg, tmp_path, monkeypatch):
    rc, s, watch = _run(tls_cfg, tmp_path / "ignore", monkeypatch, "--signals", "ignore")
    assert rc == 0 and s["complete"], s.get("error")
    assert s["options"]["signals"] == "ignore" and s["signal_withheld"] == 0
    assert len(watch.crossed_red) > 0                 # SUMO sees reds passed
    assert s["red_violations"] > 0                    # and muvsim's counter fires
    assert s["collisions_sumo"] == 0 and s["collisions_geometric"] == 0


def test_stop_line_where_the_signalised_connection_leaves_its_lane(tls_cfg):
    """East through B1 crosses one line: at the end of lane A1B1_0 (its shape's length along the
    route, which starts at that lane's start), link 13 of light B1; a route through the
    unsignalised A0 and B0 crosses none.  Tolerance 0.5 m: slivers and cut corners move the
    polyline by less (bridge.waypoints.MIN_SEGMENT_M, CHAMFER_M * sin of half a small turn)."""
    import numpy as np

    from bridge.signals import LinkSlots, route_stop_lines
    from bridge.waypoints import load_net

    geo = load_net(tls_cfg.parent / "net.net.xml")
    slots = LinkSlots()
    r = geo.route(["A1B1", "B1C1"], 3.0, turn_max_deg=45.0)
    lines = route_stop_lines(geo, r, r.arc_length, slots)
    lane = geo.lane_shape("A1B1_0")
    assert len(lines) == 1 and slots.slot == {("B1", 13): 0}
    assert abs(lines.s_line[0] - np.hypot(*np.diff(lane, axis=0).T).sum()) < 0.5
    assert len(route_stop_lines(geo, geo.route(["A0B0", "B0C0"], 3.0), np.zeros(1), slots)) == 0
