"""A sensitive end-to-end canary: a dense queue in real SUMO, where half a metre of error in the
pose muvsim sends or in the footprint it assumes is a SUMO collision.

The test writes a straight one-lane road (``netgenerate``) and a queue of cars, buses and
trucks 0.2 m apart (muvsim's footprints), then drives them forward together for 2 s through
:class:`bridge.sumo_world.SumoWorld` -- the same ``insert`` / ``push`` (front-bumper pose,
SUMO angle, ``moveToXY``) / ``step`` (SUMO's collision check) as every SUMO run.  Exactly
right, SUMO reports no collision; with the error injected it must report one.

Blind spot (stated, not tested): a constant offset error shared by every vehicle of a
single-file queue moves all bodies alike and no gap changes; the errors injected here differ
between vehicles, as a wrong offset or footprint does when classes differ in length.
"""

import dataclasses
import subprocess
from types import SimpleNamespace

import numpy as np
import pytest

import bridge.sumo_world as sw
from bridge.cosim import VehicleSpec
from bridge.pose import front_bumper
from bridge.sumo_adapter import SumoAdapter
from controllers.classes import builtin_classes
from sumo_nets.sumo_tools import binary

GAP_M = 0.2           # bumper-to-bumper gap of the queue (muvsim's footprints)
ORDER = ["car", "bus", "car", "truck", "car", "bus", "truck", "car"]  # front to back
VTYPES = {"car": ("passenger", 5.0, 1.8), "bus": ("bus", 12.0, 2.5), "truck": ("truck", 7.1, 2.4)}
SPEED = 5.0           # m/s, the whole queue together
STEPS = 20            # 2 s of SUMO


@pytest.fixture(scope="module")
def road(tmp_path_factory):
    d = tmp_path_factory.mktemp("canary")
    net = d / "road.net.xml"
    subprocess.run([str(binary("netgenerate")), "--grid", "--grid.x-number", "2", "--grid.y-number", "1",
                    "--grid.length", "400", "--default.lanenumber", "1", "--no-internal-links", "true",
                    "--no-turnarounds", "true", "--output-file", str(net)], check=True, capture_output=True)
    types = "".join(f'<vType id="{c}" vClass="{vc}" length="{L}" width="{W}" minGap="2.5"/>'
                    for c, (vc, L, W) in VTYPES.items())
    vehs = "".join(f'<vehicle id="q{i}" type="{c}" depart="0"><route edges="A0B0"/></vehicle>'
                   for i, c in enumerate(ORDER))
    rou = d / "queue.rou.xml"
    rou.write_text(f"<routes>{types}{vehs}</routes>")
    return net, rou


def _sumo_collisions(road, classes) -> list:
    """Run the queue in SUMO; the collision pairs SUMO reported."""
    net, rou = road
    adapter = SumoAdapter()
    demand = adapter.start(net=net, routes=rou, seed=0)
    try:
        shape = np.array(adapter._api.lane.getShape("A0B0_0"))
        y = float(shape[0, 1])
        lengths = [classes[c].length for c in ORDER]
        # front of the queue 300 m down the lane, each body GAP_M behind the one ahead
        x, centres = float(shape[0, 0]) + 300.0, []
        for L in lengths:
            centres.append(x - 0.5 * L)
            x -= L + GAP_M
        c = np.column_stack([centres, np.full(len(ORDER), y)])
        planned = {pv.id: pv for pv in demand.vehicles}
        world = sw.SumoWorld(adapter, planned, {v: SimpleNamespace(depart_lane_index=0) for v in planned})
        ids = [f"q{i}" for i in range(len(ORDER))]
        for i, v in enumerate(ids):
            world.insert(VehicleSpec(v, ORDER[i], np.array([c[i], c[i] + [3.0, 0.0]])), None)
        pairs = set(world.step())
        h = np.zeros(len(ids))
        for _ in range(STEPS):
            c = c + [SPEED * 0.1, 0.0]
            world.push(ids, c, h)
            pairs.update(world.step())
        return sorted(pairs)
    finally:
        adapter.close()


def test_exact_pose_and_footprint_no_collision(road):
    assert _sumo_collisions(road, builtin_classes()) == []


def test_front_bumper_offset_dropped_is_a_collision(road, monkeypatch):
    """SUMO given the centre as the front bumper (the offset of bridge/pose.py dropped): each body
    sits half its length back, the car behind a bus runs 3.5 m into it."""
    monkeypatch.setattr(sw, "front_bumper", lambda centre, heading, length: np.array(centre, dtype=float))
    assert _sumo_collisions(road, builtin_classes())


def test_half_metre_offset_error_is_a_collision(road, monkeypatch):
    """The front-bumper offset 10 % too long (+0.5 m on a car, +1.2 m on a bus): the bus behind a
    car gains 0.7 m on it, more than the 0.2 m gap."""
    monkeypatch.setattr(sw, "front_bumper", lambda centre, heading, length:
                        front_bumper(centre, heading, 1.1 * np.asarray(length, dtype=float)))
    assert _sumo_collisions(road, builtin_classes())


def test_half_metre_footprint_error_is_a_collision(road):
    """muvsim's car footprint half a metre shorter than SUMO's passenger car (4.5 m, SUMO 5 m):
    SUMO's body is 0.25 m longer at each end, so the queue muvsim thinks is 0.2 m apart overlaps
    by 0.05 m at every car in SUMO."""
    classes = dict(builtin_classes())
    classes["car"] = dataclasses.replace(classes["car"], length=classes["car"].length - 0.5)
    assert _sumo_collisions(road, classes)
