"""The only code that talks to SUMO at run time (libsumo by default, traci optional).

Who inserts vehicles.  muvsim's traffic manager admits a vehicle only when
its initial tube is free (design.md 3f); until then the vehicle must not
exist in SUMO, where it would be a physical obstacle that SUMO judges for
collisions.  SUMO cannot be told to hold a vehicle of a route file back, and
its own insertion would happen on its own terms.  So SUMO is started with the
vTypes of the route files only, and muvsim inserts each vehicle itself at
admission (:meth:`SumoAdapter.admit`): ``route.add`` + ``vehicle.add`` (depart
"now", speed 0) + speed mode 0 and lane-change mode 0 + ``moveToXY``.  A
vehicle moved by ``moveToXY`` before its first step is inserted at that
position unconditionally (SUMO's insertion checks for gaps are bypassed), so
an admission is never refused or delayed by SUMO; :meth:`SumoAdapter.step`
checks that every vehicle admitted before it was inserted and raises
otherwise.  Waiting vehicles live only in muvsim
(:class:`~bridge.demand.DepartureQueue`), so a departure delay can never drop
a vehicle.  The delay itself is muvsim's to measure: SUMO's tripinfo counts
``depart`` from admission (``departDelay`` 0).

For a user's ``.sumocfg`` the demand is SUMO's own: :meth:`SumoAdapter.expand_demand`
runs the configuration once over the run's window with an always-empty network
(each vehicle removed as SUMO inserts it) and records ids, vTypes, routes and
requested departures; :meth:`SumoAdapter.start` then gets that demand and the
configuration's demand-free inputs (:mod:`bridge.sumo_inputs`).

SUMO options always set: ``--step-length`` (0.1 s), ``--collision.action
warn --collision.check-junctions true --collision.mingap-factor 0`` (with the
default action, teleport, moved vehicles report nothing), ``--no-step-log``,
``--time-to-teleport -1`` (a vehicle stopped by the traffic manager for
minutes must not be teleported away), and
``--emergencydecel.warning-threshold`` high: the speeds SUMO infers from
positions we set are not its drivers' decisions, its braking warnings would
be noise.

Positions.  SUMO places a vehicle by its FRONT BUMPER with an angle in
degrees clockwise from north; see :mod:`bridge.pose` for conversions.
:meth:`SumoAdapter.move` uses ``keepRoute=3``: SUMO keeps the exact position
(with ``keepRoute=1`` and no sublane model it snaps the front onto the centre
line of its lane: measured up to 1.3 m on junction curves).  SUMO's body is
NOT a rigid rectangle at the pushed angle: see :mod:`bridge.sumo_body`.

A co-simulation loop, in outline::

    with SumoAdapter() as sim:
        demand = sim.start(files.sumocfg, tripinfo_path=out / "tripinfo.xml", seed=seed)
        queue, net = DepartureQueue(demand), load_net(files.net)
        waiting = []
        while sim.sim_time() < duration:
            waiting += queue.release(sim.sim_time())
            for v in admitted_by_the_tm(waiting):           # tubes free (design.md 3f)
                r = net.route(v.edges, delta, vclass=v.vclass, vehicle_id=v.id)
                sim.admit(v, front_bumper(r.waypoints[0], r.heading[0], v.length),
                          sumo_angle(r.heading[0]), depart_lane=r.depart_lane_index)
            ... controllers, TM, plant step ...
            sim.move(ids, front_bumper(centres, headings, lengths), sumo_angle(headings))
            for vid in done: sim.finish(vid)
            sim.step()
            judged = sim.collisions()                       # must stay empty

Failures.  Every error SUMO raises (``TraCIException``,
``FatalTraCIError``) becomes :class:`SumoError` with SUMO's message.  libsumo
crashes the whole process on some malformed inputs (a broken network XML
segfaults it), so :meth:`SumoAdapter.start` first checks that the inputs are
well-formed XML and runs the same command once in a child ``sumo`` process
(``preflight``, ~0.2 s) to get SUMO's own error message before loading
anything in-process.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from bridge.demand import Demand, DemandError, PlannedVehicle, needs_routing, read_demand
from bridge.sumo_inputs import PreparedInputs
from bridge.sumo_runs import (SumoError, check_xml, expand_demand, preflight as check_command, run_native,
                              sumo_home)

__all__ = ["SumoError", "CollisionEvent", "VehicleInfo", "SumoAdapter"]

BACKENDS = ("libsumo", "traci")
_REMOVE_ARRIVED = 2  # libsumo/traci constants.REMOVE_ARRIVED
#: ``moveToXY``'s keepRoute: bit 0, map onto the vehicle's route; bit 1, keep the exact position,
#: lateral offset included (SUMO's documented semantics; measured on 1.28: getPosition returns the
#: pushed point to round-off).  With 1 alone SUMO puts the front on the lane's centre line.
KEEP_ROUTE = 3

@dataclass(frozen=True)
class CollisionEvent:
    """A collision SUMO reported, once per contact (not once per step while it lasts).

    Attributes
    ----------
    time_s : float
        Simulation time of the step in which it began.
    pair : tuple of str
        The two vehicle ids, sorted.
    collider, victim : str
        SUMO's roles.
    kind : str
        SUMO's collision type (``collision``, ``frontal``, ``junction``, ...).
    lane : str
        Lane of the collision.
    pos : float
        Position on that lane (m).
    """

    time_s: float
    pair: tuple[str, str]
    collider: str
    victim: str
    kind: str
    lane: str
    pos: float


@dataclass(frozen=True)
class VehicleInfo:
    """What SUMO says about a vehicle in the network."""

    id: str
    type_id: str
    vclass: str
    length: float
    width: float
    edges: tuple[str, ...]


def backend_api(backend: str) -> tuple[object, tuple[type[BaseException], ...]]:
    """The libsumo module, or traci (its connection-based twin), and the exceptions it raises for
    SUMO's errors: this module is the only one that imports them (tests/test_layering.py)."""
    if backend == "libsumo":
        import libsumo

        return libsumo, (libsumo.TraCIException, libsumo.FatalTraCIError)
    import traci

    return traci, (traci.exceptions.TraCIException, traci.exceptions.FatalTraCIError, ConnectionError, OSError)


