"""Time vehicles spend near junction centres, turning or going straight, from a run's MCAP log.

Usage: ``python scripts/junction_passages.py RUN_DIR [--radius M]`` (a ``muvsim run`` output with
``run.mcap`` at ``--log summary`` or ``full`` and the network under ``RUN_DIR/inputs``); passages as
:func:`analysis.passages.junction_passages` defines them.  Prints the count, median duration, median
lowest speed and median mean speed of turns and straights.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np


def passages(run: Path, radius: float = 12.0):
    import sumolib

    from analysis.mcap_log import read_vehicle_states
    from analysis.passages import junction_passages

    nets = sorted(Path(run, "inputs").rglob("*.net.xml*"))
    if not nets:
        raise SystemExit(f"{run}/inputs: no .net.xml found (is this a SUMO run's output directory?)")
    if not Path(run, "run.mcap").exists():
        raise SystemExit(f"{run}: no run.mcap (a muvsim run with --log summary or full; --baseline sumo writes none)")
    net = sumolib.net.readNet(str(nets[0]))
    J = np.array([n.getCoord() for n in net.getNodes() if n.getType() != "dead_end"])
    d = read_vehicle_states(Path(run, "run.mcap"))
    if d.empty:
        raise SystemExit(f"{run}/run.mcap: no vehicle states")
    return junction_passages(d, J, radius)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", help="a muvsim run output directory")
    ap.add_argument("--radius", type=float, default=12.0, help="distance from a junction centre (m, default 12)")
    a = ap.parse_args(argv)
    out = passages(Path(a.run), a.radius)
    print("kind      passages  median duration (s)  median lowest speed (m/s)  median mean speed (m/s)")
    for kind, g in out.groupby("kind"):
        print(f"{kind:9s} {len(g):8d}  {g['duration_s'].median():19.1f}  {g['v_min'].median():25.2f}"
              f"  {g['v_mean'].median():23.2f}")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    sys.exit(main())
