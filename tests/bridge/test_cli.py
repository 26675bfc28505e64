"""The command line as a user meets it: --version, --help, unknown scenarios, readable closing tables."""

import re
from importlib.metadata import version

import pytest

from bridge.cli import main


def test_version(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0 and capsys.readouterr().out.strip() == f"muvsim {version('muvsim')}"


@pytest.mark.parametrize("argv", [["--help"], ["run", "--help"], ["report", "--help"], ["sweep", "--help"]])
def test_help_has_no_stray_markup(argv, capsys):
    with pytest.raises(SystemExit):
        main(argv)
    out = capsys.readouterr().out
    assert "``" not in out and ":func:" not in out and "usage: muvsim" in out


@pytest.mark.parametrize("cmd", ["run", "sweep"])
def test_unknown_scenario_lists_every_valid_one_and_writes_nothing(cmd, tmp_path, capsys):
    out = tmp_path / "out"
    extra = ["--seeds", "1"] if cmd == "sweep" else []
    assert main([cmd, "gird", "--out", str(out)] + extra) == 2
    err = capsys.readouterr().err
    for name in ("grid", "grid-large", "single", "paper10", "swap", "crossing", ".toml", ".sumocfg"):
        assert name in err
    assert "'gird'" in err and not out.exists()


def test_missing_scenario_file_is_named_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["run", str(tmp_path / "mine.toml"), "--out", str(out)]) == 2
    assert "mine.toml does not exist" in capsys.readouterr().err and not out.exists()


def test_closing_table_is_rounded_and_has_no_none(tmp_path, capsys):
    """A short paper10 run (free plane, 5 s: nobody arrives): counts print as integers, seconds to
    0.1, and the means over arrived vehicles say so instead of None."""
    assert main(["run", "paper10", "--out", str(tmp_path / "o"), "--duration", "5", "--log", "none",
                 "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "None" not in out and "nan" not in out
    assert re.search(r"\nvehicles_arrived +0 of 10 \(vehicles_total; 0\.0 %\)\n", out)
    assert re.search(r"\nsteps +50\n", out) and re.search(r"\ncollisions_geometric +0\n", out)
    assert re.search(r"\nmean_delay_s +no vehicle arrived\n", out)
    assert re.search(r"\nwall_s +\d+\.\d\n", out)  # seconds to 0.1
