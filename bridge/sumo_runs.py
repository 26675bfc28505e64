"""One-shot SUMO runs and the checks shared with :class:`bridge.sumo_adapter.SumoAdapter`.

:func:`run_native` runs a configuration with SUMO's own drivers (``--baseline sumo``);
:func:`expand_demand` lets SUMO expand a configuration's demand (flows, trips, distributions) and
records it; :func:`preflight` loads a command in a child ``sumo`` before libsumo does.  Neither run
keeps a simulation open: the stepwise co-simulation is :class:`~bridge.sumo_adapter.SumoAdapter`'s.
The SUMO API comes from the adapter (``api``: the libsumo module or traci, ``errors``: the exceptions
it raises): only ``bridge/sumo_adapter.py`` imports libsumo or traci (tests/test_layering.py).
"""

from __future__ import annotations

import os
import shutil
import subprocess
from contextlib import contextmanager
from pathlib import Path
from typing import Iterable
import xml.etree.ElementTree as ET

from bridge.demand import Demand, PlannedVehicle, VehicleStop, VehicleType, depart_lane_of
from bridge.sumo_inputs import InputError, PreparedInputs, parse_xml

__all__ = ["SumoError", "check_xml", "sumo_home", "run_native", "expand_demand", "preflight"]

_REMOVE_VAPORIZED = 3  # libsumo/traci constants.REMOVE_VAPORIZED
#: SUMO's desiredMaxSpeed of bicycles (``DEFAULT_BICYCLE_SPEED``, 20 km/h): their vType's maxSpeed
#: is 50 km/h, but SUMO drives them at most 20 km/h x speedFactor (measured: 5.89 m/s = 5.56 x 1.06
#: alone on a 13.89 m/s road).  libsumo has no getter for desiredMaxSpeed; a vType's own one is not read.
BICYCLE_DESIRED_MAX_SPEED = 20.0 / 3.6


class SumoError(RuntimeError):
    """SUMO failed to start or failed during the run; the message carries SUMO's own."""


def sumo_home() -> Path:
    from sumo_nets.sumo_tools import sumo_home as home

    return home()


def check_xml(kind: str, path: Path) -> None:
    """Raise SumoError naming ``path`` unless it exists and is well-formed XML."""
    if not path.is_file():
        raise SumoError(f"SUMO {kind} {path} does not exist")
    try:
        parse_xml(path)  # gzipped files as SUMO reads them
    except InputError as exc:
        raise SumoError(f"SUMO {kind} {exc}") from None


@contextmanager
def _session(api, errors: tuple, args: list[str], failure: str):
    """One SUMO run through ``api`` (started with ``args``, closed however it ends): SUMO's errors
    (``errors``) become a :class:`SumoError` saying ``failure`` and SUMO's message."""
    try:
        api.start(args)
        yield
    except errors as exc:
        raise SumoError(f"{failure}: {exc}") from None
    finally:
        try:
            api.close()
        except errors:
            pass


def run_native(api, errors: tuple, sumocfg: str | os.PathLike, *, duration_s: float, seed: int,
               tripinfo_path: str | os.PathLike, begin_s: float = 0.0, step_length: float | None = None,
               extra_args: Iterable[str] = ()) -> dict:
    """Run a configuration with SUMO's own drivers (no override): the ``--baseline sumo``.

    The window is ``begin_s .. begin_s + duration_s``; ``step_length`` None keeps the
    configuration's own (SUMO's default 1 s if it sets none).  Same collision options as
    :meth:`start`; returns steps, unique collision pairs, the run's simulated seconds and
    the demand inside the window (``vehicles_in_window``: vehicles that departed plus those
    still waiting for insertion at the end; vehicles SUMO loaded ahead of a departure
    beyond the window are not counted).  Raises :class:`SumoError` on SUMO's errors.
    """
    mod = api
    end = begin_s + duration_s
    args = ["sumo", "-c", str(sumocfg), "--seed", str(seed), "--begin", f"{begin_s:.10g}",
            "--collision.action", "warn", "--collision.check-junctions", "true",
            "--collision.mingap-factor", "0", "--tripinfo-output", str(tripinfo_path),
            "--no-step-log", "true", "--end", f"{end:.10g}", *[str(a) for a in extra_args]]
    if step_length is not None:
        args += ["--step-length", f"{step_length:.10g}"]
    pairs: set = set()
    steps = departed = 0
    with _session(mod, errors, args, f"SUMO failed running {sumocfg} with its own drivers"):
        while mod.simulation.getTime() < end - 1e-9 and (
                steps == 0 or mod.simulation.getMinExpectedNumber() > 0):
            mod.simulationStep()
            steps += 1
            departed += mod.simulation.getDepartedNumber()
            for c in mod.simulation.getCollisions():
                pairs.add(tuple(sorted((c.collider, c.victim))))
        simulated = float(mod.simulation.getTime()) - begin_s
        in_window = departed + len(mod.simulation.getPendingVehicles())
    return {"steps": steps, "collision_pairs": sorted(pairs), "simulated_s": round(simulated, 3),
            "vehicles_in_window": in_window}


