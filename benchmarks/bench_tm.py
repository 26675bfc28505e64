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


# ---------------------------------------------------------------- time-indexed reach claims (authority mode)
#: The reach case: fleet sizes, warm-up and measured steps (full, quick).
REACH_SIZES, REACH_SIZES_QUICK = (100, 300, 1000), (100,)
REACH_WARMUP, REACH_STEPS = 150, 40
REACH_WARMUP_QUICK, REACH_STEPS_QUICK = 30, 8


class LaneGrid:
    """Movement-authority vehicles on straight lanes, for the reach-claim TM case.

    Two blocks of parallel lanes ``spacing`` m apart (east/west lanes stacked in y, north/south
    lanes beside them; directions alternate), ``lane_len`` m long, one waypoint per ``delta``.
    Every lane has a stop line (a red light, 25 s of every 60 s, random phase) that no request
    may cross while red.  Vehicles (90 % car, 10 % bus, their synthesised movement-authority
    families) start at rest with random gaps, ask for the next waypoint by the controllers' rule
    (:meth:`controllers.stmpc.STMPC.may_request`), follow the ST-MPC inputs under random
    disturbances, leave at the lane end and are replaced at a lane start (condition (12) with reach
    claims, :func:`tm.reach_book.admit_reach`).  The request rate is the controllers' own.
    """

    MIX = (("car", 0.9), ("bus", 0.1))

    def __init__(self, V: int, rng: np.random.Generator, lane_len: float = 600.0, spacing: float = 5.0,
                 per_lane: int = 18, gap=(3, 16)):
        from controllers.classes import builtin_classes
        from controllers.settings import ControllerSettings
        from controllers.stmpc import STMPC
        from tm.reach_book import ReachBook

        self.rng, self.gap = rng, gap
        cls = builtin_classes()
        names = [m for m, _ in self.MIX]
        self.p = np.array([w for _, w in self.MIX])
        self.vc = {c: cls[c] for c in names}
        self.fam = {c: synthesize(cls[c].model, SynthesisSettings(authority_decel=cls[c].comfort_decel))
                    for c in names}
        self.ctl = {c: STMPC(self.fam[c], ControllerSettings(mode="authority")) for c in names}
        self.book = ReachBook(self.fam, {c: (cls[c].length, cls[c].width) for c in names})
        self.delta = cls["car"].model.delta
        nl = max(2, int(np.ceil(V / per_lane)))
        self.n_wp = int(lane_len // self.delta) + 1
        i = np.arange(nl)
        half = (nl + 1) // 2
        horiz = i < half
        slot = np.where(horiz, i, i - half)
        fwd = slot % 2 == 0
        self.lane_h = np.where(horiz, np.where(fwd, 0.0, np.pi), np.where(fwd, np.pi / 2, -np.pi / 2))
        self.lane_u = np.c_[np.cos(self.lane_h), np.sin(self.lane_h)]
        start = np.where(fwd, 0.0, lane_len)
        self.lane_o = np.c_[np.where(horiz, start, lane_len + 100.0 + slot * spacing),
                            np.where(horiz, slot * spacing, start)]
        self.stop_k = rng.integers(self.n_wp // 3, self.n_wp - 20, nl)
        self.phase = rng.uniform(0, 60.0, nl)
        self.t = self.nid = 0
        self.g = {c: dict(ids=[], lane=np.zeros(0, np.intp), k=np.zeros(0, np.intp), X=np.zeros((0, 4)),
                          l=np.zeros(0, np.intp), lq=np.zeros(0, np.intp)) for c in names}
        for lane in range(nl):
            k = 2
            while self.size < V:
                c = self._draw()
                k += int(np.ceil(self.vc[c].length / self.delta)) + int(rng.integers(*gap))
                if k >= self.n_wp - 5:
                    break
                self._add(c, lane, k)

    @property
    def size(self) -> int:
        return sum(len(g["ids"]) for g in self.g.values())

    def _draw(self) -> str:
        return list(self.vc)[self.rng.choice(len(self.vc), p=self.p / self.p.sum())]

    def wp(self, lane, k) -> np.ndarray:
        return self.lane_o[lane] + (np.asarray(k) * self.delta)[:, None] * self.lane_u[lane]

    def _add(self, c: str, lane: int, k: int) -> None:
        g = self.g[c]
        x = np.r_[self.wp(np.array([lane]), np.array([k]))[0], 0.0, 0.0]
        l = int(self.ctl[c].index(x[None], x[None, :2], self.lane_h[[lane]])[0])
        g["ids"].append(f"v{self.nid}")
        self.nid += 1
        for key, v in (("lane", lane), ("k", k), ("l", min(l, self.ctl[c].N)), ("lq", 0)):
            g[key] = np.r_[g[key], v]
        g["X"] = np.vstack([g["X"], x])

    def red(self, lane) -> np.ndarray:
        return ((self.t * 0.1 + self.phase[lane]) % 60.0) < 25.0

    def state(self) -> FleetState:
        """The fleet with its requests (groups in class order)."""
        cols = {k: [] for k in ("ids", "family", "centre", "index", "heading", "length", "width", "requesting",
                                "req_centre", "req_index")}
        for c, g in self.g.items():
            if not g["ids"]:
                continue
            ctl, lane, k, X = self.ctl[c], g["lane"], g["k"], g["X"]
            hd = self.lane_h[lane]
            cen, nxt = self.wp(lane, k), self.wp(lane, k + 1)
            g["lq"] = ctl.index(X, nxt, hd)
            may = (ctl.may_request(X, cen, hd, g["lq"]) & (k + 1 < self.n_wp) &
                   ~(self.red(lane) & (k + 1 > self.stop_k[lane]) & (k <= self.stop_k[lane])))
            n = len(k)
            for key, v in (("ids", g["ids"]), ("family", [c] * n), ("centre", cen), ("index", g["l"]),
                           ("heading", hd), ("length", np.full(n, self.vc[c].length)),
                           ("width", np.full(n, self.vc[c].width)), ("requesting", may), ("req_centre", nxt),
                           ("req_index", np.minimum(g["lq"], ctl.N))):
                cols[key].append(v)
        cat = {k: (sum(v, []) if k in ("ids", "family") else np.concatenate(v)) for k, v in cols.items()}
        return FleetState(**cat, req_heading=cat["heading"])

    def parts(self, state: FleetState | None = None, with_ids: bool = False) -> list:
        """Claim groups for :meth:`tm.reach_book.ReachBook.claims`: every vehicle's current waypoint,
        or (``state``) the requesters' requested one."""
        out, o = [], 0
        for c, g in self.g.items():
            n = len(g["ids"])
            if not n:
                continue
            lane, k = g["lane"], g["k"]
            hd = self.lane_h[lane]
            if state is None:
                part = (g["X"], self.wp(lane, k), hd, g["l"])
                out.append((c, g["ids"]) + part if with_ids else (c,) + part)
            else:
                r = state.requesting[o:o + n]
                out.append((c, g["X"][r], self.wp(lane, k + 1)[r], hd[r], np.minimum(g["lq"][r], self.ctl[c].N)))
            o += n
        return out

    def apply(self, go: np.ndarray) -> None:
        """Grants, ST-MPC inputs, plant step, departures at the lane ends, entries at lane starts."""
        from controllers.plant import step as plant_step

        o = 0
        for c, g in self.g.items():
            n = len(g["ids"])
            if not n:
                continue
            gm = go[o:o + n]
            o += n
            ctl, m = self.ctl[c], self.vc[c].model
            g["k"] = np.where(gm, g["k"] + 1, g["k"])
            g["l"] = np.where(gm, np.minimum(g["lq"], ctl.N), g["l"])
            hd = self.lane_h[g["lane"]]
            cen = self.wp(g["lane"], g["k"])
            U = ctl.control(g["X"], cen, g["l"], heading=hd)
            g["X"], _ = plant_step(m, g["X"], U, cen, "random", self.rng, heading=hd)
            g["l"] = np.minimum(ctl.index(g["X"], cen, hd), ctl.N)
            keep = ~((g["k"] >= self.n_wp - 1) & (g["l"] == 0))
            if not keep.all():
                g["ids"] = [v for v, kp in zip(g["ids"], keep.tolist()) if kp]
                for key in ("lane", "k", "X", "l", "lq"):
                    g[key] = g[key][keep]
        self.t += 1
        if self.t % 10 == 0:
            self._enter()

    def _enter(self) -> None:
        """Refill to the target size: one vehicle at rest on waypoint 2 of each lane whose entry is free."""
        from tm.reach import ReachClaims
        from tm.reach_book import admit_reach, footprint_claims

        missing = self.target - self.size
        if missing <= 0:
            return
        lanes = self.rng.permutation(len(self.lane_h))[:missing]
        cls = [self._draw() for _ in lanes]
        parts = []
        for c in self.vc:
            sel = np.array([i for i, cc in enumerate(cls) if cc == c], dtype=np.intp)
            if len(sel):
                C = self.wp(lanes[sel], np.full(len(sel), 2))
                X = np.c_[C, np.zeros((len(sel), 2))]
                parts.append((sel, (c, X, C, self.lane_h[lanes[sel]],
                                    self.ctl[c].index(X, C, self.lane_h[lanes[sel]]))))
        order = np.concatenate([p[0] for p in parts])
        cand = self.book.claims([p[1] for p in parts])
        st = self.state()
        pos = np.vstack([g["X"][:, :2] for g in self.g.values() if g["ids"]])
        now = ReachClaims.concat(self.book.claims(self.parts()),
                                 footprint_claims(pos, st.heading, st.length, st.width))
        ok = admit_reach(now, cand, "timed")
        for r in np.flatnonzero(ok):
            self._add(cls[order[r]], int(lanes[order[r]]), 2)


def reach_case(V: int, warmup: int, steps: int, repeats: int, seed: int = 0) -> list[dict]:
    """Median decision time of ``decide_reach`` on a :class:`LaneGrid` of ``V`` vehicles, timed check.

    Variants ``(policy, claims)``: ``optimal`` / ``greedy``, and ``fresh`` (every vehicle's current
    claims computed anew, as before claim reuse) / ``reuse`` (current claims from a
    :class:`tm.reach_cache.ClaimCache`, shifted, fresh only where reuse is not sound) / ``offered``
    (current claims computed before the timed region, as the co-simulation's monitor computes them
    at the end of the step before and offers them, :meth:`tm.reach_cache.ClaimCache.offer`: the
    decision computes the requesters' claims only).  The fleet is driven by
    ``(optimal, fresh)``; at each of ``steps`` steps (after ``warmup``) every variant decides on the
    same state (``repeats`` times, median).  A decision's wall time includes its claims (current ones
    and the requesters' requested ones) and, for ``reuse``, the cache's commit (``commit_ms``: the
    granted rows' requested claims kept as their claims in force, shifted the step after).  ``grants_lost``: requests the variant denies that the
    driver granted (the price of the shifted claims' outer bound)."""
    from tm.reach_cache import ClaimCache
    from tm.settings import TMSettings

    grid = LaneGrid(V, np.random.default_rng(seed))
    grid.target = grid.size
    fams = {c: f.position_sets for c, f in grid.fam.items()}
    variants = {(p, c): TrafficManager(TMSettings(policy=p, check="timed"), fams, rotating=set(fams))
                for c in ("fresh", "reuse", "offered") for p in ("optimal", "greedy")}
    caches = {key: ClaimCache(grid.book) for key in variants if key[1] == "reuse"}
    rows = []
    for t in range(warmup + steps):
        state = grid.state()
        decisions = {}
        for key, tm in variants.items():
            if t < warmup and key != ("optimal", "fresh") and key[1] != "reuse":
                continue
            walls, cpus = [], []
            cache = caches.get(key)
            given = grid.book.claims(grid.parts()) if key[1] == "offered" else None  # untimed (the monitor's)
            for _ in range(repeats if t >= warmup else 1):
                c0 = time.thread_time()
                t0 = time.perf_counter()
                cur = (cache.current(t, grid.parts(with_ids=True)) if cache else
                       given if given is not None else grid.book.claims(grid.parts()))
                new = grid.book.claims(grid.parts(state))
                d = tm.decide_reach(state, cur, new)
                walls.append(time.perf_counter() - t0)
                cpus.append(time.thread_time() - c0)
            commit_s = commit_cpu = 0.0
            if cache:  # the granted rows' requested claims are their claims in force: shifted next step
                c0, t0 = time.thread_time(), time.perf_counter()
                cache.commit(d.go, state.requesting, new, state.req_index[state.requesting])
                commit_s, commit_cpu = time.perf_counter() - t0, time.thread_time() - c0
            decisions[key] = d
            if t >= warmup:
                ti = d.timings
                rows.append(dict(vehicles=len(state), requesting=int(state.requesting.sum()), policy=key[0],
                                 claims=key[1], step=t, decide_ms=(np.median(walls) + commit_s) * 1e3,
                                 decide_cpu_ms=(np.median(cpus) + commit_cpu) * 1e3, commit_ms=commit_s * 1e3,
                                 claims_ms=(np.median(walls) - ti.broad - ti.narrow - ti.select) * 1e3,
                                 broad_ms=ti.broad * 1e3, narrow_ms=ti.narrow * 1e3, select_ms=ti.select * 1e3,
                                 grants=int(d.go.sum()), reused=int(cache.last_reused.sum()) if cache else 0))
        drive = decisions[("optimal", "fresh")]
        for r in rows[len(rows) - (len(decisions) if t >= warmup else 0):]:
            r["grants_lost"] = int((drive.go & ~decisions[(r["policy"], r["claims"])].go).sum())
        grid.apply(drive.go)
    return rows


def reach_main(quick: bool, out: Path) -> pd.DataFrame:
    """The reach case at every size: prints the medians over the measured steps, writes them to ``out``."""
    sizes = REACH_SIZES_QUICK if quick else REACH_SIZES
    warm, steps = (REACH_WARMUP_QUICK, REACH_STEPS_QUICK) if quick else (REACH_WARMUP, REACH_STEPS)
    per_step = pd.DataFrame([dict(r, fleet=V) for V in sizes
                             for r in reach_case(V, warm, steps, 3 if quick else 5)])
    cols = ["vehicles", "requesting", "grants", "reused", "grants_lost", "decide_ms", "decide_cpu_ms", "commit_ms",
            "claims_ms",
            "broad_ms",
            "narrow_ms", "select_ms"]
    df = per_step.groupby(["fleet", "policy", "claims"], sort=False)[cols].median().reset_index()
    df["p90_decide_ms"] = per_step.groupby(["fleet", "policy", "claims"], sort=False)["decide_ms"].quantile(
        0.9).to_numpy()
    df["steps"] = steps
    print("time-indexed reach claims (decide_reach, check timed), medians over the measured steps:")
    with pd.option_context("display.width", 200, "display.max_columns", 30, "display.float_format", "{:.3g}".format):
        print(df.to_string(index=False))
    out.parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(out, index=False)
    print(f"wrote {out}")
    return df


def main(argv=None) -> pd.DataFrame:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="small sizes")
    ap.add_argument("--out", default="benchmarks/results/tm.csv")
    ap.add_argument("--reach-out", default=None,
                    help="CSV of the time-indexed reach-claims case (default: beside --out, *_reach.csv)")
    ap.add_argument("--reach-only", action="store_true", help="run only the reach-claims case")
    ap.add_argument("--lp-measure-max", type=int, default=None,
                    help="measure the LP baseline outright up to this many LPs, extrapolate above "
                         "(default 12000; 1000 with --quick, so the quick run, used by the tests, "
                         "takes both the measured and the extrapolated path in a few seconds)")
    args = ap.parse_args(argv)
    if args.reach_only:
        out = Path(args.out)
        return reach_main(args.quick, Path(args.reach_out) if args.reach_out else out.with_name(out.stem + "_reach.csv"))
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
    reach_main(args.quick, Path(args.reach_out) if args.reach_out else out.with_name(out.stem + "_reach.csv"))
    return df


if __name__ == "__main__":
    main()
