"""analysis.waits: why each vehicle at rest waits, and the gridlock counters that must fire on a real
gridlock (two cars head-on on one lane in the free plane) and stay at zero where traffic flows."""

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from analysis.kpis import run_tables
from analysis.outputs import write_run_tables
from analysis.waits import WAIT_COLUMNS, wait_figures, wait_table, waits_at_end
from bridge.cosim import Cosim, CosimSettings, VehicleSpec
from bridge.layouts import subsample
from controllers.classes import builtin_classes

CLASSES = builtin_classes()


def _table(n, rest, requesting, go, withheld, edges, kinds):
    speed = np.where(np.isin(np.arange(n), rest), 0.0, 5.0)
    return wait_table([f"v{i}" for i in range(n)], np.zeros((n, 2)), speed, np.isin(np.arange(n), requesting),
                      np.isin(np.arange(n), go), withheld, np.array(edges, dtype=np.intp).reshape(-1, 2), kinds)


def test_reasons_and_chain_ends():
    """v0 -> v1 -> v2 (withheld at a signal); v3 -> v4 (moving); v5 granted; v6 asked nothing; v7 -> v8
    -> v9 -> v8 (runs into a cycle it is not part of); v10 denied with no edge."""
    w = _table(11, rest=[0, 1, 2, 3, 5, 6, 7, 8, 9, 10], requesting=[0, 1, 3, 5, 7, 8, 9, 10], go=[5],
               withheld={"v2": "signal"},
               edges=[(0, 1), (1, 2), (3, 4), (7, 8), (8, 9), (9, 8), (0, 5)],
               kinds=["new-new", "new-old", "new-fixed", "new-old", "new-old", "new-old", "new-old"])
    assert list(w.columns) == list(WAIT_COLUMNS)
    r = w.set_index("vehicle")
    assert "v4" not in r.index  # moving: not a row
    assert r.loc["v0", "blockers"] == "v5;v1"  # the other's current claim (new-old) first, then new-new
    assert r.loc["v0", "chain_end"] == "granted"  # v5 was granted: v0 waits for a vehicle moving off
    assert (r.loc["v1", "reason"], r.loc["v1", "chain_end"]) == ("traffic manager", "signal")
    assert r.loc["v2", "reason"] == "signal" and r.loc["v2", "blockers"] == ""
    assert r.loc["v3", "chain_end"] == "moving"
    assert r.loc["v6", "reason"] == "no request"
    assert (r.loc["v7", "chain_end"], r.loc["v7", "cycle"]) == ("cycle", "v8;v9")
    assert r.loc["v9", "cycle"] == "v9;v8"
    assert r.loc["v10", "chain_end"] == "traffic manager"
    assert wait_figures(w) == dict(stopped_at_end=10, gridlocked_at_end=3, wait_cycles=1)


def test_a_token_waiter_waits_for_the_holders():
    """v0 waits for a junction token held by v1, which waits (traffic manager) for v0: a cycle through
    the token; v2 waits for the token held by v3, which moves; v4 for a token with no holder named."""
    w = _table(5, rest=[0, 1, 2, 4], requesting=[1], go=[], edges=[(1, 0)], kinds=["new-old"],
               withheld={"v0": "junction token", "v2": "junction token", "v4": "junction token"})
    assert w.set_index("vehicle")["chain_end"].to_dict() == {"v0": "junction token", "v1": "junction token",
                                                             "v2": "junction token", "v4": "junction token"}
    speed = np.array([0.0, 0.0, 0.0, 5.0, 0.0])
    w = wait_table([f"v{i}" for i in range(5)], np.zeros((5, 2)), speed, np.isin(np.arange(5), [1]),
                   np.zeros(5, dtype=bool), {"v0": "junction token", "v2": "junction token", "v4": "junction token"},
                   np.array([[1, 0]]), ["new-old"], {"v0": ["v1"], "v2": ["v3", "gone"]}).set_index("vehicle")
    assert (w.loc["v0", "blockers"], w.loc["v0", "chain_end"], w.loc["v0", "cycle"]) == ("v1", "cycle", "v0;v1")
    assert (w.loc["v2", "blockers"], w.loc["v2", "chain_end"]) == ("v3", "moving")  # "gone": not in the run
    assert (w.loc["v4", "blockers"], w.loc["v4", "chain_end"]) == ("", "junction token")
    assert wait_figures(w.reset_index()) == dict(stopped_at_end=4, gridlocked_at_end=2, wait_cycles=1)


