"""bridge.pad_memo.PadMemo: the claims' padding looked up once per step, the world's own answers."""

import numpy as np

from bridge.pad_memo import PadMemo


class _World:
    """claim_pads answers a function of (vehicle, waypoint, version); counts the rows asked."""

    def __init__(self, versioned=True):
        self.asked = 0
        if versioned:
            self.pads_version = 0

    def claim_pads(self, ids, k):
        self.asked += len(ids)
        ver = getattr(self, "pads_version", 0)
        return np.array([[int(v[1:]), kk, ver, 0.5] for v, kk in zip(ids, np.asarray(k).tolist())], dtype=float)


def test_answers_are_the_worlds_and_asked_once_per_change():
    """Same ids, k and version: served from the memo (no row asked); a grant (k of one row
    changed): only that row asked; the windows moved (version) or the group changed (a new id
    list): every row asked.  Every answer equals the world's own for the same arguments."""
    w = _World()
    m = PadMemo(w)
    ids = ["v0", "v1", "v2"]
    k = np.array([3, 5, 7])

    def check(ids, k, asked):
        before = w.asked
        got = m.pads("g", ids, k)
        assert w.asked - before == asked
        ref = _World()
        ref.pads_version = w.pads_version
        np.testing.assert_array_equal(got, ref.claim_pads(ids, k))

    check(ids, k, 3)
    check(ids, k, 0)
    k2 = k.copy()
    k2[1] += 1
    check(ids, k2, 1)
    w.pads_version += 1
    check(ids, k2, 3)
    ids2 = ["v0", "v2"]
    check(ids2, k2[[0, 2]], 2)
    check(ids2, k2[[0, 2]], 0)
    assert m.asked == 9
    assert not m.pads("g", ids2, k2[[0, 2]]).flags.writeable  # handed out again: read-only


def test_offsets_kept_apart_and_no_version_no_memo():
    """Current and requested waypoints are kept apart; a world without ``pads_version`` is asked
    every time; a world answering None gives zeros."""
    w = _World()
    m = PadMemo(w)
    ids, k = ["v0", "v1"], np.array([1, 2])
    a, b = m.pads("g", ids, k, 0), m.pads("g", ids, k + 1, 1)
    assert w.asked == 4 and m.pads("g", ids, k, 0) is a and m.pads("g", ids, k + 1, 1) is b and w.asked == 4
    w2 = _World(versioned=False)
    m2 = PadMemo(w2)
    m2.pads("g", ids, k)
    m2.pads("g", ids, k)
    assert w2.asked == 4

    class _None:
        pads_version = 0

        def claim_pads(self, ids, k):
            return None

    np.testing.assert_array_equal(PadMemo(_None()).pads("g", ids, k), np.zeros((2, 4)))
