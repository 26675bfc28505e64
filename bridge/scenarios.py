"""Built-in free-plane scenarios and their runner (``muvsim run SCENARIO``).

``single``: one vehicle follows a random zig-zag of waypoints exactly delta
apart (issue: ST-MPC in the free plane).  Every run writes
``summary.json`` and ``steps.csv`` into the output directory, also when it
fails half-way (``summary.json`` then says ``"complete": false`` and why).
"""

from __future__ import annotations

import time
import traceback
from pathlib import Path

import numpy as np
import pandas as pd

from bridge.interrupt import interrupt_behind

__all__ = ["ScenarioRunError", "run_scenario", "SCENARIOS", "default_controller", "default_vclass"]

SCENARIOS = ("single", "paper10", "swap", "crossing")


def default_controller(scenario: str) -> str:
    """``muvsim run --controller``'s default for ``scenario``: ``authority`` (movement authority,
    design.md §7) for SUMO scenarios (urban classes: car, bus, truck and SUMO's vTypes), ``paper``
    for the free-plane ones (the paper's own classes and figures)."""
    return "paper" if scenario in SCENARIOS else "authority"


def default_vclass(controller: str) -> str:
    """``--vclass``'s default for the free-plane scenarios: ``car`` with the movement-authority
    controller (it needs a class with a ``comfort_decel``), the paper's ``paper-a`` otherwise."""
    return "car" if controller == "authority" else "paper-a"


class ScenarioRunError(ValueError):
    """A scenario name or option that cannot be run; the message says what is valid."""


def _write_summary(out: Path, summary: dict) -> None:
    from analysis.outputs import write_summary

    write_summary(out, summary)


def run_scenario(name: str, out: Path, opts, observers_extra: list | None = None) -> dict:
    """Run built-in scenario ``name`` with CLI-like options ``opts``; returns the summary.
    ``observers_extra``: more :class:`~bridge.cosim.Cosim` observers for a multi-vehicle run
    (:func:`run_multi`)."""
    from controllers.classes import ClassError, get_class
    from controllers.synthesis import SynthesisError

    if name in ("paper10", "swap", "crossing") or getattr(opts, "controller", "paper") == "authority":
        return run_multi(name, Path(out), opts, observers_extra=observers_extra)
    if name not in SCENARIOS:
        raise ScenarioRunError(f"unknown scenario {name!r}; built-in scenarios: {', '.join(SCENARIOS)}")
    try:
        vclass = get_class(opts.vclass)
    except ClassError as exc:
        raise ScenarioRunError(f"--vclass: {exc}") from None
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    summary = {
        "scenario": name, "seed": opts.seed, "complete": False,
        "options": {k: getattr(opts, k) for k in ("vclass", "tm", "check", "switching", "disturbance",
                                                  "solver", "duration")},
    }
    _write_summary(out, summary)
    t0 = time.perf_counter()
    try:
        from bridge.freeplane import follow_waypoints, zigzag_waypoints

        W = zigzag_waypoints(vclass.model.delta, count=30, seed=opts.seed)
        max_steps = int(round(opts.duration / vclass.model.Ts)) if opts.duration else None
        traj = follow_waypoints(vclass, W, disturbance=opts.disturbance, switching=opts.switching,
                                solver=opts.solver, seed=opts.seed, max_steps=max_steps)
        Ts = vclass.model.Ts
        steps = pd.DataFrame({
            "t_s": np.arange(len(traj.l)) * Ts,
            "x_m": traj.X[:, 0], "y_m": traj.X[:, 1],
            "vx_mps": traj.X[:, 2], "vy_mps": traj.X[:, 3],
            "waypoint": traj.k, "index": traj.l,
        })
        steps.to_csv(out / "steps.csv", index=False)
        summary.update(
            steps=traj.steps, vehicles=1, finished=bool(traj.finished),
            collisions_geometric=0, invariant_violations=int(traj.invariant_violations),
            constraint_violations=int(traj.constraint_violations),
            min_separation_m=float("inf"), stop_commands=0,
            travel_time_s=round(traj.steps * Ts, 3), complete=True,
        )
        from analysis.safety import verdict

        summary.update(verdict(summary))
    except KeyboardInterrupt:
        summary["interrupted"] = True
        raise
    except SynthesisError as exc:
        summary.update(complete=False, error=f"class {vclass.name!r} cannot be synthesised: {exc}")
    except Exception as exc:  # keep what was written, say why the run is incomplete
        if interrupt_behind(exc):  # a Ctrl-C that came back wrapped (bridge.interrupt)
            summary["interrupted"] = True
            raise KeyboardInterrupt from exc
        summary.update(complete=False, error=f"{type(exc).__name__}: {exc}",
                       traceback=traceback.format_exc(limit=5))
    finally:
        summary["wall_s"] = round(time.perf_counter() - t0, 3)
        _write_summary(out, summary)
    return summary


