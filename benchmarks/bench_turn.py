"""One movement-authority car through a 90 degree turn: today's road frame against the path frame.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_turn.py [--radii 8 15 30] [--seeds 0 1 2]

The route: 100 m straight, a 90 degree left arc of radius R, 100 m straight, conditioned by
:func:`bridge.waypoints.condition_polyline` with the car's delta and ``turn_max_deg``.  The car is
the built-in ``car`` with its STMPC in ``authority`` mode (``Cosim``'s family and settings), alone,
every request granted (no TM), random disturbance; the request rule, the speed bounds (curve speed
``sqrt(a_lat / kappa)`` with ``SpeedSettings``' defaults, ``--lat-accel``), their slack and the index
update are ``Cosim.step``'s, stepped here on one :class:`bridge.groups._Group`.

* ``road`` (today): the plant is the world double integrator; errors in the frame of the stop
  point's segment (``Cosim``).  Checked step for step against ``Cosim`` itself (``--no-check`` skips).
* ``path``: the plant is the double integrator in path coordinates ``(s, n, v_s, v_n)``
  (:class:`controllers.path.PathFrame` of the waypoints), the waypoints ``(S_k, 0)`` with heading 0;
  the world pose is ``to_world(s, n)``.  The same speed tables (world curvature).

Figures per radius and frame (medians over the seeds; every row in ``benchmarks/results/turn.csv``):
time from the centre 30 m before the turn to 30 m after it, the slowest speed in that window, the
largest speed in the turn (world speeds), the largest implied world lateral acceleration
``v^2 kappa(s)`` (kappa: :func:`controllers.speed_limits.curvature` of the waypoints, as the curve
speed uses), the lowest curve-speed cap, the largest path offset ``|n|``, the shortest lead
``S(c) - s`` (how close the stop point came: today it is held back at the corner, ``T^{N_L}(c + delta)``
being out of reach across), and index violations; in the CSV also the frame's sharpest kink (the
body heading jumps by it in the path frame) and the centre's largest jump there, ``|n| 2 sin(theta/2)``.
"""

from __future__ import annotations

import argparse
import csv
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from bridge.cosim import Cosim, CosimSettings, VehicleSpec, _look_ahead_decel
from bridge.groups import _Group
from bridge.waypoints import condition_polyline
from controllers.classes import builtin_classes
from controllers.path import PathFrame
from controllers.plant import step as plant_step
from controllers.settings import ControllerSettings, SynthesisSettings
from controllers.speed_limits import SpeedSettings, curvature, route_speeds
from controllers.stmpc import STMPC
from controllers.synthesis import synthesize

OUT = Path(__file__).resolve().parent / "results"
STRAIGHT_M = 100.0
MARGIN_M = 30.0


def route(R: float, delta: float, turn_max_deg: float) -> np.ndarray:
    """Waypoints of straight - 90 degree left arc of radius R - straight."""
    n = max(16, int(np.ceil(0.5 * np.pi * R / 0.25)))  # arc sampled every <= 0.25 m
    t = np.linspace(-0.5 * np.pi, 0.0, n + 1)
    arc = np.column_stack([R * np.cos(t), R + R * np.sin(t)])
    poly = np.vstack([[[-STRAIGHT_M, 0.0]], arc, [[R, R + STRAIGHT_M]]])
    return condition_polyline(poly, delta, turn_max_deg=turn_max_deg).waypoints


def controller(vc, solver="exact"):
    fam = synthesize(vc.model, replace(SynthesisSettings(), authority_decel=vc.comfort_decel))
    return STMPC(fam, ControllerSettings(solver=solver, switching="early", mode="authority"))


