"""Runtime monitor: overlaps, claim violations and minimum separation on hand-built cases.

Separations are hand-computed distances between rectangles; round-off in
rotating 4 x 2 m rectangles is ~1e-15 m, so 1e-9 m (GEOMETRY_TOL) is asserted.
"""

import numpy as np
import pytest

from tests.tm.helpers import box
from tm.manager import FleetState, TrafficManager
from tm.monitor import Monitor
from tm.settings import TMSettings


def test_min_separation_and_overlap_on_hand_computed_rectangles():
    m = Monitor()
    # a, b: 4 x 2 m heading +x, bumper to bumper 1.5 m apart; c: rotated 90 deg, 10 m above a
    pos = np.array([[0.0, 0.0], [5.5, 0.0], [0.0, 13.0]])
    r = m.step(["a", "b", "c"], pos, [0.0, 0.0, np.pi / 2], [4.0] * 3, [2.0] * 3)
    assert r.footprint_overlaps == 0 and r.ok
    assert r.min_separation == pytest.approx(1.5, abs=1e-9) and r.closest_pair == ("a", "b")
    # c's lower edge at y = 11, a's upper edge at y = 1: 10 m (c is 2 m wide along x, 4 m along y)
    r = m.step(["a", "c"], pos[[0, 2]], [0.0, np.pi / 2], [4.0] * 2, [2.0] * 2)
    assert r.min_separation == pytest.approx(10.0, abs=1e-9)
    # corner to corner at 45 deg: a's corner (2, 1), d's corner at (3, 2) => sqrt(2)
    r = m.step(["a", "d"], [[0.0, 0.0], [5.0, 3.0]], [0.0, 0.0], [4.0] * 2, [2.0] * 2)
    assert r.min_separation == pytest.approx(np.sqrt(2.0), abs=1e-9)
    # b moves 2 m back: overlap of 0.5 m
    r = m.step(["a", "b"], [[0.0, 0.0], [3.5, 0.0]], [0.0, 0.0], [4.0] * 2, [2.0] * 2)
    assert r.footprint_overlaps == 1 and r.overlap_pairs == (("a", "b"),) and r.min_separation == 0.0
    assert not r.ok
    assert (m.steps, m.footprint_overlaps, m.min_separation) == (4, 1, 0.0)


def test_touching_footprints_count_as_overlap():
    r = Monitor().step(["a", "b"], [[0.0, 0.0], [4.0, 0.0]], [0.0, 0.0], [4.0] * 2, [2.0] * 2)
    assert r.footprint_overlaps == 1


def test_fewer_than_two_vehicles():
    r = Monitor().step(["a"], [[0.0, 0.0]], [0.0], [4.0], [2.0])
    assert r.min_separation == np.inf and r.closest_pair is None and r.ok


def test_claim_violations_are_detected():
    """Claims are P^0 (2 x 2 m) plus a 1 x 1 m footprint: 3 m wide.  Centres 3.1 m apart
    leave a 0.1 m gap; 2.9 m apart overlap by 0.1 m while the footprints are 1.9 m apart."""
    families = {"car": [box(1.0, 1.0)]}
    tm = TrafficManager(TMSettings(), families)
    state = FleetState(ids=["a", "b", "c"], family=["car"] * 3, centre=[[0, 0], [3.1, 0], [10, 0]],
                       index=[0, 0, 0], heading=[0, 0, 0], length=[1.0] * 3, width=[1.0] * 3)
    m = Monitor("union")
    ok = m.step(state.ids, state.centre, state.heading, state.length, state.width, tm.claims(state))
    assert ok.claim_violations == 0
    bad = FleetState(ids=["a", "b", "c"], family=["car"] * 3, centre=[[0, 0], [2.9, 0], [10, 0]],
                     index=[0, 0, 0], heading=[0, 0, 0], length=[1.0] * 3, width=[1.0] * 3)
    r = m.step(bad.ids, bad.centre, bad.heading, bad.length, bad.width, tm.claims(bad))
    assert r.claim_violations == 1 and r.violation_pairs == (("a", "b"),)
    assert r.footprint_overlaps == 0 and r.min_separation == pytest.approx(1.9, abs=1e-9)
    assert m.claim_violations == 1


def test_invalid_check_is_rejected():
    with pytest.raises(ValueError, match="'union', 'timed'"):
        Monitor("exact")
