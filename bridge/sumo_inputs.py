"""A user's SUMO inputs as SUMO reads them, prepared for the two runs muvsim makes.

SUMO itself reads every input of a ``.sumocfg`` (gzipped or not; vehicles,
trips, flows, vTypes and distributions in route-files OR additional-files;
the configuration's ``xml-validation``), so muvsim never re-implements its
parsing.  It only writes filtered copies of the files, in a work directory:

* ``expansion`` inputs: the route files unchanged, the additional files
  without their output elements (``edgeData``, detectors, ``timedEvent``, ...:
  a muvsim run must not write into the scenario's directory).  SUMO expands
  the demand from these (:meth:`bridge.sumo_adapter.SumoAdapter.expand_demand`).
* ``no_demand`` inputs: the same without ``<vehicle>``, ``<trip>`` and
  ``<flow>`` elements (vTypes, routes, distributions, persons, signal programs
  kept): what the co-simulation's SUMO is started with, since muvsim inserts
  every vehicle itself.  Persons and personFlows are passed to SUMO untouched.

Gzipped files (``.gz``) are read transparently and written uncompressed.
"""

from __future__ import annotations

import gzip
import math
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Sequence

__all__ = ["InputError", "PreparedInputs", "parse_xml", "net_turn_accel", "prepare_inputs", "headless_config",
           "OUTPUT_ELEMENTS", "DEMAND_ELEMENTS", "INPUT_OPTIONS"]

#: Additional-file elements that only write outputs (dropped from muvsim's copies).
OUTPUT_ELEMENTS = frozenset({
    "edgeData", "laneData", "timedEvent", "e1Detector", "inductionLoop", "e2Detector", "laneAreaDetector",
    "e3Detector", "entryExitDetector", "instantInductionLoop", "routeProbe", "vTypeProbe", "edgeRelation",
    "tazRelation"})
#: Elements that carry vehicles (muvsim inserts those itself).
DEMAND_ELEMENTS = frozenset({"vehicle", "trip", "flow"})


#: Configuration options naming input files (resolved against the configuration's directory).
INPUT_OPTIONS = frozenset({"net-file", "n", "route-files", "r", "additional-files", "a", "weight-files", "w",
                           "load-state", "mesosim-edgetype-files"})


class InputError(ValueError):
    """An input file SUMO's configuration names that cannot be read; names the file."""


def _open_xml(p: Path):
    """``p`` opened for reading in binary, through gzip when its magic bytes say so."""
    with open(p, "rb") as fh:
        gz = fh.read(2) == b"\x1f\x8b"
    return gzip.open(p, "rb") if gz else open(p, "rb")


def parse_xml(path: str | os.PathLike) -> ET.ElementTree:
    """Parse an XML file, gzipped (by its magic bytes) or not.

    Raises
    ------
    InputError
        Missing, unreadable or not well-formed (the message names the file).
    """
    p = Path(path)
    try:
        with _open_xml(p) as fh:
            return ET.parse(fh)
    except (OSError, EOFError) as exc:
        raise InputError(f"{p}: cannot be read: {getattr(exc, 'strerror', None) or exc}") from None
    except ET.ParseError as exc:
        raise InputError(f"{p}: not well-formed XML ({exc}); SUMO cannot load it") from None


def net_turn_accel(path: str | os.PathLike) -> float | None:
    """The lateral acceleration (m/s^2) netconvert limited the network's turning junction lanes'
    speeds with: the ``limitTurnSpeed`` attribute of the ``<net>`` element (netconvert's option
    ``junctions.limit-turn-speed``, 5.5 by default; SUMO's drivers drive those lanes' speeds).
    None when the network records none (written by netconvert since SUMO 1.2) or a value <= 0
    (turn speeds not limited).  Reads the first element only.

    Raises
    ------
    InputError
        Missing, unreadable or not well-formed (the message names the file); or an attribute that
        is not a number (the message names it and the file).
    """
    p = Path(path)
    try:
        with _open_xml(p) as fh:
            root = next(el for _, el in ET.iterparse(fh, events=("start",)))
    except (OSError, EOFError) as exc:
        raise InputError(f"{p}: cannot be read: {getattr(exc, 'strerror', None) or exc}") from None
    except (ET.ParseError, StopIteration) as exc:
        raise InputError(f"{p}: not well-formed XML ({exc}); SUMO cannot load it") from None
    raw = root.get("limitTurnSpeed")
    if raw is None:
        return None
    try:
        a = float(raw)
    except ValueError:
        raise InputError(f"{p}: <{root.tag}> limitTurnSpeed={raw!r} is not a number (m/s^2; "
                         f"netconvert writes its junctions.limit-turn-speed there)") from None
    return a if math.isfinite(a) and a > 0 else None