def depart_lanes(files) -> dict[tuple[str, str], str]:
    """``departLane`` as the route files write it: ``("vehicle", id)`` for vehicles and trips,
    ``("flow", id)`` for flows (their vehicles are ``id.N``); libsumo does not report it, and on the
    empty network of the expansion SUMO resolves ``free`` and ``best`` to the first lane."""
    out: dict[tuple[str, str], str] = {}
    for f in files:
        try:
            root = parse_xml(f).getroot()
        except (InputError, OSError, ET.ParseError):
            continue  # SUMO read them: a file it could not is refused before
        for e in root.iter():
            if e.tag in ("vehicle", "trip", "flow") and e.get("id") and e.get("departLane") is not None:
                out[("flow" if e.tag == "flow" else "vehicle", e.get("id"))] = e.get("departLane")
    return out


def _stops_of(veh, vid: str) -> tuple[VehicleStop, ...]:
    """Vehicle ``vid``'s stops as SUMO resolved them (stopping places to their lane and end
    position; ``until`` and ``duration`` SUMO's own, invalid ones none)."""
    out = []
    for st in veh.getStops(vid):
        dur = float(st.duration)
        until = float(st.until)
        out.append(VehicleStop(str(st.lane), float(st.endPos), dur if dur >= 0 else 0.0,
                               until if until >= 0 else None, str(st.stoppingPlaceID) or str(st.lane)))
    return tuple(out)


