"""Scale benchmark: wall time per simulated second, by component, with N vehicles in a city grid at once.

Usage::

    python benchmarks/bench_scale.py [--sizes 100 300 1000 3000] [--sim-seconds 120] [--warmup 30]
                                     [--log summary|none|full] [--seed 1] [--runs DIR] [--timeout S]
                                     [--quick] [--out benchmarks/results/scale.csv]

For every target size N a scenario TOML (schema of :mod:`sumo_nets.scenario`) is written and
its network and demand generated once; then, each in a **fresh subprocess** (libsumo runs one
simulation per process, and peak memory -- ``ru_maxrss`` of that process -- is the run's own):

* muvsim: :func:`bridge.sumo_world.run_sumo` with the options ``muvsim run`` builds
  (``--log`` as given, default ``summary``, so the logging share is measured);
* SUMO's own drivers on the same demand: the same call with ``baseline="sumo"``.

Both simulate ``warmup + sim_seconds`` seconds.  Sizing: a J x J junction grid (100 m blocks,
2 lanes each way, approach stubs) with at least :data:`VEHICLES_PER_EDGE` target vehicles per
directed edge, at least :data:`MIN_JUNCTIONS` per side; the demand is ``ceil(SURPLUS x N)``
trips departing from any edge (``fringe_factor = 1``) during the warm-up, with an
origin-destination distance of at least ``MIN_DISTANCE_FACTOR`` x the network diagonal, so that
the network fills early and vehicles stay in it.  muvsim admits a vehicle only when its tube is
free, so the vehicles actually active are measured and reported next to the target
(``active_max``, ``active_mean``).

The measured window is ``[warmup, warmup + sim_seconds)`` of the muvsim run.  Per step the
loop's ``steps.csv`` gives ``tm_ms``, ``controller_ms``, ``world_ms`` and ``logging_ms``;
``bridge/cosim.py`` has no SUMO-only column, so the child times the SUMO adapter's calls (a subclass
of :class:`bridge.sumo_adapter.SumoAdapter` stands in for ``bridge.sumo_world.SumoAdapter``
during that one ``run_sumo`` call, by ``unittest.mock.patch`` in the child process only): ``moveToXY`` + ``simulationStep`` (part of ``world_ms``) and vehicle insertion and
removal (outside it), and the wall time between the ends of consecutive steps (a whole step).
Columns (window sums divided by the window's simulated seconds, so each is "wall seconds per
simulated second"; they add up to ``total_s_per_sim_s`` = 1 / ``rtf_window``):

* ``sumo_s_per_sim_s``: the SUMO calls above, split into ``sumo_move_s_per_sim_s``
  (``moveToXY`` of every vehicle), ``sumo_step_s_per_sim_s`` (``simulationStep`` and reading
  departures, arrivals, collisions) and ``sumo_insert_s_per_sim_s`` (insertion, removal);
  ``controllers_s_per_sim_s``: ``controller_ms + request_ms`` (QPs, plant step, index update,
  and the vehicles' request indices: the ST-MPC index at the next waypoint, On-1);
  ``tm_s_per_sim_s``: ``tm_ms - request_ms`` (fleet assembly, junction tokens, decision);
  ``monitor_s_per_sim_s``: ``world_ms`` minus its SUMO calls (runtime monitor with its claims,
  pose conversion); ``logging_s_per_sim_s``: ``logging_ms`` (MCAP); ``other_s_per_sim_s``: total
  minus these parts (fleet assembly, arrivals, admission tests, halt counting, bookkeeping);
* ``*_share``: the same as fractions of the total;
* ``active_max``, ``active_mean``, ``active_min``: vehicles in the network (``steps.csv``
  ``active``) over the window; ``demand`` the trips generated (``demand_requested`` asked for),
  ``admitted``, ``arrived`` by the end; ``requests_per_step``, ``grants_per_step``;
* ``controller_us_per_vehicle_step``: window sum of ``controller_ms + request_ms`` / window sum
  of ``active`` (membership indices and QPs); ``controller_us_per_vehicle_step_median``: the
  median over the window's steps of the same ratio per step;
* ``tm_ms_per_decision``, ``tm_decide_ms_per_decision``: mean ``tm_ms - request_ms`` /
  ``tm_decide_ms`` over the window's steps that made a decision (``tm_decide_ms > 0``);
  ``tm_decide_ms_median``: the median of ``tm_decide_ms`` there (``TrafficManager.decide``
  alone); ``tm_gate_ms_per_decision``, ``request_ms_per_decision``: mean ``gate_ms`` (the
  co-simulation's junction tokens) and ``request_ms`` there;
* ``rtf_window``: window simulated seconds / window wall seconds; ``rtf``, ``wall_s``: the
  whole ``run_sumo`` call as its ``summary.json`` reports it (start-up, the loop, writing the
  tables); ``loop_s``: from the end of the first step to the end of the last; ``setup_s``:
  ``wall_s - loop_s``; ``peak_rss_mb`` (``ru_maxrss`` of the child); ``cpu_s`` (its user +
  system CPU seconds: well below ``process_s``, the child's wall time, when other jobs share
  the machine);
* ``sumo_wall_s``, ``sumo_rtf``, ``sumo_peak_rss_mb``, ``sumo_cpu_s``, ``sumo_simulated_s``,
  ``sumo_arrived``, ``sumo_collisions``: the baseline run's, from its ``summary.json`` (the whole
  call as well); ``wall_ratio`` = ``wall_s`` / ``sumo_wall_s`` (same demand, same simulated
  time: ``simulated_s`` vs ``sumo_simulated_s``).  SUMO's drivers move the traffic through
  (compare ``sumo_arrived`` with ``arrived``), so the baseline does not hold the same number of
  vehicles at once: the ratio compares the same demand, not the same load;
* ``load_before``, ``load_after`` (1-minute load average around each size), ``machine``,
  ``cpus``, ``python``, ``command``: where and how it was measured.

``--quick``: one size (30 vehicles, 3 x 3 grid), 20 simulated seconds, no warm-up.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import resource
import shlex
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from unittest import mock

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from bridge.sumo_adapter import SumoAdapter  # noqa: E402

#: Target sizes of a full run (vehicles in the network at once).
SIZES = (100, 300, 1000, 3000)
#: Target vehicles per directed edge (100 m, 2 lanes) when choosing the grid.
VEHICLES_PER_EDGE = 2.0
#: Smallest grid (junctions per side).
MIN_JUNCTIONS = 3
#: Demand = ceil(SURPLUS x target) trips (a few arrive or are not admitted in time).
SURPLUS = 1.1
#: Minimum origin-destination distance as a fraction of the network diagonal.
MIN_DISTANCE_FACTOR = 0.5
SPACING_M = 100.0
LANES = 2
SPEED_MPS = 13.89
CLASS_MIX = {"car": 0.8, "bus": 0.1, "truck": 0.1}
#: Quick mode: one small size, no warm-up, 20 simulated seconds.
QUICK = {"sizes": (30,), "sim_seconds": 20.0, "warmup": 0.0}
#: File a child run writes into its run directory.
CHILD_RESULT = "scale_run.json"
CHILD_STEPS = "scale_steps.csv"

#: Columns printed (all are written).
PRINTED = ["target", "junctions", "demand", "active_max", "active_mean", "sumo_s_per_sim_s",
           "controllers_s_per_sim_s", "tm_s_per_sim_s", "monitor_s_per_sim_s", "logging_s_per_sim_s",
           "other_s_per_sim_s", "total_s_per_sim_s", "rtf_window", "controller_us_per_vehicle_step",
           "controller_us_per_vehicle_step_median", "tm_ms_per_decision", "tm_decide_ms_median",
           "peak_rss_mb", "wall_s", "sumo_wall_s", "sumo_rtf", "wall_ratio"]
PARTS = ("sumo", "controllers", "tm", "monitor", "logging", "other")


# --------------------------------------------------------------------------- scenarios

def directed_edges(junctions: int) -> int:
    """Directed edges of a ``junctions`` x ``junctions`` grid with approach stubs.

    Streets between neighbouring junctions (``2 J (J - 1)`` each way) plus one stub per
    border junction and side (``4 J`` each way).
    """
    return 4 * junctions * (junctions - 1) + 8 * junctions


def junctions_for(target: int, per_edge: float = VEHICLES_PER_EDGE) -> int:
    """Smallest grid (junctions per side, >= :data:`MIN_JUNCTIONS`) with ``per_edge`` x edges >= ``target``."""
    j = MIN_JUNCTIONS
    while directed_edges(j) * per_edge < target:
        j += 1
    return j


@dataclass(frozen=True)
class ScaleCase:
    """One size of the benchmark.

    Parameters
    ----------
    target : int
        Vehicles wanted in the network at once.
    junctions : int
        Junctions per grid side.
    vehicles : int
        Trips of the demand.
    warmup_s : float
        Simulated seconds before the measured window; departures spread over it (or over
        the first 10 s when it is shorter).
    window_s : float
        Simulated seconds measured.
    seed : int
        Seed of the demand and of the run.
    """

    target: int
    junctions: int
    vehicles: int
    warmup_s: float
    window_s: float
    seed: int = 1

    def __post_init__(self) -> None:
        if self.target < 1 or self.vehicles < 1:
            raise ValueError(f"ScaleCase: target and vehicles must be >= 1, got {self.target}, {self.vehicles}")
        if not (self.window_s > 0 and self.warmup_s >= 0):
            raise ValueError(f"ScaleCase: window_s must be > 0 and warmup_s >= 0, got {self.window_s}, "
                             f"{self.warmup_s}")

    @property
    def duration_s(self) -> float:
        """Simulated seconds of each run (warm-up + window)."""
        return self.warmup_s + self.window_s

    @property
    def departure_window_s(self) -> float:
        """Departures are spread over ``[0, departure_window_s)``."""
        return max(self.warmup_s, 10.0)

    @property
    def name(self) -> str:
        return f"scale{self.target}"


def case_for(target: int, window_s: float, warmup_s: float, seed: int = 1) -> ScaleCase:
    """The grid and demand of a target size (see the module notes)."""
    if target < 1:
        raise ValueError(f"size: must be >= 1 vehicle, got {target}")
    return ScaleCase(target=target, junctions=junctions_for(target), vehicles=math.ceil(SURPLUS * target),
                     warmup_s=float(warmup_s), window_s=float(window_s), seed=seed)


def scenario_toml(case: ScaleCase) -> str:
    """The scenario file of a case, in the schema :func:`sumo_nets.scenario.load_scenario` validates."""
    diagonal = math.hypot(*(2 * [(case.junctions + 1) * SPACING_M]))  # grid + one stub each side
    mix = ", ".join(f"{k} = {v}" for k, v in CLASS_MIX.items())
    return "\n".join([
        f"# muvsim scale benchmark: ~{case.target} vehicles in the network at once",
        f'name = "{case.name}"',
        f'description = "{case.junctions}x{case.junctions} grid, {case.vehicles} trips departing over '
        f'{case.departure_window_s:g} s from any edge"',
        f"seed = {case.seed}",
        f"duration_s = {case.duration_s!r}",
        'tm = "optimal"',
        # no check: each controller's own default (tm.settings.default_check: timed with movement
        # authority, union with the paper's); pinned to union before, the authority runs here
        # compared the hull of every slot and locked dense grids that the timed check clears
        'switching = "early"',
        'disturbance = "random"',
        "",
        "[net]",
        'type = "grid"',
        f"junctions = {case.junctions}",
        f"spacing_m = {SPACING_M!r}",
        f"lanes = {LANES}",
        f"speed_mps = {SPEED_MPS!r}",
        "",
        "[demand]",
        f"vehicles = {case.vehicles}",
        f"duration_s = {case.departure_window_s!r}",
        "fringe_factor = 1.0",
        f"min_distance_m = {round(MIN_DISTANCE_FACTOR * diagonal, 1)!r}",
        f"class_mix = {{ {mix} }}",
        "",
    ])


def prepare(case: ScaleCase, work: Path) -> Path:
    """Write the case's scenario into ``work`` and generate its SUMO inputs once into ``work/inputs``.

    Returns the scenario file.  Each run directory gets ``inputs`` as a symbolic link to
    ``work/inputs``, so :func:`run_sumo` finds the generated files (its generators key their
    cache on resolved paths) and runs no tool.
    """
    from sumo_nets.scenario import load_scenario, materialise

    work.mkdir(parents=True, exist_ok=True)
    path = work / f"{case.name}.toml"
    path.write_text(scenario_toml(case), encoding="utf-8")
    materialise(load_scenario(path), work / "inputs")
    return path


# --------------------------------------------------------------------------- child process

class TimedSumoAdapter(SumoAdapter):
    """A :class:`SumoAdapter` that times its calls per co-simulation step.

    Attributes
    ----------
    step_end : list of float
        ``time.perf_counter()`` at the end of every :meth:`step`.
    move_ms, step_ms, insert_ms : list of float
        Per step, ms: :meth:`move` (``moveToXY`` of every vehicle), :meth:`step`
        (``simulationStep`` and reading departures, arrivals, collisions), and
        :meth:`admit` + :meth:`finish` (insertion and removal) since the previous step.
    """

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.step_end: list[float] = []
        self.move_ms: list[float] = []
        self.step_ms: list[float] = []
        self.insert_ms: list[float] = []
        self._move = 0.0
        self._insert = 0.0

    def move(self, ids, xy_front, angle_deg, *args, **kwargs) -> None:
        t = time.perf_counter()
        try:
            super().move(ids, xy_front, angle_deg, *args, **kwargs)
        finally:
            self._move += time.perf_counter() - t

    def admit(self, vehicle, xy_front, angle_deg, **kwargs) -> None:
        t = time.perf_counter()
        try:
            super().admit(vehicle, xy_front, angle_deg, **kwargs)
        finally:
            self._insert += time.perf_counter() - t

    def finish(self, vid: str) -> None:
        t = time.perf_counter()
        try:
            super().finish(vid)
        finally:
            self._insert += time.perf_counter() - t

    def step(self) -> None:
        t = time.perf_counter()
        try:
            super().step()
        finally:
            end = time.perf_counter()
            self.step_end.append(end)
            self.step_ms.append((end - t) * 1e3)
            self.move_ms.append(self._move * 1e3)
            self.insert_ms.append(self._insert * 1e3)
            self._move = self._insert = 0.0


def run_options(driver: str, duration_s: float, log: str, controller: str = "paper") -> SimpleNamespace:
    """The options namespace ``muvsim run --controller CONTROLLER`` builds, for a SUMO scenario with its
    own settings."""
    return SimpleNamespace(seed=None, vclass="paper-a", tm=None, check=None, switching=None, disturbance=None,
                           baseline="sumo" if driver == "sumo" else None, gui=False, quiet=True,
                           solver="exact", duration=duration_s, vehicles=8, log=log, plots=False,
                           controller=controller)


def run_one(driver: str, scenario: Path, run_dir: Path, duration_s: float, log: str,
            controller: str = "paper") -> dict:
    """One run in this process (the child): ``run_sumo`` plus its SUMO call timings and peak memory.

    Writes ``run_dir/scale_steps.csv`` (muvsim only: per step ``wall_ms`` since the previous
    step's end, ``sumo_move_ms``, ``sumo_step_ms``, ``sumo_insert_ms``) and returns (and writes
    as ``run_dir/scale_run.json``) the run's summary, ``peak_rss_mb`` and ``cpu_s`` (user +
    system CPU seconds of the process).
    """
    from bridge import sumo_world

    made: list[TimedSumoAdapter] = []

    def factory(*args, **kwargs) -> TimedSumoAdapter:
        made.append(TimedSumoAdapter(*args, **kwargs))
        return made[-1]

    with mock.patch.object(sumo_world, "SumoAdapter", factory):
        summary = sumo_world.run_sumo(str(scenario), run_dir, run_options(driver, duration_s, log, controller))
    if driver == "muvsim" and made:
        a = made[0]
        end = np.asarray(a.step_end)
        pd.DataFrame({"wall_ms": np.r_[np.nan, np.diff(end) * 1e3] if len(end) else [],
                      "sumo_move_ms": a.move_ms, "sumo_step_ms": a.step_ms, "sumo_insert_ms": a.insert_ms}
                     ).to_csv(run_dir / CHILD_STEPS, index=False)
        summary["loop_s"] = float(end[-1] - end[0]) if len(end) > 1 else 0.0
    # Linux reports ru_maxrss in KiB (macOS in bytes)
    scale = 1 / 1024 if sys.platform != "darwin" else 1 / 1024**2
    ru = resource.getrusage(resource.RUSAGE_SELF)
    result = {"summary": summary, "peak_rss_mb": ru.ru_maxrss * scale, "cpu_s": ru.ru_utime + ru.ru_stime}
    (run_dir / CHILD_RESULT).write_text(json.dumps(result, default=str), encoding="utf-8")
    return result


def child_main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="bench_scale.py --child")
    ap.add_argument("--driver", choices=["muvsim", "sumo"], required=True)
    ap.add_argument("--scenario", required=True)
    ap.add_argument("--run-dir", required=True)
    ap.add_argument("--duration", type=float, required=True)
    ap.add_argument("--log", choices=["none", "summary", "full"], default="none")
    ap.add_argument("--controller", choices=["paper", "authority"], default="paper")
    a = ap.parse_args(argv)
    res = run_one(a.driver, Path(a.scenario), Path(a.run_dir), a.duration, a.log, a.controller)
    return 0 if res["summary"].get("complete") else 1


# --------------------------------------------------------------------------- parent

def run_child(driver: str, scenario: Path, run_dir: Path, duration_s: float, log: str,
              timeout: float | None, controller: str = "paper") -> dict:
    """Run one driver in a fresh Python process; returns its result (``error`` set when it failed)."""
    run_dir.mkdir(parents=True, exist_ok=True)
    link = run_dir / "inputs"
    if not link.exists():
        link.symlink_to(scenario.parent / "inputs", target_is_directory=True)
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", "--driver", driver, "--scenario",
           str(scenario), "--run-dir", str(run_dir), "--duration", repr(duration_s), "--log", log,
           "--controller", controller]
    t = time.perf_counter()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=ROOT)
    except subprocess.TimeoutExpired:
        return {"error": f"{driver} run timed out after {timeout:g} s", "process_s": time.perf_counter() - t}
    res_path = run_dir / CHILD_RESULT
    if not res_path.is_file():
        return {"error": f"{driver} run wrote no result (exit {proc.returncode}): {proc.stderr.strip()[-1500:]}",
                "process_s": time.perf_counter() - t}
    res = json.loads(res_path.read_text(encoding="utf-8"))
    res["process_s"] = time.perf_counter() - t
    if not res["summary"].get("complete"):
        res["error"] = f"{driver} run incomplete: {res['summary'].get('error', 'no error recorded')}"
    return res


def window_figures(steps: pd.DataFrame, timed: pd.DataFrame, warmup_s: float, Ts: float) -> dict:
    """Per-component figures over the measured window (see the module notes).

    Parameters
    ----------
    steps : DataFrame
        The run's ``steps.csv``.
    timed : DataFrame
        The child's ``scale_steps.csv`` (one row per step, same order).
    warmup_s : float
        Steps with ``t_s < warmup_s`` (and the first step, whose start is not timed) are left out.
    Ts : float
        Step length (s).
    """
    if len(steps) != len(timed):
        raise ValueError(f"steps.csv has {len(steps)} rows but {len(timed)} SUMO steps were timed")
    # prefixed, so that a column the loop may add one day (e.g. its own SUMO time) cannot clash
    df = pd.concat([steps.reset_index(drop=True), timed.add_prefix("timed_").reset_index(drop=True)], axis=1)
    df = df.iloc[1:]
    w = df[df["t_s"] >= warmup_s - 1e-9]
    if not len(w):
        raise ValueError(f"no step in the measured window (t >= {warmup_s:g} s; the run has {len(steps)} steps)")
    sim_s = len(w) * Ts
    total = w["timed_wall_ms"].sum() / 1e3
    sumo = {k: w[f"timed_sumo_{k}_ms"].sum() / 1e3 for k in ("move", "step", "insert")}
    # the vehicles' request indices (ST-MPC index at the next waypoint) are controller work,
    # timed inside tm_ms; older step tables have no request_ms / gate_ms (zeros then)
    req_ms = w["request_ms"] if "request_ms" in w else pd.Series(0.0, index=w.index)
    gate_ms = w["gate_ms"] if "gate_ms" in w else pd.Series(0.0, index=w.index)
    ctl_ms = w["controller_ms"] + req_ms
    parts = {"sumo": sum(sumo.values()),
             "controllers": ctl_ms.sum() / 1e3,
             "tm": (w["tm_ms"] - req_ms).sum() / 1e3,
             "monitor": (w["world_ms"].sum() - w["timed_sumo_move_ms"].sum() - w["timed_sumo_step_ms"].sum()) / 1e3,
             "logging": w["logging_ms"].sum() / 1e3}
    parts["other"] = total - sum(parts.values())
    out = {"window_steps": len(w), "window_sim_s": round(sim_s, 3),
           "active_max": int(w["active"].max()), "active_mean": float(w["active"].mean()),
           "active_min": int(w["active"].min())}
    for k in PARTS:
        out[f"{k}_s_per_sim_s"] = parts[k] / sim_s
    out["total_s_per_sim_s"] = total / sim_s
    for k, v in sumo.items():
        out[f"sumo_{k}_s_per_sim_s"] = v / sim_s
    for k in PARTS:
        out[f"{k}_share"] = parts[k] / total if total > 0 else float("nan")
    out["rtf_window"] = sim_s / total if total > 0 else float("nan")
    vs = w["active"].sum()
    out["controller_us_per_vehicle_step"] = ctl_ms.sum() * 1e3 / vs if vs else float("nan")
    busy = w["active"] > 0
    out["controller_us_per_vehicle_step_median"] = (
        float((ctl_ms[busy] * 1e3 / w["active"][busy]).median()) if busy.any() else float("nan"))
    dec = w[w["tm_decide_ms"] > 0]
    nan = float("nan")
    out["decisions"] = len(dec)
    out["tm_ms_per_decision"] = float((dec["tm_ms"] - req_ms[dec.index]).mean()) if len(dec) else nan
    out["tm_decide_ms_per_decision"] = float(dec["tm_decide_ms"].mean()) if len(dec) else nan
    out["tm_decide_ms_median"] = float(dec["tm_decide_ms"].median()) if len(dec) else nan
    out["tm_gate_ms_per_decision"] = float(gate_ms[dec.index].mean()) if len(dec) else nan
    out["request_ms_per_decision"] = float(req_ms[dec.index].mean()) if len(dec) else nan
    out["requests_per_step"] = float(w["requests"].mean())
    out["grants_per_step"] = float(w["grants"].mean())
    return out


def measure(case: ScaleCase, work: Path, log: str, timeout: float | None, machine: dict,
            controller: str = "paper") -> dict:
    """Both runs of one case and its row of the table (muvsim with ``controller``)."""
    row: dict = {"target": case.target, "junctions": case.junctions, "demand_requested": case.vehicles,
                 "warmup_s": case.warmup_s, "window_s": case.window_s, "seed": case.seed, "log": log,
                 "controller": controller}
    row["load_before"] = round(os.getloadavg()[0], 2)
    t = time.perf_counter()
    scenario = prepare(case, work)
    row["generate_s"] = round(time.perf_counter() - t, 3)
    errors = []
    muv = run_child("muvsim", scenario, work / "muvsim", case.duration_s, log, timeout, controller)
    if "error" not in muv:
        s = muv["summary"]
        try:
            steps = pd.read_csv(work / "muvsim" / "steps.csv")
            timed = pd.read_csv(work / "muvsim" / CHILD_STEPS)
            row.update(window_figures(steps, timed, case.warmup_s, s["simulated_s"] / max(s["steps"], 1)))
        except (OSError, ValueError, KeyError) as exc:
            errors.append(f"muvsim figures: {exc}")
        row.update(demand=s.get("vehicles_total"), admitted=None, arrived=s.get("vehicles_arrived"),
                   simulated_s=s.get("simulated_s"), collisions_sumo=s.get("collisions_sumo"),
                   collisions_geometric=s.get("collisions_geometric"), wall_s=s.get("wall_s"), rtf=s.get("rtf"),
                   loop_s=round(muv["summary"].get("loop_s", float("nan")), 3),
                   setup_s=round(s["wall_s"] - muv["summary"].get("loop_s", float("nan")), 3),
                   peak_rss_mb=round(muv["peak_rss_mb"], 1), cpu_s=round(muv["cpu_s"], 3),
                   process_s=round(muv["process_s"], 3))
        vt = work / "muvsim" / "vehicles.csv"
        if vt.is_file():
            row["admitted"] = int(pd.read_csv(vt)["admitted_s"].notna().sum())
    else:
        errors.append(muv["error"])
    base = run_child("sumo", scenario, work / "sumo", case.duration_s, "none", timeout)
    if "error" not in base:
        b = base["summary"]
        row.update(sumo_wall_s=b.get("wall_s"), sumo_rtf=b.get("rtf"), sumo_simulated_s=b.get("simulated_s"),
                   sumo_arrived=b.get("vehicles_arrived"), sumo_collisions=b.get("collisions_sumo"),
                   sumo_peak_rss_mb=round(base["peak_rss_mb"], 1), sumo_cpu_s=round(base["cpu_s"], 3),
                   sumo_process_s=round(base["process_s"], 3))
        if row.get("wall_s") and b.get("wall_s"):
            row["wall_ratio"] = row["wall_s"] / b["wall_s"]
    else:
        errors.append(base["error"])
    row["load_after"] = round(os.getloadavg()[0], 2)
    row["complete"] = not errors
    row["error"] = "; ".join(errors)
    row.update(machine)
    return row


def machine_info(argv: list[str] | None) -> dict:
    """Where and how the figures were measured."""
    args = sys.argv[1:] if argv is None else list(argv)
    return {"machine": f"{platform.platform()} {platform.machine()} {platform.processor()}".strip(),
            "cpus": os.cpu_count(), "python": platform.python_version(),
            "command": shlex.join([Path(sys.executable).name, "benchmarks/bench_scale.py", *args])}


def main(argv: list[str] | None = None) -> pd.DataFrame:
    raw = sys.argv[1:] if argv is None else list(argv)
    if raw[:1] == ["--child"]:
        sys.exit(child_main(raw[1:]))
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=list(SIZES), metavar="N",
                    help=f"target vehicles in the network at once (default {' '.join(map(str, SIZES))})")
    ap.add_argument("--sim-seconds", type=float, default=120.0,
                    help="simulated seconds measured per size, after the warm-up (default 120)")
    ap.add_argument("--warmup", type=float, default=30.0,
                    help="simulated seconds before the measured window, while the network fills (default 30)")
    ap.add_argument("--log", choices=["none", "summary", "full"], default="summary",
                    help="the muvsim runs' run.mcap (default summary: the logging share is measured)")
    ap.add_argument("--seed", type=int, default=1, help="demand and run seed (default 1)")
    ap.add_argument("--runs", default=None, help="keep the run directories here (default: a temporary directory)")
    ap.add_argument("--timeout", type=float, default=None, help="wall seconds per run before it is abandoned")
    ap.add_argument("--quick", action="store_true", help="30 vehicles on a 3x3 grid, 20 simulated s, no warm-up")
    ap.add_argument("--controller", choices=["paper", "authority"], default="paper",
                    help="muvsim's --controller (default paper: the figures of benchmarks/results/scale.csv)")
    ap.add_argument("--out", default="benchmarks/results/scale.csv")
    args = ap.parse_args(raw)
    sizes, window, warmup = args.sizes, args.sim_seconds, args.warmup
    if args.quick:
        sizes, window, warmup = QUICK["sizes"], QUICK["sim_seconds"], QUICK["warmup"]
    if any(n < 1 for n in sizes):
        ap.error(f"--sizes: every size must be >= 1, got {sizes}")
    if not (window > 0 and warmup >= 0):
        ap.error(f"--sim-seconds must be > 0 and --warmup >= 0, got {window} and {warmup}")
    machine = machine_info(raw)
    print(f"machine: {machine['machine']}, {machine['cpus']} CPUs, Python {machine['python']}")
    print(f"command: {machine['command']}")
    cases = [case_for(n, window, warmup, args.seed) for n in sizes]
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_scale-") as tmp:
        base = Path(args.runs) if args.runs else Path(tmp)
        for case in cases:
            print(f"size {case.target}: {case.junctions}x{case.junctions} grid, {case.vehicles} trips, "
                  f"{case.duration_s:g} simulated s ...", flush=True)
            row = measure(case, (base / case.name).resolve(), args.log, args.timeout, machine, args.controller)
            if row["error"]:
                print(f"  failed: {row['error']}", flush=True)
            rows.append(row)
    df = pd.DataFrame(rows)
    shown = [c for c in PRINTED if c in df]
    with pd.option_context("display.width", 250, "display.max_columns", 40, "display.float_format", "{:.3g}".format):
        print(df[shown].to_string(index=False))
        shares = [f"{k}_share" for k in PARTS if f"{k}_share" in df]
        if shares:
            sumo = [c for c in ("sumo_move_s_per_sim_s", "sumo_step_s_per_sim_s", "sumo_insert_s_per_sim_s")
                    if c in df]
            print("share of wall time per component; SUMO's part split (wall s per simulated s):")
            print(df[["target", *shares, *sumo]].to_string(index=False))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(out, index=False)
    print(f"wrote {out}")
    if not df["complete"].all():
        sys.exit(1)
    return df


if __name__ == "__main__":
    main()
