"""Route intervals through the junction guards (tm.guard_spans), without SUMO; the rules that use
them are tested in tests/tm/test_authority_gate.py."""

import numpy as np
from hypothesis import given, settings, strategies as st


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(0, 6), min_size=1, max_size=40), st.data())
def test_flat_intervals_gather_each_rows_intervals_in_order(counts, data):
    """``_FlatIntervals.gather`` (the requesters' guard intervals by index, :meth:`GuardSpans.gather` for
    :meth:`tm.authority_gate.AuthorityGate._wanting`)
    returns, for rows asked in any order, repeated or not, over several steps (the flat table grows
    past its first size), exactly the concatenation of each row's own intervals and their counts."""
    from types import SimpleNamespace

    from tm.guard_spans import _FlatIntervals

    rng = np.random.default_rng(len(counts))
    own = {i: tuple(rng.integers(0, 50, c) for _ in range(3)) + (np.ones(c, dtype=bool),)
           for i, c in enumerate(counts)}
    asked = []
    flat = _FlatIntervals()
    fleet = SimpleNamespace(ids=[f"v{i}" for i in range(len(counts))])
    for _ in range(3):
        rows = np.array(data.draw(st.lists(st.integers(0, len(counts) - 1), max_size=60)), dtype=np.intp)
        cnt, got = flat.gather(fleet, rows, lambda f, i: (asked.append(i), own[i])[1])
        np.testing.assert_array_equal(cnt, [counts[i] for i in rows.tolist()])
        for j in range(3):
            want = np.concatenate([own[i][j] for i in rows.tolist()]) if len(rows) else np.zeros(0)
            np.testing.assert_array_equal(got[j], want)
    assert len(asked) == len(set(asked))  # each vehicle's intervals asked for once
