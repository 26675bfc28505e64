"""Bad input and faults end in one clear message (naming the option, file or vehicle and what is
valid), never a raw traceback; ``--debug`` shows the traceback.  One test per message."""

import json

import pytest

import bridge.cosim as cosim_mod
from bridge.cli import main
from controllers.synthesis import SynthesisError
from sumo_nets.generate import write_sumocfg


def _err_lines(capsys):
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return [ln for ln in err.splitlines() if ln.strip()]


@pytest.mark.parametrize("scenario", ["swap", "paper10", "crossing"])
def test_free_plane_run_error_is_one_line_and_in_the_summary(tmp_path, monkeypatch, capsys, scenario):
    """An error inside a multi-vehicle run (here: synthesis failing) is reported as itself (not a
    NameError from the runner), and summary.json keeps it."""
    def fail(model, settings=None):
        raise SynthesisError("condition (8) does not hold (injected)")

    monkeypatch.setattr(cosim_mod, "synthesize", fail)
    rc = main(["run", scenario, "--out", str(tmp_path), "--quiet", "--log", "none"])
    assert rc == 1
    lines = _err_lines(capsys)
    assert "muvsim run: SynthesisError: condition (8) does not hold (injected)" in lines
    s = json.loads((tmp_path / "summary.json").read_text())
    assert s["complete"] is False and s["error"] == "SynthesisError: condition (8) does not hold (injected)"


@pytest.mark.parametrize("scenario", ["paper10", "crossing"])
def test_free_plane_ctrl_c_in_process(tmp_path, monkeypatch, capsys, scenario):
    """Ctrl-C in the middle of a multi-vehicle run: one line, exit 130, summary says interrupted
    with the figures of the steps taken."""
    step = cosim_mod.Cosim.step

    def step_then_interrupt(self):
        if self.t == 25:
            raise KeyboardInterrupt
        return step(self)

    monkeypatch.setattr(cosim_mod.Cosim, "step", step_then_interrupt)
    rc = main(["run", scenario, "--out", str(tmp_path), "--quiet", "--log", "none"])
    assert rc == 130
    assert _err_lines(capsys) == [f"interrupted at t = 2.5 s; outputs kept in {tmp_path}"]
    s = json.loads((tmp_path / "summary.json").read_text())
    assert s["interrupted"] is True and s["complete"] is False and s["steps"] == 25


def test_out_is_a_file(tmp_path, capsys):
    f = tmp_path / "afile"
    f.write_text("x")
    assert main(["run", "swap", "--out", str(f), "--quiet"]) == 2
    assert _err_lines(capsys) == [f"muvsim run: --out {f}: is a file, not a directory; give a directory "
                                  f"(created if missing)"]


@pytest.mark.parametrize("bad", ["fast", "-1", "11", "nan"])
def test_lat_accel_names_what_is_valid(bad, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["run", "grid", "--lat-accel", bad, "--quiet"])
    assert exc.value.code == 2
    assert _err_lines(capsys)[-1] == (f"muvsim run: error: argument --lat-accel: must be a lateral acceleration "
                                      f"in [0, 10] m/s^2 (0: no curve speeds) or 'net' (the network's own "
                                      f"limitTurnSpeed), got {bad!r}")


def test_out_under_a_file(tmp_path, capsys):
    f = tmp_path / "afile"
    f.write_text("x")
    assert main(["run", "grid", "--out", str(f / "sub" / "dir"), "--quiet"]) == 2
    assert _err_lines(capsys) == [f"muvsim run: --out {f / 'sub' / 'dir'}: cannot create it: {f} is a file, "
                                  f"not a directory"]


def test_out_not_creatable(capsys):
    # /proc refuses new directories even to root (a permission test would pass as root)
    assert main(["run", "swap", "--out", "/proc/muvsim-no/run", "--quiet"]) == 2
    lines = _err_lines(capsys)
    assert len(lines) == 1 and lines[0].startswith("muvsim run: --out /proc/muvsim-no/run: cannot create the "
                                                   "directory: ")


@pytest.mark.parametrize("scenario, least", [("swap", 2), ("crossing", 1)])
def test_too_few_vehicles(tmp_path, capsys, scenario, least):
    assert main(["run", scenario, "--vehicles", "0", "--out", str(tmp_path), "--quiet"]) == 2
    assert _err_lines(capsys) == [f"muvsim run: --vehicles: {scenario} needs at least {least} vehicle(s), got 0"]
    assert not (tmp_path / "summary.json").exists()


@pytest.mark.parametrize("vclass", ["bicycle", "pedestrian"])
def test_sumocfg_vehicle_of_another_vclass_is_driven_as_itself(grid_net, grid_routes, tmp_path, vclass):
    """A .sumocfg vehicle whose vType has vClass bicycle/pedestrian is driven with a class made from
    its own vType (its vClass, SUMO's length x width) -- never silently as a car."""
    import pandas as pd

    text = grid_routes.read_text()
    text = text.replace('<vType id="car"', f'<vType id="slow" vClass="{vclass}" length="1.6" width="0.65"/>'
                                           '\n    <vType id="car"', 1)
    text = text.replace('<vehicle id="2" type="car"', '<vehicle id="2" type="slow"', 1)
    rou = tmp_path / "mixed.rou.xml"
    rou.write_text(text)
    cfg = write_sumocfg(tmp_path / "mixed.sumocfg", grid_net, [rou])
    rc = main(["run", str(cfg), "--out", str(tmp_path / "out"), "--quiet", "--log", "none", "--duration", "5"])
    assert rc == 0
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert s["complete"] is True and s["collisions_sumo"] == 0
    veh = pd.read_csv(tmp_path / "out" / "vehicles.csv", dtype={"id": str}).set_index("id")
    assert veh.loc["2", "vclass"].startswith(f"{vclass}-1.6x0.65")  # the class name carries vClass and size


def test_unexpected_error_is_one_line_and_debug_shows_the_traceback(tmp_path, monkeypatch, capsys):
    import bridge.scenarios

    def boom(*a, **k):
        raise RuntimeError("boom (injected)")

    monkeypatch.setattr(bridge.scenarios, "run_scenario", boom)
    assert main(["run", "swap", "--out", str(tmp_path), "--quiet"]) == 1
    assert _err_lines(capsys) == ["muvsim run: RuntimeError: boom (injected) (run with --debug for the traceback)"]
    with pytest.raises(RuntimeError, match="boom"):
        main(["run", "swap", "--out", str(tmp_path), "--quiet", "--debug"])
