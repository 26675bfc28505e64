"""Free-plane layouts get the SUMO routes' geometry conditioning (bridge.waypoints.condition_polyline):
corners beyond a road-frame class's turn bound are cut, world-frame layouts keep their waypoints."""

import numpy as np
from hypothesis import given, settings, strategies as st

from bridge.cosim import Cosim, CosimSettings
from bridge.layouts import LAYOUT_SPACING, paper10, subsample, swap, turn_bound
from bridge.scenarios import kpi_tables
from bridge.waypoints import CHAMFER_M, point_polyline_distance
from controllers.classes import builtin_classes

CLASSES = builtin_classes()
CAR = CLASSES["car"].model


def _turns_deg(W: np.ndarray) -> np.ndarray:
    """Heading change between consecutive chords of a waypoint list (deg) - what Cosim checks."""
    d = np.diff(W, axis=0)
    h = np.arctan2(d[:, 1], d[:, 0])
    return np.degrees(np.abs((np.diff(h) + np.pi) % (2 * np.pi) - np.pi))


def test_a_90_deg_corner_is_cut_to_the_class_bound():
    """An L-shaped free-plane path (one 90 deg corner) for a car (45 deg bound): no turn between
    waypoints exceeds 45 deg, gaps stay <= delta, ends exact, and the cut stays within CHAMFER_M of
    the corner.  Unconditioned (world frame, no bound) the corner stays a 90 deg turn."""
    pts = np.array([[0.0, 0.0], [30.0, 0.0], [30.0, 30.0]])
    assert turn_bound(CAR) == CAR.turn_max_deg == 45.0
    W = subsample(pts, CAR.delta, turn_bound(CAR))
    assert _turns_deg(W).max() <= 45.0 + 1e-9  # tolerance: float round-off of the heading arithmetic
    assert np.hypot(*np.diff(W, axis=0).T).max() <= CAR.delta
    assert np.array_equal(W[0], pts[0]) and np.array_equal(W[-1], pts[-1])
    assert point_polyline_distance(W, pts).max() <= CHAMFER_M * np.sin(np.radians(45.0)) + 1e-9
    raw = subsample(pts, CAR.delta)
    assert np.isclose(_turns_deg(raw).max(), 90.0)


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(st.floats(3.0, 40.0), st.floats(-149.0, 149.0)), min_size=2, max_size=8),
       st.sampled_from(["car", "bus", "truck"]))
def test_conditioned_free_plane_paths_respect_the_turn_bound(steps, cls):
    """Random free-plane polylines (segments 3-40 m, corners up to 149 deg; beyond REVERSAL_DEG = 150 a corner is reported, not cut): every
    turn between waypoints within the class's bound, every gap <= LAYOUT_SPACING x delta."""
    m = CLASSES[cls].model
    h, p, pts = 0.0, np.zeros(2), [np.zeros(2)]
    for length, turn in steps:
        h += np.radians(turn)
        p = p + length * np.array([np.cos(h), np.sin(h)])
        pts.append(p)
    W = subsample(np.array(pts), m.delta, turn_bound(m))
    assert _turns_deg(W).max() <= m.turn_max_deg + 1e-9
    assert np.hypot(*np.diff(W, axis=0).T).max() <= LAYOUT_SPACING * m.delta + 1e-9


def test_road_frame_swap_is_accepted_and_world_frame_layouts_are_as_drawn():
    """The car ``swap`` (90 deg spoke-ring corners) passes Cosim's turn check; for the world-frame
    paper classes every vertex of the drawn polyline is still a waypoint (no corner cut)."""
    for sp in swap(16, "car", CAR.delta, turn_max_deg=turn_bound(CAR)):
        assert _turns_deg(sp.waypoints).max() <= CAR.turn_max_deg + 1e-9
    for sp in swap(16, "paper-a", CLASSES["paper-a"].model.delta,
                   turn_max_deg=turn_bound(CLASSES["paper-a"].model)):
        assert np.isclose(_turns_deg(sp.waypoints).max(), 90.0, atol=2.0)  # spoke onto the ring, kept
    for sp in paper10({c: CLASSES[c].model.delta for c in CLASSES}):
        assert len(sp.waypoints) >= 2 and _turns_deg(sp.waypoints).max() < 1e-6  # straight lines


def test_small_authority_swap_arrives_without_collisions():
    """Four cars swapping sides round the ring in authority mode (random disturbances): all arrive,
    no geometric collision, no claim, invariant or tube violation."""
    specs = swap(4, "car", CAR.delta, turn_max_deg=turn_bound(CAR))
    sim = Cosim(CLASSES, specs, CosimSettings(controller="authority", disturbance="random", seed=7))
    sim.run(max_steps=1500)
    figures, _, _ = kpi_tables(sim)
    assert figures["vehicles_arrived"] == 4
    assert figures["collisions_geometric"] == 0
    assert figures["footprint_overlaps"] == 0 and figures["claim_violations"] == 0
    assert figures["invariant_violations"] == 0 and figures["tube_escapes"] == 0
