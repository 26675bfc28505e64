"""The demand muvsim inserts itself: vehicles and vTypes read from SUMO route files.

muvsim, not SUMO, decides when a vehicle enters the network (the traffic
manager admits it once its initial tube is free, design.md 3f), so SUMO is
never given the vehicles of a route file: :class:`~bridge.sumo_adapter.SumoAdapter`
starts SUMO with the vTypes only (:meth:`Demand.vtypes_xml`) and adds each
vehicle at admission.  This module reads route files into that plan:

* ``<vType>``: id, vClass, length and width (SUMO's default for the vClass
  where not given); the element itself is kept and handed to SUMO verbatim;
* ``<route id=... edges=...>`` at top level, referenced by ``route="..."``;
* ``<vehicle>`` with ``depart`` (seconds), ``type``, and either
  ``route="id"`` or a nested ``<route edges=...>``; ``departLane`` as a lane
  index or one of SUMO's keywords (``best``, ``free``, ...: :class:`bridge.departure.DepartLanes`
  picks the lane as SUMO would); ``departPos`` in
  metres (SUMO's front position on the first lane, negative: from its end) and
  ``departSpeed`` in m/s, or ``max``, ``desired``, ``speedLimit`` (as fast as the
  class and the lane allow there: ``inf`` on the plan).  The other keywords
  (``departPos`` ``random``, ``free``, ``random_free``, ``last``, ``stop``,
  ``splitFront``; ``departSpeed`` ``random``, ``avg``, ``last``) depend on SUMO's
  draws or traffic: read from a route file they start the vehicle as SUMO's
  defaults do (back at the start of the lane, at rest); a ``.sumocfg`` run takes
  SUMO's own resolution of every form (:func:`bridge.sumo_runs.expand_demand`).
  :mod:`bridge.departure` turns them into the starts admission tries.

``<trip>``, ``<flow>``, persons and distributions are refused with a clear
error: route them into vehicles first (:func:`needs_routing` tells;
:func:`sumo_nets.generate.route_demand` runs ``duarouter``, which routes trips
and expands flows; :class:`~bridge.sumo_adapter.SumoAdapter` does so itself).
vTypes defined in additional files (``type_files``) are known but not handed
to SUMO again (SUMO loads those files itself).
"""

from __future__ import annotations

import bisect
import math
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Mapping, Sequence

__all__ = ["DemandError", "VehicleType", "PlannedVehicle", "VehicleStop", "Demand", "DepartureQueue", "read_demand", "demand_from",
           "needs_routing",
           "VCLASS_DEFAULTS"]

#: SUMO's default (length, width) per vClass (m), for vTypes that do not set them.
VCLASS_DEFAULTS: Mapping[str, tuple[float, float]] = {
    "passenger": (5.0, 1.8), "private": (5.0, 1.8), "taxi": (5.0, 1.8), "evehicle": (5.0, 1.8),
    "bus": (12.0, 2.5), "coach": (14.0, 2.6), "truck": (7.1, 2.4), "trailer": (16.5, 2.55),
    "delivery": (6.5, 2.16), "emergency": (6.5, 2.16), "authority": (5.0, 1.8), "army": (5.0, 1.8),
    "motorcycle": (2.2, 0.9), "moped": (2.1, 0.8), "bicycle": (1.6, 0.65), "custom1": (5.0, 1.8),
    "custom2": (5.0, 1.8),
}
_DEFAULT_VTYPE = "DEFAULT_VEHTYPE"
_REFUSED = {"trip": "a <trip> (origin/destination only)", "flow": "a <flow>", "person": "a <person>",
            "personFlow": "a <personFlow>", "container": "a <container>", "containerFlow": "a <containerFlow>",
            "routeDistribution": "a <routeDistribution>", "vTypeDistribution": "a <vTypeDistribution>"}


class DemandError(ValueError):
    """A route file muvsim cannot use; the message names the file, the element and why."""