def _inputs(sumocfg, net, routes) -> tuple[Path | None, Path, list[Path], list[Path]]:
    """``(configuration, network, route files, additional files)`` of :meth:`SumoAdapter.start`'s
    arguments: a ``.sumocfg``'s own (``routes`` replacing its route files), or a network and route
    files; a :class:`SumoError` for an unreadable configuration or neither given."""
    from sumo_nets.scenario import ScenarioError, read_sumocfg

    listed = (lambda r: [] if r is None else [Path(r)] if isinstance(r, (str, os.PathLike))  # noqa: E731
              else [Path(x) for x in r])
    if sumocfg is not None:
        try:
            cfg = read_sumocfg(sumocfg)
        except ScenarioError as exc:
            raise SumoError(str(exc)) from None
        return cfg.path, cfg.net, list(cfg.routes) if routes is None else listed(routes), list(cfg.additional)
    if net is None:
        raise SumoError("start: give a sumocfg or a net (and route files)")
    return None, Path(net).resolve(), listed(routes), []


class SumoAdapter:
    """One SUMO simulation, driven step by step.

    Parameters
    ----------
    backend : {"libsumo", "traci"}
        libsumo runs SUMO in this process (fast; ONE simulation per process);
        traci talks to a ``sumo`` child process over a socket (~10x slower per
        call, any number per process).

    Examples
    --------
    >>> with SumoAdapter() as sim:                       # doctest: +SKIP
    ...     demand = sim.start("run.sumocfg", tripinfo_path="tripinfo.xml")
    ...     sim.admit(vehicle, front_xy, angle_deg)
    ...     sim.step()
    """

    def __init__(self, backend: str = "libsumo") -> None:
        if backend not in BACKENDS:
            raise ValueError(f"backend: must be one of {', '.join(BACKENDS)}, got {backend!r}")
        self.backend = backend
        self._api = None  # libsumo module or a traci connection
        self._exc: tuple[type[BaseException], ...] = ()
        self._label = f"muvsim-{id(self)}"
        self._tmp: Path | None = None
        self.demand: Demand | None = None
        self.command: list[str] = []
        self._reset_run_state()

    def _reset_run_state(self) -> None:
        self._departed: tuple[str, ...] = ()
        self._arrived: tuple[str, ...] = ()
        self._admitted: set[str] = set()  # admitted since the last step: must depart in the next one
        self._finished: list[str] = []  # finished since the last step
        self._routes: set[str] = set()
        self._active_pairs: set[tuple[str, str]] = set()
        self._new_collisions: list[CollisionEvent] = []
        self._collision_count = 0

    # ------------------------------------------------------------------ lifecycle
    @property
    def running(self) -> bool:
        """Whether a simulation is open."""
        return self._api is not None

    def run_native(self, sumocfg: str | os.PathLike, **kw) -> dict:
        """:func:`bridge.sumo_runs.run_native` with this adapter's backend (``--baseline sumo``)."""
        return run_native(*backend_api(self.backend), sumocfg, **kw)

    def expand_demand(self, sumocfg: str | os.PathLike, inputs: PreparedInputs, **kw) -> Demand:
        """:func:`bridge.sumo_runs.expand_demand` with this adapter's backend."""
        return expand_demand(*backend_api(self.backend), sumocfg, inputs, **kw)

    def start(self, sumocfg: str | os.PathLike | None = None, *, net: str | os.PathLike | None = None,
              routes: str | os.PathLike | Sequence[str | os.PathLike] | None = None, step_length: float = 0.1,
              seed: int | None = None, gui: bool = False, tripinfo_path: str | os.PathLike | None = None,
              extra_args: Iterable[str] = (), lateral_resolution: float | None = None,
              work_dir: str | os.PathLike | None = None, preflight: bool = True,
              demand: Demand | None = None, inputs: PreparedInputs | None = None) -> Demand:
        """Start SUMO with a configuration, or a network and route files.

        The vehicles of the route files are NOT given to SUMO (see the module
        notes): they are returned as a :class:`~bridge.demand.Demand` for
        muvsim to admit.

        Parameters
        ----------
        sumocfg : path, optional
            A ``.sumocfg``; its net-file and route-files are used (its other
            settings too, except route-files and those set here).
        net : path, optional
            Network, when no ``sumocfg`` is given.
        routes : path or sequence of paths, optional
            Route files with the demand (vTypes and vehicles with routes;
            trips and flows are routed by ``duarouter`` first).  With a
            ``sumocfg`` they replace its route-files.
        step_length : float
            Seconds per step.
        seed : int, optional
            SUMO's random seed.
        gui : bool
            Use ``sumo-gui``; needs a display (``$DISPLAY``).
        tripinfo_path : path, optional
            Where SUMO writes its tripinfo output.
        extra_args : iterable of str
            More SUMO options, appended last.
        lateral_resolution : float, optional
            Enable SUMO's sublane model (m); see the module notes.
        work_dir : path, optional
            Where the vTypes-only route file is written (default: a temporary
            directory removed by :meth:`close`).
        preflight : bool
            Check the command in a child ``sumo`` first (see the module notes).
        demand, inputs : Demand and PreparedInputs, optional
            A demand already expanded by :meth:`expand_demand` and the filtered inputs it
            came from: SUMO is started with ``inputs``' demand-free files (vTypes, routes,
            distributions, persons, signals kept) instead of reading the route files here.

        Returns
        -------
        Demand
            The vehicles to admit, by planned departure.

        Raises
        ------
        SumoError
            Bad inputs, no display for the GUI, SUMO's refusal to start (with
            its message), or libsumo already running a simulation here.
        """
        if self.running:
            raise SumoError("this SumoAdapter already runs a simulation; close() it first")
        if gui and not os.environ.get("DISPLAY"):
            raise SumoError("gui=True needs a display but $DISPLAY is not set: run under a display "
                            "(e.g. xvfb-run) or without the GUI")
        if not (step_length > 0):
            raise SumoError(f"step_length: must be > 0 s, got {step_length!r}")
        cfg_path, net_path, route_paths, additional = _inputs(sumocfg, net, routes)
        check_xml("network", Path(net_path))
        for r in (route_paths if demand is None else []):  # an expanded demand was read by SUMO
            check_xml("route file", Path(r))
        if work_dir is None:
            self._tmp = Path(tempfile.mkdtemp(prefix="muvsim-sumo-"))
            wd = self._tmp
        else:
            wd = Path(work_dir)
            wd.mkdir(parents=True, exist_ok=True)
        try:
            if demand is not None:
                pass
            elif route_paths and needs_routing(route_paths):
                from sumo_nets.generate import route_demand
                from sumo_nets.sumo_tools import SumoToolError

                try:
                    route_paths = [route_demand(net_path, route_paths, wd / "routed", additional=additional)]
                except SumoToolError as exc:
                    raise SumoError(f"cannot route the trips/flows of the demand: {exc}") from None
            if demand is None:
                demand = read_demand(route_paths, type_files=additional)
        except DemandError as exc:
            self._cleanup_tmp()
            raise SumoError(f"cannot read the demand: {exc}") from None
        except SumoError:
            self._cleanup_tmp()
            raise
        vtypes = wd / "vtypes.rou.xml"
        vtypes.write_text(demand.vtypes_xml(), encoding="utf-8")

        from sumo_nets.sumo_tools import SumoToolError

        try:
            home = sumo_home()
        except SumoToolError as exc:
            self._cleanup_tmp()
            raise SumoError(str(exc)) from None
        exe = home / "bin" / ("sumo-gui" if gui else "sumo")
        if not exe.is_file():  # else on PATH
            exe = Path(shutil.which(exe.name) or "")
            if not exe.name:
                self._cleanup_tmp()
                raise SumoError(f"SUMO executable {'sumo-gui' if gui else 'sumo'!r} not found in {home / 'bin'} "
                                "nor on PATH")
        files = inputs.args("no_demand") if inputs is not None else ["--route-files", str(vtypes)]
        args = (["-c", str(cfg_path)] if cfg_path is not None else ["-n", str(net_path)]) + files + [
            "--step-length", f"{step_length:.10g}",
            "--collision.action", "warn",
            "--collision.check-junctions", "true",
            "--collision.mingap-factor", "0",
            "--no-step-log", "true",
            "--time-to-teleport", "-1",
            "--emergencydecel.warning-threshold", "1e9",
        ]
        if seed is not None:
            args += ["--seed", str(int(seed))]
        if lateral_resolution is not None:
            args += ["--lateral-resolution", f"{float(lateral_resolution):.10g}"]
        if gui:
            args += ["--start", "true", "--quit-on-end", "true"]
        extra = [str(a) for a in extra_args]
        what = f"SUMO ({'configuration ' + str(cfg_path) if cfg_path else 'network ' + str(net_path)})"
        if preflight:
            try:
                check_command(home, args + extra, what)
            except SumoError:
                self._cleanup_tmp()
                raise
        out_args = ["--tripinfo-output", str(Path(tripinfo_path).resolve())] if tripinfo_path is not None else []
        self.command = [str(exe), *args, *out_args, *extra]

        mod, errors = backend_api(self.backend)
        if self.backend == "libsumo":
            try:  # a running in-process simulation answers; a fresh libsumo raises
                mod.simulation.getTime()
                busy = True
            except errors:
                busy = False
            if busy:
                self._cleanup_tmp()
                raise SumoError("libsumo already runs a simulation in this process (one per process): close it "
                                "first, or use backend='traci'")
        try:
            if self.backend == "libsumo":
                mod.start(self.command)
                self._api = mod
            else:
                mod.start(self.command, label=self._label)
                self._api = mod.getConnection(self._label)
        except errors as exc:
            self._api = None
            self._cleanup_tmp()
            raise SumoError(f"{what} failed to start: {exc}") from None
        self._exc = errors
        self._reset_run_state()
        self.demand = demand
        return demand

    def close(self) -> None:
        """Close the simulation (flushing SUMO's outputs); safe to call twice or after a failure."""
        api, self._api = self._api, None
        if api is not None:
            try:
                api.close()
            except Exception:  # a dead simulation cannot be closed more; outputs are what they are
                pass
        self._cleanup_tmp()

    def _cleanup_tmp(self) -> None:
        if self._tmp is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None

    def __enter__(self) -> "SumoAdapter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ calls
    def _need(self, what: str):
        if self._api is None:
            raise SumoError(f"{what}: no simulation is running (start() first)")
        return self._api

    def _call(self, what: str, fn, *args):
        try:
            return fn(*args)
        except self._exc as exc:
            raise SumoError(f"SUMO failed in {what}: {exc}") from None

    def sim_time(self) -> float:
        """Current simulation time (s)."""
        api = self._need("sim_time")
        return float(self._call("simulation.getTime", api.simulation.getTime))

    def step(self) -> None:
        """Advance one step; collect departures, arrivals and collisions.

        Raises
        ------
        SumoError
            SUMO failed, or a vehicle admitted before this step was not inserted.
        """
        api = self._need("step")
        self._call("simulationStep", api.simulationStep)
        sim = api.simulation
        self._departed = tuple(self._call("simulation.getDepartedIDList", sim.getDepartedIDList))
        finished, self._finished = self._finished, []
        during = self._call("simulation.getArrivedIDList", sim.getArrivedIDList)
        seen = set(finished)
        self._arrived = tuple(finished) + tuple(a for a in during if a not in seen)
        if self._admitted:
            missing = self._admitted.difference(self._departed)
            self._admitted = set()
            if missing:
                raise SumoError(f"SUMO did not insert admitted vehicle(s) {sorted(missing)} "
                                f"at t={self.sim_time():g}")
        cols = self._call("simulation.getCollisions", sim.getCollisions)
        if not cols and not self._active_pairs:
            return
        now = self.sim_time()
        active: set[tuple[str, str]] = set()
        for c in cols:
            pair = tuple(sorted((c.collider, c.victim)))
            if pair in active:
                continue
            active.add(pair)
            if pair not in self._active_pairs:
                self._new_collisions.append(CollisionEvent(now, pair, c.collider, c.victim, c.type, c.lane,
                                                           float(c.pos)))
                self._collision_count += 1
        self._active_pairs = active

    def tls_states(self, tls_ids: Sequence[str]) -> list[str]:
        """SUMO's current signal state string of each traffic light (one letter per link,
        ``trafficlight.getRedYellowGreenState``: one call per light)."""
        tl = self._need("tls_states").trafficlight
        return [self._call(f"trafficlight.getRedYellowGreenState({t!r})", tl.getRedYellowGreenState, t)
                for t in tls_ids]

    def tls_schedule(self, tls_ids: Sequence[str]) -> list[tuple[str, int, float]]:
        """Per traffic light ``(programID, phase index, remaining s)``: ``trafficlight.getProgram``,
        ``getPhase`` and ``getNextSwitch`` less ``simulation.getTime`` (SUMO's documented way to the
        remaining duration of the current phase)."""
        api = self._need("tls_schedule")
        tl = api.trafficlight
        now = float(self._call("simulation.getTime", api.simulation.getTime))
        return [(str(self._call(f"trafficlight.getProgram({t!r})", tl.getProgram, t)),
                 int(self._call(f"trafficlight.getPhase({t!r})", tl.getPhase, t)),
                 float(self._call(f"trafficlight.getNextSwitch({t!r})", tl.getNextSwitch, t)) - now)
                for t in tls_ids]

    def tls_programs(self, tls: str) -> dict[str, list[tuple[str, float, tuple[int, ...]]]]:
        """A traffic light's programs (``trafficlight.getAllProgramLogics``): programID -> its phases
        as ``(state, minDur s, next phase indices)``."""
        tl = self._need("tls_programs").trafficlight
        logics = self._call(f"trafficlight.getAllProgramLogics({tls!r})", tl.getAllProgramLogics, tls)
        return {str(lg.programID): [(str(ph.state), float(ph.minDur), tuple(int(n) for n in ph.next))
                                    for ph in lg.phases] for lg in logics}

    def departed_ids(self) -> tuple[str, ...]:
        """Vehicles SUMO inserted in the last step (the ones admitted before it)."""
        return self._departed

    def arrived_ids(self) -> tuple[str, ...]:
        """Vehicles that left the network with the last step: finished (removed) ones, then SUMO's own."""
        return self._arrived

    def vehicle_ids(self) -> tuple[str, ...]:
        """Vehicles in the network now."""
        api = self._need("vehicle_ids")
        return tuple(self._call("vehicle.getIDList", api.vehicle.getIDList))

    def collisions(self) -> list[CollisionEvent]:
        """NEW collisions since the last call: one event per contact of an unordered pair.

        SUMO repeats a collision every step while the bodies overlap; a pair
        is reported again only after it was free for at least one step.
        Collisions are collected by :meth:`step`, so none is lost when this
        is called less often.
        """
        out, self._new_collisions = self._new_collisions, []
        return out

    @property
    def collision_count(self) -> int:
        """All collision events of the run so far."""
        return self._collision_count

    # ------------------------------------------------------------------ vehicles
    def admit(self, vehicle: PlannedVehicle, xy_front: Sequence[float], angle_deg: float, *,
              depart_lane: int | None = None, hint_edge: str = "", hint_lane: int = -1) -> None:
        """Insert a vehicle now at a pose; SUMO places it there at the next :meth:`step`.

        Parameters
        ----------
        vehicle : PlannedVehicle
            From the demand returned by :meth:`start`.
        xy_front : (2,) float
            Front-bumper position (m).
        angle_deg : float
            SUMO angle (deg, clockwise from north).
        depart_lane : int, optional
            Lane index on the first edge (e.g. ``RouteWaypoints.depart_lane_index``);
            default the vehicle's own, else the first lane.
        hint_edge, hint_lane : str and int, optional
            The lane the front is on (edge id, index), as :meth:`move`'s mapping hint.
        """
        api = self._need("admit")
        vid = vehicle.id
        rid = f"{vid}!route"
        if rid not in self._routes:
            self._call(f"route.add({rid!r})", api.route.add, rid, list(vehicle.edges))
            self._routes.add(rid)
        lane = depart_lane if depart_lane is not None else vehicle.depart_lane
        try:
            api.vehicle.add(vid, rid, typeID=vehicle.type_id, depart="now",
                            departLane=str(lane) if lane is not None else "first", departSpeed="0")
        except self._exc as exc:
            raise SumoError(f"SUMO refused to add vehicle {vid!r} (type {vehicle.type_id!r}, route "
                            f"[{' '.join(vehicle.edges)}]): {exc}") from None
        x, y = (float(v) for v in xy_front)
        try:
            self.take_over(vid)
            # keepRoute=1 first: SUMO refuses a pose farther than 100 m from the route (keepRoute=3
            # alone would place it off every lane, unjudged); then the exact position
            self._call(f"vehicle.moveToXY({vid!r})", api.vehicle.moveToXY, vid, hint_edge, int(hint_lane), x, y,
                       float(angle_deg), 1)
            self._call(f"vehicle.moveToXY({vid!r})", api.vehicle.moveToXY, vid, hint_edge, int(hint_lane), x, y,
                       float(angle_deg), KEEP_ROUTE)
        except SumoError as exc:  # all or nothing: SUMO must not insert it on its own terms
            try:
                api.vehicle.remove(vid, 3)  # REMOVE_VAPORIZED: never departed
            except self._exc:
                pass
            raise SumoError(f"cannot admit vehicle {vid!r} at ({x:.2f}, {y:.2f}): {exc}") from None
        self._admitted.add(vid)

    def take_over(self, vid: str) -> None:
        """Disable SUMO's own driving of ``vid``: speed mode 0, lane-change mode 0."""
        v = self._need("take_over").vehicle
        self._call(f"vehicle.setSpeedMode({vid!r})", v.setSpeedMode, vid, 0)
        self._call(f"vehicle.setLaneChangeMode({vid!r})", v.setLaneChangeMode, vid, 0)

    def move(self, ids: Sequence[str], xy_front, angle_deg, edges: Sequence[str] | None = None,
             lanes: Sequence[int] | None = None) -> None:
        """Place vehicles for the next step: ``moveToXY(v, edge, lane, x, y, angle, keepRoute=3)``
        (:data:`KEEP_ROUTE`: on a lane of the vehicle's route, at the exact position).

        Parameters
        ----------
        ids : sequence of str, length V
        xy_front : array (V, 2)
            Front-bumper positions (m).
        angle_deg : array (V,)
            SUMO angles (deg; SUMO only draws with them).
        edges, lanes : sequences of str and int, length V, optional
            The lane each front is on (its edge id and index): SUMO's hint where lanes overlap
            (junctions); default none (``""``, ``-1``).
        """
        mv = self._need("move").vehicle.moveToXY
        xy = np.asarray(xy_front, dtype=float).reshape(-1, 2).tolist()
        ang = np.asarray(angle_deg, dtype=float).reshape(-1).tolist()
        if not (len(ids) == len(xy) == len(ang)):
            raise ValueError(f"move: {len(ids)} ids, {len(xy)} positions and {len(ang)} angles")
        edges = [""] * len(ids) if edges is None else list(edges)
        lanes = [-1] * len(ids) if lanes is None else [int(v) for v in lanes]
        vid = None
        try:
            for vid, (x, y), a, e, ln in zip(ids, xy, ang, edges, lanes):
                mv(vid, e, ln, x, y, a, KEEP_ROUTE)
        except self._exc as exc:
            raise SumoError(f"SUMO failed to move vehicle {vid!r}: {exc}") from None

    def hold(self, ids: Sequence[str]) -> None:
        """Keep vehicles where they are without moving them each step: ``setSpeed(v, 0)``.

        A vehicle that gets no ``moveToXY`` in a step is driven by SUMO itself (speed mode 0
        ignores safe speeds, not the driver's wish to accelerate); at speed 0 it stays put
        (measured: 0.0 m drift over 66,266 held vehicle-steps on ``grid``).  Undone by
        :meth:`release`."""
        v = self._need("hold").vehicle
        vid = None
        try:
            for vid in ids:
                v.setSpeed(vid, 0.0)
        except self._exc as exc:
            raise SumoError(f"SUMO failed to hold vehicle {vid!r}: {exc}") from None

    def release(self, ids: Sequence[str]) -> None:
        """Undo :meth:`hold` (``setSpeed(v, -1)``) before vehicles are moved again."""
        v = self._need("release").vehicle
        vid = None
        try:
            for vid in ids:
                v.setSpeed(vid, -1.0)
        except self._exc as exc:
            raise SumoError(f"SUMO failed to release vehicle {vid!r}: {exc}") from None

    def speeds(self, ids: Sequence[str]) -> np.ndarray:
        """SUMO's speeds (m/s) of vehicles."""
        v = self._need("speeds").vehicle
        return np.array([self._call("vehicle.getSpeed", v.getSpeed, i) for i in ids], dtype=float)

    def finish(self, vid: str) -> None:
        """The vehicle reached the end of its route: remove it as ARRIVED (tripinfo records the arrival)."""
        v = self._need("finish").vehicle
        self._call(f"vehicle.remove({vid!r})", v.remove, vid, _REMOVE_ARRIVED)
        self._finished.append(vid)

    def positions(self, ids: Sequence[str]) -> np.ndarray:
        """SUMO's front-bumper positions (V, 2) of vehicles."""
        v = self._need("positions").vehicle
        return np.array([self._call("vehicle.getPosition", v.getPosition, i) for i in ids],
                        dtype=float).reshape(-1, 2)

    def lane_ids(self, ids: Sequence[str]) -> list[str]:
        """SUMO's lane of each vehicle (``""``: placed off every lane, where SUMO judges nothing)."""
        v = self._need("lane_ids").vehicle
        return [self._call("vehicle.getLaneID", v.getLaneID, i) for i in ids]

    def pose(self, ids: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
        """SUMO's front-bumper positions (V, 2) and angles (V,) of vehicles."""
        v = self._need("pose").vehicle
        xy = np.array([self._call("vehicle.getPosition", v.getPosition, i) for i in ids],
                      dtype=float).reshape(-1, 2)
        ang = np.array([self._call("vehicle.getAngle", v.getAngle, i) for i in ids], dtype=float)
        return xy, ang

    def vehicle_info(self, vid: str) -> VehicleInfo:
        """Type, vClass, footprint and route of a vehicle in the network, as SUMO has them."""
        v = self._need("vehicle_info").vehicle
        c = self._call
        return VehicleInfo(vid, c("vehicle.getTypeID", v.getTypeID, vid),
                           c("vehicle.getVehicleClass", v.getVehicleClass, vid),
                           float(c("vehicle.getLength", v.getLength, vid)),
                           float(c("vehicle.getWidth", v.getWidth, vid)),
                           tuple(c("vehicle.getRoute", v.getRoute, vid)))
