"""analysis.passages: passages near junction centres, told apart as turns and straights."""

import numpy as np
import pandas as pd
import pytest

from analysis.passages import junction_passages


def _track(vid, pts, speed, dt=0.1):
    """Samples of a vehicle moving at ``speed`` along the polyline ``pts``."""
    pts = np.asarray(pts, dtype=float)
    seg = np.diff(pts, axis=0)
    arc = np.r_[0.0, np.cumsum(np.hypot(*seg.T))]
    s = np.arange(0.0, arc[-1], speed * dt)
    i = np.clip(np.searchsorted(arc, s, side="right") - 1, 0, len(seg) - 1)
    u = seg[i] / np.hypot(*seg[i].T)[:, None]
    p = pts[i] + u * (s - arc[i])[:, None]
    h = np.arctan2(u[:, 1], u[:, 0])
    return pd.DataFrame({"t_s": np.arange(len(s)) * dt, "id": vid, "x_m": p[:, 0], "y_m": p[:, 1],
                         "vx_mps": speed * u[:, 0], "vy_mps": speed * u[:, 1], "heading_rad": h})


def test_a_straight_and_a_turn_through_one_junction():
    """A straight at 10 m/s crosses the 12 m circle in 24 m / 10 m/s = 2.4 s; a 90-degree turn at
    2 m/s covers 12 + 12 m of it in 12 s.  A passage runs from its first to its last sample inside
    the circle: each may lie up to one sample period (0.1 s) inside, so up to 0.2 s less."""
    states = pd.concat([_track("s", [(-50, 0), (50, 0)], 10.0), _track("t", [(-50, 0), (0, 0), (0, 50)], 2.0)])
    out = junction_passages(states, np.array([[0.0, 0.0], [500.0, 500.0]]))
    s = out[out["id"] == "s"].iloc[0]
    t = out[out["id"] == "t"].iloc[0]
    assert len(out) == 2 and s["kind"] == "straight" and t["kind"] == "turn"
    assert 2.4 - 0.2 - 1e-9 <= s["duration_s"] <= 2.4
    assert 12.0 - 0.2 - 1e-9 <= t["duration_s"] <= 12.0
    assert s["v_min"] == pytest.approx(10.0) and t["v_mean"] == pytest.approx(2.0)


def test_two_visits_of_one_junction_are_two_passages_and_bad_input_is_named():
    there = _track("a", [(-50, 0), (50, 0)], 10.0)
    back = _track("a", [(50, 0), (-50, 0)], 10.0)
    back["t_s"] += there["t_s"].max() + 5.0
    out = junction_passages(pd.concat([there, back]), np.array([[0.0, 0.0]]))
    assert len(out) == 2 and set(out["kind"]) == {"straight"}
    with pytest.raises(ValueError, match="radius"):
        junction_passages(there, np.array([[0.0, 0.0]]), radius=0.0)
