"""SUMO's pedestrians for the co-simulation: the net's walking regions, and persons' positions.

SUMO moves every person itself (its pedestrian model); muvsim only reads
where they are.  :func:`walk_regions` turns the net's crossings (a lane
centre line and its width: one rectangle per segment) and walking areas
(the lane shape is the area's outline: cut into triangles, their convex
hull if the outline is not a simple polygon) into convex polygons grown by
:data:`WALK_MARGIN_M`, read once.
:func:`read_persons` gives every person's id and position after a step.
:func:`read_personinfo` reads the pedestrians' trips from SUMO's tripinfo
output (their delay is the walks' ``timeLoss``).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from bridge.sumo_inputs import parse_xml

__all__ = ["walk_regions", "read_persons", "read_personinfo", "WALK_FUNCTIONS"]

#: Edge functions of a SUMO net where pedestrians and vehicles share space.
WALK_FUNCTIONS = ("crossing", "walkingarea")
#: Margin (m) each walking region is grown by: SUMO's paths across a walking area leave its outline
#: by up to 0.22 m (measured: tests/bridge/test_pedestrians.py); 0.5 m covers that.
WALK_MARGIN_M = 0.5


def _shape(text: str) -> np.ndarray:
    return np.array([[float(c) for c in p.split(",")[:2]] for p in text.split()], dtype=float)


def _segment_boxes(line: np.ndarray, width: float) -> list[np.ndarray]:
    """One rectangle (CCW) per segment of a centre line with the given width."""
    out = []
    for a, b in zip(line[:-1], line[1:]):
        d = b - a
        n = np.hypot(*d)
        if n <= 1e-9:
            continue
        v = np.array([-d[1], d[0]]) / n * (0.5 * width)
        out.append(np.array([a - v, b - v, b + v, a + v]))
    return out


def _area(P: np.ndarray) -> float:
    x, y = P[:, 0], P[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _triangles(P: np.ndarray) -> list[np.ndarray] | None:
    """Ear-clipping triangulation of a simple polygon (None if it is not one)."""
    P = P[np.r_[True, np.any(np.abs(np.diff(P, axis=0)) > 1e-9, axis=1)]]
    if len(P) > 3 and np.allclose(P[0], P[-1]):
        P = P[:-1]
    if len(P) < 3 or abs(_area(P)) < 1e-9:
        return None
    if _area(P) < 0:
        P = P[::-1]
    idx = list(range(len(P)))
    out = []

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    guard = 0
    while len(idx) > 3 and guard < 10 * len(P) ** 2:
        guard += 1
        for t in range(len(idx)):
            i0, i1, i2 = idx[t - 1], idx[t], idx[(t + 1) % len(idx)]
            a, b, c = P[i0], P[i1], P[i2]
            if cross(a, b, c) <= 1e-12:
                continue  # reflex or flat
            inside = any(cross(a, b, P[j]) >= 0 and cross(b, c, P[j]) >= 0 and cross(c, a, P[j]) >= 0
                         for j in idx if j not in (i0, i1, i2))
            if inside:
                continue
            out.append(np.array([a, b, c]))
            idx.pop(t)
            break
        else:
            return None
    if len(idx) == 3:
        tri = P[idx]
        if cross(*tri) > 1e-12:
            out.append(tri)
    return out or None


def _grow(P: np.ndarray, margin: float) -> np.ndarray:
    """Convex polygon ``P`` grown by the square ``[-margin, margin]^2`` (hull of the vertex sums)."""
    from tm.geometry import convex_hull

    sq = margin * np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    return convex_hull((np.asarray(P)[:, None, :] + sq[None]).reshape(-1, 2))


def walk_regions(net_path, margin_m: float = WALK_MARGIN_M, functions=WALK_FUNCTIONS) -> list[np.ndarray]:
    """Convex polygons covering the net's crossings and walking areas.

    Parameters
    ----------
    net_path : path-like
        A SUMO net (``.net.xml`` or gzipped).
    margin_m : float
        Every region grown by this margin (m), :data:`WALK_MARGIN_M`.
    functions : tuple of str
        The edge functions read, of :data:`WALK_FUNCTIONS` (``("crossing",)``: the crossings only).

    Returns
    -------
    list of ndarray (k, 2)
        Empty when the net has no crossing nor walking area.
    """
    bad = [f for f in functions if f not in WALK_FUNCTIONS]
    if bad:
        raise ValueError(f"walk_regions: functions {bad} unknown; valid: {WALK_FUNCTIONS}")
    regions: list[np.ndarray] = []
    for e in parse_xml(net_path).getroot().iter("edge"):
        fn = e.get("function")
        if fn not in functions:
            continue
        for lane in e.iter("lane"):
            shape = lane.get("shape")
            if not shape:
                continue
            P = _shape(shape)
            if fn == "crossing":
                regions += _segment_boxes(P, float(lane.get("width", 3.0)))
            else:
                tri = _triangles(P)
                regions += tri if tri is not None else ([P] if len(P) >= 3 else [])
    return [_grow(P, margin_m) for P in regions] if margin_m > 0 else regions


def read_persons(api) -> tuple[list[str], np.ndarray]:
    """Ids and positions ``(P, 2)`` of every person in the simulation (libsumo or traci ``api``) who is
    not inside a vehicle: a rider's position is its vehicle's (SUMO), so it is no pedestrian (it
    would meet its own vehicle's footprint)."""
    ids = [p for p in api.person.getIDList() if not api.person.getVehicle(p)]
    if not ids:
        return ids, np.zeros((0, 2))
    get = api.person.getPosition
    return ids, np.array([get(p) for p in ids], dtype=float).reshape(-1, 2)


def read_personinfo(path) -> pd.DataFrame:
    """The persons' trips of SUMO's ``tripinfo.xml`` (one row per finished person).

    Columns ``id, type, depart_s, arrival_s, duration_s, route_length_m, walk_duration_s,
    walk_time_loss_s, waiting_time_s``; the walk figures are summed over the person's walks
    (its delay: ``walk_time_loss_s``); ``arrival_s`` is NaN for a person still walking.
    """
    cols = ["id", "type", "depart_s", "arrival_s", "duration_s", "route_length_m", "walk_duration_s",
            "walk_time_loss_s", "waiting_time_s"]
    rows = []
    for p in parse_xml(path).getroot().iter("personinfo"):
        walks = list(p.iter("walk"))
        f = lambda el, k: float(el.get(k, "nan"))  # noqa: E731
        arrival = max((f(w, "arrival") for w in walks), default=float("nan"))
        if not arrival >= 0:  # unfinished (tripinfo-output.write-unfinished writes -1)
            arrival = float("nan")
        rows.append({"id": p.get("id"), "type": p.get("type", ""), "depart_s": f(p, "depart"),
                     "arrival_s": arrival, "duration_s": arrival - f(p, "depart"),
                     "route_length_m": sum(f(w, "routeLength") for w in walks),
                     "walk_duration_s": sum(f(w, "duration") for w in walks),
                     "walk_time_loss_s": sum(f(w, "timeLoss") for w in walks),
                     "waiting_time_s": sum(f(w, "waitingTime") for w in walks)})
    return pd.DataFrame(rows, columns=cols)
