"""The traffic-light rule (tm.signals) and the junction token give-back, without a simulator.

Positions are in metres along a route; waypoints 3 m apart.  Every comparison is of sums
of a few O(10) floats, far (>= 0.5 m, >= 5 m^2/s^2) from the thresholds, so no tolerance
is needed beyond exact comparison.
"""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from tm.junctions import JunctionGate
from tm.signals import (SignalBook, SignalSettings, SignalSettingsError, StopLines, red_crossings, stop_bounds,
                        withhold)

from tests.tm.test_junctions import CAR, EAST, J, NORTH, Scene

OBEY, IGNORE = SignalSettings("obey"), SignalSettings("ignore")
ARC = np.arange(0.0, 31.0, 3.0)  # waypoints 0, 3, ..., 30 m


def _one(state: str, k: int, bound: int, gap: float = 10.0, speed: float = 5.0, mode=OBEY, req=True):
    """Whether a single vehicle's request k -> k + 1 stays, with one line (bound, state, gap)."""
    out, held = withhold(mode, np.array([req]), np.array([k]), np.array([0]), np.array([bound]),
                         np.frombuffer(state.encode(), np.uint8), np.array([gap]), np.array([speed]))
    assert held[0] == (req and not out[0])
    return bool(out[0])


def test_bound_keeps_the_front_bumper_of_a_vehicle_at_rest_behind_the_line():
    # line at 20 m, reach 3.5 m (hold region 1 m + half a 5 m car): arc[k] + 3.5 <= 20 -> k <= 5 (15 m)
    assert stop_bounds(ARC, np.array([20.0]), 3.5).tolist() == [5]
    assert stop_bounds(ARC, np.array([18.5]), 3.5).tolist() == [5]   # 15 + 3.5 = 18.5: exactly at the line
    assert stop_bounds(ARC, np.array([18.4]), 3.5).tolist() == [4]
    assert stop_bounds(ARC, np.array([2.0, 40.0]), 3.5).tolist() == [-1, 10]  # starts past it / never reached


def test_red_withholds_only_the_switch_that_crosses_the_line():
    for red in "rRu":
        assert not _one(red, k=5, bound=5)
    assert _one("r", k=4, bound=5)      # the switch 4 -> 5 stays behind the line
    assert _one("r", k=6, bound=5)      # already granted past the line: never affected
    assert not _one("r", k=5, bound=5, req=False)  # no request stays no request


def test_green_minor_green_and_off_go():
    for go in "GgsoO":
        assert _one(go, k=5, bound=5)


def test_yellow_withheld_with_room_to_stop_granted_without():
    # a_c = 2.5: room iff v^2 <= 5 gap
    assert not _one("y", k=5, bound=5, gap=10.0, speed=5.0)   # 25 <= 50: stops
    assert _one("y", k=5, bound=5, gap=4.0, speed=5.0)        # 25 > 20: committed, goes
    assert not _one("Y", k=5, bound=5, gap=10.0, speed=7.0)   # 49 <= 50
    assert _one("y", k=6, bound=5, gap=-1.0, speed=0.0)       # past the line


def test_ignore_mode_withholds_nothing():
    for s in "rRuyYGgsoO":
        assert _one(s, k=5, bound=5, mode=IGNORE)


def test_settings_are_validated():
    with pytest.raises(SignalSettingsError, match="SignalSettings.mode"):
        SignalSettings("stop")
    with pytest.raises(SignalSettingsError, match="comfort_decel"):
        SignalSettings("obey", comfort_decel=0.0)


