"""Scenario files: what network, what demand, which traffic-manager options.

A scenario is a TOML file.  Built-in scenarios live in the package
(``sumo_nets/scenarios/*.toml``) and are found by name; any other file is
found by path.  Example (the built-in ``grid``)::

    name = "grid"
    seed = 1
    duration_s = 300.0
    tm = "optimal"          # greedy | optimal
    # check = "timed"         # union | timed; default: timed with --controller authority, union with paper
    switching = "early"     # terminal | early

    [net]
    type = "grid"
    junctions = 4
    spacing_m = 100.0
    lanes = 2
    speed_mps = 13.89

    [demand]
    vehicles = 150
    duration_s = 300.0
    class_mix = { car = 0.8, bus = 0.1, truck = 0.1 }

Instead of ``[net]`` and ``[demand]`` a scenario may name a SUMO
configuration: ``sumocfg = "city.sumocfg"`` (relative to the TOML file); its
net-file and route-files are used as they are, and ``[vtype_classes]`` maps
the vType ids of its routes to muvsim vehicle classes.

:func:`load_scenario` validates everything: an unknown key, a value of the
wrong type or out of range raises :class:`ScenarioError` naming the file, the
field and what would be valid.  :func:`materialise` turns a scenario into
SUMO files (generated and cached, see :mod:`sumo_nets.generate`).
"""

from __future__ import annotations

import math
import os
import tomllib
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Collection, Mapping, NamedTuple

from sumo_nets.generate import make_demand, make_grid, sumocfg_for

__all__ = [
    "ScenarioError",
    "NetSpec",
    "DemandSpec",
    "Scenario",
    "ScenarioFiles",
    "SumoConfig",
    "DEFAULT_CLASSES",
    "TM_POLICIES",
    "CHECKS",
    "SWITCHING",
    "DISTURBANCES",
    "VCLASS_TO_CLASS",
    "builtin_scenarios",
    "load_scenario",
    "materialise",
    "read_sumocfg",
    "sumo_time",
    "SUMO_DEFAULT_SEED",
]

#: Vehicle classes a scenario may use unless the caller passes its own set.
DEFAULT_CLASSES = frozenset({"car", "bus", "truck", "paper-a", "paper-b", "paper-c", "paper-d"})
TM_POLICIES = ("greedy", "optimal")
CHECKS = ("union", "timed")
SWITCHING = ("terminal", "early")
DISTURBANCES = ("none", "random", "adversarial")
NET_TYPES = ("grid",)
#: Default muvsim class of SUMO vClasses (vTypes not mapped in ``[vtype_classes]``).
VCLASS_TO_CLASS = {"passenger": "car", "private": "car", "taxi": "car", "evehicle": "car", "authority": "car",
                   "emergency": "car", "bus": "bus", "coach": "bus", "truck": "truck", "trailer": "truck",
                   "delivery": "truck"}


class ScenarioError(ValueError):
    """An invalid scenario or SUMO configuration; the message names the file, the field and what is valid."""


def _where(source: Path | None) -> str:
    return str(source) if source is not None else "<scenario>"


def _fail(source: Path | None, fld: str, valid: str, got: Any = ...) -> ScenarioError:
    msg = f"{_where(source)}: {fld}: {valid}"
    if got is not ...:
        msg += f", got {got!r}"
    return ScenarioError(msg)


def _check_number(source, fld, v, *, lo=None, lo_open=False, hi=None, integer=False):
    """Validate a number; returns it as int or float."""
    if integer:
        if isinstance(v, bool) or not isinstance(v, int):
            raise _fail(source, fld, "must be an integer", v)
    elif isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise _fail(source, fld, "must be a finite number", v)
    bad = (lo is not None and (v <= lo if lo_open else v < lo)) or (hi is not None and v > hi)
    if bad:
        parts = []
        if lo is not None:
            parts.append(f"{'>' if lo_open else '>='} {lo}")
        if hi is not None:
            parts.append(f"<= {hi}")
        raise _fail(source, fld, f"must be {' and '.join(parts)}", v)
    return int(v) if integer else float(v)


