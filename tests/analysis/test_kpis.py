"""KPI tables on small runs whose answers are known by hand."""

import dataclasses
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from analysis.kpis import (VEHICLE_COLUMNS, per_second, read_tripinfo, run_tables, step_table, summarise,
                           timing_means, vehicle_table)
from bridge.cosim import Cosim, CosimSettings, VehicleRecord, VehicleSpec
from bridge.layouts import subsample
from controllers.classes import builtin_classes

CLASSES = builtin_classes()
VMAX = {c: vc.v_max for c, vc in CLASSES.items()}


def test_vehicle_row_by_hand():
    """Requested 1 s, admitted 2 s, arrived 12 s, 100 m at paper-a's 20 m/s: free flow 5 s, delay 5 s;
    7 stopped steps of 0.1 s in 2 episodes; mean speed 50 / 100 steps."""
    r = VehicleRecord("a", "paper-a", 1.0, 100.0, admitted_s=2.0, arrived_s=12.0, denials=7, stop_episodes=2,
                      stopped_steps=7, closest_m=3.5, speed_sum=50.0, steps=100)
    waiting = VehicleRecord("b", "car", 5.0, 27.78)  # never admitted
    df = vehicle_table([r, waiting], VMAX, Ts=0.1)
    assert list(df.columns) == list(VEHICLE_COLUMNS)
    a = df.iloc[0]
    assert a["admission_delay_s"] == pytest.approx(1.0)
    assert a["travel_time_s"] == pytest.approx(10.0)
    assert a["free_flow_s"] == pytest.approx(5.0)
    assert a["delay_s"] == pytest.approx(5.0)
    assert a["time_stopped_s"] == pytest.approx(0.7)
    assert a["stop_episodes"] == 2 and a["denials"] == 7
    assert a["mean_speed_mps"] == pytest.approx(0.5)
    b = df.iloc[1]
    assert b["free_flow_s"] == pytest.approx(27.78 / 13.89)
    assert np.isnan(b["travel_time_s"]) and np.isnan(b["delay_s"]) and np.isnan(b["mean_speed_mps"])


def test_tripinfo_time_loss(tmp_path):
    (tmp_path / "tripinfo.xml").write_text(
        '<tripinfos><tripinfo id="a" depart="2.00" departDelay="1.00" arrival="12.00" duration="10.00" '
        'routeLength="100.00" timeLoss="4.50" waitingTime="0.70" waitingCount="2" vType="DEFAULT_VEHTYPE"/>'
        '</tripinfos>')
    ti = read_tripinfo(tmp_path / "tripinfo.xml")
    assert ti.loc[0, "requested_depart_s"] == pytest.approx(1.0) and ti.loc[0, "waiting_count"] == 2
    r = VehicleRecord("a", "paper-a", 1.0, 100.0, admitted_s=2.0, arrived_s=12.0)
    other = VehicleRecord("b", "paper-a", 1.0, 100.0)
    df = vehicle_table([r, other], VMAX, Ts=0.1, tripinfo=ti)
    assert df.loc[0, "sumo_time_loss_s"] == pytest.approx(4.5) and np.isnan(df.loc[1, "sumo_time_loss_s"])


def test_steps_per_second_and_summary_by_hand():
    rows = [dict(t_s=round(0.1 * i, 6), active=2, requests=1, grants=1 if i % 2 else 0, denials=0 if i % 2 else 1,
                 edges=i % 3, admitted=0, tm_ms=1.0, controller_ms=2.0, world_ms=3.0, footprint_overlaps=0,
                 min_separation_m=10.0 - 0.1 * i) for i in range(20)]
    steps = step_table(rows)
    assert (steps["logging_ms"] == 0).all()  # nothing logged
    sec = per_second(steps)
    assert list(sec["t_s"]) == [0.0, 1.0] and list(sec["steps"]) == [10, 10]
    assert list(sec["requests"]) == [10, 10] and list(sec["denials"]) == [5, 5]
    assert sec["tm_ms"].tolist() == [1.0, 1.0]
    assert sec["min_separation_m"].iloc[1] == pytest.approx(10.0 - 1.9)
    recs = [VehicleRecord("a", "paper-a", 0.0, 20.0, admitted_s=0.0, arrived_s=2.0, denials=10, stop_episodes=1,
                          stopped_steps=10),
            VehicleRecord("b", "paper-a", 0.0, 20.0, admitted_s=0.0)]
    fig = summarise(steps, vehicle_table(recs, VMAX, 0.1), Ts=0.1)
    assert fig["steps"] == 20 and fig["simulated_s"] == 2.0
    assert fig["vehicles_arrived"] == 1 and not fig["finished"]
    assert fig["stop_commands"] == 10 and fig["stop_episodes"] == 1 and fig["time_stopped_s"] == pytest.approx(1.0)
    assert fig["mean_travel_time_s"] == pytest.approx(2.0) and fig["mean_delay_s"] == pytest.approx(1.0)
    assert fig["throughput_vph"] == pytest.approx(1800.0)
    assert fig["min_separation_m"] == pytest.approx(8.1)
    assert timing_means(steps) == {"tm_ms": 1.0, "controller_ms": 2.0, "world_ms": 3.0, "logging_ms": 0.0}


