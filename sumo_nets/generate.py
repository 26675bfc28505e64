"""Deterministic generators for SUMO networks, demand and configurations.

Every generator writes into a sub-directory of ``out_dir`` named by a hash of
its inputs (parameters, the content of input files, the SUMO version and
:data:`FORMAT_VERSION`).  A second call with the same inputs finds the files
there and runs no tool.  Files are written to a temporary directory first and
moved into place, so an interrupted run never leaves a half-written cache
entry.  The same inputs give byte-identical files: SUMO's own headers (which
hold dates and paths) are replaced by fixed comments.

Grid networks (:func:`make_grid`) use ``netgenerate --grid`` with

* junction-internal lanes (``--no-internal-links false``): routes are drawn as
  polylines through the junctions and SUMO checks collisions there;
* no turnarounds (``--no-turnarounds true``): without them the router may send
  a vehicle through a U-turn at a junction or at the end of a dead-end stub, a
  curve of a few metres radius that a vehicle with a footprint cannot track
  inside its lane; every route therefore turns by at most 90 degrees at a time;
* approach stubs of one block at the border (``--grid.attach-length``), so
  that fringe traffic enters through a full-length lane (where vehicles queue
  before the first junction) and leaves through one, instead of appearing and
  vanishing at the outermost junctions.

Demand (:func:`make_demand`) comes from SUMO's ``randomTrips.py`` routed by
``duarouter`` (``-r``), so every route is connected; vehicles are then
assigned vehicle types with a seeded :class:`numpy.random.Generator`.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import shutil
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np

from sumo_nets.sumo_tools import binary, run_tool, sumo_version, tool_script

__all__ = [
    "GenerateError",
    "VTypeSpec",
    "DEFAULT_VTYPES",
    "FORMAT_VERSION",
    "make_grid",
    "make_demand",
    "write_sumocfg",
    "sumocfg_for",
    "route_demand",
]

#: Bump when the layout or content of generated files changes (invalidates caches).
FORMAT_VERSION = 1

_GENERATED_COMMENT = re.compile(r"<!--\s*generated on.*?-->\s*", re.DOTALL)


class GenerateError(ValueError):
    """Invalid generator input; the message names the parameter and what is valid."""


@dataclass(frozen=True)
class VTypeSpec:
    """A SUMO vType written into generated demand.

    Parameters
    ----------
    vclass : str
        SUMO vehicle class.
    length, width : float
        Footprint (m).
    """

    vclass: str
    length: float
    width: float

    def __post_init__(self) -> None:
        if not (self.length > 0 and self.width > 0):
            raise GenerateError(f"VTypeSpec: length and width must be > 0 m, got {self.length} x {self.width}")


#: vTypes of the built-in vehicle classes: SUMO's defaults for each vClass
#: (passenger 5 x 1.8 m, bus 12 x 2.5 m, truck 7.1 x 2.4 m); the paper's
#: classes have the footprint of a car.
DEFAULT_VTYPES: Mapping[str, VTypeSpec] = {
    "car": VTypeSpec("passenger", 5.0, 1.8),
    "bus": VTypeSpec("bus", 12.0, 2.5),
    "truck": VTypeSpec("truck", 7.1, 2.4),
    "paper-a": VTypeSpec("passenger", 5.0, 1.8),
    "paper-b": VTypeSpec("passenger", 5.0, 1.8),
    "paper-c": VTypeSpec("passenger", 5.0, 1.8),
    "paper-d": VTypeSpec("passenger", 5.0, 1.8),
}


# --------------------------------------------------------------------------- helpers

def _num(x: float) -> str:
    """A float as SUMO options and XML attributes want it, deterministically."""
    return f"{float(x):.10g}"


def _key(payload: Mapping) -> str:
    body = json.dumps({**payload, "sumo": sumo_version(), "format": FORMAT_VERSION},
                      sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(body.encode()).hexdigest()


def _file_sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _cached(out_dir: Path, name: str, files: Sequence[str], build: Callable[[Path], None]) -> Path:
    """Return ``out_dir/name``, building it with ``build(tmp_dir)`` unless all ``files`` exist."""
    out_dir = Path(out_dir).resolve()  # tools run in the temporary directory: absolute paths only
    final = out_dir / name
    if all((final / f).is_file() for f in files):
        return final
    out_dir.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{name}-", dir=out_dir))
    tmp.chmod(0o755)
    try:
        build(tmp)
        missing = [f for f in files if not (tmp / f).is_file()]
        if missing:
            raise GenerateError(f"generator for {name} did not write {missing}")
        for f in list(tmp.iterdir()):
            if f.name not in files:  # keep only the products
                f.unlink() if f.is_file() else shutil.rmtree(f)
        if final.exists():
            shutil.rmtree(final)
        try:
            os.replace(tmp, final)
        except OSError:  # another process won the race: its result is identical
            if not all((final / f).is_file() for f in files):
                raise
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return final


def _replace_header(text: str, comment: str) -> str:
    """Drop SUMO's ``<!-- generated on ... -->`` blocks and put ``comment`` after the XML declaration."""
    text = _GENERATED_COMMENT.sub("", text)
    comment = comment.replace("--", "")  # "--" may not occur inside an XML comment
    decl, sep, rest = text.partition("?>")
    if not sep:
        raise GenerateError("generated file has no XML declaration")
    return f"{decl}?>\n<!-- {comment} -->\n{rest.lstrip()}"


