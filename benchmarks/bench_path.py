"""Path frames of real routes: the cost of :class:`controllers.path.PathFrame` (built once per vehicle
when it is admitted), its collinear merge blocked and vectorised against the one-candidate-at-a-time
loop it replaced, on the same routes in the same run.

Usage::

    python benchmarks/bench_path.py [--junctions 8] [--vehicles 60] [--seed 1] [--out benchmarks/results/path.csv]

A ``junctions x junctions`` grid (100 m blocks, 2 lanes, ``sumo_nets.generate.make_grid``), random
trips routed by duarouter (``make_demand``), each route's waypoints at most 1 m apart
(``NetGeometry.route``, as a car's).  Prints and writes, per method, the median and total ms per
route and the median number of waypoints; the two methods keep the same vertices on every route
(checked here; the tests compare them on random routes).
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

from bridge.waypoints import load_net  # noqa: E402
from controllers import path as cpath  # noqa: E402
from controllers.tolerances import PATH_COLLINEAR_TOL_M  # noqa: E402
from sumo_nets.generate import make_demand, make_grid  # noqa: E402


def merge_loop(P, tol, fixed=None):
    """The merge before the blocked one: one candidate vertex at a time (numpy calls per point)."""
    keep = [0]
    a, n = 0, len(P)
    j = 1
    while j < n - 1:
        d = P[j + 1] - P[a]
        L = float(np.hypot(d[0], d[1]))
        ok = L > tol and (fixed is None or not fixed[j])
        if ok:
            mid = P[a + 1:j + 1] - P[a]
            t = mid @ d / L
            off = np.abs(mid[:, 0] * d[1] - mid[:, 1] * d[0]) / L
            ok = bool(np.all(off <= tol) and np.all(t > 0.0) and np.all(t < L) and np.all(np.diff(t) > 0.0))
        if not ok:
            keep.append(j)
            a = j
        j += 1
    keep.append(n - 1)
    return np.asarray(keep, dtype=np.intp)


def routes(junctions: int, vehicles: int, seed: int, work: Path) -> list[np.ndarray]:
    net_file = make_grid(work, junctions=junctions, spacing_m=100.0, lanes=2)
    rou = make_demand(net_file, work, seed=seed, vehicles=vehicles, duration_s=60.0, class_mix={"car": 1.0},
                      min_distance_m=300.0)
    net = load_net(net_file)
    out = []
    for r in ET.parse(rou).getroot().iter("route"):
        out.append(np.asarray(net.route(r.get("edges").split(), 1.0).waypoints, dtype=float))
    return out


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
    ap.add_argument("--out", default="benchmarks/results/path.csv")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        W_all = routes(a.junctions, a.vehicles, a.seed, Path(tmp))
    for W in W_all:
        if not np.array_equal(cpath._merge_collinear(W, PATH_COLLINEAR_TOL_M), merge_loop(W, PATH_COLLINEAR_TOL_M)):
            raise SystemExit("bench_path: the two merges keep different vertices on a route")
    rows = []
    fast, loop = time_frames(W_all, cpath._merge_collinear), time_frames(W_all, merge_loop)
    for name, ms in (("blocked", fast), ("loop", loop)):
        rows.append(dict(method=name, routes=len(W_all), waypoints_median=float(np.median([len(W) for W in W_all])),
                         ms_median=float(np.median(ms)), ms_total=float(ms.sum())))
    df = pd.DataFrame(rows)
    df["ratio_to_blocked"] = df["ms_median"] / df.loc[df.method == "blocked", "ms_median"].iloc[0]
    print(df.to_string(index=False, float_format=lambda x: f"{x:.3g}"))
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(a.out, index=False)
    print(f"wrote {a.out}")
    return df


if __name__ == "__main__":
    main()