def _check_choice(source, fld, v, choices):
    if not isinstance(v, str) or v not in choices:
        raise _fail(source, fld, f"must be one of {', '.join(repr(c) for c in choices)}", v)
    return v


def _floats(obj, *names: str) -> None:
    """Store validated numbers of a frozen dataclass as floats (TOML ``100`` is an int)."""
    for n in names:
        object.__setattr__(obj, n, float(getattr(obj, n)))


# --------------------------------------------------------------------------- specs

@dataclass(frozen=True)
class NetSpec:
    """A generated network.

    Parameters
    ----------
    type : {"grid"}
        Generator.
    junctions : int
        Junctions per side (2..100).
    spacing_m : float
        Distance between junctions (m, >= 20).
    lanes : int
        Lanes per direction (1..6).
    speed_mps : float
        Speed limit (m/s, > 0).
    source : Path, optional
        File the spec came from (for messages).
    """

    type: str = "grid"
    junctions: int = 4
    spacing_m: float = 100.0
    lanes: int = 2
    speed_mps: float = 13.89
    source: Path | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        s = self.source
        _check_choice(s, "net.type", self.type, NET_TYPES)
        _check_number(s, "net.junctions", self.junctions, lo=2, hi=100, integer=True)
        _check_number(s, "net.spacing_m", self.spacing_m, lo=20.0)
        _check_number(s, "net.lanes", self.lanes, lo=1, hi=6, integer=True)
        _check_number(s, "net.speed_mps", self.speed_mps, lo=0.0, lo_open=True, hi=100.0)
        _floats(self, "spacing_m", "speed_mps")


@dataclass(frozen=True)
class DemandSpec:
    """Random demand over a generated network.

    Parameters
    ----------
    vehicles : int
        Departures over the window (>= 1).
    duration_s : float
        Departure window (s, > 0).
    class_mix : tuple of (str, float)
        Vehicle class -> weight (>= 0, not all 0), in file order.
    seed : int
        Seed of trips and class assignment (>= 0).
    begin_s : float
        First departure (s, >= 0).
    fringe_factor : float
        Weight of border edges as origins/destinations (>= 1).
    min_distance_m : float or None
        Minimum origin-destination distance (m); None: 0.3 x the network diagonal.
    source : Path, optional
        File the spec came from (for messages).
    """

    vehicles: int
    duration_s: float
    class_mix: tuple[tuple[str, float], ...]
    seed: int = 1
    begin_s: float = 0.0
    fringe_factor: float = 10.0
    min_distance_m: float | None = None
    classes: frozenset[str] = field(default=DEFAULT_CLASSES, compare=False, repr=False)
    source: Path | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        s = self.source
        _check_number(s, "demand.vehicles", self.vehicles, lo=1, integer=True)
        _check_number(s, "demand.duration_s", self.duration_s, lo=0.0, lo_open=True)
        _check_number(s, "demand.seed", self.seed, lo=0, hi=2**31 - 1, integer=True)
        _check_number(s, "demand.begin_s", self.begin_s, lo=0.0)
        _check_number(s, "demand.fringe_factor", self.fringe_factor, lo=1.0)
        if self.min_distance_m is not None:
            _check_number(s, "demand.min_distance_m", self.min_distance_m, lo=0.0)
        if not isinstance(self.class_mix, tuple) or not self.class_mix:
            raise _fail(s, "demand.class_mix", "must be a non-empty table of class = weight", self.class_mix)
        for name, w in self.class_mix:
            if name not in self.classes:
                raise _fail(s, f"demand.class_mix.{name}",
                            f"unknown vehicle class; valid classes: {', '.join(sorted(self.classes))}")
            _check_number(s, f"demand.class_mix.{name}", w, lo=0.0)
        if sum(w for _, w in self.class_mix) <= 0:
            raise _fail(s, "demand.class_mix", "weights must not all be zero", dict(self.class_mix))
        _floats(self, "duration_s", "begin_s", "fringe_factor")
        if self.min_distance_m is not None:
            _floats(self, "min_distance_m")
        object.__setattr__(self, "class_mix", tuple((k, float(w)) for k, w in self.class_mix))

    @property
    def mix(self) -> dict[str, float]:
        """``class_mix`` as a dict."""
        return dict(self.class_mix)