@dataclass(frozen=True)
class PreparedInputs:
    """Filtered copies of a configuration's route and additional files (see the module notes)."""

    expansion_routes: tuple[Path, ...]
    expansion_additional: tuple[Path, ...]
    no_demand_routes: tuple[Path, ...]
    no_demand_additional: tuple[Path, ...]

    def args(self, which: str) -> list[str]:
        """SUMO options that replace the configuration's route and additional files."""
        routes, adds = ((self.expansion_routes, self.expansion_additional) if which == "expansion"
                        else (self.no_demand_routes, self.no_demand_additional))
        out = []
        if routes:
            out += ["--route-files", ",".join(str(p) for p in routes)]
        if adds:
            out += ["--additional-files", ",".join(str(p) for p in adds)]
        return out


def _filtered(src: Path, dst: Path, drop: Iterable[str]) -> Path:
    tree = parse_xml(src)
    root = tree.getroot()
    drop = frozenset(drop)
    for parent in list(root.iter()):  # at any depth (e.g. flows inside an <interval>)
        for elem in [e for e in parent if e.tag in drop]:
            parent.remove(elem)
    dst.parent.mkdir(parents=True, exist_ok=True)
    tree.write(dst, encoding="utf-8", xml_declaration=True)
    return dst


def prepare_inputs(routes: Sequence[Path], additional: Sequence[Path], work_dir: str | os.PathLike
                   ) -> PreparedInputs:
    """Write the filtered copies of ``routes`` and ``additional`` into ``work_dir``.

    Raises
    ------
    InputError
        A file cannot be read or is not XML.
    """
    wd = Path(work_dir)

    def name(i: int, p: Path, kind: str) -> Path:
        stem = p.name[:-3] if p.name.endswith(".gz") else p.name
        return wd / f"{kind}{i:02d}_{stem}"

    exp_add = tuple(_filtered(p, name(i, p, "add"), OUTPUT_ELEMENTS) for i, p in enumerate(additional))
    nd_add = tuple(_filtered(p, name(i, p, "add_nodemand"), OUTPUT_ELEMENTS | DEMAND_ELEMENTS)
                   for i, p in enumerate(additional))
    nd_routes = tuple(_filtered(p, name(i, p, "rou_nodemand"), DEMAND_ELEMENTS) for i, p in enumerate(routes))
    return PreparedInputs(tuple(Path(p) for p in routes), exp_add, nd_routes, nd_add)


def headless_config(sumocfg: str | os.PathLike, dest: str | os.PathLike) -> Path:
    """A copy of a configuration that plain ``sumo`` (and libsumo) loads: its ``<gui_only>``
    section dropped (``osg-view`` makes ``sumo -c bs3d.sumocfg`` fail: "No option with the
    name 'osg-view' exists"), input file names made absolute (so the copy finds them), other
    relative names (outputs) left relative: they land next to the copy, not the scenario's.

    Raises
    ------
    InputError
        The configuration cannot be read.
    """
    src = Path(sumocfg).resolve()
    tree = parse_xml(src)
    root = tree.getroot()
    for gui in [e for e in root if e.tag == "gui_only"]:
        root.remove(gui)
    for elem in root.iter():
        if elem.tag in INPUT_OPTIONS and elem.get("value"):
            names = [v for v in elem.get("value").replace(",", " ").split() if v]
            elem.set("value", ",".join(str((src.parent / Path(n).expanduser()).resolve()) for n in names))
    out = Path(dest)
    out.parent.mkdir(parents=True, exist_ok=True)
    tree.write(out, encoding="utf-8", xml_declaration=True)
    return out