@dataclass(frozen=True)
class VehicleType:
    """A SUMO vType.

    Parameters
    ----------
    id : str
    vclass : str
    length, width : float
        Footprint (m).
    xml : str
        The ``<vType>`` element as read (empty for SUMO's default type).
    accel, decel, max_speed : float, optional
        m/s^2, m/s^2, m/s as SUMO has them (set when SUMO itself read the vType,
        :meth:`bridge.sumo_adapter.SumoAdapter.expand_demand`).
    """

    id: str
    vclass: str
    length: float
    width: float
    xml: str = ""
    accel: float | None = None
    decel: float | None = None
    max_speed: float | None = None


@dataclass(frozen=True)
class PlannedVehicle:
    """A vehicle of the demand, before SUMO knows it.

    Parameters
    ----------
    id : str
    type_id : str
        vType id.
    depart_s : float
        Planned departure (s).
    edges : tuple of str
        Its route.
    depart_lane : int or None
        Lane index to start on; None lets the route choose.
    depart_pos_m : float or None
        SUMO's ``departPos``: the front's position along the first lane (m; negative: from
        its end); None: SUMO's ``base`` (the back at the lane's start).
    vclass : str
    length, width : float
        Footprint (m), from its vType.
    depart_speed_mps : float or None
        SUMO's ``departSpeed`` (m/s; ``inf``: as fast as allowed there); None or 0: at rest.
    stops : tuple of VehicleStop
        Its ``<stop>`` elements, in route order (:class:`VehicleStop`).
    """

    id: str
    type_id: str
    depart_s: float
    edges: tuple[str, ...]
    depart_lane: int | None
    depart_pos_m: float | None
    vclass: str
    length: float
    width: float
    depart_speed_mps: float | None = None
    stops: tuple["VehicleStop", ...] = ()
    #: a ``departLane`` keyword (``free``, ``best``, ``random``, ...; :data:`DEPART_LANE_WORDS`),
    #: resolved at set-up by :class:`bridge.departure.DepartLanes`; None: a number (``depart_lane``) or none
    depart_lane_rule: str | None = None


#: SUMO's ``departLane`` keywords
DEPART_LANE_WORDS = ("random", "free", "allowed", "best", "first", "random_free")


def depart_lane_of(raw: str | None) -> tuple[int | None, str | None]:
    """``(lane, rule)`` of a ``departLane`` value: a lane index, or one of :data:`DEPART_LANE_WORDS`;
    ``(None, None)`` for none or anything else."""
    if raw is not None and raw.isdigit():
        return int(raw), None
    return None, raw if raw in DEPART_LANE_WORDS else None


@dataclass(frozen=True)
class VehicleStop:
    """A ``<stop>`` of a vehicle: where it halts and for how long (SUMO's semantics: the front at
    ``end_pos_m`` of ``lane``, at rest for ``duration_s``, and not before ``until_s``).

    Parameters
    ----------
    lane : str
        Lane id.
    end_pos_m : float or None
        The front's position on the lane (m; negative: from its end); None: the lane's end.
    duration_s : float
        Dwell once at rest (s, >= 0).
    until_s : float or None
        Earliest departure (simulation time, s); None: none.
    place : str
        What it stops at, for messages: a stopping place's id (``busStop`` ...) or the lane.
    """

    lane: str
    end_pos_m: float | None
    duration_s: float
    until_s: float | None
    place: str


#: stop attributes naming a stopping place (its lane and position are in an additional file)
STOPPING_PLACES = ("busStop", "trainStop", "containerStop", "chargingStation", "parkingArea", "overheadWireSegment")