def drive(vc, ctl, W, frame: PathFrame, kind: str, seed: int, speed: SpeedSettings, s_stop: float,
          max_steps: int = 4000) -> dict:
    """One car, every request granted; returns per-step arrays (world pose, path s, n, speeds)."""
    Ts = 0.1
    m = vc.model
    decel = _look_ahead_decel(vc)
    rs = route_speeds(W, None, vc.v_max, decel, speed.lat_accel if speed.curves else None, speed.curve_window_m)
    g = _Group(vc, ctl, decel=decel, slack_steps=speed.slack_steps)
    if kind == "road":
        Wp = W
        H = np.concatenate([[0.0], np.arctan2(*np.diff(W, axis=0).T[::-1])])
        H[0] = H[1]
    elif kind == "path":
        S, _ = frame.to_path(W, rs.arc, window=1.0)  # the waypoints' s in the frame: the tables' arc
        if np.abs(S - rs.arc).max() > 1e-6:
            raise RuntimeError(f"waypoint arc and path frame disagree by {np.abs(S - rs.arc).max():.3g} m")
        Wp = np.column_stack([rs.arc, np.zeros(len(W))])
        H = np.zeros(len(W))
    else:
        raise ValueError(kind)
    x0 = m.equilibrium(Wp[0])
    g.add("v0", Wp, H, x0, int(ctl.index(x0[None], Wp[:1], H[:1])[0]), rs)
    rng = np.random.default_rng(seed)
    out = {k: [] for k in ("X", "k", "l")}
    viol = 0
    s_prev = 0.0
    for _ in range(max_steps):
        # 1. requests (as the co-simulation asks: _Group.request)
        may, _, _ = g.request(Ts, "early", True)
        # 2.-3a. every request granted
        g.k[may] += 1
        g.l[may] = g.req_l[may]
        g.denied_last = np.zeros(1, dtype=bool)
        # 3b.-4. control, plant, index (Cosim.step)
        cen, hd, _ = g.centres()
        U = ctl.control(g.X, cen, g.l, ids=g.ids, heading=hd, v_cap=g.cap)
        g.X, _ = plant_step(m, g.X, U, cen, "random", rng, heading=hd)
        l_new = ctl.index(g.X, cen, hd)
        viol += int(np.sum(~((l_new < g.l) | ((g.l == 0) & (l_new == 0)))))
        cap_next, _ = g.speed_caps(Ts)
        keep = np.minimum(g.l - 1, l_new + g.slack(Ts, 0, cap_next))
        g.l = np.where(g.l > 0, np.maximum(l_new, keep), l_new)
        out["X"].append(g.X[0].copy())
        out["k"].append(int(g.k[0]))
        out["l"].append(int(g.l[0]))
        s_now = g.X[0, 0] if kind == "path" else float(frame.to_path(g.X[:, :2], s_prev)[0][0])
        s_prev = s_now
        if s_now > s_stop or (g.at_last[0] and g.l[0] == 0):
            break
    X = np.array(out["X"])
    if kind == "path":
        s, n = X[:, 0], X[:, 1]
        xy, _ = frame.to_world(s, n)
        v_al = X[:, 2]
    else:
        xy = X[:, :2]
        s = np.empty(len(X))
        n = np.empty(len(X))
        prev = 0.0
        for i in range(len(X)):  # sequential hints: the projection follows the car
            si, ni = frame.to_path(X[i:i + 1, :2], prev)
            s[i], n[i], prev = si[0], ni[0], si[0]
        T = frame.tangent[frame.segment(s)]
        v_al = np.einsum("ij,ij->i", X[:, 2:4], T)
    return dict(kind=kind, X=X, xy=xy, s=s, n=n, speed=np.hypot(X[:, 2], X[:, 3]), v_al=v_al,
                k=np.array(out["k"]), l=np.array(out["l"]), violations=viol,
                arc=rs.arc, bound=rs.bound)


def cosim_road(classes, W, seed: int, steps: int) -> np.ndarray:
    """The same car in ``Cosim`` (authority, road frame, free plane, one vehicle): its states, ``steps`` steps."""
    sim = Cosim(classes, [VehicleSpec("v0", "car", W)],
                CosimSettings(controller="authority", disturbance="random", seed=seed, frame="road"))
    sim._admit(0.0)
    g = sim.groups["car"]
    X = []
    while len(X) < steps and g.ids:
        sim.step()
        if g.ids:
            X.append(g.X[0].copy())
    return np.array(X)


