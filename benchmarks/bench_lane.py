"""One lane: flow at cruise, queue discharge and the 20th car's time past the line, muvsim's
movement-authority cars (reach claims, ``timed`` and ``union``) against SUMO's Krauss drivers on
the same lane in the same run.

Usage::

    python benchmarks/bench_lane.py [--quick] [--seed 0] [--out benchmarks/results/lane.csv]

The lane is straight, 600 m, speed limit 13.89 m/s, a stop line at 500 m; cars (5 m) enter at
the start as fast as they can (SUMO: a flow far above capacity, ``departSpeed=max``, Krauss
defaults but ``speedDev=0`` so every driver keeps the limit as muvsim's cars do; muvsim: a
car at 13.89 m/s whenever its claims miss every claim on the lane, condition (12)).

* ``cruise``: the light stays green; ``flow_vph`` counts fronts passing x = 300 m after the
  first ``warmup`` seconds.
* ``queue``: red for ``red`` seconds (the queue fills back from the line), then green;
  ``flow_vph`` is the discharge over the line from the 1st to the 20th car after green
  (19 headways), ``t20_s`` the 20th car's front past the line, after green.

muvsim rows also give the safety counters (claim overlaps, footprint overlaps, index invariant
violations, all must be 0); SUMO rows its collisions; ``crossed``: fronts past the measured line.  ``--quick``: short runs (cruise 30 s,
red 15 s, green 25 s); the figures are then only a smoke test.
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

from controllers.classes import get_class
from controllers.settings import SynthesisSettings
from sumo_nets.sumo_tools import binary, run_tool
from tm.lane import Lane, LaneSettings, lane_class

LENGTH, STOP, MEASURE, V = 600.0, 500.0, 300.0, 13.89
COLUMNS = ["driver", "check", "experiment", "flow_vph", "t20_s", "crossed", "claim_overlaps", "footprint_overlaps",
           "invariant_violations", "collisions", "sim_s", "wall_s"]


def _headway_flow(times: np.ndarray, first: int = 0, last: int | None = None) -> float:
    t = np.sort(times)[first:last]
    return float((len(t) - 1) / (t[-1] - t[0]) * 3600.0) if len(t) > 1 and t[-1] > t[0] else float("nan")


# ---------------------------------------------------------------------------- muvsim
def run_muvsim(check: str, experiment: str, sim_s: float, red_s: float, warmup_s: float, seed: int,
               cache: Path | None) -> dict:
    car = lane_class(get_class("car"), SynthesisSettings(cache_dir=cache))
    half = 0.5 * car.vclass.length
    lane = Lane(LaneSettings(check=check, disturbance="random", seed=seed, v_entry=V))
    line = MEASURE if experiment == "cruise" else STOP
    lane.crossings[line - half] = []  # the log records the centre: front = centre + L/2
    t0 = time.perf_counter()
    green_at = red_s if experiment == "queue" else 0.0
    t00_extent = float(car.reach.tables.p_hi[0])
    for t in range(int(round(sim_s / 0.1))):
        now = t * 0.1
        # red: no stop point whose T^0 ⊕ footprint reaches past the line
        lane.stop_k = int(np.floor((STOP - half - t00_extent) / lane.delta)) if now < green_at else None
        lane.try_enter(car)
        lane.step()
        lane.remove_beyond(LENGTH)
    wall = time.perf_counter() - t0
    times = np.array([c[1] for c in lane.crossings[line - half]])
    if experiment == "cruise":
        flow, t20 = _headway_flow(times[times >= warmup_s]), float("nan")
    else:
        after = np.sort(times[times >= green_at]) - green_at
        flow = _headway_flow(after, 0, 20) if len(after) >= 20 else float("nan")
        t20 = float(after[19]) if len(after) >= 20 else float("nan")
    return dict(driver="muvsim", check=check, experiment=experiment, flow_vph=flow, t20_s=t20,
                crossed=len(times), claim_overlaps=lane.claim_overlaps,
                footprint_overlaps=lane.footprint_overlaps, invariant_violations=lane.invariant_violations,
                collisions=lane.footprint_overlaps, sim_s=sim_s, wall_s=round(wall, 2))


# ---------------------------------------------------------------------------- SUMO
def _write_lane(d: Path, experiment: str, red_s: float, sim_s: float) -> Path:
    (d / "lane.nod.xml").write_text(
        '<nodes>\n  <node id="A" x="0" y="0"/>\n'
        f'  <node id="B" x="{STOP}" y="0" type="traffic_light"/>\n'
        f'  <node id="C" x="{LENGTH}" y="0"/>\n</nodes>\n')
    (d / "lane.edg.xml").write_text(
        '<edges>\n'
        f'  <edge id="AB" from="A" to="B" numLanes="1" speed="{V}"/>\n'
        f'  <edge id="BC" from="B" to="C" numLanes="1" speed="{V}"/>\n</edges>\n')
    run_tool([binary("netconvert"), "-n", "lane.nod.xml", "-e", "lane.edg.xml", "-o", "lane.net.xml",
              "--no-turnarounds", "true"], what="one-lane network", cwd=d)
    (d / "lane.rou.xml").write_text(
        '<routes>\n  <vType id="car" vClass="passenger" speedDev="0"/>\n  <route id="r" edges="AB BC"/>\n'
        f'  <flow id="f" type="car" begin="0" end="{sim_s}" vehsPerHour="10000" route="r" departSpeed="max" '
        'departPos="base" departLane="first"/>\n</routes>\n')
    phases = (f'    <phase duration="{red_s}" state="r"/>\n' if experiment == "queue" and red_s > 0 else "") + \
        f'    <phase duration="{10 * sim_s}" state="G"/>\n'
    (d / "lane.add.xml").write_text(
        '<additional>\n'
        f'  <tlLogic id="B" type="static" programID="bench" offset="0">\n{phases}  </tlLogic>\n'
        f'  <instantInductionLoop id="measure" lane="AB_0" pos="{MEASURE}" file="measure.xml"/>\n'
        f'  <instantInductionLoop id="stop" lane="BC_0" pos="0.1" file="stop.xml"/>\n'
        '</additional>\n')
    cfg = d / "lane.sumocfg"
    cfg.write_text('<configuration>\n  <input>\n    <net-file value="lane.net.xml"/>\n'
                   '    <route-files value="lane.rou.xml"/>\n    <additional-files value="lane.add.xml"/>\n'
                   '  </input>\n</configuration>\n')
    return cfg


def _enter_times(path: Path) -> np.ndarray:
    if not path.exists():
        return np.zeros(0)
    root = ET.parse(path).getroot()
    return np.array([float(e.get("time")) for e in root.iter("instantOut") if e.get("state") == "enter"])


def run_sumo(experiment: str, sim_s: float, red_s: float, warmup_s: float, seed: int) -> dict:
    with tempfile.TemporaryDirectory(prefix="bench-lane-") as tmp:
        d = Path(tmp)
        cfg = _write_lane(d, experiment, red_s, sim_s)
        t0 = time.perf_counter()
        # the sumo binary, with run_native's collision options (libsumo runs one simulation per process)
        run_tool([binary("sumo"), "-c", cfg, "--step-length", "0.1", "--seed", str(seed), "--end", str(sim_s),
                  "--collision.action", "warn", "--collision.check-junctions", "true",
                  "--collision.mingap-factor", "0", "--collision-output", "collisions.xml",
                  "--tripinfo-output", "trips.xml", "--no-step-log", "true"], what="SUMO lane run", cwd=d)
        root = ET.parse(d / "collisions.xml").getroot()
        pairs = {tuple(sorted((c.get("collider"), c.get("victim")))) for c in root.iter("collision")}
        wall = time.perf_counter() - t0
        if experiment == "cruise":
            times = _enter_times(d / "measure.xml")
            flow, t20 = _headway_flow(times[times >= warmup_s]), float("nan")
        else:
            after = np.sort(_enter_times(d / "stop.xml"))
            after = after[after >= red_s] - red_s
            flow = _headway_flow(after, 0, 20) if len(after) >= 20 else float("nan")
            t20 = float(after[19]) if len(after) >= 20 else float("nan")
        crossed = len(_enter_times(d / ("measure.xml" if experiment == "cruise" else "stop.xml")))
    return dict(driver="sumo", check="-", experiment=experiment, flow_vph=flow, t20_s=t20, crossed=crossed,
                claim_overlaps=0, footprint_overlaps=0, invariant_violations=0,
                collisions=len(pairs), sim_s=sim_s, wall_s=round(wall, 2))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="short runs (a smoke test)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cache-dir", type=Path, default=None, help="set cache (default: muvsim's)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "lane.csv")
    a = ap.parse_args(argv)
    cruise_s, warm, red, green = (30.0, 10.0, 15.0, 25.0) if a.quick else (150.0, 60.0, 60.0, 60.0)
    rows = []
    for experiment, sim_s in (("cruise", cruise_s), ("queue", red + green)):
        rows.append(run_sumo(experiment, sim_s, red, warm, a.seed))
        for check in ("timed", "union"):
            rows.append(run_muvsim(check, experiment, sim_s, red, warm, a.seed, a.cache_dir))
        for r in rows[-3:]:
            print(f"{r['experiment']:7s} {r['driver']:7s} {r['check']:6s} flow {r['flow_vph']:7.0f} veh/h  "
                  f"20th car {r['t20_s']:6.1f} s  crossed {r['crossed']:4d}  collisions {r['collisions']}  "
                  f"claim overlaps {r['claim_overlaps']}  invariant {r['invariant_violations']}  "
                  f"wall {r['wall_s']} s", flush=True)
    df = pd.DataFrame(rows, columns=COLUMNS)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(a.out, index=False)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