@settings(max_examples=200, deadline=None)
@given(st.data())
def test_vectorised_rule_equals_the_rule_per_line(data):
    """Random fleets and lines: a request stays iff no line of its vehicle has bound == k and a
    red, or a yellow with room to stop (v^2 <= 2 a_c gap)."""
    n = data.draw(st.integers(1, 8))
    m = data.draw(st.integers(0, 16))
    req = np.array(data.draw(st.lists(st.booleans(), min_size=n, max_size=n)))
    k = np.array(data.draw(st.lists(st.integers(0, 4), min_size=n, max_size=n)))
    row = np.array(data.draw(st.lists(st.integers(0, n - 1), min_size=m, max_size=m)), dtype=np.intp)
    bound = np.array(data.draw(st.lists(st.integers(-1, 4), min_size=m, max_size=m)), dtype=np.intp)
    letters = data.draw(st.text(alphabet="rRyYgGsuoO", min_size=m, max_size=m))
    gap = np.array(data.draw(st.lists(st.floats(-5, 30), min_size=m, max_size=m)), dtype=float)
    speed = np.array(data.draw(st.lists(st.floats(0, 14), min_size=n, max_size=n)), dtype=float)
    out, _ = withhold(OBEY, req, k, row, bound, np.frombuffer(letters.encode(), np.uint8), gap, speed)
    want = req.copy()
    for j in range(m):
        i = row[j]
        if req[i] and bound[j] == k[i] and (letters[j] in "rRu" or
                                           (letters[j] in "yY" and speed[i] ** 2 <= 5.0 * gap[j])):
            want[i] = False
    assert out.tolist() == want.tolist()


def _drive(book, vid, front_path, states, lines_s):
    """Count red crossings of one vehicle whose front goes through ``front_path`` (one per step)."""
    n = 0
    for f, s in zip(front_path, states):
        n += book.count_crossings([vid], np.array([f]), np.zeros(len(lines_s), np.intp), np.array(lines_s),
                                  np.frombuffer(s.encode(), np.uint8))
    return n


def test_red_crossings_count_front_bumpers_crossing_on_red_only():
    assert red_crossings([9.0, 9.0, 9.0, 11.0], [10.0, 11.0, 9.5, 12.0], [10.0] * 4,
                         np.frombuffer(b"rgrr", np.uint8)).tolist() == [True, False, False, False]
    book = SignalBook(OBEY)
    assert _drive(book, "a", [8.0, 9.5, 10.5, 12.0], ["r", "r", "r", "r"], [10.0]) == 1
    assert _drive(book, "b", [8.0, 9.5, 10.5, 12.0], ["G", "G", "G", "r"], [10.0]) == 0
    assert book.red_violations == 1


def test_signal_book_gathers_each_vehicles_lines_and_front():
    book = SignalBook(OBEY)
    book.add("a", StopLines(ARC, np.array([20.0, 29.0]), np.array([0, 1])), reach=3.5)
    book.add("none", StopLines(ARC, np.zeros(0), np.zeros(0, np.intp)), reach=3.5)  # no line: not kept
    assert len(book) == 1 and book.bounds("a").tolist() == [5, 8]
    ids = ["x", "a"]
    k = np.array([0, 2])
    centre = np.array([[0.0, 0.0], [6.0, 0.0]])
    pos = np.array([[0.0, 0.0], [5.0, 0.0]])  # a: 1 m behind its waypoint (arc 6): along 5 m
    row, bound, s, slot, front = book.gather(ids, k, centre, np.zeros(2), pos, np.array([2.5, 2.5]))
    assert row.tolist() == [1, 1] and bound.tolist() == [5, 8] and slot.tolist() == [0, 1]
    assert np.isnan(front[0]) and front[1] == 7.5


def test_a_holder_held_at_red_gives_its_token_back_and_must_ask_again():
    """A (east) holds the junction's token and stands at a red: the crossing N, green, gets no
    token while A keeps it; once A gives it back (what the co-simulation does for a vehicle a
    signal holds), N gets it.  A's request from inside the guard then needs the token again."""
    gate = JunctionGate([J], {"car": CAR})
    scene = Scene({"A": EAST})
    assert scene.withhold(gate) == {"A"} and set(gate.holders[0]) == {"A"}
    both = Scene({"A": EAST, "N": NORTH}, k={"A": 3}, idle=("A",))  # A inside the guard, held
    assert both.withhold(gate, t=1) == set() and set(gate.holders[0]) == {"A"}
    gate.give_back(["A"])
    assert both.withhold(gate, t=2) == {"N"} and set(gate.holders[0]) == {"N"}
    both.k[1] = 3  # N moved into the guard (it keeps its token there)
    both.requesting[:] = True  # green for A: it asks again, from inside the guard: N holds, A waits
    assert both.withhold(gate, t=3) == {"N"}
    assert (0, "A") in gate.wait


