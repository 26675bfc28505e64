"""Traffic lights on real SUMO: a red is never passed with ``--signals obey`` (SUMO's own view of
every vehicle against its next light, each step), vehicles still arrive, and ``--signals ignore``
passes reds (and ``red_violations`` counts them).

The network is written by the ``tls_cfg`` fixture (tests/bridge/conftest.py: netgenerate, a 3 x 3
grid, one traffic light at the centre ``B1`` with SUMO's static program of 17 s green, 3 s yellow
per direction), the demand four crossing streams through it.
"""

import json

import pytest

import bridge.sumo_world as sumo_world
from bridge.cli import main


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


class GamePlayer:
    """Plays SUMO's traffic-light game: at ``at_s`` it switches every light to ``phase`` (what a
    click does in ``tools/game/runner.py``: the next phase of the manual program)."""

    def __init__(self, at_s: float, phase: int):
        self.at_s, self.phase, self.switched_at = at_s, phase, None

    def on_step(self, sim, state, decision, row):
        if self.switched_at is None and sim.t * sim.settings.Ts >= self.at_s:
            api = sim.world.adapter._api
            for tls in api.trafficlight.getIDList():
                api.trafficlight.setPhase(tls, self.phase)
            self.switched_at = sim.t * sim.settings.Ts

    def close(self):
        pass


def test_game_corridor_holds_only_at_sumos_reds_and_goes_on_green(tmp_path, monkeypatch):
    """SUMO's ``tools/game/corridor``, unchanged.  Its lights are manual: the side streets' phases
    last 10005 s until the player switches, so with nobody playing they are red for the whole
    run (SUMO's own drivers land none of them either; issue 11).  Here a player switches every
    light at 50 s (corridor yellow, all red, side streets green).

    Every request a light withholds is, in SUMO's own view (``getNextTLS``), at the vehicle's
    next light, the same link index, a red or yellow state, and our gap to the stop line is
    SUMO's distance to it (tolerance 0.5 m as above; measured < 0.01 m).  Every vehicle held
    before the switch goes once its light is green and crosses its line (no vehicle stays held
    after green), none on red (SUMO's view and ``red_violations``)."""
    from bridge.request_filters import RequestFilters
    from sumo_nets.sumo_tools import sumo_home

    checked, bad, held_before = [0], [], {}
    player, watch = GamePlayer(50.0, 3), RedWatch()
    inner = RequestFilters._signals

    def signals(self, state):
        out = inner(self, state)
        if self._link_state is None:
            return out
        api = self.world.adapter._api
        k, _, (row, bound, s_line, slot, front) = self._signal_lines(state.ids, state.centre, state.heading,
                                                                   state.length)
        link_of = {s: key for key, s in self.world.slots.slot.items()}
        held = state.requesting & ~out.requesting
        for j in range(len(row)):
            i = int(row[j])
            if not (held[i] and bound[j] == k[i]):
                continue
            vid, ours, letter = state.ids[i], link_of[int(slot[j])], chr(self._link_state[slot[j]])
            nxt = api.vehicle.getNextTLS(vid)
            checked[0] += 1
            if not nxt or nxt[0][:2] != ours or nxt[0][3] != letter or letter not in "rRuyY" \
                    or abs(nxt[0][2] - float(s_line[j] - front[i])) > 0.5:
                bad.append((self.t, vid, ours, letter, float(s_line[j] - front[i]), nxt[:1]))
            if player.switched_at is None:
                held_before[vid] = ours
        return out

    monkeypatch.setattr(RequestFilters, "_signals", signals)
    base = sumo_world.observers_for
    monkeypatch.setattr(sumo_world, "observers_for", lambda *a, **k: base(*a, **k) + [player, watch])
    cfg = sumo_home() / "tools" / "game" / "corridor.sumocfg"
    out = tmp_path / "corridor"
    rc = main(["run", str(cfg), "--out", str(out), "--quiet", "--log", "none", "--duration", "90"])
    s = json.loads((out / "summary.json").read_text())
    assert rc == 0 and s["complete"], s.get("error")
    assert player.switched_at is not None and checked[0] > 0 and bad == [], bad[:5]
    assert len(held_before) >= 3, held_before          # side-street heads stood at their reds
    # each crossed its line after the switch: SUMO no longer lists that light ahead of it
    still = {v: key for v, key in held_before.items() if key in watch.prev.get(v, {})}
    assert still == {}, still
    assert watch.crossed_red == [] and s["red_violations"] == 0
    assert s["collisions_sumo"] == 0 and s["collisions_geometric"] == 0 and s["invariant_violations"] == 0