def _straight(cls="paper-a", length=40.0, y=0.0, vid="v"):
    W = subsample(np.array([[0.0, y], [length, y]]), CLASSES[cls].model.delta)
    return VehicleSpec(id=vid, vclass=cls, waypoints=W)


class _DenyWindow:
    """Wraps a TM: denies ``vid``'s first ``k`` requests made from step ``start`` on."""

    def __init__(self, tm, sim, vid, start, k):
        self.tm, self.sim, self.vid, self.start, self.left = tm, sim, vid, start, k
        self.denied_at = []

    def __getattr__(self, name):
        return getattr(self.tm, name)

    def decide(self, state):
        dec = self.tm.decide(state)
        i = list(state.ids).index(self.vid) if self.vid in state.ids else None
        if i is not None and self.sim.t >= self.start and self.left > 0 and dec.go[i]:
            go = dec.go.copy()
            go[i] = False
            self.left -= 1
            self.denied_at.append(self.sim.t)
            dec = dataclasses.replace(dec, go=go, stopped=tuple(dec.stopped) + (self.vid,))
        return dec


@pytest.mark.parametrize("k", [0, 6])
def test_a_vehicle_stopped_exactly_k_steps(k):
    """A single vehicle on a straight 40 m road (free flow 2 s at 20 m/s) is denied its requests in k
    consecutive steps: the tables show k denials, one stop episode (if k > 0), k * Ts stopped, and the
    delay is the travel time minus 2 s; the summary is the tables' figures."""
    spec = _straight()
    sim = Cosim(CLASSES, [spec], CosimSettings(disturbance="none"))
    wrap = _DenyWindow(sim.tm, sim, "v", start=5, k=k)
    sim.tm = wrap
    sim.run(max_steps=2000)
    assert wrap.left == 0
    if k:  # the vehicle asked in k consecutive steps and was denied each time
        assert wrap.denied_at == list(range(wrap.denied_at[0], wrap.denied_at[0] + k))
    figures, steps, vehicles = run_tables(sim)
    v = vehicles.iloc[0]
    assert v["denials"] == k and v["stop_episodes"] == (1 if k else 0)
    assert v["time_stopped_s"] == pytest.approx(0.1 * k)
    assert v["route_length_m"] == pytest.approx(40.0) and v["free_flow_s"] == pytest.approx(2.0)
    assert v["travel_time_s"] == pytest.approx(v["arrival_s"] - v["admitted_s"])
    assert v["delay_s"] == pytest.approx(v["travel_time_s"] - 2.0)
    assert steps["denials"].sum() == k
    assert figures["stop_commands"] == k and figures["mean_delay_s"] == pytest.approx(v["delay_s"])
    assert figures["vehicles_arrived"] == 1 and figures["finished"]


def test_summary_json_is_computed_from_the_written_tables(tmp_path):
    import json

    from bridge.scenarios import run_multi

    opts = SimpleNamespace(vclass="paper-a", tm="greedy", check="union", switching="early", disturbance="random",
                           solver="exact", duration=8.0, vehicles=8, seed=1, log="none")
    run_multi("paper10", tmp_path, opts)
    summary = json.loads((tmp_path / "summary.json").read_text())
    steps = pd.read_csv(tmp_path / "steps.csv")
    vehicles = pd.read_csv(tmp_path / "vehicles.csv", dtype={"id": str})
    again = summarise(steps, vehicles, Ts=0.1)
    for key, value in again.items():
        if isinstance(value, float):
            assert summary[key] == pytest.approx(value, rel=1e-9, nan_ok=True), key
        else:
            assert summary[key] == value, key
    assert (tmp_path / "steps_1s.csv").exists()


def test_halts_are_counted_like_sumo_waiting():
    """A vehicle standing at an intermediate waypoint halts (speed <= 0.1 m/s); at its last waypoint it
    does not.  Hand-made group states: step 1 both slow, step 2 'a' moving, step 3 'a' slow again."""
    from analysis.halts import HaltCounter

    g = SimpleNamespace(ids=["a", "b"], X=np.zeros((2, 4)), at_last=np.array([False, True]))
    sim = SimpleNamespace(groups={"paper-a": g})
    h = HaltCounter()
    for vx in (0.05, 2.0, 0.1, 0.0):
        g.X[0, 2] = vx
        h.on_step(sim, None, None, {})
    assert h.steps == {"a": 3} and h.episodes == {"a": 2}  # 'b' stands at its last waypoint
    recs = [VehicleRecord("a", "paper-a", 0.0, 10.0), VehicleRecord("b", "paper-a", 0.0, 10.0)]
    df = vehicle_table(recs, VMAX, 0.1, halts=h)
    assert df["halt_episodes"].tolist() == [2, 0] and df["time_halted_s"].tolist() == pytest.approx([0.3, 0.0])
    assert vehicle_table(recs, VMAX, 0.1)["halt_episodes"].isna().all()
