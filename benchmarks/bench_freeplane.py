"""Free-plane scenarios: time to finish, stops and safety figures per TM option.

Usage: python benchmarks/bench_freeplane.py [--quick] [--out benchmarks/results/freeplane.csv]
Runs paper10 and swap (20 vehicles; 6 with --quick) for check union/timed x switching
terminal/early x policy greedy/optimal, prints a table and writes it as CSV.
"""

from __future__ import annotations

import argparse
import itertools
import tempfile
from pathlib import Path
from types import SimpleNamespace

import pandas as pd

from bridge.scenarios import run_multi


def main(argv=None) -> pd.DataFrame:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", default="benchmarks/results/freeplane.csv")
    args = ap.parse_args(argv)
    rows = []
    scenarios = [("paper10", 10), ("swap", 6 if args.quick else 20)]
    combos = itertools.product(scenarios, ["union", "timed"], ["terminal", "early"], ["greedy", "optimal"])
    with tempfile.TemporaryDirectory() as tmp:
        for (name, n), check, switching, policy in combos:
            if args.quick and (check == "timed" or policy == "greedy"):
                continue
            opts = SimpleNamespace(vclass="paper-a", tm=policy, check=check, switching=switching,
                                   disturbance="random", solver="exact", duration=60.0 if args.quick else 600.0,
                                   vehicles=n, seed=0)
            s = run_multi(name, Path(tmp) / f"{name}-{check}-{switching}-{policy}", opts)
            rows.append({"scenario": name, "vehicles": s["vehicles"], "check": check, "switching": switching,
                         "policy": policy, "finished": s["finished"], "arrived": s["vehicles_arrived"],
                         "time_to_finish_s": s["simulated_s"] if s["finished"] else None,
                         "stop_commands": s["stop_commands"], "collisions_geometric": s["collisions_geometric"],
                         "invariant_violations": s["invariant_violations"],
                         "min_separation_m": round(s["min_separation_m"], 3), "wall_s": s["wall_s"]})
            print(rows[-1], flush=True)
    df = pd.DataFrame(rows)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(args.out, index=False)
    print(df.to_string(index=False))
    return df


if __name__ == "__main__":
    main()
