"""The code that faster versions replaced, kept verbatim as references: equality tests
(tests/controllers/test_path.py, tests/bridge/test_sumo_body.py) compare the fast code with these
without tolerance, and ``benchmarks/bench_admission.py`` times the two on the same routes.  They must
not follow the modules' code: each is as it was written when it was replaced."""

from __future__ import annotations

import numpy as np


def merge_loop(P, tol, fixed=None, matvec=False):
    """The candidate-at-a-time loop :func:`controllers.path._merge_collinear` replaced (the reference):
    with ``matvec`` verbatim (``mid @ d``), else with the fast version's elementwise products."""
    keep = [0]
    a, n = 0, len(P)
    j = 1
    while j < n - 1:
        d = P[j + 1] - P[a]
        L = float(np.hypot(d[0], d[1]))
        ok = L > tol and (fixed is None or not fixed[j])
        if ok:
            mid = P[a + 1:j + 1] - P[a]
            t = mid @ d / L if matvec else (mid[:, 0] * d[0] + mid[:, 1] * d[1]) / L
            off = np.abs(mid[:, 0] * d[1] - mid[:, 1] * d[0]) / L
            ok = bool(np.all(off <= tol) and np.all(t > 0.0) and np.all(t < L) and np.all(np.diff(t) > 0.0))
        if not ok:
            keep.append(j)
            a = j
        j += 1
    keep.append(n - 1)
    return np.asarray(keep, dtype=np.intp)


def ref_at(points, arc, s):
    """``bridge.sumo_body._at`` as written when the reference below was (kept here: the reference
    must not follow the module's code)."""
    s = np.clip(np.asarray(s, dtype=float), 0.0, arc[-1])
    i = np.clip(np.searchsorted(arc, s, side="right") - 1, 0, len(points) - 2)
    d = points[i + 1] - points[i]
    n = np.hypot(d[:, 0], d[:, 1])
    t = d / np.where(n > 0, n, 1.0)[:, None]
    return points[i] + t * (s - arc[i])[:, None], t, i


def ref_project(points, arc, p):
    """``bridge.sumo_body._project`` without a window, as written when the reference below was."""
    a, b = points[:-1], points[1:]
    d = b - a
    ln2 = np.maximum((d ** 2).sum(axis=1), 1e-18)
    w = p[:, None, :] - a[None]
    u = np.clip((w * d[None]).sum(axis=2) / ln2[None], 0.0, 1.0)
    q = a[None] + u[..., None] * d[None]
    dist = np.hypot(p[:, None, 0] - q[..., 0], p[:, None, 1] - q[..., 1])
    j = np.argmin(dist, axis=1)
    r = np.arange(len(p))
    sigma = arc[j] + u[r, j] * np.sqrt(ln2[j])
    t = d[j] / np.sqrt(ln2[j])[:, None]
    e = t[:, 0] * (p[:, 1] - q[r, j, 1]) - t[:, 1] * (p[:, 0] - q[r, j, 0])
    return sigma, e


def bodies_lane_by_lane(b, sigma, e):
    """The reference :meth:`RouteBody.bodies` (its code until it took every row at once through
    :class:`bridge.body_fleet.FleetBodies`): lane by lane, a few numpy calls per lane."""
    sigma = np.asarray(sigma, dtype=float).reshape(-1)
    e = np.broadcast_to(np.asarray(e, dtype=float), sigma.shape)
    L, half = b.length, 0.5 * b.length
    q, t, seg = ref_at(b.poly, b.parc, sigma + half)
    front = q + e[:, None] * np.column_stack([-t[:, 1], t[:, 0]])
    lane = b.seg_lane[seg]
    back = np.empty_like(front)
    for k in np.unique(lane):
        rows = np.flatnonzero(lane == k)
        s, lat = ref_project(b.shapes[k], b.arcs[k], front[rows])
        rem = s / b.scale[k] - L
        cur = np.full(len(rows), k)
        for _ in range(8):
            prev = b.behind[cur]
            go = (rem < 0) & (prev >= 0)
            if not go.any():
                break
            cur = np.where(go, prev, cur)
            rem = np.where(go, rem + b.lane_len[cur], rem)
        for c in np.unique(cur):
            sel = cur == c
            pt, tt, _ = ref_at(b.shapes[c], b.arcs[c], rem[sel] * b.scale[c])
            back[rows[sel]] = pt + lat[sel, None] * np.column_stack([-tt[:, 1], tt[:, 0]])
    axis = front - back
    n = np.hypot(axis[:, 0], axis[:, 1])
    u = axis / np.where(n > 0, n, 1.0)[:, None]
    side = 0.5 * b.width * np.column_stack([-u[:, 1], u[:, 0]])
    return front, back, lane, np.stack([front - side, front + side, back + side, back - side], axis=1)