def test_a_vehicle_standing_at_red_blocks_only_the_queue_behind_it():
    """A stands at a red inside the guard (token given back).  B, behind it on its lane, gets no
    token (its route runs into A's claim); C, on a lane 2.6 m beside it (corridor boxes of
    +-1.4 m across meet A's claim box, its waypoints do not), does.  Once A no longer stands (a
    plain claim in the guard without a token), C's corridor box meeting it is enough to keep
    C out, as before."""
    behind = ((-17.5, -1.6), (60.0, -1.6))
    beside = ((-17.0, 1.0), (60.0, 1.0))
    for standing, want in ((["A"], {"C"}), ([], set())):
        gate = JunctionGate([J], {"car": CAR})
        assert Scene({"A": EAST}).withhold(gate) == {"A"}
        gate.give_back(["A"])
        gate.give_back(standing)
        scene = Scene({"A": EAST, "B": behind, "C": beside}, k={"A": 3}, idle=("A",))
        assert scene.withhold(gate, t=1) == want, standing
        assert "B" not in gate.holders[0]


# ---------------------------------------------------------------- time to red (issue 12)
from tm.signals import LineTiming, commit_points, time_to_line  # noqa: E402


def _numeric_time(gap, rest, v0, V, a, b, n=200_000):
    """Reference: integrate ds / v(s) of the profile min(sqrt(v0^2 + 2 a s), V, sqrt(2 b (rest - s)))
    with the midpoint rule (v0 first clipped to V and the braking curve, as time_to_line does)."""
    v0 = min(v0, V, np.sqrt(2 * b * rest))
    s = (np.arange(n) + 0.5) * gap / n
    v = np.minimum(np.minimum(np.sqrt(v0 * v0 + 2 * a * s), V), np.sqrt(2 * b * (rest - s)))
    return float(np.sum(gap / n / v))


def test_time_to_line_cruise_then_braking_closed_form():
    # 13.9 m/s, line 47 m ahead, rest 1.5 m past it, a_c 2.5: cruise to s = 48.5 - 13.9^2/5 = 9.86 m
    # (0.709 s), then brake to sqrt(5 * 1.5) = 2.739 m/s at the line ((13.9 - 2.739) / 2.5 = 4.465 s)
    t = time_to_line(47.0, 48.5, 13.9, 13.9, 1.0, 2.5)
    assert abs(t - (9.858 / 13.9 + (13.9 - np.sqrt(7.5)) / 2.5)) < 1e-3
    assert time_to_line(47.0, 47.0, 13.9, 13.9, 1.0, 2.5) == np.inf    # stops at the line: never reaches it
    assert time_to_line(-1.0, 2.0, 0.0, 13.9, 1.0, 2.5) == 0.0         # already past
    assert time_to_line(4.0, 6.0, 0.0, 13.9, 1.0, 2.5) < 4.0           # from rest: accelerates (finite)


@settings(max_examples=60, deadline=None)
@given(gap=st.floats(0.5, 80.0), past=st.floats(0.3, 10.0), v0=st.floats(0.0, 20.0), V=st.floats(1.0, 20.0),
       a=st.floats(0.3, 3.0), b=st.floats(1.0, 5.0))
def test_time_to_line_matches_the_integral_of_its_profile(gap, past, v0, V, a, b):
    """Closed form against the midpoint rule on 2e5 cells.  Tolerance 1 %, + 5 ms: the integrand
    1/v has an integrable singularity at s = 0 from rest, where the midpoint rule errs by
    ~sqrt(cell / a) (< 2 ms here); elsewhere it is smooth and the error is far below 1 %."""
    t = float(time_to_line(gap, gap + past, v0, V, a, b))
    ref = _numeric_time(gap, gap + past, v0, V, a, b)
    assert abs(t - ref) <= 0.01 * ref + 5e-3, (t, ref)


def _timed(state, k, bound, commit, gap, speed, to_red, past=1.5, cap=13.9):
    timing = LineTiming(commit=np.array([commit]), rest_past=np.array([past]), time_to_red=np.array([to_red]),
                        v_cap=np.array([cap]), decel=np.array([2.5]))
    out, held = withhold(OBEY, np.array([True]), np.array([k]), np.array([0]), np.array([bound]),
                         np.frombuffer(state.encode(), np.uint8), np.array([gap]), np.array([speed]), timing)
    assert held[0] == (not out[0])
    return bool(out[0])