def test_bad_edges_and_empty():
    with pytest.raises(ValueError, match="2 edges and 1 kinds"):
        _table(3, [0], [0], [], {}, [(0, 1), (0, 2)], ["new-old"])
    assert wait_figures(pd.DataFrame([], columns=list(WAIT_COLUMNS))) == dict(
        stopped_at_end=0, gridlocked_at_end=0, wait_cycles=0)


def _run(routes, steps):
    specs = [VehicleSpec(v, "car", W) for v, W in routes.items()]
    sim = Cosim(CLASSES, specs, CosimSettings(controller="authority"))
    sim.run(steps)
    return sim


def test_head_on_gridlock_fires_and_is_written(tmp_path):
    """Two cars head-on on one 120 m lane: each stops where its next claim meets the other's, for good;
    after 60 s both are at rest, each the other's blocker, one cycle of two -- in the summary's figures
    and in waits.csv."""
    W = subsample([[0.0, 0.0], [120.0, 0.0]], CLASSES["car"].model.delta)
    sim = _run({"a": W, "b": W[::-1].copy()}, 600)
    assert all(r.arrived_s is None for r in sim.records.values())
    w = waits_at_end(sim).set_index("vehicle")
    assert w.loc["a", "blockers"] == "b" and w.loc["b", "blockers"] == "a"
    assert set(w["chain_end"]) == {"cycle"} and (w["speed_mps"] < 0.1).all()
    figures = run_tables(sim)[0]
    assert (figures["stopped_at_end"], figures["gridlocked_at_end"], figures["wait_cycles"]) == (2, 2, 1)
    write_run_tables(tmp_path, sim)
    on_disk = pd.read_csv(tmp_path / "waits.csv")
    assert sorted(on_disk["vehicle"]) == ["a", "b"] and set(on_disk["cycle"]) == {"a;b", "b;a"}


def test_no_gridlock_where_traffic_flows():
    """The same lane, both cars the same way, departing 4 s apart: no cycle in the first 15 s (while
    the second queues behind the first at its start), both arrive, and none at rest at the end."""
    W = subsample([[0.0, 0.0], [120.0, 0.0]], CLASSES["car"].model.delta)
    specs = [VehicleSpec("a", "car", W), VehicleSpec("b", "car", W, depart_s=4.0)]
    sim = Cosim(CLASSES, specs, CosimSettings(controller="authority"))
    sim.run(1)
    seen = []
    for _ in range(149):
        sim.step()
        seen.append(wait_figures(waits_at_end(sim))["gridlocked_at_end"])
    assert max(seen) == 0
    sim.run(3000)
    assert all(r.arrived_s is not None for r in sim.records.values())
    assert (run_tables(sim)[0]["gridlocked_at_end"], run_tables(sim)[0]["stopped_at_end"]) == (0, 0)


def test_the_closing_table_says_it():
    from analysis.report import format_summary

    line = lambda s: next(ln for ln in format_summary(s).splitlines() if ln.startswith("gridlocked_at_end"))  # noqa: E731
    assert "47 of the 55 vehicles at rest wait on a circle of waits (1 cycle(s)" in line(
        dict(gridlocked_at_end=47, stopped_at_end=55, wait_cycles=1))
    assert line(dict(gridlocked_at_end=0, stopped_at_end=0, wait_cycles=0)).endswith("no vehicle at rest")
    assert "gridlocked_at_end" not in format_summary(dict(vehicles_arrived=3))  # SUMO's drivers: no such figure


def _walk(i, reason, blockers):
    """The chain walked vehicle by vehicle (the first version, quadratic): the reference."""
    seen = []
    cur = i
    while True:
        if cur in seen:
            return "cycle", seen[seen.index(cur):]
        seen.append(cur)
        if cur not in reason:
            return "moving", []
        if not blockers.get(cur):
            return reason[cur], []
        cur = blockers[cur][0]


@settings(max_examples=300, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 40))
def test_chain_ends_walk_each_vehicle_once_with_the_same_answers(seed, n):
    """Random wait-for graphs (vehicles at rest or not, with or without blockers, cycles and tails):
    the linear pass gives every chain's end and cycle exactly as walking each chain does."""
    from analysis.waits import _chain_ends

    rng = np.random.default_rng(seed)
    rest = [i for i in range(n) if rng.random() < 0.8]
    reason = {i: str(rng.choice(["traffic manager", "signal", "junction token"])) for i in rest}
    blockers = {i: rng.integers(0, n, int(rng.integers(0, 3))).tolist() for i in rest}
    got = _chain_ends(reason, blockers)
    for i in rest:
        assert got[i] == _walk(i, reason, blockers)