def run_multi(name: str, out: Path, opts, world=None, specs=None, observers_extra: list | None = None) -> dict:
    """Run a multi-vehicle scenario through :class:`bridge.cosim.Cosim`; write summary and CSVs.
    ``observers_extra``: more observers (``on_step(sim, state, decision, row)``), before the outputs'."""
    from analysis.halts import HaltCounter
    from analysis.mcap_log import observers_for
    from analysis.outputs import StreamingOutputs, close_observers, write_run_tables
    from controllers.speed_limits import SpeedSettings
    from bridge.cosim import Cosim, CosimSettings
    from bridge.cosim import VehicleSpec
    from bridge.layouts import crossing, paper10, subsample, swap, turn_bound
    from controllers.classes import ClassError, builtin_classes
    from controllers.synthesis import SynthesisError
    from tm.settings import TMSettings

    classes = builtin_classes()
    if name != "paper10" and opts.vclass not in classes:
        raise ScenarioRunError(f"--vclass: unknown vehicle class {opts.vclass!r}; valid: {', '.join(classes)}")
    zones = None
    if specs is None:
        if name in ("swap", "crossing") and opts.vehicles < (2 if name == "swap" else 1):
            raise ScenarioRunError(f"--vehicles: {name} needs at least {2 if name == 'swap' else 1} vehicle(s), "
                                   f"got {opts.vehicles}")
        if name == "paper10":
            specs = paper10({c: classes[c].model.delta for c in classes},
                            {c: turn_bound(classes[c].model) for c in classes})
        elif name == "swap":
            specs = swap(opts.vehicles, opts.vclass, classes[opts.vclass].model.delta,
                         turn_max_deg=turn_bound(classes[opts.vclass].model))
        elif name == "single":  # authority mode: one vehicle alone on a 600 m straight
            specs = [VehicleSpec("single", opts.vclass, subsample([[0.0, 0.0], [600.0, 0.0]],
                                                                   classes[opts.vclass].model.delta,
                                                                   turn_bound(classes[opts.vclass].model)))]
        elif name == "crossing":
            specs, zones = crossing(max(opts.vehicles // 4, 1), opts.vclass, classes[opts.vclass].model.delta,
                                   turn_max_deg=turn_bound(classes[opts.vclass].model))
        else:
            raise ScenarioRunError(f"unknown scenario {name!r}; built-in scenarios: {', '.join(SCENARIOS)}")
    out.mkdir(parents=True, exist_ok=True)
    options = {k: getattr(opts, k) for k in ("vclass", "tm", "check", "switching", "disturbance", "solver",
                                             "duration", "vehicles", "controller", "claim_cache", "frame")
               if hasattr(opts, k)}
    summary = {"scenario": name, "seed": opts.seed, "options": options, "complete": False}
    _write_summary(out, summary)
    t0 = time.perf_counter()
    sim = None
    observers: list = []
    try:
        settings = CosimSettings(tm=TMSettings(policy=opts.tm, check=opts.check, seed=opts.seed),
                                 switching=opts.switching, disturbance=opts.disturbance, solver=opts.solver,
                                 seed=opts.seed, duration_s=opts.duration,
                                 controller=getattr(opts, "controller", "paper"),
                                 speed=SpeedSettings.from_options(opts),
                                 claim_cache=(getattr(opts, "claim_cache", None) or "on") == "on",
                                 frame=getattr(opts, "frame", None) or "auto")
        observers = [HaltCounter()] + observers_for(out, getattr(opts, "log", None) or "none",
                                                    {"scenario": name, "seed": opts.seed, **options})
        observers += list(observers_extra or [])
        observers.append(StreamingOutputs(out, dict(summary)))  # last: the row is complete by then
        sim = Cosim(classes, specs, settings, world=world, zones=zones, observers=observers)
        max_steps = int(getattr(opts, "max_steps", 0) or 20000)
        sim.run(max_steps)
        summary["complete"] = True
    except KeyboardInterrupt:
        summary["interrupted"] = True  # written below; the caller says where it stopped
        raise
    except (SynthesisError, ClassError, ValueError) as exc:
        summary["error"] = f"{type(exc).__name__}: {exc}"
    except Exception as exc:  # keep what was written, say why the run is incomplete
        if interrupt_behind(exc):  # a Ctrl-C that came back wrapped (bridge.interrupt)
            summary["interrupted"] = True
            raise KeyboardInterrupt from exc
        summary.update(error=f"{type(exc).__name__}: {exc}", traceback=traceback.format_exc(limit=6))
    finally:
        summary["wall_s"] = round(time.perf_counter() - t0, 3)
        log_errors = close_observers(observers)
        if log_errors:
            summary["log_error"] = "; ".join(log_errors)
        if sim is not None:
            summary.update(write_run_tables(out, sim))
        _write_summary(out, summary)
    return summary


def kpi_tables(sim) -> tuple[dict, pd.DataFrame, pd.DataFrame]:
    """Summary figures, the per-step table and the per-vehicle table of a (possibly partial) run.

    Kept for callers of the loop; the tables are :func:`analysis.kpis.run_tables`'s.
    """
    from analysis.kpis import run_tables

    return run_tables(sim)
