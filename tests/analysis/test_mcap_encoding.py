"""The template encoder of ``McapLogger`` writes, byte for byte, what the dict encoder it
replaced wrote (``json.dumps`` of one dict per message, kept below as the reference), for
fake steps with awkward values: NaN, infinities, -0.0, tiny and huge floats, ids with
quotes, percent signs and non-ASCII, vehicles leaving and returning, waypoints advancing."""

import json
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader

import analysis.mcap_log
from analysis.mcap_log import McapLogger
from bridge.scenarios import run_multi

# ---------------------------------------------------------------- the reference (dict) encoder
_FRAME = "world"
_GREY = {"r": 0.6, "g": 0.6, "b": 0.6, "a": 0.8}
_GREEN = {"r": 0.1, "g": 0.75, "b": 0.2, "a": 0.9}
_RED = {"r": 0.9, "g": 0.1, "b": 0.1, "a": 0.9}
_BLUE = {"r": 0.2, "g": 0.4, "b": 0.9, "a": 0.9}
_ORANGE = {"r": 1.0, "g": 0.6, "b": 0.0, "a": 1.0}


def _stamp(ns):
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _quat(yaw):
    return {"x": 0.0, "y": 0.0, "z": float(np.sin(yaw / 2)), "w": float(np.cos(yaw / 2))}


def _pose(x, y, yaw=0.0, z=0.0):
    return {"position": {"x": float(x), "y": float(y), "z": z}, "orientation": _quat(yaw)}


def reference_messages(sim, state, decision, row, level):
    """topic -> message bytes, as ``McapLogger.on_step`` wrote them up to commit 9dd0bc7."""
    out = {}

    def put(topic, msg):
        out[topic] = json.dumps(msg, separators=(",", ":")).encode()

    t_end = float(row["t_s"]) + float(sim.settings.Ts)
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
    put("/vehicles", {"t_s": t_end, "vehicles": vehicles})
    put("/membership", {"t_s": t_end, "vehicles": idx})
    clear = [{"timestamp": _stamp(ns), "type": 1, "id": ""}]
    put("/scene/vehicles", {"deletions": clear, "entities": cubes_entities})
    if state is not None and decision is not None:
        ids = list(decision.ids)
        req = np.asarray(decision.requesting, dtype=bool)
        go = np.asarray(decision.go, dtype=bool)
        forced = np.asarray(decision.forced, dtype=bool)
        edges = np.asarray(decision.edges, dtype=int).reshape(-1, 2)
        kinds = [str(k) for k in np.asarray(decision.edge_kinds).reshape(-1)]
        put("/tm/decision", {
            "t_s": float(row["t_s"]), "requests": [v for v, r in zip(ids, req) if r],
            "granted": [v for v, r in zip(ids, go) if r], "denied": list(decision.stopped),
            "forced": [v for v, r in zip(ids, forced) if r],
            "edges": [{"from": ids[u], "to": ids[v], "kind": k} for (u, v), k in zip(edges, kinds)],
            "tm_ms": float(row.get("tm_ms", 0.0))})
        if level == "full":
            polys = decision.claims.polygons()
            ents = []
            for i, vid in enumerate(ids):
                col = _GREEN if go[i] else _RED if req[i] else _GREY
                pts = [{"x": float(p[0]), "y": float(p[1]), "z": 0.05} for p in polys[i]]
                ents.append({"timestamp": _stamp(ns), "frame_id": _FRAME, "id": f"claim/{vid}",
                             "lifetime": _stamp(0), "frame_locked": False, "metadata": [], "cubes": [],
                             "spheres": [], "lines": [{"type": 1, "pose": _pose(0.0, 0.0), "thickness": 0.15,
                                                       "scale_invariant": False, "points": pts, "color": col,
                                                       "colors": [], "indices": []}]})
            if len(edges):
                C = np.asarray(state.centre, dtype=float)
                pts = []
                for u, v in edges:
                    pts += [{"x": float(C[u, 0]), "y": float(C[u, 1]), "z": 0.1},
                            {"x": float(C[v, 0]), "y": float(C[v, 1]), "z": 0.1}]
                ents.append({"timestamp": _stamp(ns), "frame_id": _FRAME, "id": "conflicts",
                             "lifetime": _stamp(0), "frame_locked": False, "metadata": [], "cubes": [],
                             "spheres": [], "lines": [{"type": 2, "pose": _pose(0.0, 0.0), "thickness": 0.1,
                                                       "scale_invariant": False, "points": pts, "color": _RED,
                                                       "colors": [], "indices": []}]})
            put("/scene/claims", {"deletions": clear, "entities": ents})
    elif level == "full":
        put("/scene/claims", {"deletions": clear, "entities": []})
    return out