@dataclass(frozen=True)
class Scenario:
    """A validated scenario.

    Parameters
    ----------
    name : str
        Scenario name (default: the file's stem).
    seed : int
        Seed of the run (disturbances, tie-breaks) and default demand seed.
    duration_s : float
        Simulated time (s, > 0).
    tm : {"greedy", "optimal"}
        Traffic-manager policy.
    check : {"union", "timed"} or None
        Tube conflict check; None (the default): the controller's (:func:`tm.settings.default_check`:
        ``timed`` with ``--controller authority``, ``union`` with ``paper``).
    switching : {"terminal", "early"}
        When vehicles ask to switch waypoint.
    disturbance : {"none", "random", "adversarial"}
        Disturbance policy of the plant.
    net : NetSpec or None
        Generated network; None when ``sumocfg`` is given.
    demand : DemandSpec or None
        Generated demand; None when ``sumocfg`` is given.
    sumocfg : Path or None
        A user's SUMO configuration (absolute).
    vtype_classes : tuple of (str, str)
        vType id -> muvsim class, for ``sumocfg`` scenarios.
    description : str
        Free text.
    source : Path or None
        The TOML file (None when built in code).
    """

    name: str
    seed: int = 1
    duration_s: float = 300.0
    tm: str = "optimal"
    check: str | None = None
    switching: str = "early"
    disturbance: str = "random"
    net: NetSpec | None = None
    demand: DemandSpec | None = None
    sumocfg: Path | None = None
    vtype_classes: tuple[tuple[str, str], ...] = ()
    description: str = ""
    classes: frozenset[str] = field(default=DEFAULT_CLASSES, compare=False, repr=False)
    source: Path | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        s = self.source
        if not isinstance(self.name, str) or not self.name:
            raise _fail(s, "name", "must be a non-empty string", self.name)
        if not isinstance(self.description, str):
            raise _fail(s, "description", "must be a string", self.description)
        _check_number(s, "seed", self.seed, lo=0, hi=2**31 - 1, integer=True)
        _check_number(s, "duration_s", self.duration_s, lo=0.0, lo_open=True)
        _check_choice(s, "tm", self.tm, TM_POLICIES)
        if self.check is not None:
            _check_choice(s, "check", self.check, CHECKS)
        _check_choice(s, "switching", self.switching, SWITCHING)
        _check_choice(s, "disturbance", self.disturbance, DISTURBANCES)
        _floats(self, "duration_s")
        if self.sumocfg is not None:
            if self.net is not None or self.demand is not None:
                raise _fail(s, "sumocfg", "a scenario has either 'sumocfg' or [net] and [demand], not both")
        elif self.net is None or self.demand is None:
            raise _fail(s, "net/demand", "a scenario needs both [net] and [demand] tables (or 'sumocfg')")
        for vtype, cls in self.vtype_classes:
            if cls not in self.classes:
                raise _fail(s, f"vtype_classes.{vtype}",
                            f"unknown vehicle class; valid classes: {', '.join(sorted(self.classes))}", cls)

    def class_for(self, vtype_id: str, vclass: str = "passenger") -> str:
        """The muvsim class of a SUMO vType.

        ``vtype_classes`` first, then a vType named like a class, then by
        SUMO vClass (:data:`VCLASS_TO_CLASS`: passenger-like -> car, bus and
        coach -> bus, truck, trailer and delivery -> truck).

        Raises
        ------
        ScenarioError
            None of these applies.
        """
        explicit = dict(self.vtype_classes)
        if vtype_id in explicit:
            return explicit[vtype_id]
        if vtype_id in self.classes:
            return vtype_id
        cls = VCLASS_TO_CLASS.get(vclass)
        if cls is not None and cls in self.classes:
            return cls
        raise _fail(self.source, f"vtype_classes.{vtype_id}",
                    f"vType {vtype_id!r} (vClass {vclass!r}) has no muvsim class: map it in [vtype_classes] "
                    f"to one of {', '.join(sorted(self.classes))}")

    @property
    def class_of_vtype(self) -> dict[str, str]:
        """vType id -> vehicle class: ``vtype_classes``, and for generated demand the identity."""
        out = {} if self.demand is None else {c: c for c, _ in self.demand.class_mix}
        out.update(dict(self.vtype_classes))
        return out