def expand_demand(api, errors: tuple, sumocfg: str | os.PathLike, inputs: PreparedInputs, *, begin_s: float,
                  end_s: float, seed: int, step_length: float, work_dir: str | os.PathLike) -> Demand:
    """The demand of a configuration as SUMO itself expands it, inside ``begin_s .. end_s``.

    SUMO runs the configuration (its own parser: gzip, route and additional files,
    flows, ``probability`` and ``exp(...)`` draws, vType and route distributions, all
    with ``seed``) and every vehicle is removed the moment SUMO inserts it, so the
    network stays empty and each one departs at its requested time (one SUMO cannot
    insert even then keeps the route it was loaded with).  Recorded per vehicle:
    id, vType (the one drawn from a distribution), route (as routed by SUMO for trips),
    requested departure (``depart - departDelay``), and where and how fast SUMO inserted it
    (its ``departPos`` and ``departSpeed`` as SUMO resolves them on the empty network: the
    front's lane position and the speed; None for one not inserted in the window).  vTypes are read back with
    ``vehicletype.get*`` (SUMO's defaults per vClass for what a vType leaves out).

    Raises
    ------
    SumoError
        SUMO refused the inputs (its message) or failed.
    """
    from sumo_nets.scenario import ScenarioError, read_sumocfg

    try:
        check_xml("network", read_sumocfg(sumocfg).net)  # libsumo crashes on a broken one
    except ScenarioError as exc:
        raise SumoError(str(exc)) from None
    mod = api
    base = ["-c", str(sumocfg), *inputs.args("expansion"), "--seed", str(int(seed)),
            "--begin", f"{begin_s:.10g}", "--step-length", f"{step_length:.10g}",
            "--no-step-log", "true",
            "--tripinfo-output", str(Path(work_dir) / "expansion.tripinfo.xml")]
    # no child-process preflight: the network was checked above (what crashes libsumo) and
    # prepare_inputs parsed every other file; SUMO's own refusals arrive as TraCIException
    seen: dict[str, list] = {}  # id -> [requested depart, type, route, order]
    with _session(mod, errors, ["sumo", *base, "--no-warnings", "true", "--end", f"{end_s:.10g}"],
                  f"SUMO failed expanding the demand of {sumocfg}"):
        veh, sim = mod.vehicle, mod.simulation
        while sim.getTime() < end_s - 1e-9:
            mod.simulationStep()
            now = sim.getTime()
            departed = list(sim.getDepartedIDList())
            now_departed = set(departed)
            for v in sim.getLoadedIDList():  # loaded (possibly ahead of time): requested = now - delay
                if v not in now_departed:
                    seen[v] = [round(now - veh.getDepartDelay(v), 6), veh.getTypeID(v), tuple(veh.getRoute(v)),
                               len(seen)]
            for v in departed:  # the route as SUMO routed it (trips), where and how fast SUMO inserted
                # it on the empty network (its departPos / departSpeed resolved: draws, keywords, vType
                # defaults), then out of the network
                seen[v] = [round(veh.getDeparture(v) - veh.getDepartDelay(v), 6), veh.getTypeID(v),
                           tuple(veh.getRoute(v)), seen[v][3] if v in seen else len(seen),
                           float(veh.getLanePosition(v)), float(veh.getSpeed(v)), _stops_of(veh, v)]
                veh.remove(v, _REMOVE_VAPORIZED)
        vt = mod.vehicletype
        types = {}
        for tid in sorted({r[1] for r in seen.values()}):
            vclass = vt.getVehicleClass(tid)
            vmax = float(vt.getMaxSpeed(tid))
            if vclass == "bicycle":
                vmax = min(vmax, BICYCLE_DESIRED_MAX_SPEED)
            types[tid] = VehicleType(tid, vclass, float(vt.getLength(tid)), float(vt.getWidth(tid)), "",
                                     accel=float(vt.getAccel(tid)), decel=float(vt.getDecel(tid)),
                                     max_speed=vmax)
    lanes = depart_lanes([*inputs.expansion_routes, *inputs.expansion_additional])
    vehicles = []
    for vid, (dep, tid, edges, order, *how) in sorted(seen.items(), key=lambda kv: (kv[1][0], kv[1][3])):
        if not (begin_s - 1e-9 <= dep < end_s - 1e-9):
            continue
        t = types[tid]
        pos, speed, stops = how if how else (None, None, ())  # not inserted in the window: SUMO's defaults
        lane, rule = depart_lane_of(lanes.get(("vehicle", vid)) or lanes.get(("flow", vid.rsplit(".", 1)[0])))
        vehicles.append(PlannedVehicle(vid, tid, float(dep), edges, lane, pos, t.vclass, t.length, t.width,
                                       speed, stops, rule))
    return Demand(tuple(vehicles), types, tuple(Path(p) for p in inputs.expansion_routes))


def preflight(home: Path, args: list[str], what: str) -> None:
    """Load ``args`` in a child ``sumo`` first (libsumo crashes the process on some inputs): a
    :class:`SumoError` with SUMO's own message (or the signal it died of) when it fails."""
    exe = home / "bin" / "sumo"
    exe = exe if exe.is_file() else Path(shutil.which("sumo") or "sumo")
    try:
        proc = subprocess.run([str(exe), *args, "--no-warnings", "true"], capture_output=True, text=True,
                              timeout=300, env={**os.environ, "SUMO_HOME": str(home)})
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise SumoError(f"{what}: could not run the sumo check: {exc}") from None
    if proc.returncode != 0:
        msg = (proc.stderr.strip() or proc.stdout.strip())[-3000:]
        if proc.returncode < 0:
            msg = f"SUMO crashed (signal {-proc.returncode}) while loading its inputs. {msg}".strip()
        raise SumoError(f"{what} failed to start: {msg or f'exit code {proc.returncode}'}")