def test_green_crossing_withheld_when_the_front_cannot_reach_the_line_before_red():
    """Vehicle 34 of issue 12 (tlsgrid, authority): cruising at 13.9 m/s it asks for the crossing
    switch 47 m before the line on 'G' 0.4 s before yellow (3 s): red in 3.4 s.  Under the profile
    the cost tracks with nothing further granted (5.17 s to the line, + 0.5 s margin) it is
    withheld; the letter alone let it go (and it entered 0.2 s into red)."""
    assert _one("G", k=5, bound=5, gap=47.0, speed=13.9)                              # before: granted
    assert not _timed("G", k=5, bound=5, commit=6, gap=47.0, speed=13.9, to_red=3.4)  # now: held
    assert _timed("G", k=5, bound=5, commit=6, gap=47.0, speed=13.9, to_red=6.0)      # 5.67 s < 6 s: goes
    assert _timed("g", k=5, bound=5, commit=6, gap=47.0, speed=13.9, to_red=np.inf)   # never red: goes
    assert not _timed("r", k=5, bound=5, commit=6, gap=47.0, speed=13.9, to_red=np.inf)  # red stays red


def test_crossing_chain_is_judged_until_the_front_is_past_the_line():
    """bound 5, commit 7 (the rest front at stop point 6 still short of the line): the switch 6 -> 7
    is judged too while the front is behind the line, not once it is past; 7 -> 8 never."""
    assert not _timed("G", k=6, bound=5, commit=7, gap=20.0, speed=10.0, to_red=1.0)
    assert not _timed("r", k=6, bound=5, commit=7, gap=20.0, speed=10.0, to_red=0.0)
    assert _timed("r", k=6, bound=5, commit=7, gap=-0.5, speed=10.0, to_red=0.0)   # front past the line
    assert _timed("r", k=7, bound=5, commit=7, gap=20.0, speed=10.0, to_red=0.0)   # beyond the chain
    assert _timed("r", k=4, bound=5, commit=7, gap=20.0, speed=10.0, to_red=0.0)   # behind the bound


def test_commit_point_is_the_first_rest_front_past_the_line():
    # rest lead 2.5 m (half a 5 m car, s0 0): arc + 2.5 > 20 -> first k = 6 (18 m)
    assert commit_points(ARC, np.array([20.0]), 2.5).tolist() == [6]
    assert commit_points(ARC, np.array([20.5]), 2.5).tolist() == [7]   # 18 + 2.5 = 20.5: at, not past
    book = SignalBook(OBEY)
    book.add("a", StopLines(ARC, np.array([20.0]), np.array([0])), 3.5, rest_lead=2.5)
    book.add("b", StopLines(ARC, np.array([20.0]), np.array([0])), 3.5)
    commit, past = book.timing_of(["a"])
    assert commit.tolist() == [6] and past.tolist() == [0.5]
    assert book.timing_of(["a", "b"]) is None   # b registered without the rest lead: no timing


@settings(max_examples=200, deadline=None)
@given(gap=st.floats(0.1, 80.0), past=st.floats(0.1, 6.0), v=st.floats(0.0, 16.0), cap=st.floats(1.0, 16.0),
       to_red=st.floats(0.0, 30.0), letter=st.sampled_from("GgsoOyY"))
def test_a_granted_crossing_reaches_the_line_before_red_under_the_tracked_profile(gap, past, v, cap, to_red,
                                                                                  letter):
    """Safety claim of the rule: whatever the non-red letter, a switch of the crossing chain that
    stays granted has its front at the line (tracked profile, nothing further granted) at least
    ``red_margin_s`` before red; withheld ones are the late ones or the yellow-with-room ones."""
    ok = _timed(letter, k=5, bound=5, commit=6, gap=gap, speed=v, to_red=to_red, past=past, cap=cap)
    t = float(time_to_line(gap, gap + past, v, cap, OBEY.accel_floor, 2.5))
    late = t + OBEY.red_margin_s > to_red
    room = letter in "yY" and v * v <= 2.0 * OBEY.comfort_decel * gap
    assert ok == (not late and not room)
