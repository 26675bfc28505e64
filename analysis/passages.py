"""Junction passages: how long vehicles stay near junction centres, turning or going straight.

A passage is one vehicle's consecutive samples within ``radius`` of one junction centre; it is a
turn when the heading changes by more than ``turn_rad`` between its first and last sample.  Used by
``scripts/junction_passages.py`` on a run's MCAP log (``read_vehicle_states``).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

__all__ = ["junction_passages"]


def junction_passages(states: pd.DataFrame, centres: np.ndarray, radius: float = 12.0,
                      turn_rad: float = 0.5, dt: float = 0.1) -> pd.DataFrame:
    """One row per passage: ``id, junction, duration_s, v_min, v_mean, kind`` (``turn`` or
    ``straight``).

    Parameters
    ----------
    states : DataFrame
        Columns ``t_s, id, x_m, y_m, vx_mps, vy_mps, heading_rad`` (one row per vehicle and sample).
    centres : ndarray, shape (J, 2)
        Junction centres (m).
    radius, turn_rad : float
        Passage radius (m) and the heading change (rad) that makes it a turn.
    dt : float
        Sample period (s): a gap longer than 1.5 ``dt`` ends a passage.
    """
    if not radius > 0 or len(centres) == 0:
        raise ValueError(f"junction_passages: need radius > 0 and at least one centre, got {radius}, {len(centres)}")
    d = states.sort_values(["id", "t_s"], kind="stable")
    P = d[["x_m", "y_m"]].to_numpy(dtype=float)
    dist = np.linalg.norm(P[:, None, :] - np.asarray(centres, dtype=float)[None], axis=2)
    d = d.assign(junction=dist.argmin(axis=1), speed=np.hypot(d["vx_mps"], d["vy_mps"]))[dist.min(axis=1) < radius]
    brk = (d["id"] != d["id"].shift()) | (d["junction"] != d["junction"].shift()) | (d["t_s"].diff() > 1.5 * dt)
    g = d.assign(passage=brk.cumsum()).groupby("passage")
    out = pd.DataFrame({"id": g["id"].first(), "junction": g["junction"].first(),
                        "duration_s": g["t_s"].max() - g["t_s"].min(), "v_min": g["speed"].min(),
                        "v_mean": g["speed"].mean()})
    turn = np.abs((g["heading_rad"].last() - g["heading_rad"].first() + np.pi) % (2 * np.pi) - np.pi) > turn_rad
    return out.assign(kind=np.where(turn, "turn", "straight")).reset_index(drop=True)