# ---------------------------------------------------------------- fake steps
class FakeGroup:
    """What the logger reads of ``bridge.cosim._Group``."""

    def __init__(self, vclass, ids, X, k, l, W, heading):
        self.vclass, self.ids, self.X, self.k, self.l, self.W = vclass, list(ids), X, k, l, W
        self.heading = heading  # one array per vehicle, like W

    def centres(self):
        if not self.ids:
            return np.zeros((0, 2)), np.zeros(0), np.zeros(0, dtype=bool)
        cen = np.array([w[min(k, len(w) - 1)] for w, k in zip(self.W, self.k)]).reshape(-1, 2)
        hd = np.array([h[min(k, len(h) - 1)] for h, k in zip(self.heading, self.k)], dtype=float)
        return cen, hd, self.k < np.array([len(w) for w in self.W])

    world_centres = centres  # a road-frame plant: its frame is the world's


class FakeClaims:
    def __init__(self, polys):
        self._p = polys

    def polygons(self):
        return self._p


def fake_step(rng, groups, t_s, n_edges=3, K=6, decision=True, polys=None):
    """(sim, state, decision, row) for ``groups`` {class name: FakeGroup}; claim polygons
    ``polys`` (n, K, 2), or random ones."""
    sim = SimpleNamespace(settings=SimpleNamespace(Ts=0.1), groups=groups, world_states=lambda g: g.X[:, :4])
    row = {"t_s": t_s, "tm_ms": float(rng.uniform(0, 5))}
    if not decision:
        return sim, None, None, row
    ids = [v for g in groups.values() for v in g.ids]
    n = len(ids)
    centre = np.vstack([g.centres()[0] for g in groups.values()] or [np.zeros((0, 2))]).reshape(-1, 2)
    req = rng.random(n) < 0.7
    go = req & (rng.random(n) < 0.5)
    forced = req & ~go & (rng.random(n) < 0.3)
    edges = rng.integers(0, max(n, 1), size=(n_edges if n else 0, 2))
    kinds = np.array(rng.choice(["new-new", "new-old", "new-fixed"], size=len(edges)), dtype=str)
    if polys is None:
        polys = centre[:, None, :] + rng.normal(size=(n, K, 2)) * 3.0
    dec = SimpleNamespace(ids=tuple(ids), requesting=req, go=go, forced=forced, edges=edges, edge_kinds=kinds,
                          stopped=tuple(v for v, r, g in zip(ids, req, go) if r and not g),
                          claims=FakeClaims(polys))
    return sim, SimpleNamespace(centre=centre), dec, row


def _read_all(path):
    with open(path, "rb") as fh:
        return [(ch.topic, m.log_time, m.data) for _, ch, m in make_reader(fh).iter_messages()]


def _check(tmp_path, steps, level, spare=None):
    """Log ``steps`` and compare every message with the reference encoder's (``spare``: the
    logger's text caches' spare room; 0 makes them drop their entries every few steps)."""
    expected = []
    with McapLogger(tmp_path / f"{level}.mcap", level) as log:
        if spare is not None:
            for cache in (log._wp_text, log._claim_text, log._id_text, log._claim_id_text):
                cache.spare = spare
        for sim, state, dec, row in steps:
            ref = reference_messages(sim, state, dec, dict(row), level)
            log.on_step(sim, state, dec, row)
            assert row["logging_ms"] >= 0
            ns = int(round((float(row["t_s"]) + 0.1) * 1e9))
            expected += [(topic, ns, data) for topic, data in ref.items()]
    got = _read_all(tmp_path / f"{level}.mcap")
    assert [(t, ns) for t, ns, _ in got] == [(t, ns) for t, ns, _ in expected]
    for (topic, _, data), (_, _, want) in zip(got, expected):
        assert data == want, topic  # the same bytes, hence the same decoded message
        json.loads(data)


def _vclass(length, width):
    return SimpleNamespace(length=length, width=width)


def _sequence(rng, n_steps=12):
    """Two classes; vehicles leave and come back, waypoints advance, values get awkward."""
    names = ['uv0', 'q"uote', "pct%s%d", "ünï/c\u00f8de", "back\\slash"] + [f"v{i}" for i in range(7)]
    routes = {v: rng.normal(size=(rng.integers(2, 9), 2)) * 50 for v in names}
    headings = {v: rng.uniform(-np.pi, np.pi, size=len(routes[v])) for v in names}
    headings["uv0"][0] = -0.0  # its sin is -0.0 too
    headings["uv0"][-1] = np.pi
    classes = {"car%": _vclass(5.0, 1.8), "bus": _vclass(np.float64(12.25), 2)}
    k = {v: 0 for v in names}
    poly = {v: rng.normal(size=(5, 2)) * 4 for v in names}  # claims change in some steps only
    steps = []
    for t in range(n_steps):
        groups = {}
        for ci, (c, vc) in enumerate(classes.items()):
            ids = [v for i, v in enumerate(names) if i % 2 == ci and (i + t) % 5 != 0]  # some away each step
            for v in ids:
                k[v] = min(k[v] + int(rng.random() < 0.3), len(routes[v]) - 1)
            X = rng.normal(size=(len(ids), 5)) * rng.choice([1e-9, 1.0, 1e3, 1e17], size=(len(ids), 1))
            if t == 3 and len(ids) > 2:
                X[0, 0], X[1, 2], X[2, 3] = np.nan, np.inf, -np.inf
            if t == 4 and ids:
                X[0, :4] = [-0.0, 0.0, 1e-320, 123456789.0]
            groups[c] = FakeGroup(vc, ids, X, np.array([k[v] for v in ids], dtype=np.intp),
                                  rng.integers(0, 7, size=len(ids)).astype(np.intp), [routes[v] for v in ids],
                                  [headings[v] for v in ids])
        groups["empty"] = FakeGroup(_vclass(1.0, 1.0), [], np.zeros((0, 4)), np.zeros(0, dtype=np.intp),
                                    np.zeros(0, dtype=np.intp), [], [])
        ids = [v for g in groups.values() for v in g.ids]
        for v in ids:
            if rng.random() < 0.4:
                poly[v] = rng.normal(size=(5, 2)) * rng.choice([1e-3, 4.0, 1e6])
        polys = np.array([poly[v] for v in ids]).reshape(-1, 5, 2)
        steps.append(fake_step(rng, groups, round(t * 0.1, 10), n_edges=t % 4, decision=t % 6 != 5, polys=polys))
    return steps


