"""TMSettings validation: every bad value is rejected with the field and valid values named."""

import pytest

from tm.settings import TMSettings, TMSettingsError


def test_defaults():
    s = TMSettings()
    assert (s.policy, s.check, s.seed, s.starvation_horizon) == ("optimal", "union", 0, 50)


@pytest.mark.parametrize("field, value, needle", [
    ("policy", "fifo", "'greedy', 'optimal'"),
    ("check", "exact", "'union', 'timed'"),
    ("seed", -1, ">= 0"),
    ("seed", 1.5, "integer"),
    ("starvation_horizon", 0, ">= 1"),
    ("starvation_horizon", True, "integer"),
    ("exhaustive_max", 17, "[1, 16]"),
    ("milp_time_limit", 0.0, "> 0"),
    ("verify", 1, "True or False"),
])
def test_invalid_values_name_the_field(field, value, needle):
    with pytest.raises(TMSettingsError) as err:
        TMSettings(**{field: value})
    assert f"TMSettings.{field}" in str(err.value) and needle in str(err.value)


def test_frozen():
    with pytest.raises(AttributeError):
        TMSettings().policy = "greedy"
