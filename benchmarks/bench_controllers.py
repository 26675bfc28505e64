"""Controller benchmark: synthesis time and N per class, and online cost per vehicle-step per solver.

Usage: python benchmarks/bench_controllers.py [--quick] [--out benchmarks/results/controllers.csv]
Prints a table and writes it as CSV. Medians over repeats; one run, one machine.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from controllers.classes import builtin_classes
from controllers.settings import ControllerSettings, SynthesisSettings
from controllers.stmpc import STMPC
from controllers.synthesis import synthesize

PAPER_N = {"paper-a": 21, "paper-b": 19, "paper-c": 15, "paper-d": 18}


def main(argv=None) -> pd.DataFrame:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="small sizes (used by the tests)")
    ap.add_argument("--out", default="benchmarks/results/controllers.csv")
    args = ap.parse_args(argv)
    classes = ["paper-c", "car"] if args.quick else list(builtin_classes())
    vehicles = 50 if args.quick else 1000
    repeats = 3 if args.quick else 7
    solvers = ["exact", "daqp"] if args.quick else ["exact", "daqp", "proxsuite"]
    rows = []
    with tempfile.TemporaryDirectory() as cache:
        for name in classes:
            model = builtin_classes()[name].model
            fam = synthesize(model, SynthesisSettings(cache_dir=Path(cache)))
            cached = synthesize(model, SynthesisSettings(cache_dir=Path(cache)))
            t = time.perf_counter()
            synthesize(model, SynthesisSettings(cache_dir=Path(cache)))
            load_s = time.perf_counter() - t
            rng = np.random.default_rng(0)
            X = np.vstack([fam.sample(l, max(vehicles // (fam.N + 1), 1), rng) for l in range(fam.N + 1)])
            C = np.zeros((len(X), 2))
            H = np.zeros(len(X))  # segment headings (road-frame classes); 0: frames coincide
            # time the QP on states that need it (l >= 1); the index on all states
            Xq = X[STMPC(fam).index(X, C, H) > 0]
            Cq = np.zeros((len(Xq), 2))
            Hq = np.zeros(len(Xq))
            for solver in solvers:
                ctl = STMPC(fam, ControllerSettings(solver=solver))
                n = len(X) if solver == "exact" else min(len(X), 200)
                idx_t, ctl_t = [], []
                for _ in range(repeats):
                    t = time.perf_counter()
                    l = ctl.index(X[:n], C[:n], H[:n])
                    idx_t.append(time.perf_counter() - t)
                    nq = min(n, len(Xq))
                    lq = ctl.index(Xq[:nq], Cq[:nq], Hq[:nq])
                    t = time.perf_counter()
                    ctl.control(Xq[:nq], Cq[:nq], lq, heading=Hq[:nq])
                    ctl_t.append((time.perf_counter() - t) / nq * n)
                rows.append({
                    "class": name, "N": fam.N, "paper_N": PAPER_N.get(name), "facets_T0": fam.facet_counts()[0],
                    "facets_TN": fam.facet_counts()[-1], "synthesis_s": round(fam.seconds, 4),
                    "cached_load_s": round(load_s, 4), "from_cache_second_call": cached.from_cache,
                    "solver": solver, "vehicles": n,
                    "index_us_per_vehicle": round(np.median(idx_t) / n * 1e6, 2),
                    "qp_us_per_vehicle": round(np.median(ctl_t) / n * 1e6, 2),
                })
    df = pd.DataFrame(rows)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(args.out, index=False)
    print(df.to_string(index=False))
    return df


if __name__ == "__main__":
    main()
