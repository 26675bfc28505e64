"""The safety verdict (analysis.safety): which counters make a run unsafe."""

from analysis.safety import SAFETY_COUNTERS, verdict


def test_red_violations_make_an_obeying_run_unsafe():
    """Issue 12: tlsgrid in authority mode said ``safe: true`` with 2 red crossings."""
    s = {"collisions_sumo": 0, "red_violations": 2, "options": {"signals": "obey"}}
    assert "red_violations" in SAFETY_COUNTERS
    assert verdict(s) == {"safe": False, "safety_violations": {"red_violations": 2}}
    assert verdict({**s, "red_violations": 0})["safe"] is True


def test_red_violations_reported_but_not_judged_when_lights_are_ignored():
    """``--signals ignore`` passes reds by design (AIM-style); other counters are still judged."""
    s = {"red_violations": 5, "options": {"signals": "ignore"}}
    assert verdict(s) == {"safe": True, "safety_violations": {}}
    assert verdict({**s, "collisions_sumo": 1}) == {"safe": False, "safety_violations": {"collisions_sumo": 1}}
    assert verdict({"red_violations": 1})["safe"] is False   # no options recorded: judged
