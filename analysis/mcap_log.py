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
row as ``logging_ms``.  Messages are assembled from text templates, column by
column (see "encoding" below), and are byte for byte what ``json.dumps`` of the
message dicts gives: every float at full round-trip precision.  Measured
(``benchmarks/bench_logging.py``, README "MCAP logs"): 11-13 us CPU per
vehicle-step at ``summary``, of which ~4 us are the MCAP writer and its zstd
chunks and ~2.5 us the text of x, y, vx, vy; ``full`` about doubles it (claim
polygons, 8 points each).
"""

from __future__ import annotations

import json
import math
import os
import time
from itertools import chain, compress
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

# ---------------------------------------------------------------------------- encoding
# Messages are JSON text assembled from templates; it is, byte for byte, what
# ``json.dumps(msg, separators=(",", ":"))`` of the message as dicts gives (the encoder
# this replaced; ``tests/analysis/test_mcap_encoding.py`` compares the two).  Per step
# and class a message part is one ``%`` of a template repeated once per vehicle, filled
# from columns: ids and class names as ``json.dumps`` writes them, floats as their
# shortest round-trip text (``float.__repr__``, which is what ``json.dumps`` writes;
# ``NaN``/``Infinity`` as ``json.dumps`` writes them), so a reader decodes every value
# exactly.  Float text is the expensive part (0.6-1 us a value), so what repeats
# from step to step -- the text derived from a vehicle's current waypoint, and a claim
# polygon's points -- is kept in a cache keyed by the bytes of the values it was made
# from (exact: -0.0 and 0.0 differ there, as their texts do).

_SEP = (",", ":")
_REPR = float.__repr__
_SLOT, _QSLOT, _STAMP = "\x00", "\x01", "\x02"  # template markers: %s, "%s", the step's stamp


_ENCODER = json.JSONEncoder(separators=_SEP)  # json.dumps(obj, separators=_SEP), without a new encoder a call


def _j(obj) -> str:
    return _ENCODER.encode(obj)


def _template(obj) -> str:
    """``obj`` as compact JSON with ``_SLOT`` values as ``%s``, ``_QSLOT`` as ``"%s"`` (other
    ``%`` doubled); ``_STAMP`` stays a marker (``"\\u0002"``) to replace once per step."""
    return (_j(obj).replace("%", "%%").replace('"\\u0000"', "%s").replace('"\\u0001"', '"%s"'))


_STAMP_TEXT = _j(_STAMP)


def _stamp(ns: int) -> dict:
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


_ZERO_POSE = {"position": {"x": 0.0, "y": 0.0, "z": 0.0},
              "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}  # the pose at (0, 0), heading 0
_MEMBER = _template({"id": _SLOT, "index": _SLOT})
_CLAIM_POINT = _template({"x": _SLOT, "y": _SLOT, "z": 0.05})
_EDGE_POINT = _template({"x": _SLOT, "y": _SLOT, "z": 0.1})
_CLAIM = _template({"timestamp": _STAMP, "frame_id": _FRAME, "id": _SLOT, "lifetime": _stamp(0),
                    "frame_locked": False, "metadata": [], "cubes": [], "spheres": [],
                    "lines": [{"type": 1, "pose": _ZERO_POSE, "thickness": 0.15, "scale_invariant": False,
                               "points": [_SLOT], "color": _SLOT, "colors": [], "indices": []}]})
_CONFLICTS = _template({"timestamp": _STAMP, "frame_id": _FRAME, "id": "conflicts", "lifetime": _stamp(0),
                        "frame_locked": False, "metadata": [], "cubes": [], "spheres": [],
                        "lines": [{"type": 2, "pose": _ZERO_POSE, "thickness": 0.1, "scale_invariant": False,
                                   "points": [_SLOT], "color": _RED, "colors": [], "indices": []}]})
_CLEAR = _template([{"timestamp": _STAMP, "type": 1, "id": ""}])
_COLOURS = (_j(_GREY), _j(_RED), _j(_GREEN))  # not asking, denied, granted
# The waypoint-derived runs of text of one vehicle; each fills one slot of the class templates.
_WP_VEHICLE = '%s,"waypoint":%s,"waypoints":%s,"wx_m":%s,"wy_m":%s'  # from "heading_rad":
_WP_QUAT = '%s,"w":%s'  # from the cube's "orientation":{..,"z":
_WP_SPHERE = '%s,"y":%s'  # from the sphere's "position":{"x":


def _class_templates(c: str, vc) -> tuple[str, str]:
    """Templates of one vehicle of class ``c`` in ``/vehicles`` and in ``/scene/vehicles``; the
    slots marked ``_WP`` take the ``_WP_*`` runs (the keys after them are in the runs)."""
    vehicle = _template({"id": _SLOT, "vclass": c, "x_m": _SLOT, "y_m": _SLOT, "vx_mps": _SLOT,
                         "vy_mps": _SLOT, "heading_rad": _SLOT,  # _WP: .. "wy_m"
                         "index": _SLOT})
    entity = _template({
        "timestamp": _STAMP, "frame_id": _FRAME, "id": _SLOT, "lifetime": _stamp(0), "frame_locked": False,
        "metadata": [{"key": "class", "value": c}, {"key": "index", "value": _QSLOT}],
        "cubes": [{"pose": {"position": {"x": _SLOT, "y": _SLOT, "z": 0.75},
                            "orientation": {"x": 0.0, "y": 0.0, "z": _SLOT}},  # _WP: .. "w"
                   "size": {"x": vc.length, "y": vc.width, "z": 1.5}, "color": _BLUE}],
        "spheres": [{"pose": {"position": {"x": _SLOT, "z": 0.0},  # _WP: .. "y"
                              "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}},
                     "size": {"x": 0.8, "y": 0.8, "z": 0.8}, "color": _ORANGE}],
        "lines": []})
    return vehicle, entity


_DECISION = '{"t_s":%s,"requests":[%s],"granted":[%s],"denied":[%s],"forced":[%s],"edges":[%s],"tm_ms":%s}'
_EDGE = '{"from":%s,"to":%s,"kind":%s}'


def _float_text(v: float) -> str:
    """``json.dumps`` of one float."""
    return _REPR(v) if math.isfinite(v) else _j(v)


def _edges_text(idt: list[str], edges: np.ndarray, kinds) -> str:
    """The ``/tm/decision`` edge objects, comma-joined: ``idt`` is the JSON text of each id."""
    if not len(edges):
        return ""
    names, inv = np.unique(np.asarray(kinds).reshape(-1), return_inverse=True)
    text = [_j(str(k)) for k in names]
    a, b = edges.T.tolist()
    return _fill(_EDGE, len(a), [idt[i] for i in a], [idt[i] for i in b], [text[i] for i in inv.tolist()])


def _fill(template: str, n: int, *columns) -> str:
    """``n`` copies of ``template`` joined by commas, slot ``i`` of copy ``j`` filled with ``columns[i][j]``."""
    if n == 0:
        return ""
    return (",".join([template] * n)) % tuple(chain.from_iterable(zip(*columns)))


def _floats(a) -> list[str]:
    """JSON text of each value of ``a`` (flattened), as ``json.dumps`` writes a float."""
    a = np.asarray(a, dtype=float).reshape(-1)
    values = a.tolist()
    if np.isfinite(a).all():
        return list(map(_REPR, values))
    return [_j(v) for v in values]


def _row_keys(a) -> list[bytes]:
    """The bytes of each row of 2-D ``a`` as float64 (exact keys: NaN finds NaN, -0.0 is not 0.0)."""
    a = np.ascontiguousarray(a, dtype=float)
    return a.view(np.dtype((np.void, a.shape[1] * 8))).reshape(-1).tolist()


class _TextCache:
    """Text by key (rows of numbers by their bytes, ids by themselves).  What repeats is mostly
    the previous step's rows, so once it holds more than three lookups' worth (plus ``spare``)
    it keeps only the rows of the current lookup: its size follows the fleet."""

    def __init__(self, spare: int = 1000):
        self.spare = spare
        self.text: dict = {}

    def get(self, keys: list, make) -> list:
        """The text of each key; ``make(rows)`` makes the missing ones (``rows``: their positions)."""
        out = list(map(self.text.get, keys))
        if None in out:
            rows = [j for j, t in enumerate(out) if t is None]
            for j, t in zip(rows, make(np.asarray(rows, dtype=np.intp))):
                out[j] = t
            if len(self.text) + len(rows) > 3 * len(keys) + self.spare:
                self.text = dict(zip(keys, out))
            else:
                self.text.update((keys[j], out[j]) for j in rows)
        return out


class _TailedFile:
    """A write-only binary file that is a complete MCAP after every :meth:`flush`.

    The MCAP writer's output is buffered here; :meth:`flush` writes what it buffered at the end
    of the data so far followed by a minimal ending (``DataEnd``, a ``Footer`` with no summary,
    the magic) in one ``pwrite``, and the next flush writes over that ending.  So a process
    killed outright (SIGKILL) leaves a file that ``mcap.reader.make_reader`` opens and reads up
    to the last flushed chunk (with no summary it reads linearly).  Killed *during* that one
    ``pwrite`` (a few hundred microseconds a second) the ending can be torn.  :meth:`close`
    writes the writer's real ending (summary, index) and truncates there.
    """

    def __init__(self, path):
        from mcap.records import DataEnd, Footer
        from mcap.data_stream import RecordBuilder
        from mcap.writer import MCAP0_MAGIC

        rb = RecordBuilder()
        DataEnd(data_section_crc=0).write(rb)
        Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(rb)
        self._tail = bytes(rb.end()) + MCAP0_MAGIC
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        self._pos = 0          # bytes committed to the file (the data, without the ending)
        self._buf = bytearray()

    def write(self, data) -> int:
        self._buf += data
        return len(data)

    def tell(self) -> int:
        return self._pos + len(self._buf)

    def seekable(self) -> bool:
        return False

    def _commit(self, ending: bytes) -> None:
        data = bytes(self._buf) + ending
        written = 0
        while written < len(data):
            written += os.pwrite(self._fd, data[written:], self._pos + written)
        self._pos += len(self._buf)
        self._buf.clear()

    def flush(self) -> None:
        if self._buf:
            self._commit(self._tail)

    def close(self) -> None:
        """Write what is buffered (the writer's own ending once it finished) and truncate there."""
        if self._fd < 0:
            return
        try:
            self._commit(b"")
            os.ftruncate(self._fd, self._pos)
        finally:
            os.close(self._fd)
            self._fd = -1


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
    Call :meth:`close` (or use it as a context manager) to finish the file (summary, index).
    Until then the chunk in progress is closed every ``flush_s`` simulated seconds (mcap 1.6's
    ``Writer.flush``; by size alone, 1 MiB chunks, a chunk could span minutes) and the file is
    a complete MCAP without summary up to that chunk (:class:`_TailedFile`): a run killed
    outright loses at most the last ``flush_s``.
    """

    def __init__(self, path, level: str = "summary", metadata: dict | None = None, flush_s: float = 1.0):
        from mcap.writer import CompressionType, Writer

        if level not in ("summary", "full"):
            raise ValueError(f"McapLogger: level must be 'summary' or 'full', got {level!r}")
        if not flush_s > 0:
            raise ValueError(f"McapLogger: flush_s must be > 0 s, got {flush_s}")
        self.path = Path(path)
        self.level = level
        self.flush_s = float(flush_s)
        self._next_flush = self.flush_s
        self._fh = _TailedFile(self.path)
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
        self._wp_text = _TextCache()  # waypoint rows -> their three runs of text
        self._claim_text = _TextCache()  # claim polygons -> their points' text
        self._id_text = _TextCache()  # vehicle id -> its JSON string
        self._claim_id_text = _TextCache()  # vehicle id -> the JSON string "claim/<id>"
        self._class_text: dict[tuple, tuple[str, str]] = {}

    # ------------------------------------------------------------------ writing
    def _put(self, topic: str, ns: int, text: str) -> None:
        self._seq += 1
        self._w.add_message(self._ch[topic], log_time=ns, data=text.encode(), publish_time=ns,
                            sequence=self._seq)
        self.messages += 1

    def on_step(self, sim, state, decision, row) -> None:
        """Log the step just taken; adds ``logging_ms`` to ``row``."""
        t0 = time.perf_counter()
        Ts = float(sim.settings.Ts)
        t_end = float(row["t_s"]) + Ts
        ns = int(round(t_end * 1e9))
        stamp = '{"sec":%d,"nsec":%d}' % divmod(ns, 1_000_000_000)  # as _j(_stamp(ns))
        # the fleet's columns, class after class: one conversion to text for all classes
        classes, X, cen, hd, k, count, lv, vids = [], [], [], [], [], [], [], []
        for c, g in sim.groups.items():
            if not g.ids:
                continue
            key = (c, g.vclass.length, g.vclass.width)
            tmpl = self._class_text.get(key)
            if tmpl is None:
                tmpl = self._class_text[key] = _class_templates(c, g.vclass)
            classes.append((tmpl, len(g.ids)))
            cen_g, hd_g, _ = g.world_centres()
            X.append(sim.world_states(g))
            cen.append(cen_g)
            hd.append(hd_g)
            k.append(g.k)
            lv.append(g.l)
            count += [len(w) for w in g.W]
            vids += g.ids
        vehicles, entities, members = [], [], ""
        if classes:
            n = len(vids)
            ids = self._id_text.get(vids, lambda rows: [json.dumps(vids[j]) for j in rows])
            xy = _floats(np.concatenate(X).T)  # x, then y, vx, vy of every vehicle
            x, y, vx, vy = (xy[i * n:(i + 1) * n] for i in range(4))
            lv = np.concatenate(lv).astype(int).tolist()
            wp = np.empty((n, 5))  # heading, waypoint x, y, its index, the route's waypoints
            wp[:, 0] = np.concatenate(hd)
            wp[:, 1:3] = np.concatenate(cen)
            wp[:, 3] = np.concatenate(k)
            wp[:, 4] = count
            runs = self._wp_text.get(_row_keys(wp), lambda rows: self._waypoint_runs(wp[rows]))
            wv, wq, ws = zip(*runs)
            o = 0
            for (tv, te), m in classes:
                s = slice(o, o + m)
                vehicles.append(_fill(tv, m, ids[s], x[s], y[s], vx[s], vy[s], wv[s], lv[s]))
                entities.append(_fill(te.replace(_STAMP_TEXT, stamp), m, ids[s], lv[s], x[s], y[s], wq[s], ws[s]))
                o += m
            members = _fill(_MEMBER, n, ids, lv)
        t_text = _REPR(t_end) if math.isfinite(t_end) else _j(t_end)
        self._put("/vehicles", ns, '{"t_s":%s,"vehicles":[%s]}' % (t_text, ",".join(vehicles)))
        self._put("/membership", ns, '{"t_s":%s,"vehicles":[%s]}' % (t_text, members))
        clear = _CLEAR.replace(_STAMP_TEXT, stamp)
        self._put("/scene/vehicles", ns, '{"deletions":%s,"entities":[%s]}' % (clear, ",".join(entities)))
        if state is not None and decision is not None:
            ids = list(decision.ids)
            req = np.asarray(decision.requesting, dtype=bool)
            go = np.asarray(decision.go, dtype=bool)
            forced = np.asarray(decision.forced, dtype=bool)
            edges = np.asarray(decision.edges, dtype=int).reshape(-1, 2)
            idt = self._id_text.get(ids, lambda rows: [json.dumps(ids[j]) for j in rows])
            denied = list(decision.stopped)
            where = dict(zip(ids, idt)) if denied else {}
            self._put("/tm/decision", ns, _DECISION % (
                _float_text(float(row["t_s"])), ",".join(compress(idt, req.tolist())),
                ",".join(compress(idt, go.tolist())),
                ",".join([where[v] if v in where else _j(v) for v in denied]),
                ",".join(compress(idt, forced.tolist())), _edges_text(idt, edges, decision.edge_kinds),
                _float_text(float(row.get("tm_ms", 0.0)))))
            if self.level == "full":
                self._put("/scene/claims", ns, self._claims_scene(stamp, clear, ids, req, go, edges, decision, state))
        elif self.level == "full":
            self._put("/scene/claims", ns, '{"deletions":%s,"entities":[]}' % clear)
        if t_end + 1e-9 >= self._next_flush:  # close the chunk: the file is readable up to here
            self._next_flush += self.flush_s
            self._w.flush()
        ms = (time.perf_counter() - t0) * 1e3
        self.total_ms += ms
        row["logging_ms"] = round(ms, 4)

    @staticmethod
    def _waypoint_runs(wp) -> list[tuple[str, str, str]]:
        """The ``_WP_*`` runs of text of waypoint rows ``(heading, x, y, k, count)``."""
        m = len(wp)
        text = _floats(np.concatenate([wp[:, :3].T.reshape(-1), np.sin(wp[:, 0] / 2), np.cos(wp[:, 0] / 2)]))
        h, cx, cy, qz, qw = (text[i * m:(i + 1) * m] for i in range(5))
        k, count = wp[:, 3:5].astype(int).T.tolist()
        return [(_WP_VEHICLE % v, _WP_QUAT % q, _WP_SPHERE % s) for v, q, s in
                zip(zip(h, k, count, cx, cy), zip(qz, qw), zip(cx, cy))]

    def _claims_scene(self, stamp, clear, ids, req, go, edges, decision, state) -> str:
        n = len(ids)
        ents = []
        if n:
            polys = np.asarray(decision.claims.polygons(), dtype=float)[:n]
            K = polys.shape[1]
            if K:
                flat = polys.reshape(n, 2 * K)
                points_tmpl = ",".join([_CLAIM_POINT] * K)

                def make(rows):  # one string of all rows' points, split on a byte JSON text never has
                    return (("\x00".join([points_tmpl] * len(rows))) % tuple(_floats(flat[rows]))).split("\x00")

                points = self._claim_text.get(_row_keys(flat), make)
            else:
                points = [""] * n
            colour = [_COLOURS[i] for i in (go.astype(np.intp) * 2 + (req & ~go)).tolist()]
            ents.append(_fill(_CLAIM.replace(_STAMP_TEXT, stamp), n,
                              self._claim_id_text.get(ids, lambda rows: [json.dumps(f"claim/{ids[j]}") for j in rows]),
                              points, colour))
        if len(edges):
            C = np.asarray(state.centre, dtype=float)
            ends = C[edges.reshape(-1)][:, :2]  # u, v of each edge, in order
            ents.append(_CONFLICTS.replace(_STAMP_TEXT, stamp)
                        % _fill(_EDGE_POINT, len(ends), _floats(ends[:, 0]), _floats(ends[:, 1])))
        return '{"deletions":%s,"entities":[%s]}' % (clear, ",".join(ents))

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
