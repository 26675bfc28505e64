"""Random route polylines shared by the path-frame tests (tests/controllers/test_path.py,
tests/tm/test_path_cover.py)."""

import numpy as np


def random_polyline(rng, n_seg: int, min_len: float = 1.0, max_len: float = 10.0, max_turn_deg: float = 45.0,
                    straight_p: float = 0.2) -> np.ndarray:
    """``n_seg`` segments of random length, turning by at most ``max_turn_deg`` at each vertex
    (exactly 0 with probability ``straight_p``: collinear runs to merge)."""
    h = rng.uniform(-np.pi, np.pi)
    P = [rng.uniform(-50, 50, 2)]
    for k in range(n_seg):
        if k:
            h += 0.0 if rng.random() < straight_p else np.radians(rng.uniform(-max_turn_deg, max_turn_deg))
        P.append(P[-1] + rng.uniform(min_len, max_len) * np.array([np.cos(h), np.sin(h)]))
    return np.array(P)
