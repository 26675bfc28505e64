"""SUMO as the co-simulation's world: routes in, positions out, SUMO judges collisions.

:func:`run_sumo` runs a built-in scenario (``grid``, ``grid-large``), a
scenario TOML file, or a user's ``.sumocfg``: SUMO's routes become waypoints
at most the class's delta apart (junction-internal lanes included), every
vehicle is driven by its ST-MPC through :class:`bridge.cosim.Cosim`, and each
step the vehicles are pushed into SUMO with ``moveToXY``.  Junctions are the
co-simulation's conflict zones.  ``baseline=True`` runs the same demand driven
by SUMO itself (no override) for comparison.
"""

from __future__ import annotations

import json
import sys
import time
import traceback
import xml.etree.ElementTree as ET
from dataclasses import replace
from pathlib import Path

import numpy as np

from bridge.cosim import Cosim, CosimSettings, VehicleSpec, Zone
from bridge.pose import front_bumper, sumo_angle
from analysis.kpis import baseline_vehicle_table, read_tripinfo
from analysis.halts import HaltCounter
from analysis.mcap_log import observers_for
from analysis.outputs import StreamingOutputs, close_observers, write_run_tables
from analysis.safety import verdict
from bridge.scenarios import _write_summary
from bridge.stopping import route_file_departures, run_limit, stop_reason
from bridge.sumo_adapter import SumoAdapter, SumoError
from bridge.waypoints import RouteError, load_net, trim_start
from controllers.classes import builtin_classes
from controllers.tolerances import HOLD_TOL_M, HOLD_TOL_RAD
from tm.settings import TMSettings

#: Gap between a departing vehicle's back and the start of its first lane (m).
DEPART_CLEARANCE_M = 0.5

#: Options of a user's ``.sumocfg`` run when the command line leaves them out.
SUMOCFG_DEFAULTS = {"tm": "optimal", "check": "union", "switching": "early", "disturbance": "random"}

__all__ = ["SumoWorld", "junction_zones", "run_sumo"]


_NEVER = (1e18, 1e18, 0.0)  # pose of a vehicle not yet sent: far from any, so always moved


class SumoWorld:
    """The :class:`~bridge.cosim.World` adapter over a started :class:`SumoAdapter`."""

    def __init__(self, adapter: SumoAdapter, planned: dict, routes: dict):
        self.adapter = adapter
        self.planned = planned
        self.routes = routes
        self.lengths: dict[str, float] = {}
        self.step_ms = 0.0
        self._sent: dict[str, list] = {}  # vehicle -> (x, y, heading) last sent by moveToXY
        self._held: set[str] = set()      # vehicles SUMO holds at speed 0 (see push)

    def insert(self, spec: VehicleSpec, vclass) -> None:
        pv, r = self.planned[spec.id], self.routes[spec.id]
        self.lengths[spec.id] = pv.length
        W = np.asarray(spec.waypoints, dtype=float)
        h0 = float(np.arctan2(*(W[1] - W[0])[::-1]))
        self.adapter.admit(pv, front_bumper(W[0], h0, pv.length), sumo_angle(h0),
                           depart_lane=r.depart_lane_index)

    def push(self, ids, centre, heading) -> None:
        """Move the vehicles whose pose changed (beyond :data:`HOLD_TOL_M` /
        :data:`HOLD_TOL_RAD` since it was last sent); hold the others still in SUMO."""
        c = np.asarray(centre, dtype=float).reshape(-1, 2)
        h = np.asarray(heading, dtype=float).reshape(-1)
        last = np.array([self._sent.get(v, _NEVER) for v in ids], dtype=float).reshape(-1, 3)
        still = (np.hypot(c[:, 0] - last[:, 0], c[:, 1] - last[:, 1]) < HOLD_TOL_M) & \
            (np.abs(np.angle(np.exp(1j * (h - last[:, 2])))) < HOLD_TOL_RAD)
        hold = [v for v, s in zip(ids, still.tolist()) if s and v not in self._held]
        if hold:
            self.adapter.hold(hold)
            self._held.update(hold)
        mv = np.flatnonzero(~still)
        if not len(mv):
            return
        mids = [ids[i] for i in mv.tolist()]
        release = [v for v in mids if v in self._held]
        if release:
            self.adapter.release(release)
            self._held.difference_update(release)
        lengths = np.array([self.lengths[v] for v in mids])
        self.adapter.move(mids, front_bumper(c[mv], h[mv], lengths), sumo_angle(h[mv]))
        self._sent.update(zip(mids, np.column_stack([c[mv], h[mv]]).tolist()))

    def finish(self, vid: str) -> None:
        self._sent.pop(vid, None)
        self._held.discard(vid)
        self.adapter.finish(vid)

    def step(self) -> list:
        t = time.perf_counter()
        self.adapter.step()
        self.step_ms = (time.perf_counter() - t) * 1e3
        return [e.pair for e in self.adapter.collisions()]


