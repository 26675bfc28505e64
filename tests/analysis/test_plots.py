"""Plots from a real short run: a file per kind with non-trivial size."""

from types import SimpleNamespace

from analysis.plots import PLOT_KINDS, write_plots
from bridge.cli import main
from bridge.scenarios import run_multi


def test_a_plot_per_kind(tmp_path):
    opts = SimpleNamespace(vclass="paper-a", tm="optimal", check="union", switching="early", disturbance="random",
                           solver="exact", duration=30.0, vehicles=8, seed=0, log="summary")
    run_multi("paper10", tmp_path / "a", opts)
    run_multi("paper10", tmp_path / "b", SimpleNamespace(**{**vars(opts), "tm": "greedy", "log": "none"}))
    written = write_plots(tmp_path / "a", tmp_path / "b")
    assert set(written) == set(PLOT_KINDS)
    for kind, path in written.items():
        assert path.exists() and path.stat().st_size > 10_000, kind
    # through the CLI; a run without run.mcap gets the distributions only
    assert main(["report", str(tmp_path / "b"), "--plots"]) == 0
    assert {p.stem for p in (tmp_path / "b" / "plots").glob("*.png")} == {"delay", "stops"}


def test_run_plots_through_the_cli(tmp_path, capsys):
    out = tmp_path / "p"
    assert main(["run", "paper10", "--out", str(out), "--duration", "3", "--log", "full", "--plots"]) == 0
    assert (out / "run.mcap").exists() and (out / "plots" / "trajectories.png").stat().st_size > 10_000
    assert "ms per step" in capsys.readouterr().out
    # `single` has no per-vehicle table: no plots, a message, no crash
    assert main(["run", "single", "--out", str(tmp_path / "s"), "--duration", "2", "--plots"]) == 0
    assert "no plots" in capsys.readouterr().err


def test_states_are_coloured_moving_halted_or_tm_stopped():
    import pandas as pd

    from analysis.plots import busiest_routes, halted_longest, vehicle_states_with_state

    st = pd.DataFrame({
        "t_s": [0.0, 0.1, 0.2, 0.0, 0.1, 0.2], "id": ["a"] * 3 + ["b"] * 3,
        "x_m": [0.0, 1.0, 1.0, 5.0, 5.0, 8.0], "y_m": [0.0] * 6,
        "vx_mps": [10.0, 0.05, 0.0, 0.0, 3.0, 3.0], "vy_mps": [0.0] * 6,
        "wx_m": [3.0, 3.0, 3.0, 9.0, 9.0, 12.0], "wy_m": [0.0] * 6, "waypoints": [4] * 6, "index": [1] * 6})
    df = vehicle_states_with_state(st, {(0.2, "a"), (0.1, "b")}).set_index(["id", "t_s"])
    assert df.loc[("a", 0.0), "state"] == "moving" and df.loc[("a", 0.1), "state"] == "halted"
    assert df.loc[("a", 0.2), "state"] == "TM-stopped"  # denied beats halted
    assert df.loc[("b", 0.1), "state"] == "TM-stopped" and df.loc[("b", 0.2), "state"] == "moving"
    assert df.loc[("b", 0.2), "s_m"] == 3.0 and df.loc[("a", 0.2), "s_m"] == 1.0  # distance travelled so far
    st2 = pd.concat([st, st[st.id == "a"].assign(id="c")])
    (label, ids), = busiest_routes(st2, count=1)
    assert ids == ["a", "c"] and label.startswith("3,0 -> 3,0")
    v = pd.DataFrame({"id": ["a", "b", "c"], "time_halted_s": [1.0, 9.0, 4.0], "time_stopped_s": [0.0, 0.0, 5.0]})
    assert halted_longest(v, {"a", "b", "c"}, 2) == ["b", "c"]
