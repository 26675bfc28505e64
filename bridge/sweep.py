"""``muvsim sweep``: one scenario over seeds and traffic-manager options, run in parallel with Dask.

A sweep is the cross product of its seeds and option values (``controller``, ``tm``, ``check``,
``switching``, ``disturbance``, ``solver``, and for SUMO scenarios ``signals`` and
``pedestrians``, as ``muvsim run --controller / --signals / --pedestrians``), plus, with
``baseline=True``, one run by SUMO's own drivers per seed.  Every run is a task on a Dask
distributed cluster -- a local one started for the sweep (one worker process
per run at a time, see below) or an existing one given by its scheduler
address -- and writes its own run directory ``OUT/<label>/`` exactly as
``muvsim run`` would (:func:`bridge.sumo_world.run_sumo` for SUMO scenarios,
:func:`bridge.scenarios.run_scenario` for the free-plane ones).  The sweep
returns, and writes as ``OUT/sweep.csv``, one row per run: its options, seed
and directory, the KPI figures of its ``summary.json`` and per-vehicle
statistics from :func:`analysis.report.statistics` (over arrived vehicles).
A run that fails -- in muvsim, in SUMO, or by losing its worker -- is a row
with ``complete`` False and its ``error``; it never ends the sweep.

One simulation per process
    libsumo runs SUMO inside the Python process, one simulation at a time.  The
    local cluster therefore has ``threads_per_worker=1``: a worker process runs
    one simulation, closes it (``run_sumo`` closes SUMO in ``finally``) and then
    runs the next.  Reusing a worker this way was measured to give exactly the
    summary of a run in a fresh process (small grid, seeds 1 and 2 alternating
    with a ``--baseline sumo`` run, 6 runs per process), with no growth of
    resident memory; a fresh ``python`` per run would cost ~1.3 s of start-up
    and imports per run.  On an existing cluster whose workers have more than
    one thread, SUMO runs of one worker process take turns under a
    :class:`distributed.Lock` named after the worker (start such workers with
    ``--nthreads 1`` to use every process).

A fresh process per run (``fresh_process=True``)
    Each run then goes to a new ``python`` started by the task (:func:`run_one`), which imports
    this checkout's packages (the ``bridge`` the sweep itself imported), runs the one
    simulation and exits: runs share nothing (no module state, no growth of resident memory
    over a long sweep), for ~1.3 s of start-up per run.  A run whose process dies (a crash,
    a signal) is a failed row naming its exit code and the end of its error output.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import time
import traceback
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Iterable, Sequence

import pandas as pd

from bridge.scenarios import SCENARIOS, default_controller, default_vclass
from tm.settings import default_check

__all__ = ["SweepSettingsError", "SweepSettings", "RunSpec", "ROW_COLUMNS", "SUMMARY_KPIS", "VEHICLE_STATS",
           "COUNT_COLUMNS", "TABLE_COLUMNS", "OPTION_CHOICES", "plan", "run_plan", "sweep",
           "run_one", "format_table", "is_free_plane", "check_scheduler_address", "spec_from_summary",
           "runs_from_dirs"]

#: Free-plane scenarios (run by :func:`bridge.scenarios.run_scenario`); everything else is SUMO.
FREE_PLANE = SCENARIOS
#: What ``muvsim run`` uses for a free-plane scenario's options left out (see ``bridge/cli.py``).
FREE_PLANE_DEFAULTS = {"tm": "optimal", "switching": "early", "disturbance": "random"}  # check: default_check
#: Valid values of every option that a sweep can vary.
OPTION_CHOICES = {
    "controller": ("paper", "authority"),
    "tm": ("greedy", "optimal"),
    "check": ("union", "timed"),
    "switching": ("terminal", "early"),
    "disturbance": ("random", "adversarial", "none"),
    "solver": ("exact", "daqp", "proxsuite"),
    "signals": ("obey", "ignore"),
    "pedestrians": ("guard", "ignore"),
}
#: Options that only SUMO scenarios have (traffic lights, pedestrians), with ``muvsim run``'s defaults.
SUMO_ONLY_DEFAULTS = {"signals": "obey", "pedestrians": "guard"}
LOG_MODES = ("none", "summary", "full")
DRIVERS = ("muvsim", "sumo")
_SCHEMES = ("tcp", "tls", "ws", "wss", "ucx", "inproc")
_ADDRESS = re.compile(r"^(?:(?P<scheme>[a-z]+)://)?(?P<host>\[[0-9a-fA-F:]+\]|[^\s:/\[\]]+):(?P<port>\d{1,5})/?$")
_LABEL = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")

#: Figures copied from each run's ``summary.json`` (missing ones are NaN; ``vehicles_total`` falls back
#: to ``vehicles`` for free-plane runs).
SUMMARY_KPIS = ("vehicles_total", "vehicles_arrived", "collisions_sumo", "collisions_geometric",
                "invariant_violations", "min_separation_m", "mean_travel_time_s", "mean_delay_s", "stop_commands",
                "halt_episodes", "time_halted_s", "throughput_vph", "simulated_s", "rtf", "wall_s")
#: Per-vehicle statistics (over arrived vehicles) from :func:`analysis.report.statistics`, as
#: ``metric.statistic`` -> column.
VEHICLE_STATS = {"delay_s.mean": "delay_s_mean", "delay_s.p95": "delay_s_p95",
                 "halt_episodes.mean": "halt_episodes_mean", "time_halted_s.mean": "time_halted_s_mean",
                 "stop_episodes.mean": "stop_episodes_mean", "travel_time_s.mean": "travel_time_s_mean"}
#: Integer columns of the sweep table (pandas ``Int64``: missing where a run has no such figure).
COUNT_COLUMNS = ("seed", "vehicles_total", "vehicles_arrived", "collisions_sumo", "collisions_geometric",
                 "invariant_violations", "stop_commands", "halt_episodes")
#: Columns of the sweep table, in order.
ROW_COLUMNS = (("label", "driver", "seed", "controller", "tm", "check", "switching", "disturbance", "solver",
                "signals", "pedestrians", "duration_s", "run_dir") + SUMMARY_KPIS + tuple(VEHICLE_STATS.values())
               + ("complete", "error", "worker"))


class SweepSettingsError(ValueError):
    """Invalid sweep settings; the message names the field and what would be valid."""


def _fail(fld: str, valid: str, got=...) -> SweepSettingsError:
    msg = f"{fld}: {valid}"
    if got is not ...:
        msg += f", got {got!r}"
    return SweepSettingsError(msg)


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _check_seed(fld: str, v) -> int:
    if not _is_int(v) or not 0 <= v <= 2**31 - 1:
        raise _fail(fld, "must be an integer in 0..2147483647", v)
    return int(v)


def _check_duration(fld: str, v) -> float | None:
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
        raise _fail(fld, "must be a finite number of simulated seconds > 0 (or None: the scenario's)", v)
    return float(v)


def is_free_plane(scenario: str) -> bool:
    """Whether ``scenario`` names a built-in free-plane scenario (else it is a SUMO scenario)."""
    return scenario in FREE_PLANE


def check_scheduler_address(address: str) -> str:
    """Validate a Dask scheduler address (``tcp://host:8786``, ``host:8786``); returns it stripped.

    Raises
    ------
    SweepSettingsError
        Not of the form ``[scheme://]host:port`` with a known scheme and a port in 1..65535.
    """
    valid = ("must be a Dask scheduler address [scheme://]host:port, e.g. tcp://10.0.0.5:8786 "
             f"(schemes: {', '.join(_SCHEMES)})")
    if not isinstance(address, str):
        raise _fail("scheduler", valid, address)
    m = _ADDRESS.match(address.strip())
    if m is None or (m["scheme"] is not None and m["scheme"] not in _SCHEMES) or not 0 < int(m["port"]) < 65536:
        raise _fail("scheduler", valid, address)
    return address.strip()


# --------------------------------------------------------------------------- one run


@dataclass(frozen=True)
class RunSpec:
    """One run of a sweep: what ``muvsim run`` would be told.

    Parameters
    ----------
    label : str
        Name of the run's directory under the sweep's output (letters, digits, ``.``, ``_``, ``-``;
        no ``:``, which SUMO would read as a port in an output path).
    scenario : str
        A free-plane name, a built-in SUMO scenario, a scenario ``.toml`` or a ``.sumocfg``.
        Not loaded here: a scenario that cannot be run makes a failed run (a row with ``complete``
        False), not an error of the sweep.
    seed : int
        Seed of the run.
    driver : {"muvsim", "sumo"}
        ``"sumo"``: SUMO's own drivers (``--baseline sumo``; SUMO scenarios only).
    controller : {"paper", "authority"} or None
        ``muvsim run --controller``; None: its default (:func:`bridge.scenarios.default_controller`:
        ``authority`` for SUMO scenarios, ``paper`` for free-plane ones).  Not for SUMO's own drivers.
    tm, check, switching, disturbance : str or None
        Options; None takes the scenario's value.
    solver : {"exact", "daqp", "proxsuite"}
    signals : {"obey", "ignore"} or None
        ``muvsim run --signals``: SUMO's traffic lights obeyed or ignored (the TM alone); None:
        ``obey``.  SUMO scenarios driven by muvsim only (free-plane scenarios have no lights, and
        SUMO's own drivers always obey them).
    pedestrians : {"guard", "ignore"} or None
        ``muvsim run --pedestrians``; None: ``guard``.  Same scope as ``signals``.
    duration_s : float or None
        Simulated seconds; None takes the scenario's (free plane: until every vehicle is done).
    log : {"none", "summary", "full"}
        ``run.mcap`` of the run.
    vclass : str or None
        Vehicle class of ``single``, ``swap`` and ``crossing``; None: ``muvsim run``'s (``car`` with the
        authority controller, ``paper-a`` with the paper's).
    vehicles : int
        Vehicles of ``swap`` and ``crossing``.
    """

    label: str
    scenario: str
    seed: int
    driver: str = "muvsim"
    controller: str | None = None
    tm: str | None = None
    check: str | None = None
    switching: str | None = None
    disturbance: str | None = None
    solver: str = "exact"
    signals: str | None = None
    pedestrians: str | None = None
    duration_s: float | None = None
    log: str = "none"
    vclass: str | None = None
    vehicles: int = 8

    def __post_init__(self) -> None:
        if not isinstance(self.label, str) or not _LABEL.match(self.label):
            raise _fail("label", "must start with a letter or digit and use only letters, digits, '.', '_', '-'",
                        self.label)
        if not isinstance(self.scenario, str) or not self.scenario.strip():
            raise _fail("scenario", "must be a scenario name or a path to a .toml or .sumocfg file", self.scenario)
        object.__setattr__(self, "seed", _check_seed("seed", self.seed))
        if self.driver not in DRIVERS:
            raise _fail("driver", f"must be one of {', '.join(DRIVERS)}", self.driver)
        if self.driver == "sumo" and is_free_plane(self.scenario):
            raise _fail("driver", f"'sumo' (a --baseline sumo run) needs a SUMO scenario, not the free-plane "
                                  f"{self.scenario!r}")
        for name in ("tm", "check", "switching", "disturbance"):
            v = getattr(self, name)
            if v is not None and v not in OPTION_CHOICES[name]:
                raise _fail(name, f"must be one of {', '.join(OPTION_CHOICES[name])} (or None: the scenario's)", v)
        if self.controller is not None:
            if self.controller not in OPTION_CHOICES["controller"]:
                raise _fail("controller", f"must be one of {', '.join(OPTION_CHOICES['controller'])} (or None: "
                                          f"{default_controller(str(self.scenario))})", self.controller)
            if self.driver == "sumo":
                raise _fail("controller", "SUMO's own drivers (driver 'sumo') use none of muvsim's options "
                                          "(leave it None)", self.controller)
        if self.solver not in OPTION_CHOICES["solver"]:
            raise _fail("solver", f"must be one of {', '.join(OPTION_CHOICES['solver'])}", self.solver)
        for name in SUMO_ONLY_DEFAULTS:
            v = getattr(self, name)
            if v is None:
                continue
            if v not in OPTION_CHOICES[name]:
                raise _fail(name, f"must be one of {', '.join(OPTION_CHOICES[name])} (or None: "
                                  f"{SUMO_ONLY_DEFAULTS[name]})", v)
            if is_free_plane(self.scenario):
                raise _fail(name, f"the free-plane {self.scenario!r} has no traffic lights or pedestrians "
                                  f"(a SUMO scenario only; leave it None)", v)
            if self.driver == "sumo":
                raise _fail(name, "SUMO's own drivers (driver 'sumo') use none of muvsim's options "
                                  "(leave it None)", v)
        object.__setattr__(self, "duration_s", _check_duration("duration_s", self.duration_s))
        if self.log not in LOG_MODES:
            raise _fail("log", f"must be one of {', '.join(LOG_MODES)}", self.log)
        if self.vclass is not None and (not isinstance(self.vclass, str) or not self.vclass):
            raise _fail("vclass", "must be a vehicle class name (or None: the controller's)", self.vclass)
        if not _is_int(self.vehicles) or self.vehicles < 1:
            raise _fail("vehicles", "must be an integer >= 1", self.vehicles)

    @property
    def uses_sumo(self) -> bool:
        """Whether the run starts SUMO (libsumo: one simulation per process)."""
        return not is_free_plane(self.scenario)

    def options(self) -> argparse.Namespace:
        """The options ``muvsim run`` would hand to ``run_sumo`` / ``run_scenario`` for this run.

        Free-plane options left out get ``muvsim run``'s defaults (:data:`FREE_PLANE_DEFAULTS`);
        SUMO runs leave them None (``run_sumo`` takes the scenario's).
        """
        opts = argparse.Namespace(
            scenario=self.scenario, seed=self.seed, controller=self.controller or default_controller(self.scenario),
            tm=self.tm, check=self.check, switching=self.switching, disturbance=self.disturbance, solver=self.solver,
            duration=self.duration_s,
            baseline="sumo" if self.driver == "sumo" else None, gui=False, quiet=True, log=self.log,
            plots=False, vclass=self.vclass, vehicles=self.vehicles, signals=self.signals,
            pedestrians=self.pedestrians)
        if not self.uses_sumo:
            for name, default in FREE_PLANE_DEFAULTS.items():
                if getattr(opts, name) is None:
                    setattr(opts, name, default)
            if opts.check is None:
                opts.check = default_check(opts.controller)
            if opts.vclass is None:  # as muvsim run: the controller's class
                opts.vclass = default_vclass(opts.controller)
        return opts


def _nan_row(spec: RunSpec, run_dir: Path) -> dict:
    row = {c: math.nan for c in ROW_COLUMNS}
    row.update(label=spec.label, driver=spec.driver, seed=spec.seed,
               controller=spec.controller or (default_controller(spec.scenario) if spec.driver == "muvsim" else None),
               tm=spec.tm, check=spec.check,
               switching=spec.switching, disturbance=spec.disturbance, solver=spec.solver,
               signals=spec.signals, pedestrians=spec.pedestrians,
               duration_s=spec.duration_s, run_dir=str(run_dir), complete=False, error=None, worker=None)
    if spec.driver == "sumo":  # SUMO's drivers use none of muvsim's options
        row.update(controller=None, tm=None, check=None, switching=None, disturbance=None, solver=None,
                   signals=None, pedestrians=None)
    return row


def _row_from_run(spec: RunSpec, run_dir: Path, summary: dict) -> dict:
    """The sweep row of a finished (or failed) run from its summary and its vehicle table."""
    from analysis.report import load_run, statistics

    row = _nan_row(spec, run_dir)
    opts = summary.get("options") or {}
    if spec.driver == "muvsim":  # what the run actually used (the scenario's values for options left out)
        for name in OPTION_CHOICES:
            if opts.get(name) is not None:
                row[name] = opts[name]
    duration = opts.get("duration_s", opts.get("duration"))
    if duration is not None:
        row["duration_s"] = float(duration)
    for k in SUMMARY_KPIS:
        v = summary.get(k)
        if k == "vehicles_total" and v is None:
            v = summary.get("vehicles")
        row[k] = math.nan if v is None else v
    row["complete"] = bool(summary.get("complete", False))
    row["error"] = summary.get("error")
    try:
        stats = statistics(load_run(run_dir))
    except FileNotFoundError:  # no vehicle table (a single-vehicle run, or failed before the loop)
        stats = None
    except Exception as exc:  # e.g. the tripinfo of a SUMO that died half-way: keep the summary's figures
        stats = None
        row["error"] = row["error"] or f"per-vehicle statistics: {type(exc).__name__}: {exc}"
    if stats is not None:
        for key, col in VEHICLE_STATS.items():
            row[col] = float(stats.get(key, math.nan))
    return row


def _worker_and_threads():
    """The Dask worker running this task and its thread count, or ``(None, 1)`` outside a worker."""
    try:
        from distributed import get_worker

        w = get_worker()
    except (ImportError, ValueError):
        return None, 1
    return w, int(getattr(w.state, "nthreads", 1) or 1)


def _execute(spec: RunSpec, run_dir: Path) -> dict:
    if spec.uses_sumo:
        from bridge.sumo_world import run_sumo

        return run_sumo(spec.scenario, run_dir, spec.options())
    from bridge.scenarios import run_scenario

    return run_scenario(spec.scenario, run_dir, spec.options())


#: The code a fresh run process executes (``python -c``): this checkout's packages first on the path.
_CHILD_CODE = ("import sys; sys.path.insert(0, sys.argv[1]); from bridge.sweep import _child_main; "
               "sys.exit(_child_main(sys.argv[2:]))")
#: Characters of a dead run process's error output kept in its row's ``error``.
_CHILD_ERR_CHARS = 600


def _child_main(argv: Sequence[str]) -> int:
    """Entry of a fresh run process: ``SPEC_JSON OUT ROW_PATH``; runs the spec, writes its row as JSON."""
    spec_json, out, row_path = argv
    row = run_one(RunSpec(**json.loads(spec_json)), out)
    Path(row_path).write_text(json.dumps(row, default=str), encoding="utf-8")
    return 0


def _run_fresh(spec: RunSpec, out: Path) -> dict:
    """:func:`run_one` of ``spec`` in a new Python process; its row (a failed row if the process died)."""
    root = str(Path(__file__).resolve().parents[1])  # the checkout whose bridge is running here
    with tempfile.TemporaryDirectory(prefix="muvsim-sweep-run-") as tmp:
        row_path = Path(tmp) / "row.json"
        proc = subprocess.run([sys.executable, "-c", _CHILD_CODE, root, json.dumps(asdict(spec)), str(out),
                               str(row_path)], stdin=subprocess.DEVNULL, capture_output=True, text=True)
        if proc.returncode == 0 and row_path.exists():
            return json.loads(row_path.read_text(encoding="utf-8"))
    row = _nan_row(spec, out / spec.label)
    sfile = out / spec.label / "summary.json"
    if sfile.exists():  # the figures up to where it died (summary.json is rewritten every simulated minute)
        try:
            row = _row_from_run(spec, out / spec.label, json.loads(sfile.read_text()))
            row["complete"] = False
        except (OSError, ValueError):
            pass
    err = (proc.stderr or "").strip()[-_CHILD_ERR_CHARS:]
    row["error"] = f"run process exited with code {proc.returncode}" + (f": {err}" if err else "")
    return row


def run_one(spec: RunSpec, out: str | os.PathLike, fresh_process: bool = False) -> dict:
    """Run one sweep run into ``out/<label>`` and return its row; never raises for a failed run.

    Called on a Dask worker (or directly).  On a worker with more than one thread, SUMO runs of
    that worker process take turns under a :class:`distributed.Lock` named after the worker
    (not with ``fresh_process``: each simulation then has a process of its own).

    Parameters
    ----------
    spec : RunSpec
    out : path-like
        The sweep's output directory.
    fresh_process : bool
        Run it in a new Python process (this checkout's packages) instead of this one.

    Returns
    -------
    dict
        Keys :data:`ROW_COLUMNS`.
    """
    worker, nthreads = _worker_and_threads()
    if fresh_process:
        row = _run_fresh(spec, Path(out).expanduser().absolute())
        row["worker"] = None if worker is None else worker.address
        return row
    run_dir = Path(out) / spec.label
    try:
        if spec.uses_sumo and worker is not None and nthreads > 1:
            from distributed import Lock

            with Lock(f"muvsim-libsumo-{worker.address}"):
                summary = _execute(spec, run_dir)
        else:
            summary = _execute(spec, run_dir)
        sfile = run_dir / "summary.json"  # the figures as written (what `muvsim report` reads)
        row = _row_from_run(spec, run_dir, json.loads(sfile.read_text()) if sfile.exists() else summary)
    except Exception as exc:  # a run that cannot even start (e.g. an unknown free-plane option)
        row = _nan_row(spec, run_dir)
        row["error"] = f"{type(exc).__name__}: {exc}"
        row["traceback"] = traceback.format_exc(limit=6)
    row["worker"] = None if worker is None else worker.address
    return row


# --------------------------------------------------------------------------- settings and plan


@dataclass(frozen=True)
class SweepSettings:
    """What a sweep runs and where.

    Option tuples are the values swept; an empty tuple means "the scenario's value" (free-plane
    scenarios: ``muvsim run``'s defaults), which :func:`plan` writes into every run, so the table
    shows what ran.  Lists are accepted and stored as tuples.

    Parameters
    ----------
    scenario : str
        ``grid``, ``grid-large``, a scenario ``.toml`` or ``.sumocfg`` (loaded and validated here), or a
        free-plane scenario ``single``, ``paper10``, ``swap``, ``crossing``.
    seeds : tuple of int
        One or more distinct seeds (0..2**31-1).
    out : Path
        Output directory: ``OUT/<label>/`` per run and ``OUT/sweep.csv``.  On an existing cluster it must
        be a path the workers can write (a shared file system) and the scenario a path they can read.
    controller, tm, check, switching, disturbance, solver, signals, pedestrians : tuple of str
        Values of each option to sweep (see :data:`OPTION_CHOICES`); ``solver`` defaults to ``("exact",)``,
        ``controller`` to ``muvsim run --controller``'s default (:func:`bridge.scenarios.default_controller`).
        ``signals`` and ``pedestrians`` mean what ``muvsim run --signals / --pedestrians`` do (defaults
        ``obey`` and ``guard``); SUMO scenarios only (the baseline runs are SUMO's drivers either way).
    duration_s : float or None
        Simulated seconds of every run (None: the scenario's).
    baseline : bool
        Add one ``--baseline sumo`` run (SUMO's own drivers) per seed; SUMO scenarios only.
    log : {"none", "summary", "full"}
        ``run.mcap`` of each run (default none: sweeps are about figures).
    workers : int or None
        Worker processes of the local cluster (default ``os.cpu_count()``, at most one per run).  Not
        with ``scheduler``.
    scheduler : str or None
        Address of an existing Dask scheduler (``tcp://host:8786``); None starts a local cluster.
    vclass : str or None
        Vehicle class of the free-plane ``single``, ``swap``, ``crossing``; None: ``muvsim run``'s
        (``car`` with the authority controller, ``paper-a`` with the paper's).
    vehicles : int
        Vehicles of ``swap`` and ``crossing``.
    fresh_process : bool
        Each run in a new Python process started by its task (see the module's notes) instead of in
        the worker process itself: runs independent of each other, memory not growing over a sweep.

    Raises
    ------
    SweepSettingsError
        A field is invalid; the message names it and says what would be valid.
    """

    scenario: str
    seeds: tuple[int, ...]
    out: Path
    controller: tuple[str, ...] = ()
    tm: tuple[str, ...] = ()
    check: tuple[str, ...] = ()
    switching: tuple[str, ...] = ()
    disturbance: tuple[str, ...] = ()
    solver: tuple[str, ...] = ("exact",)
    signals: tuple[str, ...] = ()
    pedestrians: tuple[str, ...] = ()
    duration_s: float | None = None
    baseline: bool = False
    log: str = "none"
    workers: int | None = None
    scheduler: str | None = None
    vclass: str | None = None
    vehicles: int = 8
    fresh_process: bool = False
    _defaults: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        self._check_scenario()
        seeds = self.seeds
        if isinstance(seeds, (str, bytes)) or not isinstance(seeds, Iterable):
            raise _fail("seeds", "must be a sequence of one or more integer seeds", seeds)
        seeds = tuple(seeds)
        if not seeds:
            raise _fail("seeds", "must name at least one seed", seeds)
        seeds = tuple(_check_seed(f"seeds[{i}]", s) for i, s in enumerate(seeds))
        if len(set(seeds)) != len(seeds):
            raise _fail("seeds", "must be distinct (each seed is run once per option combination)", seeds)
        object.__setattr__(self, "seeds", seeds)
        if isinstance(self.out, bool) or not isinstance(self.out, (str, os.PathLike)) or not str(self.out):
            raise _fail("out", "must be a directory path", self.out)
        object.__setattr__(self, "out", Path(self.out).expanduser().absolute())
        for name, choices in OPTION_CHOICES.items():
            values = getattr(self, name)
            if values is None:
                values = ()
            elif isinstance(values, str) or not isinstance(values, Iterable):
                raise _fail(name, f"must be a sequence of values from {', '.join(choices)}", values)
            values = tuple(v for v in values if v is not None)
            for v in values:
                if v not in choices:
                    raise _fail(name, f"each value must be one of {', '.join(choices)}", v)
            if len(set(values)) != len(values):
                raise _fail(name, "values must be distinct", values)
            if name == "solver" and not values:
                values = ("exact",)
            if name in SUMO_ONLY_DEFAULTS and values and is_free_plane(self.scenario):
                raise _fail(name, f"the free-plane {self.scenario!r} has no traffic lights or pedestrians "
                                  f"(a SUMO scenario only)", values)
            object.__setattr__(self, name, values)
        object.__setattr__(self, "duration_s", _check_duration("duration_s", self.duration_s))
        if not isinstance(self.baseline, bool):
            raise _fail("baseline", "must be True or False", self.baseline)
        if self.baseline and is_free_plane(self.scenario):
            raise _fail("baseline", f"a --baseline sumo run needs a SUMO scenario (grid, grid-large, a .toml or a "
                                    f".sumocfg), not the free-plane {self.scenario!r}")
        if self.log not in LOG_MODES:
            raise _fail("log", f"must be one of {', '.join(LOG_MODES)}", self.log)
        if self.workers is not None and (not _is_int(self.workers) or self.workers < 1):
            raise _fail("workers", "must be an integer >= 1 (or None: one per CPU)", self.workers)
        if self.scheduler is not None:
            object.__setattr__(self, "scheduler", check_scheduler_address(self.scheduler))
            if self.workers is not None:
                raise _fail("workers", "sets the size of the local cluster; an existing cluster (scheduler) has "
                                       "its own workers: give one of workers or scheduler", self.workers)
        if self.vclass is not None and (not isinstance(self.vclass, str) or not self.vclass):
            raise _fail("vclass", "must be a vehicle class name (or None: the controller's)", self.vclass)
        if not _is_int(self.vehicles) or self.vehicles < 1:
            raise _fail("vehicles", "must be an integer >= 1", self.vehicles)
        if not isinstance(self.fresh_process, bool):
            raise _fail("fresh_process", "must be True or False", self.fresh_process)

    def _check_scenario(self) -> None:
        from sumo_nets.scenario import ScenarioError, builtin_scenarios, load_scenario

        s = self.scenario
        if isinstance(s, os.PathLike):
            s = os.fspath(s)
        if not isinstance(s, str) or not s.strip():
            raise _fail("scenario", "must be a scenario name (" + ", ".join(FREE_PLANE + tuple(builtin_scenarios()))
                        + ") or a path to a .toml or .sumocfg file", self.scenario)
        if is_free_plane(s):
            object.__setattr__(self, "scenario", s)
            object.__setattr__(self, "_defaults", {"controller": default_controller(s), **FREE_PLANE_DEFAULTS})
            return
        try:
            loaded = load_scenario(s)
        except ScenarioError as exc:
            raise _fail("scenario", f"cannot be loaded ({exc}); valid: a free-plane scenario "
                                    f"({', '.join(FREE_PLANE)}), a built-in SUMO scenario "
                                    f"({', '.join(builtin_scenarios())}), or a .toml / .sumocfg file") from None
        if s not in builtin_scenarios() or s.endswith((".toml", ".sumocfg")) or os.sep in s:
            s = str(Path(s).expanduser().absolute())  # workers may not share the client's working directory
        object.__setattr__(self, "scenario", s)
        # the scenario's own options (a .sumocfg: Scenario's defaults), used for options not swept
        object.__setattr__(self, "_defaults", {"controller": default_controller(s),
                                               **{n: getattr(loaded, n) for n in FREE_PLANE_DEFAULTS},
                                               **SUMO_ONLY_DEFAULTS})

    def option_values(self, name: str) -> tuple:
        """Values run for option ``name``: the swept ones, else the scenario's own value."""
        return getattr(self, name) or (self._defaults.get(name),)


def _label(seed: int, varied: Sequence[tuple[str, str]]) -> str:
    return "_".join([f"seed{seed}"] + [f"{k}-{v}" for k, v in varied])


def plan(settings: SweepSettings) -> tuple[RunSpec, ...]:
    """The runs of a sweep: every seed x every option combination (+ one baseline run per seed).

    Labels name the seed and the options that take more than one value, e.g.
    ``seed1_tm-greedy_check-timed``; a baseline run is ``seed1_baseline-sumo``.
    """
    names = tuple(OPTION_CHOICES)
    varied = [n for n in names if len(settings.option_values(n)) > 1]
    runs = []
    for seed in settings.seeds:
        for combo in itertools.product(*(settings.option_values(n) for n in names)):
            opts = dict(zip(names, combo))
            runs.append(RunSpec(label=_label(seed, [(n, opts[n]) for n in varied]), scenario=settings.scenario,
                                seed=seed, driver="muvsim", controller=opts["controller"], tm=opts["tm"],
                                check=opts["check"], switching=opts["switching"], disturbance=opts["disturbance"],
                                solver=opts["solver"], signals=opts["signals"], pedestrians=opts["pedestrians"],
                                duration_s=settings.duration_s, log=settings.log,
                                vclass=settings.vclass, vehicles=settings.vehicles))
        if settings.baseline:
            runs.append(RunSpec(label=f"seed{seed}_baseline-sumo", scenario=settings.scenario, seed=seed,
                                driver="sumo", duration_s=settings.duration_s, log="none"))
    return tuple(runs)


# --------------------------------------------------------------------------- running


def _local_cluster(n_workers: int):
    from distributed import LocalCluster

    # processes: libsumo is one simulation per process.  memory_limit=0: Dask's memory heuristics (pause,
    # kill at 95 % of an equal share) are for data workloads; a large run may need more than its share.
    # allowed_failures=1: a run that kills its worker (e.g. SUMO crashing) is tried once more, then is a
    # failed row (the default 3 retries would repeat a deterministic crash).
    return LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=None,
                        memory_limit=0, scheduler_kwargs={"allowed_failures": 1})


def _progress(i: int, n: int, row: dict, stream) -> None:
    if row["complete"]:
        what = (f"arrived {row['vehicles_arrived']:.0f}/{row['vehicles_total']:.0f}"
                if row["vehicles_total"] == row["vehicles_total"] and row["vehicles_arrived"] == row["vehicles_arrived"]
                else "complete")
    else:
        what = f"FAILED: {row['error']}"
    wall = row.get("wall_s")
    wall = f", {wall:.1f} s" if isinstance(wall, (int, float)) and wall == wall else ""
    print(f"[{i}/{n}] {row['label']}: {what}{wall}", file=stream, flush=True)


def run_plan(runs: Sequence[RunSpec], out: str | os.PathLike, *, workers: int | None = None,
             scheduler: str | None = None, client=None, quiet: bool = True, stream=None,
             fresh_process: bool = False) -> pd.DataFrame:
    """Run ``runs`` on Dask, one task each, and return (and write ``out/sweep.csv``) their table.

    Parameters
    ----------
    runs : sequence of RunSpec
        Distinct labels.
    out : path-like
        Output directory (created).
    workers : int, optional
        Processes of the local cluster (default ``os.cpu_count()``), at most one per run.
    scheduler : str, optional
        Address of an existing scheduler instead of a local cluster.
    client : distributed.Client, optional
        Run on this client (``workers`` and ``scheduler`` are then ignored).
    quiet : bool
        No progress line per finished run.
    stream : file, optional
        Where progress goes (default ``sys.stderr``).
    fresh_process : bool
        Each run in a new Python process (:func:`run_one`).

    Returns
    -------
    DataFrame
        One row per run in the order of ``runs``; columns :data:`ROW_COLUMNS` (+ ``traceback`` when a
        run raised).  Failed runs have ``complete`` False and ``error`` set.
    """
    from distributed import Client, as_completed

    runs = tuple(runs)
    if not runs:
        raise SweepSettingsError("runs: nothing to run (no seed or option combination)")
    labels = [r.label for r in runs]
    dup = sorted({lb for lb in labels if labels.count(lb) > 1})
    if dup:
        raise SweepSettingsError(f"runs: labels must be distinct (each is a directory), repeated: {dup}")
    if scheduler is not None:
        scheduler = check_scheduler_address(scheduler)
    if workers is not None and (not _is_int(workers) or workers < 1):
        raise _fail("workers", "must be an integer >= 1 (or None: one per CPU)", workers)
    out = Path(out).expanduser().absolute()
    out.mkdir(parents=True, exist_ok=True)
    stream = sys.stderr if stream is None else stream
    rows: dict[str, dict] = {}

    def gather(c) -> None:
        futures = {c.submit(run_one, spec, str(out), fresh_process,
                            key=f"muvsim-run-{spec.label}-{os.getpid()}-{time.time_ns()}", pure=False): spec
                   for spec in runs}
        for i, fut in enumerate(as_completed(futures), start=1):
            spec = futures[fut]
            try:
                row = fut.result()
            except Exception as exc:  # the task itself died: e.g. its worker was killed (KilledWorker)
                row = _nan_row(spec, out / spec.label)
                row["error"] = f"{type(exc).__name__}: {exc}"
            rows[spec.label] = row
            if not quiet:
                _progress(i, len(runs), row, stream)

    if client is not None:
        gather(client)
    elif scheduler is not None:
        with Client(scheduler) as c:
            gather(c)
    else:
        n = min(workers or os.cpu_count() or 1, len(runs))
        with _local_cluster(n) as cluster, Client(cluster) as c:
            gather(c)
    df = _table([rows[lb] for lb in labels])
    df.to_csv(out / "sweep.csv", index=False)
    return df


def _table(rows: Sequence[dict]) -> pd.DataFrame:
    """The sweep table of ``rows`` (in their order): columns :data:`ROW_COLUMNS` first, counts ``Int64``."""
    df = pd.DataFrame(list(rows))
    cols = list(ROW_COLUMNS) + [c for c in df.columns if c not in ROW_COLUMNS]
    df = df.reindex(columns=cols)
    for c in COUNT_COLUMNS:  # counts stay integers where a run has none (a baseline's stop_commands, a failure)
        df[c] = pd.to_numeric(df[c]).round().astype("Int64")
    df["complete"] = df["complete"].fillna(False).astype(bool)
    return df


def spec_from_summary(label: str, summary: dict) -> RunSpec:
    """The :class:`RunSpec` a kept run directory ``label`` was run with, from its ``summary.json``.

    Driver from ``baseline`` (``sumo``: SUMO's own drivers, no muvsim option), seed, and the options
    the run used (``options``: the scenario's values for those it was not given).

    Raises
    ------
    SweepSettingsError
        The summary does not describe a run (no scenario or seed, or an option out of range).
    """
    opts = summary.get("options") or {}
    driver = "sumo" if summary.get("baseline") == "sumo" else "muvsim"
    scenario, seed = summary.get("scenario"), summary.get("seed")
    if not scenario or seed is None:
        raise SweepSettingsError(f"{label}: summary.json names no scenario or seed")
    duration = opts.get("duration_s", opts.get("duration"))
    kw = dict(label=label, scenario=str(scenario), seed=seed, driver=driver, duration_s=duration)
    if driver == "muvsim":
        kw.update({n: opts.get(n) for n in ("controller", "tm", "check", "switching", "disturbance")})
        kw["solver"] = opts.get("solver") or "exact"
        if not is_free_plane(str(scenario)):
            kw.update(signals=opts.get("signals"), pedestrians=opts.get("pedestrians"))
        if opts.get("vclass"):
            kw["vclass"] = opts["vclass"]
    return RunSpec(**kw)


def runs_from_dirs(out: str | os.PathLike) -> pd.DataFrame:
    """The sweep table rebuilt from the kept run directories ``out/<label>/`` (each with a
    ``summary.json``), without running anything: one row per directory, in label order, as
    :func:`run_plan` returns it (figures from ``summary.json`` and the per-vehicle table)."""
    out = Path(out).expanduser().absolute()
    dirs = sorted(d for d in out.iterdir() if d.is_dir() and (d / "summary.json").is_file()) if out.is_dir() else []
    if not dirs:
        raise SweepSettingsError(f"out: no run directory (DIR/<label>/summary.json) under {out}")
    rows = []
    for d in dirs:
        summary = json.loads((d / "summary.json").read_text())
        rows.append(_row_from_run(spec_from_summary(d.name, summary), d, summary))
    return _table(rows)


def sweep(settings: SweepSettings, *, client=None, quiet: bool = True, stream=None) -> pd.DataFrame:
    """Run a sweep (:func:`plan` of ``settings``) on Dask; return its table and write ``OUT/sweep.csv``.

    Parameters
    ----------
    settings : SweepSettings
    client : distributed.Client, optional
        Run on this client instead of ``settings.scheduler`` / a local cluster.
    quiet : bool
        No progress line per finished run.
    stream : file, optional
        Where progress goes (default ``sys.stderr``).

    Returns
    -------
    DataFrame
        See :func:`run_plan`.
    """
    return run_plan(plan(settings), settings.out, workers=settings.workers, scheduler=settings.scheduler,
                    client=client, quiet=quiet, stream=stream, fresh_process=settings.fresh_process)


#: Columns :func:`format_table` prints.
TABLE_COLUMNS = ("label", "complete", "vehicles_arrived", "vehicles_total", "collisions_sumo",
                 "collisions_geometric", "invariant_violations", "stop_commands", "mean_travel_time_s",
                 "delay_s_mean", "delay_s_p95", "halt_episodes_mean", "rtf", "wall_s")


def _figure_of(column: str) -> tuple[str, str]:
    """``(name, statistic)`` of a table column for :func:`analysis.readable.fmt` (``delay_s_mean`` is the
    mean of ``delay_s``: seconds)."""
    for key, col in VEHICLE_STATS.items():
        if col == column:
            name, stat = key.split(".", 1)
            return name, stat
    return column, ""


def format_table(df: pd.DataFrame) -> str:
    """The sweep table's main columns as text for the terminal (errors listed below it), each figure
    rounded as ``muvsim run`` and ``muvsim report`` print it (:mod:`analysis.readable`)."""
    from analysis.readable import fmt

    cols = [c for c in TABLE_COLUMNS if c in df]
    cells = pd.DataFrame({c: [fmt(None if v is pd.NA else v, *_figure_of(c)) for v in df[c]] for c in cols})
    text = cells.to_string(index=False)
    failed = df[~df["complete"].astype(bool)]
    for _, r in failed.iterrows():
        text += f"\n{r['label']}: {r['error']}"
    return text