def junction_zones(net_path) -> list[Zone]:
    """Every junction where two or more edges enter, as a zone (its shape's bounding box)."""
    root = ET.parse(net_path).getroot()
    zones = []
    for j in root.iter("junction"):
        if j.get("type") in ("internal", "dead_end"):
            continue
        inc = [e for e in (j.get("incLanes") or "").split() if e]
        edges = {lane.rsplit("_", 1)[0] for lane in inc}
        shape = j.get("shape")
        if len(edges) < 2 or not shape:
            continue
        pts = np.array([[float(c) for c in p.split(",")[:2]] for p in shape.split()])
        zones.append(Zone(j.get("id"), tuple(pts.min(axis=0)), tuple(pts.max(axis=0))))
    return zones


def _classes_for(scenario, demand, classes, source=None):
    """The muvsim class of every vehicle: the scenario's mapping, or for a user's .sumocfg a
    vType named like a class, else its SUMO vClass (``VCLASS_TO_CLASS``); any other vClass
    (bicycle, pedestrian, ...) is refused by name, never driven as a car."""
    from sumo_nets.scenario import VCLASS_TO_CLASS, ScenarioError

    out = {}
    for pv in demand.vehicles:
        if scenario is not None:
            name = scenario.class_for(pv.type_id, pv.vclass)
        elif pv.type_id in ("car", "bus", "truck"):
            name = pv.type_id
        elif pv.vclass in VCLASS_TO_CLASS:
            name = VCLASS_TO_CLASS[pv.vclass]
        else:
            raise ScenarioError(
                f"{source or 'the demand'}: vehicle {pv.id!r}: vType {pv.type_id!r} has vClass {pv.vclass!r}, "
                f"which muvsim cannot drive (it has no class for it); valid vClasses: "
                f"{', '.join(sorted(VCLASS_TO_CLASS))} (or a vType named car, bus or truck)")
        if name not in classes:
            raise ValueError(f"vehicle {pv.id}: vType {pv.type_id!r} maps to unknown class {name!r}")
        out[pv.id] = name
    return out


def run_sumo(target: str, out: Path, opts) -> dict:
    """Run a SUMO scenario (built-in name, scenario TOML or .sumocfg) and write its outputs."""
    from sumo_nets.scenario import ScenarioError, load_scenario, materialise, read_sumocfg

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    summary: dict = {"scenario": str(target), "complete": False, "baseline": opts.baseline or "muvsim"}
    _write_summary(out, summary)
    t0 = time.perf_counter()
    sim = None
    observers: list = []
    adapter = SumoAdapter()
    try:
        if str(target).endswith(".sumocfg"):
            scenario = None
            cfg = read_sumocfg(target)
            sumocfg, net = cfg.path, cfg.net
            seed, routes_in, additional = opts.seed, cfg.routes, cfg.additional
            tm, check, switching, disturbance = (getattr(opts, k) or SUMOCFG_DEFAULTS[k]
                                                 for k in ("tm", "check", "switching", "disturbance"))
        else:
            scenario = load_scenario(target)
            if opts.seed is not None and scenario.demand is not None:  # --seed draws the demand too
                scenario = replace(scenario, demand=replace(scenario.demand, seed=opts.seed))
            files = materialise(scenario, out / "inputs")
            sumocfg, net = files.sumocfg, files.net
            seed = scenario.seed if opts.seed is None else opts.seed
            routes_in, additional = files.routes, ()
            if scenario.demand is not None:
                summary["demand_seed"] = scenario.demand.seed
            tm = opts.tm or scenario.tm
            check = opts.check or scenario.check
            switching = opts.switching or scenario.switching
            disturbance = opts.disturbance or scenario.disturbance
        summary.update(seed=seed, options=dict(tm=tm, check=check, switching=switching, disturbance=disturbance,
                                               solver=opts.solver, duration_s=opts.duration))
        _write_summary(out, summary)
        tripinfo = out / "tripinfo.xml"
        if opts.baseline == "sumo":
            planned = _planned_demand(routes_in, additional)
            deps = [pv.depart_s for pv in planned.vehicles] if planned is not None \
                else route_file_departures(routes_in)
            limit = run_limit(deps, opts.duration)
            return _run_baseline(adapter, sumocfg, tripinfo, seed, limit, out, summary, t0,
                                 None if planned is None else len(planned))
        demand = adapter.start(sumocfg, tripinfo_path=tripinfo, seed=seed, gui=opts.gui)
        limit = run_limit([pv.depart_s for pv in demand.vehicles], opts.duration)
        duration = limit.duration_s
        classes = builtin_classes()
        cls_of = _classes_for(scenario, demand, classes, source=sumocfg)
        geo = load_net(net)
        routes, specs = {}, []
        for pv in demand.vehicles:
            c = cls_of[pv.id]
            r = geo.route(pv.edges, classes[c].model.delta, vclass=pv.vclass, vehicle_id=pv.id)
            routes[pv.id] = r
            # depart with the whole body on the first lane (SUMO's departPos="base"), not
            # with its back half in the junction behind it
            W = trim_start(r, 0.5 * classes[c].length + DEPART_CLEARANCE_M)
            specs.append(VehicleSpec(id=pv.id, vclass=c, waypoints=W, depart_s=pv.depart_s))
        world = SumoWorld(adapter, {pv.id: pv for pv in demand.vehicles}, routes)
        settings = CosimSettings(tm=TMSettings(policy=tm, check=check, seed=seed), switching=switching,
                                 disturbance=disturbance, solver=opts.solver, seed=seed, duration_s=duration)
        observers = [HaltCounter()] + observers_for(out, getattr(opts, "log", None) or "none",
                                                    {"scenario": str(target), "seed": seed, **summary["options"]})
        observers.append(StreamingOutputs(out, dict(summary)))  # last: the row is complete by then
        sim = Cosim(classes, specs, settings, world=world, zones=junction_zones(net), observers=observers)
        bar = None
        if not getattr(opts, "quiet", False):
            from tqdm import tqdm
            bar = tqdm(total=int(round(duration / settings.Ts)), unit="step", file=sys.stderr,
                       mininterval=1.0, leave=False)

        def progress(s):
            if bar is not None:
                bar.update(1)
                if s.t % 50 == 0:
                    bar.set_postfix(active=sum(len(g.ids) for g in s.groups.values()),
                                    waiting=len(s.pending))

        sim.run(int(round(duration / settings.Ts)) + 1, progress=progress)
        if bar is not None:
            bar.close()
        summary["complete"] = True
    except KeyboardInterrupt:
        summary["interrupted"] = True  # written below; the caller says where it stopped
        raise
    except (ScenarioError, RouteError, SumoError) as exc:
        summary["error"] = f"{type(exc).__name__}: {exc}"
    except Exception as exc:
        summary.update(error=f"{type(exc).__name__}: {exc}", traceback=traceback.format_exc(limit=6))
    finally:
        try:
            adapter.close()
        except Exception:  # pragma: no cover - a dead SUMO
            pass
        log_errors = close_observers(observers)
        if log_errors:
            summary["log_error"] = "; ".join(log_errors)
        wall = time.perf_counter() - t0
        summary["wall_s"] = round(wall, 3)
        if sim is not None:
            figures = write_run_tables(out, sim, out / "tripinfo.xml")
            summary.update(figures)
            summary.update(
                collisions_sumo=len(sim.collisions_world),
                vehicles_total=figures["vehicles"],
                stop_reason=stop_reason(limit, figures["vehicles"], figures["vehicles_arrived"],
                                        figures["simulated_s"]),
                rtf=round(sim.t * sim.settings.Ts / wall, 3) if wall > 0 else None)
            summary.update(verdict(summary))
        _write_summary(out, summary)
    return summary


