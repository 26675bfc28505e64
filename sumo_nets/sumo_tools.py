"""Locating and running SUMO's command-line tools.

SUMO comes from the ``eclipse-sumo`` wheel.  Its package directory *is*
``SUMO_HOME`` (``bin/`` holds the executables, ``tools/`` the Python tools such
as ``randomTrips.py``).  Importing that package writes ``SUMO_HOME`` into
``os.environ``, so this module finds the directory through
:func:`importlib.util.find_spec` without importing it, and hands ``SUMO_HOME``
to child processes through their own environment only.  ``$SUMO_HOME`` from
the environment is used when the wheel is not installed.
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Sequence

__all__ = ["SumoToolError", "sumo_home", "sumo_version", "binary", "tool_script", "tool_env", "run_tool"]


class SumoToolError(RuntimeError):
    """A SUMO tool is missing or failed; the message names the tool and quotes its output."""


def sumo_home() -> Path:
    """``SUMO_HOME``: the ``eclipse-sumo`` package directory, else ``$SUMO_HOME``.

    Raises
    ------
    SumoToolError
        If neither is available.
    """
    spec = importlib.util.find_spec("sumo")
    if spec is not None and spec.submodule_search_locations:
        for loc in spec.submodule_search_locations:
            if (Path(loc) / "bin").is_dir():
                return Path(loc)
    env = os.environ.get("SUMO_HOME")
    if env and Path(env).is_dir():
        return Path(env)
    raise SumoToolError("SUMO not found: install the 'eclipse-sumo' package (pip install eclipse-sumo) "
                        "or set SUMO_HOME to a SUMO installation")


def sumo_version() -> str:
    """Version of the installed SUMO (the ``eclipse-sumo`` distribution), or ``"unknown"``."""
    try:
        return importlib.metadata.version("eclipse-sumo")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


def binary(name: str) -> Path:
    """Path of a SUMO executable (``sumo``, ``netgenerate``, ``duarouter``, ...).

    Looks in ``SUMO_HOME/bin`` first, then on ``PATH``.
    """
    try:
        cand = sumo_home() / "bin" / name
        if cand.is_file() and os.access(cand, os.X_OK):
            return cand
    except SumoToolError:
        pass
    found = shutil.which(name)
    if found:
        return Path(found)
    raise SumoToolError(f"SUMO executable {name!r} not found in SUMO_HOME/bin nor on PATH")


def tool_script(relative: str) -> Path:
    """Path of a Python tool under ``SUMO_HOME/tools`` (e.g. ``"randomTrips.py"``)."""
    path = sumo_home() / "tools" / relative
    if not path.is_file():
        raise SumoToolError(f"SUMO tool {relative!r} not found at {path}")
    return path


def tool_env() -> dict[str, str]:
    """A copy of the environment with ``SUMO_HOME`` set, for child processes only."""
    env = dict(os.environ)
    env["SUMO_HOME"] = str(sumo_home())
    return env


def run_tool(args: Sequence[str | os.PathLike], *, what: str, cwd: Path | None = None,
             python: bool = False, timeout_s: float = 600.0) -> subprocess.CompletedProcess:
    """Run a SUMO tool, raising :class:`SumoToolError` with its output on failure.

    Parameters
    ----------
    args : sequence of str or path
        The command: an executable path first, or a script when ``python``.
    what : str
        What is being made, for the error message (e.g. ``"grid network"``).
    cwd : Path, optional
        Working directory.
    python : bool
        Run ``args[0]`` with the current interpreter (``sys.executable``).
    timeout_s : float
        Wall-clock limit.
    """
    cmd = [str(a) for a in args]
    if python:
        cmd = [sys.executable, *cmd]
    try:
        proc = subprocess.run(cmd, cwd=cwd, env=tool_env(), capture_output=True, text=True,
                              timeout=timeout_s, check=False)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise SumoToolError(f"{what}: could not run {Path(cmd[0]).name}: {exc}") from exc
    if proc.returncode != 0:
        out = (proc.stderr.strip() or proc.stdout.strip() or "(no output)")[-2000:]
        raise SumoToolError(f"{what}: {' '.join(Path(c).name if i < 2 else c for i, c in enumerate(cmd))} "
                            f"failed with exit code {proc.returncode}:\n{out}")
    return proc