def _check_int(name: str, value, lo: int, hi: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise GenerateError(f"{name}: must be an integer, got {value!r}")
    if value < lo or (hi is not None and value > hi):
        rng = f">= {lo}" if hi is None else f"in [{lo}, {hi}]"
        raise GenerateError(f"{name}: must be {rng}, got {value}")
    return int(value)


def _check_pos(name: str, value, *, allow_zero: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise GenerateError(f"{name}: must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise GenerateError(f"{name}: must be a finite number {'>=' if allow_zero else '>'} 0, got {value!r}")
    return v


# --------------------------------------------------------------------------- networks

def make_grid(out_dir: str | os.PathLike, junctions: int = 4, spacing_m: float = 100.0, lanes: int = 2,
              speed_mps: float = 13.89, *, attach: bool = True) -> Path:
    """A ``junctions`` x ``junctions`` city grid made by ``netgenerate``.

    Parameters
    ----------
    out_dir : path
        Cache directory; the network goes to ``out_dir/grid-<N>x<N>-<hash>/grid.net.xml``.
    junctions : int
        Junctions per side (>= 2).
    spacing_m : float
        Distance between neighbouring junctions (m, >= 20).
    lanes : int
        Lanes per direction on every street (1..6).
    speed_mps : float
        Speed limit (m/s, > 0).
    attach : bool
        Add one block long approach stubs at the border (see the module notes).

    Returns
    -------
    Path
        The ``.net.xml`` file.
    """
    n = _check_int("junctions", junctions, 2, 100)
    length = _check_pos("spacing_m", spacing_m)
    if length < 20.0:
        raise GenerateError(f"spacing_m: must be >= 20 m (junctions need room), got {spacing_m}")
    k = _check_int("lanes", lanes, 1, 6)
    v = _check_pos("speed_mps", speed_mps)
    args = ["--grid", "--grid.number", str(n), "--grid.length", _num(length),
            "--default.lanenumber", str(k), "--default.speed", _num(v),
            "--no-internal-links", "false", "--no-turnarounds", "true"]
    if attach:
        args += ["--grid.attach-length", _num(length)]
    name = f"grid-{n}x{n}-{_key({'kind': 'grid', 'args': args})[:12]}"

    def build(tmp: Path) -> None:
        raw = tmp / "raw.net.xml"
        run_tool([binary("netgenerate"), *args, "--output-file", raw], what="grid network", cwd=tmp)
        text = _replace_header(raw.read_text(encoding="utf-8"),
                               f"generated by muvsim sumo_nets.generate.make_grid with SUMO {sumo_version()}: "
                               f"netgenerate {' '.join(args)}")
        (tmp / "grid.net.xml").write_text(text, encoding="utf-8")

    return _cached(Path(out_dir), name, ["grid.net.xml"], build) / "grid.net.xml"


# --------------------------------------------------------------------------- demand

def _net_diagonal(net: Path) -> float:
    """Diagonal of the network's ``convBoundary`` (m), read without parsing the whole file."""
    for _, elem in ET.iterparse(net, events=("start",)):
        if elem.tag == "location":
            x0, y0, x1, y1 = (float(c) for c in elem.get("convBoundary", "0,0,0,0").split(","))
            return math.hypot(x1 - x0, y1 - y0)
        if elem.tag in ("edge", "junction"):
            break
    raise GenerateError(f"{net}: no <location convBoundary=...> before the first edge; is it a SUMO network?")


def make_demand(net: str | os.PathLike, out_dir: str | os.PathLike, seed: int, vehicles: int, duration_s: float,
                class_mix: Mapping[str, float], *, begin_s: float = 0.0, fringe_factor: float = 10.0,
                min_distance_m: float | None = None,
                vtypes: Mapping[str, VTypeSpec] | None = None) -> Path:
    """Random trips over ``net``, routed, with vehicle types drawn by ``class_mix``.

    Parameters
    ----------
    net : path
        SUMO network.
    out_dir : path
        Cache directory; files go to ``out_dir/demand-<hash>/`` (``routes.rou.xml``
        and ``run.sumocfg``, which references ``net`` by a relative path).
    seed : int
        Seed of ``randomTrips.py`` and of the type assignment.
    vehicles : int
        Number of departures wanted; one every ``duration_s / vehicles`` seconds.
        Trips that ``duarouter`` cannot route are dropped, so a few fewer may result.
    duration_s : float
        Departure window ``[begin_s, begin_s + duration_s)`` (s).
    class_mix : mapping of str to float
        Type name -> weight (>= 0, not all zero; normalised here).  Names must be
        keys of ``vtypes``.
    begin_s : float
        First departure time (s).
    fringe_factor : float
        ``randomTrips --fringe-factor``: weight of edges at the border as
        origins and destinations (>= 1).  The default 10 makes most traffic
        cross the grid, entering and leaving through the approach stubs.
    min_distance_m : float, optional
        ``randomTrips --min-distance`` (straight-line distance from origin to
        destination).  Default: 0.3 x the diagonal of the network, so trips
        are not trivial.
    vtypes : mapping of str to VTypeSpec, optional
        Known vTypes (default :data:`DEFAULT_VTYPES`).

    Returns
    -------
    Path
        The ``.rou.xml`` file: vTypes, then vehicles sorted by departure, each
        with an explicit ``<route edges=...>``, ``departLane="best"`` and
        ``departSpeed="0"``.
    """
    net = Path(net).resolve()
    if not net.is_file():
        raise GenerateError(f"net: file {net} does not exist")
    seed = _check_int("seed", seed, 0, 2**31 - 1)
    n = _check_int("vehicles", vehicles, 1)
    duration = _check_pos("duration_s", duration_s)
    begin = _check_pos("begin_s", begin_s, allow_zero=True)
    fringe = _check_pos("fringe_factor", fringe_factor)
    if fringe < 1.0:
        raise GenerateError(f"fringe_factor: must be >= 1, got {fringe_factor}")
    known = dict(DEFAULT_VTYPES if vtypes is None else vtypes)
    if not class_mix:
        raise GenerateError("class_mix: must name at least one vehicle type")
    names = sorted(class_mix)  # independent of the mapping's order
    for name in names:
        if name not in known:
            raise GenerateError(f"class_mix: unknown vehicle type {name!r}; valid types: {', '.join(sorted(known))}")
        _check_pos(f"class_mix[{name!r}]", class_mix[name], allow_zero=True)
    weights = np.array([float(class_mix[k]) for k in names])
    if weights.sum() <= 0:
        raise GenerateError(f"class_mix: weights must not all be zero, got {dict(class_mix)}")
    probs = weights / weights.sum()
    min_dist = 0.3 * _net_diagonal(net) if min_distance_m is None else _check_pos(
        "min_distance_m", min_distance_m, allow_zero=True)
    period = duration / n

    rt_args = ["--seed", str(seed), "--begin", _num(begin), "--end", _num(begin + duration),
               "--period", _num(period), "--fringe-factor", _num(fringe), "--min-distance", _num(min_dist)]
    key = _key({"kind": "demand", "net": _file_sha256(net), "net_path": str(net), "args": rt_args,
                "mix": [[k, float(class_mix[k])] for k in names],
                "vtypes": {k: [known[k].vclass, known[k].length, known[k].width] for k in names}})

    def build(tmp: Path) -> None:
        run_tool([tool_script("randomTrips.py"), "--net-file", net, "--output-trip-file", tmp / "trips.xml",
                  "--route-file", tmp / "duarouter.rou.xml", *rt_args],
                 what=f"random demand for {net.name}", cwd=tmp, python=True)
        routed = _read_routed(tmp / "duarouter.rou.xml")
        if not routed:
            raise GenerateError(f"random demand for {net.name}: duarouter routed no trip "
                                f"(min_distance_m={min_dist:g} too large for the network?)")
        rng = np.random.default_rng(seed)
        types = rng.choice(len(names), size=len(routed), p=probs)
        used = sorted({names[i] for i in types} | {k for k, p in zip(names, probs) if p > 0})
        lines = ['<?xml version="1.0" encoding="UTF-8"?>',
                 f"<!-- generated by muvsim sumo_nets.generate.make_demand with SUMO {sumo_version()}: "
                 f"randomTrips.py {' '.join(rt_args).replace('--', '')}; vehicles={n}; "
                 f"class_mix={','.join(f'{k}:{_num(class_mix[k])}' for k in names)} -->",
                 '<routes xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" '
                 'xsi:noNamespaceSchemaLocation="http://sumo.dlr.de/xsd/routes_file.xsd">']
        for t in used:
            spec = known[t]
            lines.append(f'    <vType id="{t}" vClass="{spec.vclass}" length="{_num(spec.length)}" '
                         f'width="{_num(spec.width)}"/>')
        for (vid, depart, edges), ti in zip(routed, types):
            lines.append(f'    <vehicle id="{vid}" type="{names[ti]}" depart="{depart:.2f}" departLane="best" '
                         f'departSpeed="0">')
            lines.append(f'        <route edges="{" ".join(edges)}"/>')
            lines.append("    </vehicle>")
        lines.append("</routes>")
        (tmp / "routes.rou.xml").write_text("\n".join(lines) + "\n", encoding="utf-8")
        write_sumocfg(tmp / "run.sumocfg", net, [tmp / "routes.rou.xml"], relative_to=out / name)

    out = Path(out_dir).resolve()
    name = f"demand-{key[:12]}"
    return _cached(out, name, ["routes.rou.xml", "run.sumocfg"], build) / "routes.rou.xml"


def _read_routed(path: Path) -> list[tuple[str, float, list[str]]]:
    """``(id, depart, edges)`` of every routed vehicle in a duarouter output, by departure."""
    out = []
    for _, elem in ET.iterparse(path):
        if elem.tag == "vehicle":
            route = elem.find("route")
            if route is None or not route.get("edges"):
                continue
            out.append((elem.get("id"), float(elem.get("depart", "0")), route.get("edges").split()))
            elem.clear()
    out.sort(key=lambda r: r[1])  # stable: duarouter keeps id order within a time
    return out


def route_demand(net: str | os.PathLike, route_files: Sequence[str | os.PathLike], out_dir: str | os.PathLike, *,
                 additional: Sequence[str | os.PathLike] = ()) -> Path:
    """Route trips and expand flows of ``route_files`` into vehicles with explicit routes.

    Runs ``duarouter`` (which routes ``<trip>`` elements and expands
    ``<flow>`` elements into vehicles by default); vehicles that already have
    routes are kept.  A trip that cannot be routed is an error (SUMO's message).

    Parameters
    ----------
    net : path
        SUMO network.
    route_files : sequence of paths
        Route files with trips, flows and/or vehicles.
    out_dir : path
        Cache directory; the result goes to ``out_dir/routed-<hash>/routed.rou.xml``.
    additional : sequence of paths
        Additional files the routes need (vTypes, TAZ, stops).

    Returns
    -------
    Path
        The routed ``.rou.xml``.
    """
    net = Path(net).resolve()
    files = [Path(f).resolve() for f in route_files]
    adds = [Path(f).resolve() for f in additional]
    for f in [net, *files, *adds]:
        if not f.is_file():
            raise GenerateError(f"route_demand: file {f} does not exist")
    key = _key({"kind": "routed", "net": _file_sha256(net), "routes": [_file_sha256(f) for f in files],
                "additional": [_file_sha256(f) for f in adds]})

    def build(tmp: Path) -> None:
        args = [binary("duarouter"), "--net-file", net, "--route-files", ",".join(map(str, files)),
                "--output-file", tmp / "raw.rou.xml", "--alternatives-output", "NUL", "--no-step-log", "true"]
        if adds:
            args += ["--additional-files", ",".join(map(str, adds))]
        run_tool(args, what=f"routing {', '.join(f.name for f in files)}", cwd=tmp)
        text = _replace_header((tmp / "raw.rou.xml").read_text(encoding="utf-8"),
                               f"generated by muvsim sumo_nets.generate.route_demand with SUMO {sumo_version()}: "
                               f"duarouter of {', '.join(f.name for f in files)}")
        (tmp / "routed.rou.xml").write_text(text, encoding="utf-8")

    return _cached(Path(out_dir), f"routed-{key[:12]}", ["routed.rou.xml"], build) / "routed.rou.xml"


# --------------------------------------------------------------------------- configurations

def sumocfg_for(routes: str | os.PathLike) -> Path:
    """The ``run.sumocfg`` that :func:`make_demand` wrote beside ``routes``."""
    return Path(routes).with_name("run.sumocfg")


def write_sumocfg(path: str | os.PathLike, net: str | os.PathLike, route_files: Sequence[str | os.PathLike], *,
                  step_length: float = 0.1, relative_to: str | os.PathLike | None = None) -> Path:
    """Write a minimal SUMO configuration referencing ``net`` and ``route_files``.

    Parameters
    ----------
    path : path
        The ``.sumocfg`` to write.
    net, route_files : path
        Inputs, written relative to the directory the configuration will live
        in (``relative_to``, default ``path``'s directory).
    step_length : float
        ``<step-length>`` (s).
    relative_to : path, optional
        Final directory of the configuration when it is written elsewhere first.
    """
    path = Path(path)
    base = Path(relative_to) if relative_to is not None else path.parent
    base = base.resolve()

    def rel(p) -> str:
        p = Path(p).resolve()
        # a file written beside the configuration (possibly in a temporary dir)
        if p.parent == path.parent.resolve():
            return p.name
        return os.path.relpath(p, base)

    routes = ",".join(rel(r) for r in route_files)
    text = "\n".join([
        '<?xml version="1.0" encoding="UTF-8"?>',
        "<!-- generated by muvsim sumo_nets.generate.write_sumocfg -->",
        '<configuration xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" '
        'xsi:noNamespaceSchemaLocation="http://sumo.dlr.de/xsd/sumoConfiguration.xsd">',
        "    <input>",
        f'        <net-file value="{rel(net)}"/>',
        f'        <route-files value="{routes}"/>',
        "    </input>",
        "    <time>",
        f'        <step-length value="{_num(step_length)}"/>',
        "    </time>",
        "</configuration>",
    ]) + "\n"
    path.write_text(text, encoding="utf-8")
    return path