class ScenarioFiles(NamedTuple):
    """SUMO inputs of a scenario."""

    net: Path
    routes: tuple[Path, ...]
    sumocfg: Path


#: SUMO's seed when a configuration sets none (``sumo --help``: ``--seed INT ... default 23423``).
SUMO_DEFAULT_SEED = 23423


def sumo_time(text: str) -> float:
    """A SUMO time value in seconds: ``"3600"``, ``"60.5"`` or ``"[D:]H:M:S"`` (e.g. ``"15:0:0"``).

    Raises
    ------
    ValueError
        Not a time SUMO accepts.
    """
    parts = text.strip().split(":")
    if len(parts) > 4 or not all(p.strip() for p in parts):
        raise ValueError(f"not a SUMO time: {text!r}")
    vals = [float(p) for p in parts]
    weights = (86400.0, 3600.0, 60.0, 1.0)[-len(vals):]
    out = sum(w * v for w, v in zip(weights, vals))
    if not math.isfinite(out):
        raise ValueError(f"not a SUMO time: {text!r}")
    return out


def _sumo_bool(text: str) -> bool:
    low = text.strip().lower()
    if low in ("true", "1", "on", "yes", "x"):
        return True
    if low in ("false", "0", "off", "no", "-"):
        return False
    raise ValueError(text)


class SumoConfig(NamedTuple):
    """The inputs named by a ``.sumocfg`` file (paths resolved against its directory)."""

    path: Path
    net: Path
    routes: tuple[Path, ...]
    additional: tuple[Path, ...]
    begin_s: float = 0.0
    end_s: float | None = None
    seed: int | None = None
    step_length_s: float | None = None
    random: bool = False

    @property
    def duration_s(self) -> float | None:
        """``end - begin`` when the configuration sets an end, else None."""
        return None if self.end_s is None else self.end_s - self.begin_s

    @property
    def run_seed(self) -> int:
        """The seed plain ``sumo -c`` uses: the configuration's, else SUMO's default
        :data:`SUMO_DEFAULT_SEED` (``--random`` draws one: muvsim then uses the default too)."""
        return SUMO_DEFAULT_SEED if self.seed is None else self.seed


# --------------------------------------------------------------------------- loading

_TOP_KEYS = {"name", "description", "seed", "duration_s", "tm", "check", "switching", "disturbance",
             "net", "demand", "sumocfg", "vtype_classes"}
_NET_KEYS = {"type", "junctions", "spacing_m", "lanes", "speed_mps"}
_DEMAND_KEYS = {"vehicles", "duration_s", "class_mix", "seed", "begin_s", "fringe_factor", "min_distance_m"}


def _reject_unknown(source, table: Mapping, allowed: set[str], prefix: str) -> None:
    for k in table:
        if k not in allowed:
            raise _fail(source, f"{prefix}{k}", f"unknown key; valid keys{' in [' + prefix[:-1] + ']' if prefix else ''}: "
                        f"{', '.join(sorted(allowed))}")


def _table(source, data: Mapping, key: str) -> dict | None:
    v = data.get(key)
    if v is None:
        return None
    if not isinstance(v, dict):
        raise _fail(source, key, "must be a table", v)
    return v