def _planned_demand(routes, additional):
    """The demand of routed route files as muvsim reads it (None for trips/flows or unreadable files)."""
    from bridge.demand import DemandError, needs_routing, read_demand

    if not routes or needs_routing(routes):
        return None
    try:
        return read_demand(list(routes), type_files=list(additional))
    except DemandError:
        return None


def _run_baseline(adapter: SumoAdapter, sumocfg, tripinfo, seed, limit, out, summary, t0,
                  demand_size: int | None = None) -> dict:
    """The same demand driven by SUMO's own drivers (no muvsim control), until ``limit``.

    ``vehicles_total`` is the demand's size when known (routed route files), else the
    vehicles SUMO loaded."""
    res = adapter.run_native(sumocfg, duration_s=limit.duration_s, seed=seed, tripinfo_path=tripinfo)
    wall = time.perf_counter() - t0
    vehicles = baseline_vehicle_table(read_tripinfo(tripinfo),
                                      {c: vc.v_max for c, vc in builtin_classes().items()})
    vehicles.to_csv(out / "vehicles.csv", index=False)
    arrived = vehicles["arrival_s"].notna()
    summary.update(complete=True, steps=res["steps"], simulated_s=res["simulated_s"],
                   collisions_sumo=len(res["collision_pairs"]), vehicles_arrived=int(arrived.sum()),
                   mean_travel_time_s=float(vehicles["travel_time_s"].mean()) if arrived.any() else None,
                   mean_delay_s=float(vehicles["delay_s"].mean()) if arrived.any() else None,
                   throughput_vph=round(float(arrived.sum()) * 3600.0 / res["simulated_s"], 3)
                   if res["simulated_s"] else None,
                   rtf=round(res["simulated_s"] / wall, 3), wall_s=round(wall, 3))
    total = demand_size if demand_size is not None else res.get("vehicles_loaded")
    if total is not None:
        summary["vehicles_total"] = int(total)
        summary["stop_reason"] = stop_reason(limit, summary["vehicles_total"], summary["vehicles_arrived"],
                                             res["simulated_s"])
    _write_summary(out, summary)
    return summary
