"""What a vehicle's body padding table costs when it is admitted: :class:`bridge.sumo_body.RouteBody`
and its :class:`bridge.sumo_body.PadTable`, on the routes of a real scenario.

Usage::

    python benchmarks/bench_pads.py [--scenario grid | --scale N] [--routes 40] [--repeat 3]
                                    [--fleet 1000] [--steps 30] [--out benchmarks/results/pads.csv]

The scenario's network and demand are generated into a temporary directory
(:func:`sumo_nets.scenario.materialise`; default the built-in ``grid``: 4 x 4 junctions, 100 m
blocks, 2 lanes; ``--scale N``: ``benchmarks/bench_scale.py``'s scenario of ``N`` vehicles, e.g.
1000: an 11 x 11 grid whose trips run at least half its diagonal); the first ``--routes`` routes
of its demand are resolved as the co-simulation does for the urban classes (``NetGeometry.route``,
3 m waypoints, turns over 45 degrees cut).  For every route, each size (car 5.0 x 1.8 m, bus 12.0 x
2.5 m) and frame (``road``, ``path``): a fresh ``RouteBody`` and its ``PadTable`` (the box 40 m
back to 1.2 m ahead, offsets up to the class's across extent: 0.95 m car, 1.5 m bus, as
:data:`bridge.sumo_body.OFFSET_MAX_M` caps), timed together, best of ``--repeat`` per table (the
machine is shared).

Prints and writes, per size and frame and over all: tables, median route length (m) and samples,
median and total ms per table (``RouteBody`` + ``PadTable``), and the median ms of
``RouteBody.bodies`` over a table's samples at offset 0 (one of the three calls a table makes).
A last row (``size = fleet``): the per-step use of the same code, a car's body on each of the first
``--fleet`` routes of the demand in one :class:`bridge.body_fleet.FleetBodies`, one reference point
each (random arc, offset up to 0.5 m): ``FleetBodies.project`` (window 0.3 m behind) then
``FleetBodies.bodies``, median ms of ``--steps`` calls (``ms_median``, in ``tables`` the vehicles).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bridge.body_fleet import FleetBodies  # noqa: E402
from bridge.groups import _headings  # noqa: E402
from bridge.sumo_body import SAMPLE_M, RouteBody, _at  # noqa: E402
from bridge.waypoints import load_net  # noqa: E402
from controllers.classes import CITY_TURN_MAX_DEG  # noqa: E402
from sumo_nets.scenario import load_scenario, materialise  # noqa: E402

#: name: (SUMO vClass, length, width, across extent of the padding box (m))
SIZES = {"car": ("passenger", 5.0, 1.8, 0.95), "bus": ("bus", 12.0, 2.5, 1.5)}


def fleet_ms(net, all_edges, steps: int) -> float:
    """Median ms of one step's ``FleetBodies.project`` + ``bodies`` for a car on each route."""
    fleet, bodies = FleetBodies(), []
    for i, e in enumerate(all_edges):
        b = RouteBody(net.route(e, 3.0, vclass="passenger", turn_max_deg=CITY_TURN_MAX_DEG), net, 5.0, 1.8)
        fleet.add(str(i), b)
        bodies.append(b)
    ids = [str(i) for i in range(len(bodies))]
    rng = np.random.default_rng(1)
    sig = np.array([rng.uniform(0.0, b.route_length) for b in bodies])
    off = rng.uniform(-0.5, 0.5, len(bodies))
    p = np.empty((len(bodies), 2))
    for i, b in enumerate(bodies):
        q, t, _ = _at(b.poly, b.parc, sig[i:i + 1])
        p[i] = q[0] + off[i] * np.array([-t[0, 1], t[0, 0]])
    fleet.bodies(ids[:1], sig[:1], off[:1])  # its arrays built outside the timing
    ms = []
    for _ in range(steps):
        t0 = time.perf_counter()
        s, e = fleet.project(ids, p, sig - 0.3)
        fleet.bodies(ids, s, e)
        ms.append(1e3 * (time.perf_counter() - t0))
    return float(np.median(ms))


def routes(scenario: str, scale: int | None, n: int, work: Path):
    if scale is not None:
        from benchmarks.bench_scale import case_for, scenario_toml

        path = work / "scale.toml"
        path.write_text(scenario_toml(case_for(scale, 60.0, 30.0)), encoding="utf-8")
        scenario = str(path)
    files = materialise(load_scenario(scenario), work)
    net = load_net(files.net)
    edges = [r.get("edges").split() for r in ET.parse(files.routes[0]).getroot().iter("route")][:n]
    return net, edges


def best_ms(fn, repeat: int) -> tuple[float, object]:
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, 1e3 * (time.perf_counter() - t0))
    return best, out


def main(argv=None) -> pd.DataFrame:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="grid")
    ap.add_argument("--scale", type=int, default=None, help="bench_scale.py's scenario of this many vehicles")
    ap.add_argument("--routes", type=int, default=40)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--fleet", type=int, default=1000, help="vehicles of the fleet row (at most the demand's routes)")
    ap.add_argument("--steps", type=int, default=30, help="steps timed for the fleet row")
    ap.add_argument("--out", default="benchmarks/results/pads.csv")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        net, all_edges = routes(a.scenario, a.scale, max(a.routes, a.fleet), Path(tmp))
    fleet_edges, all_edges = all_edges[:a.fleet], all_edges[:a.routes]
    rows = []
    for name, (vclass, L, Wd, across) in SIZES.items():
        R = [net.route(e, 3.0, vclass=vclass, turn_max_deg=CITY_TURN_MAX_DEG) for e in all_edges]
        box = ((-40.0, -across), (1.2, across))
        for frame in ("road", "path"):
            for r in R:
                H = _headings(r.waypoints)

                def build():
                    b = RouteBody(r, net, L, Wd)
                    return b.pad_table(r.arc_length, r.waypoints, H, *box, frame=frame)

                ms, t = best_ms(build, a.repeat)
                b = RouteBody(r, net, L, Wd)
                b.bodies(t.sig[:2], 0.0)  # its arrays built outside the timing
                ms_b, _ = best_ms(lambda: b.bodies(t.sig, 0.0), a.repeat)
                rows.append(dict(size=name, frame=frame, route_m=b.route_length, samples=len(t.sig), ms=ms,
                                 bodies_ms=ms_b))
    df = pd.DataFrame(rows)

    def summary(g, size, frame):
        return dict(size=size, frame=frame, tables=len(g), route_m_median=float(g.route_m.median()),
                    samples_median=float(g.samples.median()), ms_median=float(g.ms.median()),
                    ms_total=float(g.ms.sum()), bodies_ms_median=float(g.bodies_ms.median()))

    out = [summary(g, s, f) for (s, f), g in df.groupby(["size", "frame"], sort=False)]
    out.append(summary(df, "all", "all"))
    out.append(dict(size="fleet", frame="step", tables=len(fleet_edges), ms_median=fleet_ms(net, fleet_edges, a.steps)))
    res = pd.DataFrame(out)
    res["sample_m"] = SAMPLE_M
    res["scenario"] = a.scenario if a.scale is None else f"bench_scale {a.scale}"
    res["repeat"] = a.repeat
    res["command"] = "python benchmarks/bench_pads.py " + " ".join(argv if argv is not None else sys.argv[1:])
    print(res.drop(columns=["command"]).to_string(index=False, float_format=lambda x: f"{x:.4g}"))
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    res.to_csv(a.out, index=False)
    print(f"wrote {a.out}")
    return res


if __name__ == "__main__":
    main()
