"""What a vehicle costs once, when it is admitted (authority mode in SUMO): its path frame
(:class:`controllers.path.PathFrame`) and its body padding table (:class:`bridge.sumo_body.PadTable`),
each against the code it replaced, on the same routes in the same run.

Usage::

    python benchmarks/bench_admission.py [--junctions 8] [--vehicles 60] [--seed 1] [--out benchmarks/results/admission.csv]

A ``junctions x junctions`` grid (100 m blocks, 2 lanes, ``sumo_nets.generate.make_grid``), random
trips routed by duarouter (``make_demand``), each route's waypoints at most 1 m apart
(``NetGeometry.route``).  Rows:

* ``path_frame`` / ``blocked`` against ``loop``: the collinear merge, candidate vertices a block at
  a time (vectorised) against one at a time (the same vertices on every route: checked here);
* ``pad_table`` / ``all_rows`` against ``lane_by_lane``: a car's path-frame padding table (a
  car's box, 40 m back to 1.2 m ahead, offsets +-0.95 m), SUMO's bodies at its 0.1 m samples
  computed every row at once (:class:`bridge.body_fleet.FleetBodies`) against lane by lane (the
  same arrays: checked here).  Since the table takes its samples block by block through
  ``FleetBodies.corners_at_offsets`` (``benchmarks/bench_pads.py``), ``lane_by_lane`` replaces that
  call only: the rest of the table is the new code in both rows.

Prints and writes the median and total ms per route, the median waypoints and each method's ratio
to the new one.
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
from bridge.sumo_body import RouteBody  # noqa: E402
from bridge.waypoints import load_net  # noqa: E402
from controllers import path as cpath  # noqa: E402
from controllers.tolerances import PATH_COLLINEAR_TOL_M  # noqa: E402
from sumo_nets.generate import make_demand, make_grid  # noqa: E402
from tests.reference import bodies_lane_by_lane, merge_loop  # noqa: E402


#: a car's padding box (path frame): arc from the waypoint and offset (the car's sets, rounded out)
BOX = ((-40.0, -0.95), (1.2, 0.95))


def corners_lane_by_lane(fleet, row, sigma, offsets):
    """``FleetBodies.corners_at_offsets`` of a route's own fleet of one (how a :class:`PadTable` asks
    for its samples' bodies) through :func:`bodies_lane_by_lane`, one offset after the other."""
    b = next(iter(fleet._bodies.values()))
    cs = [bodies_lane_by_lane(b, sigma, np.full(len(sigma), ev))[3] for ev in offsets]
    return [(np.stack([c[:, i, 0] for c in cs]), np.stack([c[:, i, 1] for c in cs])) for i in range(4)]


def pad_tables(net, R, reference: bool):
    saved = FleetBodies.corners_at_offsets
    if reference:  # the PadTable asks its route's fleet of one for its samples' bodies
        FleetBodies.corners_at_offsets = corners_lane_by_lane
    try:
        ms, tables = [], []
        for r in R:
            t0 = time.perf_counter()
            b = RouteBody(r, net, 5.0, 1.8)
            tables.append(b.pad_table(r.arc_length, r.waypoints, _headings(r.waypoints), *BOX, frame="path"))
            ms.append(1e3 * (time.perf_counter() - t0))
        return np.array(ms), tables
    finally:
        FleetBodies.corners_at_offsets = saved


def routes(junctions: int, vehicles: int, seed: int, work: Path):
    net_file = make_grid(work, junctions=junctions, spacing_m=100.0, lanes=2)
    rou = make_demand(net_file, work, seed=seed, vehicles=vehicles, duration_s=60.0, class_mix={"car": 1.0},
                      min_distance_m=300.0)
    net = load_net(net_file)
    return net, [net.route(r.get("edges").split(), 1.0) for r in ET.parse(rou).getroot().iter("route")]


def time_frames(W_all, merge) -> np.ndarray:
    saved = cpath._merge_collinear
    cpath._merge_collinear = merge
    try:
        ms = []
        for W in W_all:
            t0 = time.perf_counter()
            cpath.PathFrame(W)
            ms.append(1e3 * (time.perf_counter() - t0))
        return np.array(ms)
    finally:
        cpath._merge_collinear = saved


def main(argv=None) -> pd.DataFrame:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--junctions", type=int, default=8)
    ap.add_argument("--vehicles", type=int, default=60)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default="benchmarks/results/admission.csv")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        net, R = routes(a.junctions, a.vehicles, a.seed, Path(tmp))
    W_all = [np.asarray(r.waypoints, dtype=float) for r in R]
    def old_merge(P, tol, fixed=None):  # the loop verbatim (``mid @ d``)
        return merge_loop(P, tol, fixed, matvec=True)

    for W in W_all:
        if not np.array_equal(cpath._merge_collinear(W, PATH_COLLINEAR_TOL_M), old_merge(W, PATH_COLLINEAR_TOL_M)):
            raise SystemExit("bench_admission: the two merges keep different vertices on a route")
    wp = float(np.median([len(W) for W in W_all]))
    pad_new, tabs_new = pad_tables(net, R, False)
    pad_ref, tabs_ref = pad_tables(net, R, True)
    for x, y in zip(tabs_new, tabs_ref):
        if not (np.array_equal(x._path_reach, y._path_reach) and np.array_equal(x.step, y.step)):
            raise SystemExit("bench_admission: the two padding tables differ on a route")
    runs = [("path_frame", "blocked", time_frames(W_all, cpath._merge_collinear)),
            ("path_frame", "loop", time_frames(W_all, old_merge)),
            ("pad_table", "all_rows", pad_new), ("pad_table", "lane_by_lane", pad_ref)]
    rows = [dict(part=p, method=m, routes=len(W_all), waypoints_median=wp, ms_median=float(np.median(ms)),
                 ms_total=float(ms.sum())) for p, m, ms in runs]
    df = pd.DataFrame(rows)
    new = df.groupby("part")["ms_median"].transform("first")
    df["ratio_to_new"] = df["ms_median"] / new
    print(df.to_string(index=False, float_format=lambda x: f"{x:.3g}"))
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(a.out, index=False)
    print(f"wrote {a.out}")
    return df


if __name__ == "__main__":
    main()
