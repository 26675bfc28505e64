"""Traffic-manager benchmark: decision time (broad phase + SAT) vs the paper's LPs.

Usage: python benchmarks/bench_tm.py [--quick] [--out benchmarks/results/tm.csv]

Scenario: a 5 x 5 city grid (streets 200 m apart, two opposite lanes each),
vehicles of the synthesised ``car`` and ``bus`` classes (their real position
sets, N = 21 and 31) dropped on the lanes (half uniformly, half within 60 m
before a junction, where they queue) and admitted with
``TrafficManager.admit`` (so the claims are pairwise disjoint, as in a run),
with a random index 0..3.  ``R`` of them request the next waypoint 1 m ahead
with a random index 1..4.

Per (V, R, policy, check): median wall time of ``TrafficManager.decide`` over
repeats and its phases (claims / broad / narrow = Minkowski sums + separating
axes of the candidate pairs / select).  Baseline: the paper builds graph (10)
with one LP per pair that involves a requester, ``R (V - 1) - R (R - 1) / 2``
LPs (scipy ``linprog``, HiGHS).  The time per LP is measured on a sample of
the scenario's own claim pairs; the total is measured outright when it has at
most ``--lp-measure-max`` pairs and otherwise extrapolated (column
``lp_measured``).  Prints a table and writes it as CSV; also prints the
median time of one runtime-monitor step per fleet size (footprints at the
claim centres).  One machine, medians.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from controllers.classes import builtin_classes
from controllers.settings import SynthesisSettings
from controllers.synthesis import synthesize
from tm.geometry import lp_depth
from tm.manager import FleetState, TrafficManager
from tm.monitor import Monitor
from tm.settings import TMSettings

STREETS = np.arange(5) * 200.0
LANE = 1.75
DELTA = 1.0


def families_and_footprints(cache: Path) -> tuple[dict, dict]:
    fams, feet = {}, {}
    for name in ("car", "bus"):
        cls = builtin_classes()[name]
        fams[name] = synthesize(cls.model, SynthesisSettings(cache_dir=cache)).position_sets
        feet[name] = (cls.length, cls.width)
    return fams, feet


def city_fleet(rng: np.random.Generator, tm: TrafficManager, feet: dict, V: int) -> FleetState:
    """Drop candidates on random lanes, admit them in batches until V are in."""
    cols = {k: [] for k in ("ids", "family", "centre", "index", "heading", "length", "width")}
    n = 0
    while n < V:
        m = 2 * (V - n) + 10
        vertical = rng.random(m) < 0.5
        street = rng.choice(STREETS, m)
        side = rng.choice([-1.0, 1.0], m)
        queue = rng.random(m) < 0.5                       # half queue up before a junction
        along = np.where(queue, rng.choice(STREETS, m) - side * rng.uniform(8, 60, m), rng.uniform(-50, 850, m))
        x = np.where(vertical, street + side * LANE, along)
        y = np.where(vertical, along, street - side * LANE)
        heading = np.where(vertical, np.where(side > 0, np.pi / 2, -np.pi / 2), np.where(side > 0, 0.0, np.pi))
        fam = np.where(rng.random(m) < 0.9, "car", "bus")
        cand = dict(ids=[f"c{n}_{t}" for t in range(m)], family=fam.tolist(), centre=np.c_[x, y],
                    index=rng.integers(0, 4, m), heading=heading,
                    length=np.array([feet[f][0] for f in fam]), width=np.array([feet[f][1] for f in fam]))
        current = FleetState(**cols) if n else None
        if current is None:
            ok = tm.admit(FleetState(**{k: v[:0] if k != "centre" else np.zeros((0, 2)) for k, v in cand.items()}),
                          FleetState(**cand))
        else:
            ok = tm.admit(current, FleetState(**cand))
        take = np.flatnonzero(ok)[: V - n]
        for k in cols:
            vals = cand[k]
            picked = [vals[t] for t in take] if isinstance(vals, list) else vals[take]
            cols[k] = (list(cols[k]) + picked) if isinstance(vals, list) else (
                np.concatenate([cols[k], picked]) if n else picked)
        n += len(take)
    cols["ids"] = [f"v{t}" for t in range(V)]
    return FleetState(**cols)


def with_requests(rng: np.random.Generator, state: FleetState, R: int) -> FleetState:
    V = len(state)
    req = np.zeros(V, dtype=bool)
    req[rng.choice(V, R, replace=False)] = True
    step = DELTA * np.c_[np.cos(state.heading), np.sin(state.heading)]
    return FleetState(ids=state.ids, family=state.family, centre=state.centre, index=state.index,
                      heading=state.heading, length=state.length, width=state.width, requesting=req,
                      req_centre=state.centre + step, req_index=rng.integers(1, 5, V),
                      req_heading=state.heading)


def lp_seconds_per_pair(tm: TrafficManager, state: FleetState, rng: np.random.Generator, n: int) -> float:
    claims = tm.claims(state)
    polys = claims.polygons()
    pairs = rng.integers(0, len(state), size=(n, 2))
    t = time.perf_counter()
    for a, b in pairs:
        lp_depth(polys[a], polys[b])
    return (time.perf_counter() - t) / n


def lp_all_requester_pairs(tm: TrafficManager, state: FleetState) -> float:
    """Measured: the paper's graph (10) built by one LP per pair involving a requester."""
    cur = tm.claims(state).polygons()
    req = np.flatnonzero(state.requesting)
    new = tm.claims(FleetState(ids=[state.ids[v] for v in req], family=state.family[req],
                               centre=state.req_centre[req], index=state.req_index[req],
                               heading=state.req_heading[req], length=state.length[req],
                               width=state.width[req])).polygons()
    is_req = state.requesting
    t = time.perf_counter()
    for a, i in enumerate(req):
        for j in range(len(state)):
            if j == i or (is_req[j] and j < i):
                continue
            other = new[np.searchsorted(req, j)] if is_req[j] else cur[j]
            lp_depth(new[a], other)
    return time.perf_counter() - t


