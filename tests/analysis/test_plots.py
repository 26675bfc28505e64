"""Plots from a real short run: a file per kind with non-trivial size."""

from types import SimpleNamespace

from analysis.plots import PLOT_KINDS, write_plots
from bridge.cli import main
from bridge.scenarios import run_multi


def test_a_plot_per_kind(tmp_path):
    opts = SimpleNamespace(vclass="paper-a", tm="optimal", check="union", switching="early", disturbance="random",
                           solver="exact", duration=45.0, vehicles=8, seed=0, log="summary")
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