def figures(run: dict, W, frame: PathFrame, R: float, speed: SpeedSettings) -> dict:
    s0 = float(frame.to_path(np.array([[0.0, 0.0]]), STRAIGHT_M)[0][0])
    s1 = float(frame.to_path(np.array([[R, R]]), STRAIGHT_M + 0.5 * np.pi * R)[0][0])
    s, Ts = run["s"], 0.1
    t = np.arange(1, len(s) + 1) * Ts
    i_in = int(np.argmax(s >= s0 - MARGIN_M))
    if not np.any(s >= s1 + MARGIN_M):
        raise RuntimeError(f"R = {R}: the car did not get 30 m past the turn (s = {s.max():.1f} of {s1 + 30:.1f})")
    i_out = int(np.argmax(s >= s1 + MARGIN_M))
    win = slice(i_in, i_out + 1)
    turn = (s >= s0) & (s <= s1)
    k_turn = curvature(W, speed.curve_window_m)  # at the waypoints, as the curve speed takes it
    a_lat = run["speed"] ** 2 * np.interp(s, run["arc"], k_turn)
    return {
        "t_window_s": round(t[i_out] - t[i_in], 2),
        "v_min_window_mps": round(float(run["speed"][win].min()), 3),
        "v_max_turn_mps": round(float(run["speed"][turn].max()), 3),
        "v_mean_turn_mps": round(float((s1 - s0) / max(Ts * turn.sum(), Ts)), 3),
        "a_lat_max_mps2": round(float(a_lat[win].max()), 3),
        "v_curve_min_mps": round(float(np.sqrt(speed.lat_accel / k_turn.max())), 3),
        "kappa_max_1pm": round(float(k_turn.max()), 4),
        "n_abs_max_m": round(float(np.abs(run["n"][win]).max()), 3),
        "lead_min_m": round(float((run["arc"][run["k"]] - s)[win].min()), 2),
        "index_violations": int(run["violations"]),
        "turn_m": round(s1 - s0, 2),
        "kink_max_deg": round(float(np.degrees(np.abs(frame.turn).max())), 2),
        # the path frame's jump of the centre at its kinks (the road frame has none: blank)
        "centre_jump_max_m": round(frame.kink_jump_bound(float(np.abs(run["n"][win]).max())), 4)
        if run["kind"] == "path" else "",
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--radii", type=float, nargs="+", default=[8.0, 15.0, 30.0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--no-check", action="store_true", help="skip the step-for-step check against Cosim")
    ap.add_argument("--out", type=Path, default=OUT / "turn.csv")
    a = ap.parse_args()
    t_start = time.process_time()
    classes = builtin_classes()
    vc = classes["car"]
    ctl = controller(vc)
    speed = SpeedSettings()
    rows = []
    checked = False
    for R in a.radii:
        W = route(R, vc.model.delta, vc.model.turn_max_deg)
        frame = PathFrame(W)
        s_stop = STRAIGHT_M + 0.5 * np.pi * R + MARGIN_M + 5.0
        for kind in ("road", "path"):
            for seed in a.seeds:
                run = drive(vc, ctl, W, frame, kind, seed, speed, s_stop)
                if kind == "road" and not checked and not a.no_check:
                    ref = cosim_road(classes, W, seed, len(run["X"]))
                    err = float(np.abs(ref - run["X"][:len(ref)]).max())
                    print(f"check: road frame here vs Cosim, R = {R:g}, seed {seed}, {len(ref)} steps: "
                          f"largest state difference {err:.3g}")
                    if err > 1e-9:
                        raise SystemExit("the road-frame loop here does not reproduce Cosim")
                    checked = True
                fig = figures(run, W, frame, R, speed)
                rows.append({"radius_m": R, "frame": kind, "seed": seed, **fig})
    cpu = time.process_time() - t_start
    a.out.parent.mkdir(parents=True, exist_ok=True)
    with open(a.out, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    keys = ["t_window_s", "v_min_window_mps", "v_max_turn_mps", "v_mean_turn_mps", "a_lat_max_mps2",
            "v_curve_min_mps", "n_abs_max_m", "lead_min_m", "index_violations"]
    print(f"\ncar, authority, random disturbance, seeds {a.seeds} (medians; worst index violations: max)")
    print(f"{'R m':>5} {'frame':>5} " + " ".join(f"{k:>17}" for k in keys))
    for R in a.radii:
        for kind in ("road", "path"):
            sel = [r for r in rows if r["radius_m"] == R and r["frame"] == kind]
            vals = [max(r[k] for r in sel) if k == "index_violations" else float(np.median([r[k] for r in sel]))
                    for k in keys]
            print(f"{R:5g} {kind:>5} " + " ".join(f"{v:17.3f}" for v in vals))
    print(f"\nwrote {a.out}; CPU {cpu:.1f} s")


if __name__ == "__main__":
    main()
