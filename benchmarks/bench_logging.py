"""Logging benchmark: what ``McapLogger.on_step`` costs per vehicle-step.

Usage: python benchmarks/bench_logging.py [--quick] [--out benchmarks/results/logging.csv]

No SUMO and no controllers: a synthetic fleet of V vehicles (V = 100, 1000) in
two classes, shaped like the ``bridge.cosim`` groups the logger reads (state
rows, waypoint routes as one buffer, current waypoint ``k``, membership index
``l``), and a synthetic TM decision with real :class:`tm.claims.Claims` (a
nested family of squares, so ``Claims.polygons()`` has 8 vertices as the city
classes' claims do).  Every step every vehicle moves; as measured on ``muvsim
run grid`` (100 s, ``--log full``), a vehicle's waypoint advances in ~10 % of
its steps and its claim changes in ~70 %; the index changes in 30 %; 70 % of
the vehicles request, half of the requests are granted; conflict edges are
2 % of V.  The logger writes a real ``run.mcap`` in a temporary directory.

Per level (``summary``, ``full``) and V, over the measured steps after a few
warm-up steps: mean (and median) wall time of ``on_step`` per step -- its own
``logging_ms``, which includes encoding and handing the messages to the MCAP
writer and its zstd chunks -- and per vehicle-step; the process CPU time of
``on_step`` per vehicle-step (steadier than wall time on a shared machine); the
file's bytes per vehicle-step; the time of ``close()``.  Prints a table and
writes it as CSV.  One machine, means.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from analysis.mcap_log import McapLogger  # noqa: E402
from tm.claims import Claims  # noqa: E402
from tm.families import build_family_table  # noqa: E402

TS = 0.1
CLASSES = {"car": (5.0, 1.8), "bus": (12.0, 2.5)}
LEVELS = 6  # P^0 .. P^5
K_ROUTE = 200  # waypoints per route


class SyntheticGroup:
    """The attributes and ``centres()``, ``world_centres()`` of ``bridge.cosim._Group`` that the logger
    reads (a road-frame plant: the two are the same)."""

    def __init__(self, rng, name, ids):
        n = len(ids)
        self.vclass = SimpleNamespace(name=name, length=CLASSES[name][0], width=CLASSES[name][1])
        self.ids = list(ids)
        start = rng.uniform(-1000, 1000, size=(n, 1, 2))
        heading = rng.uniform(-np.pi, np.pi, size=(n, 1))
        steps = np.cumsum(np.ones((n, K_ROUTE)), axis=1)
        route = start + np.stack([np.cos(heading) * steps, np.sin(heading) * steps], axis=-1)
        self.W = list(route)
        self._wbuf = np.concatenate([route.reshape(-1, 2), np.repeat(heading, K_ROUTE).reshape(-1, 1)], axis=1)
        self.start = np.arange(n) * K_ROUTE
        self.K = np.full(n, K_ROUTE)
        self.k = rng.integers(0, K_ROUTE // 2, size=n)
        self.l = rng.integers(0, LEVELS, size=n)
        cen = self.centres()[0]
        self.X = np.concatenate([cen + rng.normal(size=(n, 2)), rng.normal(size=(n, 2)) * 3.0,
                                 np.zeros((n, 2))], axis=1)

    def centres(self, offset=0):
        row = self._wbuf[self.start + np.minimum(self.k + offset, self.K - 1)]
        return row[:, :2], row[:, 2], self.k + offset < self.K

    world_centres = centres

    def advance(self, rng):
        n = len(self.ids)
        self.X[:, :2] += self.X[:, 2:4] * TS
        self.X[:, 2:4] += rng.normal(size=(n, 2)) * 0.1
        self.k = np.minimum(self.k + (rng.random(n) < 0.1), self.K - 1)
        self.l = np.where(rng.random(n) < 0.3, rng.integers(0, LEVELS, size=n), self.l)


def family_table():
    squares = [np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=float) * 0.5 * (lv + 1) for lv in range(LEVELS)]
    return build_family_table({name: squares for name in CLASSES})


class SyntheticFleet:
    """A sim (``settings.Ts``, ``groups``) and a TM decision per step."""

    def __init__(self, V: int, seed: int = 0):
        self.rng = np.random.default_rng(seed)
        half = V // 2
        self.groups = {"car": SyntheticGroup(self.rng, "car", [f"car{i}" for i in range(V - half)]),
                       "bus": SyntheticGroup(self.rng, "bus", [f"bus{i}" for i in range(half)])}
        self.sim = SimpleNamespace(settings=SimpleNamespace(Ts=TS), groups=self.groups,
                                   world_states=lambda g: g.X[:, :4])
        self.table = family_table()
        self.V = V
        gs = list(self.groups.values())
        self.claim_centre = np.vstack([g.centres()[0] for g in gs])
        self.claim_index = np.concatenate([g.l for g in gs])
        self.t = 0

    def step(self):
        """(sim, state, decision, row) of the next step."""
        rng, V = self.rng, self.V
        for g in self.groups.values():
            g.advance(rng)
        gs = list(self.groups.values())
        ids = tuple(v for g in gs for v in g.ids)
        centre = np.vstack([g.centres()[0] for g in gs])
        heading = np.concatenate([g.centres()[1] for g in gs])
        change = rng.random(V) < 0.7
        self.claim_centre = np.where(change[:, None], centre, self.claim_centre)
        self.claim_index = np.where(change, rng.integers(0, LEVELS, size=V), self.claim_index)
        family = np.concatenate([np.full(len(g.ids), f) for f, g in enumerate(gs)])
        length = np.concatenate([np.full(len(g.ids), g.vclass.length) for g in gs])
        width = np.concatenate([np.full(len(g.ids), g.vclass.width) for g in gs])
        claims = Claims(self.table, family, self.claim_centre.copy(), self.claim_index.copy(), heading,
                        length, width)
        req = rng.random(V) < 0.7
        go = req & (rng.random(V) < 0.5)
        forced = req & ~go & (rng.random(V) < 0.2)
        edges = rng.integers(0, V, size=(max(1, V // 50), 2))
        decision = SimpleNamespace(ids=ids, requesting=req, go=go, forced=forced, edges=edges,
                                   edge_kinds=np.array(["new-new"] * len(edges)),
                                   stopped=tuple(v for v, r, g in zip(ids, req, go) if r and not g),
                                   claims=claims)
        row = {"t_s": round(self.t * TS, 6), "tm_ms": 1.0}
        self.t += 1
        return self.sim, SimpleNamespace(centre=centre), decision, row


def measure(level: str, V: int, steps: int, warmup: int, tmp: Path) -> dict:
    """Log ``warmup + steps`` steps of a fresh fleet of ``V``; figures of the last ``steps``."""
    fleet = SyntheticFleet(V)
    path = tmp / f"{level}_{V}.mcap"
    ms, cpu = [], []
    log = McapLogger(path, level)
    try:
        for t in range(warmup + steps):
            sim, state, dec, row = fleet.step()
            c0 = time.process_time()
            log.on_step(sim, state, dec, row)
            if t >= warmup:
                cpu.append(time.process_time() - c0)
                ms.append(row["logging_ms"])
    finally:
        c0 = time.perf_counter()
        log.close()
        close_ms = (time.perf_counter() - c0) * 1e3
    ms_step = float(np.mean(ms))
    return {"level": level, "vehicles": V, "steps": steps, "ms_per_step": round(ms_step, 4),
            "ms_per_step_median": round(float(np.median(ms)), 4),
            "us_per_vehicle_step": round(ms_step * 1e3 / V, 3),
            "cpu_us_per_vehicle_step": round(float(np.mean(cpu)) * 1e6 / V, 3),
            "bytes_per_vehicle_step": round(path.stat().st_size / (V * (warmup + steps)), 1),
            "close_ms": round(close_ms, 2)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="few steps (a smoke test of the script)")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "logging.csv")
    args = ap.parse_args(argv)
    steps, warmup = (5, 2) if args.quick else (200, 10)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for level in ("summary", "full"):
            for V in (100, 1000):
                rows.append(measure(level, V, steps, warmup, Path(tmp)))
                r = rows[-1]
                print(f"{level:8s} V={V:5d}  {r['ms_per_step']:8.3f} ms/step  "
                      f"{r['us_per_vehicle_step']:7.2f} us/vehicle-step (cpu {r['cpu_us_per_vehicle_step']:.2f})  "
                      f"{r['bytes_per_vehicle_step']:6.1f} B/vehicle-step", flush=True)
    df = pd.DataFrame(rows)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(args.out, index=False)
    print(df.to_string(index=False))
    print(f"written: {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