def _stops(file: Path, vid: str, elems) -> tuple[VehicleStop, ...]:
    """The ``<stop>`` children ``elems`` of vehicle ``vid`` (route files read without SUMO: lane stops)."""
    out = []
    for e in elems:
        place = next((a for a in STOPPING_PLACES if e.get(a)), None)
        if place is not None:
            raise DemandError(f"{file}: vehicle {vid!r}: <stop {place}={e.get(place)!r}> needs the additional "
                              f"file that defines it: run the scenario from a .sumocfg (SUMO resolves its lane "
                              f"and position), or give the stop a lane= and endPos=")
        lane = e.get("lane")
        if not lane:
            raise DemandError(f"{file}: vehicle {vid!r}: <stop> needs a lane= (or a stopping place in a .sumocfg run)")
        end = _float(file, e, "endPos")
        dur = _float(file, e, "duration", 0.0)
        until = _float(file, e, "until")
        if dur is None or dur < 0 or not math.isfinite(dur):
            raise DemandError(f"{file}: vehicle {vid!r}: <stop lane={lane!r}> duration must be a time >= 0 s, "
                              f"got {e.get('duration')!r}")
        out.append(VehicleStop(lane, end, float(dur), until, lane))
    return tuple(out)


@dataclass(frozen=True, eq=False)
class Demand:
    """All vehicles (sorted by planned departure, then file order) and their vTypes."""

    vehicles: tuple[PlannedVehicle, ...]
    types: Mapping[str, VehicleType]
    files: tuple[Path, ...]

    def __len__(self) -> int:
        return len(self.vehicles)

    def by_id(self) -> dict[str, PlannedVehicle]:
        """Vehicles by id."""
        return {v.id: v for v in self.vehicles}

    def vtypes_xml(self) -> str:
        """A route file holding only the vTypes (what SUMO is started with)."""
        body = "\n".join("    " + t.xml for t in self.types.values() if t.xml)
        return f'<?xml version="1.0" encoding="UTF-8"?>\n<routes>\n{body}\n</routes>\n'


class DepartureQueue:
    """Hands out the vehicles of a demand as their planned departure comes.

    Parameters
    ----------
    demand : Demand
    """

    def __init__(self, demand: Demand) -> None:
        self._vehicles = demand.vehicles
        self._departs = [v.depart_s for v in demand.vehicles]
        self._next = 0

    def release(self, t: float, eps: float = 1e-6) -> list[PlannedVehicle]:
        """Vehicles planned to depart at or before ``t`` not released yet, in order."""
        end = bisect.bisect_right(self._departs, t + eps, lo=self._next)
        out = list(self._vehicles[self._next:end])
        self._next = end
        return out

    @property
    def remaining(self) -> int:
        """Vehicles not released yet."""
        return len(self._vehicles) - self._next

    @property
    def next_depart_s(self) -> float | None:
        """Planned departure of the next vehicle, or None when all are released."""
        return self._departs[self._next] if self._next < len(self._departs) else None


#: departPos / departSpeed keywords SUMO accepts (sumo.dlr.de, Definition of Vehicles): those read as a
#: start here, and those that depend on SUMO's draws or traffic (then SUMO's defaults: base, at rest)
DEPART_POS_WORDS = ("base", "random", "free", "random_free", "last", "stop", "splitFront")
DEPART_SPEED_WORDS = {"max": math.inf, "desired": math.inf, "speedLimit": math.inf, "random": None, "avg": None,
                      "last": None}


def _depart_pos(file: Path, elem: ET.Element) -> float | None:
    """``departPos``: metres (the front along the first lane; negative: from its end), or a keyword."""
    raw = elem.get("departPos")
    if raw is None or raw in DEPART_POS_WORDS:
        return None
    try:
        v = float(raw)
    except ValueError:
        v = math.nan
    if not math.isfinite(v):
        raise DemandError(f"{file}: <{elem.tag} id={elem.get('id')!r}> departPos={raw!r}: must be a position in "
                          f"metres or one of {', '.join(DEPART_POS_WORDS)}")
    return v


