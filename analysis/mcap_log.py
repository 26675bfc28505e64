"""``run.mcap``: a co-simulation observer that logs a run for Foxglove (and any MCAP reader).

Channels are JSON-encoded with JSON-schema schemas (``message_encoding="json"``,
``schema encoding="jsonschema"``); the two scene channels use the name and the
message shape of Foxglove's well-known ``foxglove.SceneUpdate``, so the 3D panel
draws them without any plug-in.  Log time of a step's messages is the simulated
time at the end of the step (ns).

========================  =======================  ==========================================  =========
topic                     schema                   content                                     level
========================  =======================  ==========================================  =========
``/vehicles``             ``muvsim.VehicleStates``  per vehicle: id, class, x, y, vx, vy,        summary
                                                   heading, current waypoint (index, x, y),
                                                   membership index
``/membership``           ``muvsim.Membership``    ``vehicles[:]{id, index}`` (for plots)      summary
``/tm/decision``          ``muvsim.TMDecision``    requests, granted, denied, forced, conflict  summary
                                                   edges (from, to, kind), TM time
``/scene/vehicles``       ``foxglove.SceneUpdate``  footprints as cubes, current waypoints as    summary
                                                   spheres
``/scene/claims``         ``foxglove.SceneUpdate``  claims (position sets ⊕ footprint) as       full
                                                   line loops, conflict edges as line lists
========================  =======================  ==========================================  =========

The observer's own time per step (encoding and writing) goes into the step
row as ``logging_ms``.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

__all__ = ["LOG_LEVELS", "TOPICS", "McapLogger", "observers_for", "read_vehicle_states"]

#: ``--log`` values: nothing, states and decisions, everything (with claim polygons).
LOG_LEVELS = ("none", "summary", "full")

_VEC3 = {"type": "object", "properties": {k: {"type": "number"} for k in "xyz"}}
_QUAT = {"type": "object", "properties": {k: {"type": "number"} for k in "xyzw"}}
_COLOR = {"type": "object", "properties": {k: {"type": "number"} for k in "rgba"}}
_TIME = {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}}
_POSE = {"type": "object", "properties": {"position": _VEC3, "orientation": _QUAT}}
_SCENE_UPDATE = {
    "title": "foxglove.SceneUpdate",
    "description": "An update to the entities displayed in a 3D scene (subset of Foxglove's schema)",
    "type": "object",
    "properties": {
        "deletions": {"type": "array", "items": {"type": "object", "properties": {
            "timestamp": _TIME, "type": {"type": "integer"}, "id": {"type": "string"}}}},
        "entities": {"type": "array", "items": {"type": "object", "properties": {
            "timestamp": _TIME, "frame_id": {"type": "string"}, "id": {"type": "string"},
            "lifetime": _TIME, "frame_locked": {"type": "boolean"},
            "metadata": {"type": "array", "items": {"type": "object", "properties": {
                "key": {"type": "string"}, "value": {"type": "string"}}}},
            "cubes": {"type": "array", "items": {"type": "object", "properties": {
                "pose": _POSE, "size": _VEC3, "color": _COLOR}}},
            "spheres": {"type": "array", "items": {"type": "object", "properties": {
                "pose": _POSE, "size": _VEC3, "color": _COLOR}}},
            "lines": {"type": "array", "items": {"type": "object", "properties": {
                "type": {"type": "integer"}, "pose": _POSE, "thickness": {"type": "number"},
                "scale_invariant": {"type": "boolean"}, "points": {"type": "array", "items": _VEC3},
                "color": _COLOR, "colors": {"type": "array", "items": _COLOR},
                "indices": {"type": "array", "items": {"type": "integer"}}}}},
        }}},
    },
}
_NUM, _STR, _INT = {"type": "number"}, {"type": "string"}, {"type": "integer"}
_IDS = {"type": "array", "items": _STR}
_SCHEMAS = {
    "muvsim.VehicleStates": {
        "title": "muvsim.VehicleStates", "type": "object",
        "properties": {"t_s": _NUM, "vehicles": {"type": "array", "items": {"type": "object", "properties": {
            "id": _STR, "vclass": _STR, "x_m": _NUM, "y_m": _NUM, "vx_mps": _NUM, "vy_mps": _NUM,
            "heading_rad": _NUM, "waypoint": _INT, "waypoints": _INT, "wx_m": _NUM, "wy_m": _NUM,
            "index": _INT}}}}},
    "muvsim.Membership": {
        "title": "muvsim.Membership", "type": "object",
        "properties": {"t_s": _NUM, "vehicles": {"type": "array", "items": {"type": "object", "properties": {
            "id": _STR, "index": _INT}}}}},
    "muvsim.TMDecision": {
        "title": "muvsim.TMDecision", "type": "object",
        "properties": {"t_s": _NUM, "requests": _IDS, "granted": _IDS, "denied": _IDS, "forced": _IDS,
                       "edges": {"type": "array", "items": {"type": "object", "properties": {
                           "from": _STR, "to": _STR, "kind": _STR}}}, "tm_ms": _NUM}},
    "foxglove.SceneUpdate": _SCENE_UPDATE,
}

#: topic -> (schema name, lowest level that writes it)
TOPICS = {
    "/vehicles": ("muvsim.VehicleStates", "summary"),
    "/membership": ("muvsim.Membership", "summary"),
    "/tm/decision": ("muvsim.TMDecision", "summary"),
    "/scene/vehicles": ("foxglove.SceneUpdate", "summary"),
    "/scene/claims": ("foxglove.SceneUpdate", "full"),
}

_FRAME = "world"
_GREY = {"r": 0.6, "g": 0.6, "b": 0.6, "a": 0.8}
_GREEN = {"r": 0.1, "g": 0.75, "b": 0.2, "a": 0.9}
_RED = {"r": 0.9, "g": 0.1, "b": 0.1, "a": 0.9}
_BLUE = {"r": 0.2, "g": 0.4, "b": 0.9, "a": 0.9}
_ORANGE = {"r": 1.0, "g": 0.6, "b": 0.0, "a": 1.0}


def _stamp(ns: int) -> dict:
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _quat(yaw: float) -> dict:
    return {"x": 0.0, "y": 0.0, "z": float(np.sin(yaw / 2)), "w": float(np.cos(yaw / 2))}


def _pose(x: float, y: float, yaw: float = 0.0, z: float = 0.0) -> dict:
    return {"position": {"x": float(x), "y": float(y), "z": z}, "orientation": _quat(yaw)}


class McapLogger:
    """Observer of :class:`bridge.cosim.Cosim` writing ``run.mcap`` (zstd chunks).

    Parameters
    ----------
    path : path-like
        The MCAP file to write.
    level : {"summary", "full"}
        ``summary``: states and decisions; ``full``: also claim polygons and conflict edges
        in the 3D scene.
    metadata : dict of str to str, optional
        Written as the file's ``muvsim`` metadata record (scenario, options).

    Notes
    -----
    Call :meth:`close` (or use it as a context manager) to finish the file: an unfinished
    MCAP has no summary section (readers then stream it).
    """

    def __init__(self, path, level: str = "summary", metadata: dict | None = None):
        from mcap.writer import CompressionType, Writer

        if level not in ("summary", "full"):
            raise ValueError(f"McapLogger: level must be 'summary' or 'full', got {level!r}")
        self.path = Path(path)
        self.level = level
        self._fh = open(self.path, "wb")
        self._w = Writer(self._fh, compression=CompressionType.ZSTD)
        self._w.start(profile="", library="muvsim")
        schema_ids = {name: self._w.register_schema(name, "jsonschema", json.dumps(s).encode())
                      for name, s in _SCHEMAS.items()}
        self._ch = {}
        for topic, (schema, lvl) in TOPICS.items():
            if lvl == "summary" or level == "full":
                self._ch[topic] = self._w.register_channel(topic, "json", schema_ids[schema])
        if metadata:
            self._w.add_metadata("muvsim", {str(k): str(v) for k, v in metadata.items()})
        self._seq = 0
        self.messages = 0
        self.total_ms = 0.0
        self.closed = False

    # ------------------------------------------------------------------ writing
    def _put(self, topic: str, ns: int, msg: dict) -> None:
        self._seq += 1
        self._w.add_message(self._ch[topic], log_time=ns, data=json.dumps(msg, separators=(",", ":")).encode(),
                            publish_time=ns, sequence=self._seq)
        self.messages += 1

    def on_step(self, sim, state, decision, row) -> None:
        """Log the step just taken; adds ``logging_ms`` to ``row``."""
        t0 = time.perf_counter()
        Ts = float(sim.settings.Ts)
        t_end = float(row["t_s"]) + Ts
        ns = int(round(t_end * 1e9))
        vehicles, cubes_entities, idx = [], [], []
        for c, g in sim.groups.items():
            if not g.ids:
                continue
            cen, hd, _ = g.centres()
            vc = g.vclass
            for j, vid in enumerate(g.ids):
                x, y, vx, vy = (float(v) for v in g.X[j, :4])
                h = float(hd[j])
                vehicles.append({"id": vid, "vclass": c, "x_m": x, "y_m": y, "vx_mps": vx, "vy_mps": vy,
                                 "heading_rad": h, "waypoint": int(g.k[j]), "waypoints": int(len(g.W[j])),
                                 "wx_m": float(cen[j, 0]), "wy_m": float(cen[j, 1]), "index": int(g.l[j])})
                idx.append({"id": vid, "index": int(g.l[j])})
                cubes_entities.append({
                    "timestamp": _stamp(ns), "frame_id": _FRAME, "id": vid, "lifetime": _stamp(0),
                    "frame_locked": False, "metadata": [{"key": "class", "value": c},
                                                        {"key": "index", "value": str(int(g.l[j]))}],
                    "cubes": [{"pose": _pose(x, y, h, 0.75), "size": {"x": vc.length, "y": vc.width, "z": 1.5},
                               "color": _BLUE}],
                    "spheres": [{"pose": _pose(cen[j, 0], cen[j, 1]), "size": {"x": 0.8, "y": 0.8, "z": 0.8},
                                 "color": _ORANGE}],
                    "lines": []})
        self._put("/vehicles", ns, {"t_s": t_end, "vehicles": vehicles})
        self._put("/membership", ns, {"t_s": t_end, "vehicles": idx})
        clear = [{"timestamp": _stamp(ns), "type": 1, "id": ""}]
        self._put("/scene/vehicles", ns, {"deletions": clear, "entities": cubes_entities})
        if state is not None and decision is not None:
            ids = list(decision.ids)
            req = np.asarray(decision.requesting, dtype=bool)
            go = np.asarray(decision.go, dtype=bool)
            forced = np.asarray(decision.forced, dtype=bool)
            edges = np.asarray(decision.edges, dtype=int).reshape(-1, 2)
            kinds = [str(k) for k in np.asarray(decision.edge_kinds).reshape(-1)]
            self._put("/tm/decision", ns, {
                "t_s": float(row["t_s"]), "requests": [v for v, r in zip(ids, req) if r],
                "granted": [v for v, r in zip(ids, go) if r], "denied": list(decision.stopped),
                "forced": [v for v, r in zip(ids, forced) if r],
                "edges": [{"from": ids[u], "to": ids[v], "kind": k} for (u, v), k in zip(edges, kinds)],
                "tm_ms": float(row.get("tm_ms", 0.0))})
            if self.level == "full":
                self._put("/scene/claims", ns, self._claims_scene(ns, ids, req, go, edges, decision, state))
        elif self.level == "full":
            self._put("/scene/claims", ns, {"deletions": clear, "entities": []})
        ms = (time.perf_counter() - t0) * 1e3
        self.total_ms += ms
        row["logging_ms"] = round(ms, 4)

    @staticmethod
    def _claims_scene(ns, ids, req, go, edges, decision, state) -> dict:
        polys = decision.claims.polygons()
        ents = []
        for i, vid in enumerate(ids):
            col = _GREEN if go[i] else _RED if req[i] else _GREY
            pts = [{"x": float(p[0]), "y": float(p[1]), "z": 0.05} for p in polys[i]]
            ents.append({"timestamp": _stamp(ns), "frame_id": _FRAME, "id": f"claim/{vid}", "lifetime": _stamp(0),
                         "frame_locked": False, "metadata": [], "cubes": [], "spheres": [],
                         "lines": [{"type": 1, "pose": _pose(0.0, 0.0), "thickness": 0.15, "scale_invariant": False,
                                    "points": pts, "color": col, "colors": [], "indices": []}]})
        if len(edges):
            C = np.asarray(state.centre, dtype=float)
            pts = []
            for u, v in edges:
                pts += [{"x": float(C[u, 0]), "y": float(C[u, 1]), "z": 0.1},
                        {"x": float(C[v, 0]), "y": float(C[v, 1]), "z": 0.1}]
            ents.append({"timestamp": _stamp(ns), "frame_id": _FRAME, "id": "conflicts", "lifetime": _stamp(0),
                         "frame_locked": False, "metadata": [], "cubes": [], "spheres": [],
                         "lines": [{"type": 2, "pose": _pose(0.0, 0.0), "thickness": 0.1, "scale_invariant": False,
                                    "points": pts, "color": _RED, "colors": [], "indices": []}]})
        return {"deletions": [{"timestamp": _stamp(ns), "type": 1, "id": ""}], "entities": ents}

    # ------------------------------------------------------------------ closing
    def close(self) -> None:
        """Finish the MCAP file (summary section, index); idempotent."""
        if self.closed:
            return
        self.closed = True
        try:
            self._w.finish()
        finally:
            self._fh.close()

    def __enter__(self) -> "McapLogger":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def observers_for(out, level: str, metadata: dict | None = None) -> list:
    """The observers a run with ``--log LEVEL`` attaches (``none``: none; else a :class:`McapLogger`
    writing ``out/run.mcap``)."""
    if level not in LOG_LEVELS:
        raise ValueError(f"--log must be one of {', '.join(LOG_LEVELS)}, got {level!r}")
    if level == "none":
        return []
    return [McapLogger(Path(out) / "run.mcap", level, metadata)]


def read_vehicle_states(path) -> "pd.DataFrame":
    """The ``/vehicles`` channel of a ``run.mcap`` as a table.

    Returns
    -------
    DataFrame
        One row per vehicle and step: ``t_s, id, vclass, x_m, y_m, vx_mps, vy_mps, heading_rad,
        waypoint, waypoints, wx_m, wy_m, index``.
    """
    import pandas as pd
    from mcap.reader import make_reader

    rows = []
    with open(path, "rb") as fh:
        for _, _, msg in make_reader(fh).iter_messages(topics=["/vehicles"]):
            m = json.loads(msg.data)
            for v in m["vehicles"]:
                rows.append({"t_s": m["t_s"], **v})
    cols = ["t_s", "id", "vclass", "x_m", "y_m", "vx_mps", "vy_mps", "heading_rad", "waypoint", "waypoints",
            "wx_m", "wy_m", "index"]
    return pd.DataFrame(rows, columns=cols)
