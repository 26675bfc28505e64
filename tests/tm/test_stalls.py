"""tm.stalls: how long each holder's stop point has stayed put."""

from tm.stalls import StallClock


def test_the_clock_restarts_when_the_stop_point_moves_or_the_token_is_let_go():
    c = StallClock()
    c.note(3, [("a", 10), ("b", 4)])
    c.note(7, [("a", 10), ("b", 5)])
    assert c.still_for(7, "a") == 4 and c.still_for(7, "b") == 0  # b moved at step 7
    c.note(8, [("b", 5)])                                          # a no longer holds
    c.note(9, [("a", 10), ("b", 5)])                               # a holds again: starts afresh
    assert c.still_for(9, "a") == 0 and c.still_for(9, "b") == 2
    assert c.still_for(9, "c") is None


def test_a_holder_of_two_zones_counts_once():
    c = StallClock()
    c.note(0, [("a", 2), ("a", 2)])
    c.note(5, [("a", 2), ("a", 2)])
    assert c.still_for(5, "a") == 5