@pytest.mark.parametrize("spare", [None, 0])
@pytest.mark.parametrize("level", ["summary", "full"])
def test_template_encoder_writes_the_dict_encoders_bytes(tmp_path, level, spare):
    _check(tmp_path, _sequence(np.random.default_rng(7), n_steps=20), level, spare)


def test_no_vehicles_and_no_claims(tmp_path):
    rng = np.random.default_rng(1)
    empty = {"car": FakeGroup(_vclass(5.0, 1.8), [], np.zeros((0, 4)), np.zeros(0, dtype=np.intp),
                              np.zeros(0, dtype=np.intp), [], [])}
    _check(tmp_path, [fake_step(rng, empty, 0.0), fake_step(rng, empty, 0.1, decision=False)], "full")


def test_claim_polygons_with_nan_and_signed_zero(tmp_path):
    rng = np.random.default_rng(2)
    W = [np.array([[0.0, 0.0], [1.0, 1.0]]), np.array([[5.0, -5.0]])]
    g = FakeGroup(_vclass(5.0, 1.8), ["a", "b"], np.ones((2, 4)), np.zeros(2, dtype=np.intp),
                  np.array([2, 0]), W, [np.array([0.3, 0.4]), np.array([-0.0])])
    sim, state, dec, row = fake_step(rng, {"car": g}, 1.5, K=4)
    dec.claims._p[0, 0] = [np.nan, -0.0]
    dec.claims._p[1, 2] = [0.0, np.inf]
    _check(tmp_path, [(sim, state, dec, row)], "full")


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.tuples(st.floats(width=64), st.floats(width=64), st.floats(width=64), st.floats(width=64),
                          st.floats(-10, 10), st.floats(allow_nan=False, allow_infinity=False)),
                min_size=1, max_size=6))
def test_any_float_is_written_as_json_dumps_writes_it(tmp_path, vals):
    a = np.array(vals, dtype=float)
    n = len(a)
    W = [np.array([[a[i, 5], -a[i, 5]]]) for i in range(n)]
    g = FakeGroup(_vclass(4.0, 2.0), [f"v{i}" for i in range(n)], a[:, :4], np.zeros(n, dtype=np.intp),
                  np.arange(n), W, [a[i, 4:5] for i in range(n)])
    sim, state, dec, row = fake_step(np.random.default_rng(n), {"c": g}, 0.2, K=3)
    dec.claims._p[:, 0] = a[:, :2]
    path = tmp_path / "h"
    path.mkdir(exist_ok=True)
    _check(path, [(sim, state, dec, row)], "full")


class _Reference:
    """An observer recording the reference encoder's messages of every step of a real run."""

    def __init__(self, level):
        self.level, self.messages = level, []

    def on_step(self, sim, state, decision, row):
        ns = int(round((float(row["t_s"]) + float(sim.settings.Ts)) * 1e9))
        self.messages += [(topic, ns, data) for topic, data in
                          reference_messages(sim, state, decision, dict(row), self.level).items()]


def test_a_real_run_logs_the_dict_encoders_bytes(tmp_path, monkeypatch):
    """paper10, 5 s, ``--log full``: real groups, TM decisions and claims."""
    ref = _Reference("full")
    real = analysis.mcap_log.observers_for
    monkeypatch.setattr(analysis.mcap_log, "observers_for", lambda out, level, md=None: real(out, level, md) + [ref])
    opts = SimpleNamespace(vclass="paper-a", tm="optimal", check="union", switching="early", disturbance="random",
                           solver="exact", duration=5.0, vehicles=8, seed=0, log="full")
    run_multi("paper10", tmp_path, opts)
    got = _read_all(tmp_path / "run.mcap")
    assert len(got) == 250 and got == ref.messages