# departSpeed="0": the timing below is for a car starting at rest (SUMO 1.28 inserts at the lane's
# speed by default, and muvsim now starts vehicles as SUMO does: bridge/departure.py)
LONG_ROUTE = """<routes><vType id="car" length="5" width="1.8"/><route id="e" edges="A1B1 B1C1"/>
  <vehicle id="late" type="car" depart="{depart}" route="e" departSpeed="0"/></routes>"""


@pytest.fixture(scope="module")
def end_of_green_cfg(tmp_path_factory):
    """A 3 x 3 grid, 200 m edges (room to reach 13.9 m/s), a static light at B1 (cycle 40 s,
    3 s yellow: east 17 s green from 0 s), one car east through it departing at 24.6 s: it asks
    for the switch past the line on green just before yellow, 3.6 s out (before issue 12's fix it
    entered on red: depart times 24.6 and 24.8 s, 1 crossing each, 24.4 s none; measured)."""
    import subprocess
    import sys
    from pathlib import Path

    d = tmp_path_factory.mktemp("tls_end_of_green")
    subprocess.run([str(Path(sys.executable).parent / "netgenerate"), "--grid", "--grid.x-number", "3",
                    "--grid.y-number", "3", "--grid.length", "200", "--default.lanenumber", "1", "--tls.set", "B1",
                    "--tls.cycle.time", "40", "--tls.yellow.time", "3", "-o", str(d / "net.net.xml")],
                   check=True, capture_output=True)
    (d / "late.rou.xml").write_text(LONG_ROUTE.format(depart=24.6))
    cfg = d / "late.sumocfg"
    cfg.write_text('<configuration><input><net-file value="net.net.xml"/><route-files value="late.rou.xml"/>'
                   '</input><time><begin value="0"/><end value="150"/><step-length value="0.1"/></time>'
                   '</configuration>')
    return cfg


def _run_late(cfg, out, monkeypatch):
    watch = RedWatch()
    base = sumo_world.observers_for
    monkeypatch.setattr(sumo_world, "observers_for", lambda *a, **k: base(*a, **k) + [watch])
    rc = main(["run", str(cfg), "--out", str(out), "--quiet", "--log", "none", "--duration", "90",
               "--controller", "authority"])
    return rc, json.loads((out / "summary.json").read_text()), watch


def test_authority_car_at_the_end_of_green_waits_instead_of_entering_on_red(end_of_green_cfg, tmp_path,
                                                                          monkeypatch):
    """Issue 12: with the time-to-red rule the car is held at the line and crosses on the next
    green (SUMO's view and ``red_violations`` 0, safe); without it (the letter alone, as before)
    it enters on red, SUMO sees it, the counter fires and the run is flagged unsafe (exit 3)."""
    from analysis.safety import UNSAFE_EXIT
    from bridge.request_filters import RequestFilters

    rc, s, watch = _run_late(end_of_green_cfg, tmp_path / "rule", monkeypatch)
    assert rc == 0 and s["complete"], s.get("error")
    assert watch.crossed > 0 and watch.crossed_red == [] and s["red_violations"] == 0
    assert s["signal_withheld"] > 0 and s["vehicles_arrived"] == 1 and s["safe"] is True, s

    monkeypatch.setattr(RequestFilters, "_line_timing", lambda self, ids, slot: None)  # the rule off
    rc, s, watch = _run_late(end_of_green_cfg, tmp_path / "letter_only", monkeypatch)
    assert s["complete"], s.get("error")
    assert len(watch.crossed_red) == 1 and s["red_violations"] == 1
    assert rc == UNSAFE_EXIT and s["safe"] is False and s["safety_violations"] == {"red_violations": 1}
