"""Time until a link turns red, from a SUMO program's phases (bridge.signals.link_time_to_red),
without a simulator.  Durations are sums of a few exact binary fractions: compared exactly."""

import math

from bridge.signals import link_time_to_red

# netgenerate --tls.guess's static program shape: 2 links, green 17 s, yellow 3 s, each way
PHASES = [("Gr", 17.0, ()), ("yr", 3.0, ()), ("rG", 17.0, ()), ("ry", 3.0, ())]


def test_green_then_yellow_then_red():
    assert link_time_to_red(PHASES, 0, 5.5, 0) == 5.5 + 3.0   # rest of green, all of yellow
    assert link_time_to_red(PHASES, 1, 1.25, 0) == 1.25       # yellow: its remaining time
    assert link_time_to_red(PHASES, 2, 4.0, 0) == 0.0         # red now
    assert link_time_to_red(PHASES, 2, 4.0, 1) == 4.0 + 3.0   # the other link, in its own green


def test_red_now_and_never_red():
    assert link_time_to_red(PHASES, 0, 5.0, 1) == 0.0
    assert link_time_to_red([("G", 30.0, ()), ("g", 5.0, ())], 0, 2.0, 0) == math.inf


def test_branching_program_stops_the_look_ahead():
    """A phase with several ``next`` phases: red assumed from there (conservative)."""
    phases = [("G", 10.0, (1, 2)), ("G", 10.0, ()), ("r", 10.0, ())]
    assert link_time_to_red(phases, 0, 4.0, 0) == 4.0