def _depart_speed(file: Path, elem: ET.Element) -> float | None:
    """``departSpeed``: m/s >= 0, or a keyword (``inf``: as fast as allowed; None: at rest)."""
    raw = elem.get("departSpeed")
    if raw is None:
        return None
    if raw in DEPART_SPEED_WORDS:
        return DEPART_SPEED_WORDS[raw]
    try:
        v = float(raw)
    except ValueError:
        v = math.nan
    if not (math.isfinite(v) and v >= 0):
        raise DemandError(f"{file}: <{elem.tag} id={elem.get('id')!r}> departSpeed={raw!r}: must be a speed "
                          f"in m/s (>= 0) or one of {', '.join(DEPART_SPEED_WORDS)}")
    return v


def _float(file: Path, elem: ET.Element, attr: str, default: float | None = None) -> float | None:
    raw = elem.get(attr)
    if raw is None:
        return default
    try:
        v = float(raw)
    except ValueError:
        raise DemandError(f"{file}: <{elem.tag} id={elem.get('id')!r}> {attr}={raw!r}: must be a number "
                          "(seconds or metres)") from None
    if not math.isfinite(v):
        raise DemandError(f"{file}: <{elem.tag} id={elem.get('id')!r}> {attr}={raw!r}: must be finite")
    return v


def _vtype(file: Path, elem: ET.Element) -> VehicleType:
    vid = elem.get("id")
    if not vid:
        raise DemandError(f"{file}: <vType> without id")
    vclass = elem.get("vClass", "passenger")
    dl, dw = VCLASS_DEFAULTS.get(vclass, (None, None))
    length = _float(file, elem, "length", dl)
    width = _float(file, elem, "width", dw)
    if length is None or width is None:
        raise DemandError(f"{file}: <vType id={vid!r}> vClass {vclass!r}: set length and width explicitly "
                          f"(muvsim knows SUMO's defaults for {', '.join(sorted(VCLASS_DEFAULTS))})")
    if not (length > 0 and width > 0):
        raise DemandError(f"{file}: <vType id={vid!r}>: length and width must be > 0, got {length} x {width}")
    elem.tail = None
    return VehicleType(vid, vclass, length, width, ET.tostring(elem, encoding="unicode").strip())


def needs_routing(route_files: str | os.PathLike | Sequence[str | os.PathLike]) -> bool:
    """Whether route files hold ``<trip>`` or ``<flow>`` elements (to be routed by duarouter first)."""
    files = [Path(route_files)] if isinstance(route_files, (str, os.PathLike)) else [Path(f) for f in route_files]
    for file in files:
        try:
            for _, elem in ET.iterparse(file, events=("start",)):
                if elem.tag in ("trip", "flow"):
                    return True
        except (OSError, ET.ParseError):
            return False  # read_demand reports it with the file named
    return False


