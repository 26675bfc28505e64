"""A lone vehicle on a straight 13.89 m/s road with a slow stretch: its speed profile against the limit.

    .venv/bin/python benchmarks/bench_speed_limits.py [--slow 5] [--controller authority]

Free plane (muvsim's plant and monitor only), every request decided by the TM (alone: granted
unless the speed rule withholds it).  Writes ``benchmarks/results/speed_limits.csv`` (one row per
run) and ``benchmarks/results/speed_profile_<controller>_<slow>.png``.
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np

from bridge.cosim import Cosim, CosimSettings, VehicleSpec
from bridge.waypoints import subsample
from controllers.classes import builtin_classes
from controllers.speed_limits import SpeedSettings

OUT = Path(__file__).resolve().parent / "results"


def run(controller: str, slow: float, zone=(200.0, 260.0), length=400.0, vclass="car", seed=0,
        disturbance="random", lane_limits=True):
    """One run; returns (t, centre arc, speed, lane limit at the front) per step and the figures."""
    classes = builtin_classes()
    vc = classes[vclass]
    W, arc = subsample(np.array([[0.0, 0.0], [length, 0.0]]), vc.model.delta)
    lim = np.where((arc >= zone[0]) & (arc <= zone[1]), slow, 13.89)
    spec = VehicleSpec("v0", vclass, W, speed_limits=lim)
    sim = Cosim(classes, [spec], CosimSettings(controller=controller, disturbance=disturbance, seed=seed,
                                                     speed=SpeedSettings(lane_limits=lane_limits)))
    sim._admit(0.0)
    rows = []
    g = sim.groups[vclass]
    while not sim.done and sim.t < 3000:
        sim.step()
        if g.ids:
            _, limit = g.speed_caps(sim.settings.Ts)
            rows.append((sim.t * sim.settings.Ts, float(g.X[0, 0]), float(g.X[0, 2]), float(limit[0])))
    sim.flush_records()
    rec = sim.records["v0"]
    prof = np.array(rows)
    front = prof[:, 1] + 0.5 * vc.length
    inz = (front >= zone[0]) & (front <= zone[1])
    return prof, {
        "controller": controller, "vclass": vclass, "slow_mps": slow, "zone_m": f"{zone[0]:g}-{zone[1]:g}",
        "disturbance": disturbance, "seed": seed,
        "speed_limit_excess_max": round(max(rec.speed_limit_excess, 0.0), 4),
        "max_speed_in_zone": round(float(prof[inz, 2].max()), 4),
        "median_speed_in_zone": round(float(np.median(prof[inz, 2])), 4),
        "max_speed": round(float(prof[:, 2].max()), 4),
        "travel_time_s": None if rec.arrived_s is None else round(rec.arrived_s - rec.admitted_s, 2),
        "free_flow_s": round(rec.free_flow_s, 2),
        "invariant_violations": sim.invariant_violations, "lane_limits": lane_limits,
        "tube_escapes": int(getattr(sim.monitor, "tube_escapes", 0)),
        "constraint_violations": sim.constraint_violations,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--slow", type=float, nargs="+", default=[5.0])
    ap.add_argument("--controller", nargs="+", default=["authority", "paper"])
    ap.add_argument("--plot", action="store_true")
    a = ap.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    rows = []
    for c in a.controller:
        for slow in a.slow:
            prof, fig = run(c, slow)
            rows.append(fig)
            print(fig)
            if a.plot:
                import matplotlib
                matplotlib.use("Agg")
                import matplotlib.pyplot as plt
                f, ax = plt.subplots(figsize=(8, 3.5))
                ax.plot(prof[:, 1] + 2.5, prof[:, 2], label="speed (m/s)")
                ax.step(prof[:, 1] + 2.5, prof[:, 3], where="post", label="lane limit under the front")
                ax.set_xlabel("front position (m)")
                ax.set_ylabel("m/s")
                ax.set_title(f"{c}: lone car, 13.89 m/s road, {slow:g} m/s on 200-260 m")
                ax.legend(loc="lower left")
                f.tight_layout()
                f.savefig(OUT / f"speed_profile_{c}_{slow:g}.png", dpi=90)
                plt.close(f)
    path = OUT / "speed_limits.csv"
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


if __name__ == "__main__":
    main()