def _scenario_from_dict(data: Mapping, source: Path | None, classes: frozenset[str]) -> Scenario:
    _reject_unknown(source, data, _TOP_KEYS, "")
    top = {k: data[k] for k in ("name", "description", "seed", "duration_s", "tm", "check", "switching",
                                "disturbance") if k in data}
    if "name" not in top:
        top["name"] = source.stem if source is not None else "scenario"
    seed = top.get("seed", 1)
    duration = top.get("duration_s", 300.0)
    net = demand = sumocfg = None
    if (raw := _table(source, data, "net")) is not None:
        _reject_unknown(source, raw, _NET_KEYS, "net.")
        net = NetSpec(**raw, source=source)
    if (raw := _table(source, data, "demand")) is not None:
        _reject_unknown(source, raw, _DEMAND_KEYS, "demand.")
        raw = dict(raw)
        mix = raw.pop("class_mix", None)
        if not isinstance(mix, dict) or not mix:
            raise _fail(source, "demand.class_mix", "must be a non-empty table of class = weight",
                        mix if mix is not None else ...)
        if "vehicles" not in raw:
            raise _fail(source, "demand.vehicles", "is required (an integer >= 1)")
        raw.setdefault("duration_s", duration)
        raw.setdefault("seed", seed)
        demand = DemandSpec(class_mix=tuple(mix.items()), classes=classes, source=source, **raw)
    if "sumocfg" in data:
        if not isinstance(data["sumocfg"], str) or not data["sumocfg"]:
            raise _fail(source, "sumocfg", "must be a path (string) to a .sumocfg file", data["sumocfg"])
        p = Path(data["sumocfg"]).expanduser()
        if not p.is_absolute():
            p = (source.parent if source is not None else Path.cwd()) / p
        sumocfg = p.resolve()
        read_sumocfg(sumocfg)  # fails early, naming the file, when unusable
    vtc = _table(source, data, "vtype_classes") or {}
    for k, v in vtc.items():
        if not isinstance(v, str):
            raise _fail(source, f"vtype_classes.{k}", "must be a class name (string)", v)
    return Scenario(net=net, demand=demand, sumocfg=sumocfg, vtype_classes=tuple(vtc.items()),
                    classes=classes, source=source, **top)


def builtin_scenarios() -> list[str]:
    """Names of the packaged scenarios."""
    root = resources.files("sumo_nets").joinpath("scenarios")
    return sorted(p.name[:-5] for p in root.iterdir() if p.name.endswith(".toml"))


def load_scenario(name_or_path: str | os.PathLike, *, classes: Collection[str] | None = None) -> Scenario:
    """Load and validate a scenario.

    Parameters
    ----------
    name_or_path : str or path
        A built-in name (see :func:`builtin_scenarios`), a ``.toml`` file, or a
        ``.sumocfg`` file (a scenario with default options around it).
    classes : collection of str, optional
        Valid vehicle classes (default :data:`DEFAULT_CLASSES`).

    Raises
    ------
    ScenarioError
        Unknown name, unreadable file, bad TOML, or an invalid field.
    """
    allowed = frozenset(DEFAULT_CLASSES if classes is None else classes)
    text = str(name_or_path)
    path = Path(text).expanduser()
    if text.endswith(".sumocfg"):
        cfg = read_sumocfg(path)
        return Scenario(name=cfg.path.stem, sumocfg=cfg.path, classes=allowed, source=None)
    builtin = path.suffix != ".toml" and os.sep not in text and text in builtin_scenarios()
    if not builtin and (path.suffix == ".toml" or os.sep in text or path.exists()):
        if not path.is_file():
            raise ScenarioError(f"{path}: scenario file does not exist")
        try:
            data = tomllib.loads(path.read_text(encoding="utf-8"))
        except OSError as exc:
            raise ScenarioError(f"{path}: cannot read scenario file: {exc.strerror or exc}") from None
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise ScenarioError(f"{path}: not valid TOML: {exc}") from None
        return _scenario_from_dict(data, path.resolve(), allowed)
    names = builtin_scenarios()
    if text not in names:
        raise ScenarioError(f"unknown scenario {text!r}: built-in scenarios are {', '.join(names)}; "
                            f"or give a path to a .toml or .sumocfg file")
    res = resources.files("sumo_nets").joinpath("scenarios", f"{text}.toml")
    with resources.as_file(res) as p:
        data = tomllib.loads(Path(p).read_text(encoding="utf-8"))
        return _scenario_from_dict(data, Path(p), allowed)


# --------------------------------------------------------------------------- SUMO files

def _split_files(value: str) -> list[str]:
    return [v for v in value.replace(",", " ").split() if v]