def read_demand(route_files: str | os.PathLike | Sequence[str | os.PathLike], *,
                type_files: Sequence[str | os.PathLike] = ()) -> Demand:
    """Read route files into a :class:`Demand`.

    Parameters
    ----------
    route_files : path or sequence of paths
        SUMO route files (``.rou.xml``), read in order.
    type_files : sequence of paths
        Additional files whose ``<vType>`` elements the vehicles may use
        (SUMO loads these files itself, so their vTypes get no ``xml``).

    Raises
    ------
    DemandError
        Unreadable or malformed file, refused element, unknown type or route,
        duplicate vehicle id, non-numeric departure.
    """
    files = [Path(route_files)] if isinstance(route_files, (str, os.PathLike)) else [Path(f) for f in route_files]
    types: dict[str, VehicleType] = {_DEFAULT_VTYPE: VehicleType(_DEFAULT_VTYPE, "passenger", 5.0, 1.8)}
    routes: dict[str, tuple[str, ...]] = {}
    raw: list[tuple[float, int, Path, ET.Element, tuple[str, ...]]] = []
    seen: set[str] = set()
    external: set[str] = set()  # vTypes SUMO loads from additional files itself
    for file in (Path(f) for f in type_files):
        try:
            root = ET.parse(file).getroot()
        except (OSError, ET.ParseError) as exc:
            raise DemandError(f"{file}: cannot read additional file: {exc}") from None
        for elem in root.iter("vType"):
            t = _vtype(file, elem)
            types[t.id] = VehicleType(t.id, t.vclass, t.length, t.width, "")
            external.add(t.id)
    for file in files:
        try:
            root = ET.parse(file).getroot()
        except OSError as exc:
            raise DemandError(f"{file}: cannot read route file: {exc.strerror or exc}") from None
        except ET.ParseError as exc:
            raise DemandError(f"{file}: not a well-formed route file (XML): {exc}") from None
        for elem in root:
            tag = elem.tag
            if tag == "vType":
                t = _vtype(file, elem)
                if t.id not in external:  # duarouter copies vTypes of additional files into its output
                    types[t.id] = t
            elif tag == "route":
                rid, edges = elem.get("id"), (elem.get("edges") or "").split()
                if not rid or not edges:
                    raise DemandError(f"{file}: top-level <route> needs an id and edges")
                routes[rid] = tuple(edges)
            elif tag == "vehicle":
                vid = elem.get("id")
                if not vid:
                    raise DemandError(f"{file}: <vehicle> without id")
                if vid in seen:
                    raise DemandError(f"{file}: duplicate vehicle id {vid!r}")
                seen.add(vid)
                depart = _float(file, elem, "depart")
                if depart is None:
                    raise DemandError(f"{file}: <vehicle id={vid!r}> has no depart time")
                nested = elem.find("route")
                if nested is not None:
                    edges = tuple((nested.get("edges") or "").split())
                elif elem.get("route"):
                    if elem.get("route") not in routes:
                        raise DemandError(f"{file}: <vehicle id={vid!r}> references unknown route "
                                          f"{elem.get('route')!r} (routes must be defined before use)")
                    edges = routes[elem.get("route")]
                else:
                    raise DemandError(f"{file}: <vehicle id={vid!r}> has no route: muvsim needs explicit routes")
                if not edges:
                    raise DemandError(f"{file}: <vehicle id={vid!r}> has an empty route")
                raw.append((depart, len(raw), file, elem, edges))
            elif tag in _REFUSED:
                raise DemandError(f"{file}: {_REFUSED[tag]} (id {elem.get('id')!r}) is not supported: muvsim needs "
                                  "vehicles with explicit routes; convert with duarouter "
                                  "(duarouter -n NET -r FILE -o routed.rou.xml) or randomTrips.py -r")
            # other elements (e.g. <interval>, comments, <param>) carry no vehicles: ignored
    vehicles = []
    for depart, _, file, elem, edges in sorted(raw, key=lambda r: (r[0], r[1])):
        tid = elem.get("type", _DEFAULT_VTYPE)
        if tid not in types:
            raise DemandError(f"{file}: <vehicle id={elem.get('id')!r}> has unknown type {tid!r}; "
                              f"types: {', '.join(sorted(types))}")
        t = types[tid]
        lane_raw = elem.get("departLane")
        lane, rule = depart_lane_of(lane_raw)
        if lane_raw is not None and lane is None and rule is None:
            raise DemandError(f"{file}: vehicle {elem.get('id')!r}: departLane={lane_raw!r}: must be a lane index "
                              f"or one of {', '.join(DEPART_LANE_WORDS)}")
        pos, speed = _depart_pos(file, elem), _depart_speed(file, elem)
        nested = elem.find("route")
        stops = _stops(file, elem.get("id"), [*(nested.findall("stop") if nested is not None else ()),
                                                *elem.findall("stop")])
        vehicles.append(PlannedVehicle(elem.get("id"), tid, depart, edges, lane, pos, t.vclass, t.length, t.width,
                                       speed, stops, rule))
    return Demand(tuple(vehicles), types, tuple(files))


def demand_from(vehicles: Iterable[PlannedVehicle], types: Mapping[str, VehicleType]) -> Demand:
    """A :class:`Demand` built in code (tests, synthetic scenarios)."""
    vs = sorted(vehicles, key=lambda v: v.depart_s)
    return Demand(tuple(vs), dict(types), ())
