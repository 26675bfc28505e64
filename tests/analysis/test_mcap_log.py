"""``run.mcap`` written by a real short free-plane run reads back with the mcap reader."""

import json
from types import SimpleNamespace

import pandas as pd
import pytest
from mcap.reader import make_reader

from analysis.kpis import timing_means
from analysis.mcap_log import TOPICS, McapLogger, observers_for, read_vehicle_states
from bridge.scenarios import run_multi


def _opts(log):
    return SimpleNamespace(vclass="paper-a", tm="optimal", check="union", switching="early", disturbance="random",
                           solver="exact", duration=5.0, vehicles=8, seed=0, log=log)


@pytest.fixture(scope="module")
def full_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("mcap-full")
    run_multi("paper10", out, _opts("full"))
    return out


def _read(path):
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        first = {}
        for schema, channel, msg in reader.iter_messages():
            first.setdefault(channel.topic, (schema, channel, json.loads(msg.data), msg.log_time))
    return summary, first


def test_full_log_channels_schemas_counts_and_messages(full_run):
    summary, first = _read(full_run / "run.mcap")
    topics = {c.topic: c for c in summary.channels.values()}
    assert set(topics) == set(TOPICS)
    for topic, (schema_name, _) in TOPICS.items():
        ch = topics[topic]
        assert ch.message_encoding == "json"
        schema = summary.schemas[ch.schema_id]
        assert schema.name == schema_name and schema.encoding == "jsonschema"
        assert json.loads(schema.data)["title"] == schema_name
    counts = {topics_id: n for topics_id, n in summary.statistics.channel_message_counts.items()}
    by_topic = {summary.channels[cid].topic: n for cid, n in counts.items()}
    assert by_topic == {t: 50 for t in TOPICS}  # 5 s at 0.1 s, ten vehicles in every step
    # one decoded message per channel
    _, _, veh, t_ns = first["/vehicles"]
    assert t_ns == 100_000_000 and veh["t_s"] == pytest.approx(0.1)
    assert len(veh["vehicles"]) == 10
    v = veh["vehicles"][0]
    assert set(v) == {"id", "vclass", "x_m", "y_m", "vx_mps", "vy_mps", "heading_rad", "waypoint", "waypoints",
                      "wx_m", "wy_m", "index"}
    _, _, mem, _ = first["/membership"]
    assert {m["id"] for m in mem["vehicles"]} == {m["id"] for m in veh["vehicles"]}
    _, _, dec, _ = first["/tm/decision"]
    assert dec["t_s"] == 0.0 and len(dec["requests"]) == 10 and set(dec["granted"]) <= set(dec["requests"])
    assert {"edges", "denied", "forced", "tm_ms"} <= set(dec)
    _, _, scene, _ = first["/scene/vehicles"]
    assert scene["deletions"][0]["type"] == 1 and len(scene["entities"]) == 10
    cube = scene["entities"][0]["cubes"][0]
    assert cube["size"]["x"] == 5.0 and cube["size"]["y"] == 1.8 and scene["entities"][0]["frame_id"] == "world"
    _, _, claims, _ = first["/scene/claims"]
    loops = [e for e in claims["entities"] if e["id"].startswith("claim/")]
    assert len(loops) == 10
    assert loops[0]["lines"][0]["type"] == 1 and len(loops[0]["lines"][0]["points"]) >= 4
    assert {"muvsim"} == {m.name for m in summary.metadata_indexes}


def test_logging_cost_is_in_the_step_table(full_run):
    steps = pd.read_csv(full_run / "steps.csv")
    assert (steps["logging_ms"] > 0).all()
    assert timing_means(steps)["logging_ms"] > 0


def test_summary_level_has_no_polygons_and_none_writes_nothing(tmp_path):
    run_multi("paper10", tmp_path / "s", _opts("summary"))
    summary, _ = _read(tmp_path / "s" / "run.mcap")
    assert {c.topic for c in summary.channels.values()} == {t for t, (_, lvl) in TOPICS.items() if lvl == "summary"}
    states = read_vehicle_states(tmp_path / "s" / "run.mcap")
    assert len(states) == 500 and states["id"].nunique() == 10
    run_multi("paper10", tmp_path / "n", _opts("none"))
    assert not (tmp_path / "n" / "run.mcap").exists()
    assert (pd.read_csv(tmp_path / "n" / "steps.csv")["logging_ms"] == 0).all()


def test_invalid_level_named(tmp_path):
    with pytest.raises(ValueError, match="--log must be one of none, summary, full"):
        observers_for(tmp_path, "all")
    with pytest.raises(ValueError, match="level must be"):
        McapLogger(tmp_path / "x.mcap", "none")


def test_full_log_in_authority_mode_draws_every_vehicles_claim(tmp_path):
    """``--controller authority --log full`` (reach claims, tm.reach.ReachClaims) writes a claim loop
    per vehicle and step (``muvsim run grid --controller authority --log full`` failed at the first
    step: ReachClaims had no ``polygons``), each four points of positive area."""
    opts = SimpleNamespace(vclass="car", tm="optimal", check="timed", switching="early", disturbance="random",
                           solver="exact", duration=2.0, vehicles=8, seed=0, log="full", controller="authority")
    summary = run_multi("crossing", tmp_path, opts)
    assert "error" not in summary
    loops = rows = 0
    with open(tmp_path / "run.mcap", "rb") as fh:
        for _, channel, msg in make_reader(fh).iter_messages(topics=["/scene/claims", "/vehicles"]):
            if channel.topic == "/vehicles":
                rows += len(json.loads(msg.data)["vehicles"])
                continue
            for e in json.loads(msg.data)["entities"]:
                if not e["id"].startswith("claim/"):
                    continue
                pts = [(p["x"], p["y"]) for p in e["lines"][0]["points"]]
                assert len(pts) == 4
                x, y = zip(*pts)
                area = 0.5 * abs(sum(x[i] * y[i - 1] - x[i - 1] * y[i] for i in range(4)))
                assert area > 1.0  # at least a footprint (5 m x 1.8 m)
                loops += 1
    assert loops == rows > 0  # one loop per vehicle and step