def read_sumocfg(path: str | os.PathLike) -> SumoConfig:
    """The net-file, route-files and additional-files of a SUMO configuration.

    Paths are resolved against the configuration's directory.

    Raises
    ------
    ScenarioError
        The file is missing, unreadable or not XML, names no net-file, or a
        named file does not exist.
    """
    path = Path(path).expanduser().resolve()
    if not path.is_file():
        raise ScenarioError(f"{path}: SUMO configuration does not exist")
    try:
        root = ET.parse(path).getroot()
    except OSError as exc:
        raise ScenarioError(f"{path}: cannot read SUMO configuration: {exc.strerror or exc}") from None
    except ET.ParseError as exc:
        raise ScenarioError(f"{path}: not a well-formed SUMO configuration (XML): {exc}") from None

    def values(*tags: str) -> list[str]:
        out = []
        for tag in tags:
            for elem in root.iter(tag):
                if elem.get("value"):
                    out += _split_files(elem.get("value"))
        return out

    nets = values("net-file", "n")
    if not nets:
        raise ScenarioError(f"{path}: no <net-file value=...> in the SUMO configuration")
    if len(nets) > 1:
        raise ScenarioError(f"{path}: net-file: exactly one network is supported, got {nets}")

    def resolve(kind: str, name: str) -> Path:
        p = Path(name).expanduser()
        p = (p if p.is_absolute() else path.parent / p).resolve()
        if not p.is_file():
            raise ScenarioError(f"{path}: {kind} {name!r} does not exist (looked for {p})")
        return p

    def one(kind: str, *tags: str, parse=float):
        got = [e.get("value") for t in tags for e in root.iter(t) if e.get("value") is not None]
        if not got:
            return None
        try:
            return parse(got[-1])
        except ValueError:
            raise ScenarioError(f"{path}: <{tags[0]} value={got[-1]!r}>: {kind}") from None

    begin = one("must be a time (seconds or H:M:S)", "begin", "b", parse=sumo_time)
    end = one("must be a time (seconds or H:M:S)", "end", "e", parse=sumo_time)
    seed = one("must be an integer >= 0", "seed", parse=int)
    step = one("must be a number of seconds > 0", "step-length", parse=sumo_time)
    rnd = one("must be true or false", "random", parse=_sumo_bool)
    if seed is not None and seed < 0:
        raise ScenarioError(f"{path}: <seed value={seed}>: must be an integer >= 0")
    if step is not None and not step > 0:
        raise ScenarioError(f"{path}: <step-length value={step}>: must be a number of seconds > 0")
    if end is not None and end >= 0 and end <= (begin or 0.0):
        raise ScenarioError(f"{path}: <end value={end:g}>: must be after begin ({begin or 0.0:g} s)")
    return SumoConfig(path=path, net=resolve("net-file", nets[0]),
                      routes=tuple(resolve("route-files", r) for r in values("route-files", "r")),
                      additional=tuple(resolve("additional-files", a) for a in values("additional-files", "a")),
                      begin_s=begin or 0.0, end_s=end if end is not None and end >= 0 else None, seed=seed,
                      step_length_s=step, random=bool(rnd))


def materialise(scenario: Scenario, work_dir: str | os.PathLike) -> ScenarioFiles:
    """SUMO files of a scenario: generated (and cached under ``work_dir``) or the user's.

    Returns
    -------
    ScenarioFiles
        ``(net, routes, sumocfg)``; ``routes`` is a tuple of route files (one
        for generated demand).
    """
    if scenario.sumocfg is not None:
        cfg = read_sumocfg(scenario.sumocfg)
        return ScenarioFiles(cfg.net, cfg.routes, cfg.path)
    net_spec, dem = scenario.net, scenario.demand
    assert net_spec is not None and dem is not None  # guaranteed by Scenario validation
    work = Path(work_dir)
    net = make_grid(work, junctions=net_spec.junctions, spacing_m=net_spec.spacing_m, lanes=net_spec.lanes,
                    speed_mps=net_spec.speed_mps)
    routes = make_demand(net, work, seed=dem.seed, vehicles=dem.vehicles, duration_s=dem.duration_s,
                         class_mix=dem.mix, begin_s=dem.begin_s, fringe_factor=dem.fringe_factor,
                         min_distance_m=dem.min_distance_m)
    return ScenarioFiles(net, (routes,), sumocfg_for(routes))
