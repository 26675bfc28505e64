"""Free-plane runs (no SUMO): vehicles follow waypoint sequences under their ST-MPC.

:func:`follow_waypoints` drives one vehicle through a waypoint sequence with
the ST-MPC-i algorithm of the paper (terminal or early switching, no traffic
manager: a single vehicle is always granted).  It records the state, input,
disturbance, current waypoint and membership index of every step and checks
the tube invariant (the index strictly decreases until 0, then stays in
``T^0``) and the constraints after every step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers import tolerances as tol
from controllers.classes import VehicleClass
from controllers.plant import DISTURBANCES, step
from controllers.settings import ControllerSettings, SynthesisSettings
from controllers.stmpc import STMPC
from controllers.synthesis import rotate_pairs, synthesize

__all__ = ["Trajectory", "follow_waypoints", "zigzag_waypoints"]


@dataclass(frozen=True)
class Trajectory:
    """Per-step record of a single-vehicle run (arrays indexed by step)."""

    X: np.ndarray          # (T+1, n) states
    U: np.ndarray          # (T, m) inputs
    D: np.ndarray          # (T, n) disturbances
    k: np.ndarray          # (T+1,) current waypoint index
    l: np.ndarray          # (T+1,) membership index
    waypoints: np.ndarray  # (K, 2)
    invariant_violations: int
    constraint_violations: int
    finished: bool
    steps: int

    @property
    def time_s(self) -> float:
        """Steps times Ts is left to the caller; this is the step count as float."""
        return float(self.steps)


def zigzag_waypoints(delta: float, count: int = 30, seed: int = 0) -> np.ndarray:
    """A waypoint sequence with spacing exactly ``delta`` and random turns."""
    rng = np.random.default_rng(seed)
    heading = 0.0
    pts = [np.zeros(2)]
    for _ in range(count - 1):
        heading += rng.uniform(-np.pi / 3, np.pi / 3)
        pts.append(pts[-1] + delta * np.array([np.cos(heading), np.sin(heading)]))
    return np.array(pts)


def follow_waypoints(vclass: VehicleClass, waypoints: np.ndarray, *, disturbance: str = "random",
                     switching: str = "early", solver: str = "exact", seed: int = 0,
                     max_steps: int | None = None,
                     synthesis: SynthesisSettings | None = None) -> Trajectory:
    """Drive one vehicle of ``vclass`` from rest at ``waypoints[0]`` to the last waypoint.

    Raises
    ------
    ValueError
        If the waypoints are more than the class's delta apart, or an option is invalid.
    """
    if disturbance not in DISTURBANCES:
        raise ValueError(f"disturbance must be one of {DISTURBANCES}, got {disturbance!r}")
    W = np.asarray(waypoints, dtype=float)
    gaps = np.linalg.norm(np.diff(W, axis=0), axis=1)
    if np.any(gaps > vclass.model.delta + 1e-9):
        i = int(np.argmax(gaps))
        raise ValueError(f"waypoints {i} and {i + 1} are {gaps[i]:.3f} m apart; class "
                         f"{vclass.name!r} needs at most delta = {vclass.model.delta} m")
    fam = synthesize(vclass.model, synthesis)
    ctl = STMPC(fam, ControllerSettings(solver=solver, switching=switching))
    m = vclass.model
    rng = np.random.default_rng(seed)
    max_steps = max_steps or (len(W) + 2) * (fam.N + 2)
    d = np.diff(W, axis=0)
    H = np.arctan2(d[:, 1], d[:, 0])
    H = np.concatenate([H[:1], H])  # heading of the segment into each waypoint (road frame)
    x = m.equilibrium(W[0])[None, :]
    k = 0
    l = int(ctl.index(x, W[[k]], H[[k]])[0])
    Xs, Us, Ds, ks, ls = [x[0]], [], [], [k], [l]
    inv = cons = 0
    for _ in range(max_steps):
        if k == len(W) - 1 and l == 0:
            break
        if k < len(W) - 1:
            l_next = int(ctl.index(x, W[[k + 1]], H[[k + 1]])[0])
            may = (l == 0) if switching == "terminal" else True
            if may and l_next <= fam.N:
                k, l = k + 1, l_next
        u = ctl.control(x, W[[k]], np.array([l]), heading=H[[k]])
        x, d = step(m, x, u, W[[k]], disturbance, rng, heading=H[[k]])
        l_new = int(ctl.index(x, W[[k]], H[[k]])[0])
        if not (l_new < l or (l == 0 and l_new == 0)):
            inv += 1
        z = ctl.error(x, W[[k]], H[[k]])[0, 2:]  # constraints hold in the model's frame
        u_model = rotate_pairs(u, -H[[k]]) if m.frame == "road" else u
        if np.any(z > m.z_bounds[1] + tol.VERIFY_TOL) or np.any(z < m.z_bounds[0] - tol.VERIFY_TOL) \
                or np.any(u_model > m.u_bounds[1] + 1e-9) or np.any(u_model < m.u_bounds[0] - 1e-9):
            cons += 1
        l = l_new
        Xs.append(x[0]); Us.append(u[0]); Ds.append(d[0]); ks.append(k); ls.append(l)
    finished = k == len(W) - 1 and l == 0
    return Trajectory(X=np.array(Xs), U=np.array(Us).reshape(-1, m.m), D=np.array(Ds).reshape(-1, m.n),
                      k=np.array(ks), l=np.array(ls), waypoints=W, invariant_violations=inv,
                      constraint_violations=cons, finished=finished, steps=len(Us))