def main(argv=None) -> pd.DataFrame:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="small sizes")
    ap.add_argument("--out", default="benchmarks/results/tm.csv")
    ap.add_argument("--lp-measure-max", type=int, default=None,
                    help="measure the LP baseline outright up to this many LPs, extrapolate above "
                         "(default 12000; 1000 with --quick, so the quick run, used by the tests, "
                         "takes both the measured and the extrapolated path in a few seconds)")
    args = ap.parse_args(argv)
    if args.lp_measure_max is None:
        args.lp_measure_max = 1000 if args.quick else 12000
    rng = np.random.default_rng(0)
    cases = [(100, 10), (100, 100)] if args.quick else [(100, 10), (100, 100), (1000, 10), (1000, 100),
                                                         (1000, 1000)]
    repeats = 5 if args.quick else 31
    with tempfile.TemporaryDirectory() as cache:
        families, feet = families_and_footprints(Path(cache))
    rows = []
    fleets: dict[int, FleetState] = {}
    for V, R in cases:
        if V not in fleets:
            fleets[V] = city_fleet(rng, TrafficManager(TMSettings(), families), feet, V)
        state = with_requests(rng, fleets[V], R)
        lp_pairs = R * (V - 1) - R * (R - 1) // 2
        per_lp = lp_seconds_per_pair(TrafficManager(TMSettings(), families), state, rng, 100 if args.quick else 300)
        measured = lp_pairs <= args.lp_measure_max
        lp_total = lp_all_requester_pairs(TrafficManager(TMSettings(), families), state) if measured \
            else per_lp * lp_pairs
        for policy in ("optimal", "greedy"):
            for check in ("union", "timed"):
                tm = TrafficManager(TMSettings(policy=policy, check=check), families)
                tm.decide(state)                                   # warm-up
                walls, phases = [], []
                for _ in range(repeats):
                    t = time.perf_counter()
                    d = tm.decide(state)
                    walls.append(time.perf_counter() - t)
                    ti = d.timings
                    phases.append((ti.claims, ti.broad, ti.narrow, ti.select))
                ph = np.median(np.array(phases), axis=0) * 1e3
                rows.append(dict(vehicles=V, requesting=R, policy=policy, check=check,
                                 decide_ms=np.median(walls) * 1e3, claims_ms=ph[0], broad_ms=ph[1],
                                 narrow_ms=ph[2], select_ms=ph[3], broad_plus_sat_ms=ph[1] + ph[2],
                                 conflicts=len(d.edges), stopped=len(d.stopped),
                                 lp_pairs=lp_pairs, lp_ms_per_pair=per_lp * 1e3, lp_total_s=lp_total,
                                 lp_measured=measured, speedup=lp_total / np.median(walls)))
    for V, fleet in fleets.items():                             # the runtime monitor, every step of a run
        claims = TrafficManager(TMSettings(), families).claims(fleet)
        monitor = Monitor("union")
        walls = []
        for _ in range(repeats):
            t = time.perf_counter()
            ms = monitor.step(fleet.ids, fleet.centre, fleet.heading, fleet.length, fleet.width, claims)
            walls.append(time.perf_counter() - t)
        print(f"monitor step, {V} vehicles: {np.median(walls) * 1e3:.2f} ms (min separation "
              f"{ms.min_separation:.3f} m, {ms.footprint_overlaps} overlaps, {ms.claim_violations} violations)")
    df = pd.DataFrame(rows)
    with pd.option_context("display.width", 200, "display.max_columns", 30, "display.float_format", "{:.3g}".format):
        print(df.to_string(index=False))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(out, index=False)
    print(f"wrote {out}")
    return df


if __name__ == "__main__":
    main()
