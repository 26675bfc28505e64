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


class _RunWorld:
    """A world whose rows are the same over runs of 10 window starts: a row is a function of
    (vehicle, waypoint, window start // 10); ``claim_pad_runs`` tells each row's run."""

    def __init__(self, j0):
        self.pads_version = 0
        self.j0 = dict(j0)
        self.asked = 0

    def pad_windows(self, ids):
        return np.array([self.j0[v] for v in ids], dtype=np.int64)

    def claim_pads(self, ids, k):
        return np.array([[int(v[1:]), kk, self.j0[v] // 10, 0.5] for v, kk in zip(ids, np.asarray(k).tolist())],
                        dtype=float)

    def claim_pad_runs(self, ids, k):
        self.asked += len(ids)
        j = self.pad_windows(ids)
        return self.claim_pads(ids, k), 10 * (j // 10), 10 * (j // 10) + 9


def test_after_the_windows_move_only_rows_whose_start_left_its_run_are_asked():
    """With runs: after the windows moved (version), a row is asked again only if its waypoint
    changed or its window start left the run its row holds for; every answer equals the world's
    own for the same arguments (a memo serving a stale row fails here)."""
    w = _RunWorld({"v0": 0, "v1": 15, "v2": 29})
    m = PadMemo(w)
    ids, k = ["v0", "v1", "v2"], np.array([3, 5, 7])

    def check(k, asked):
        before = w.asked
        got = m.pads("g", ids, k)
        assert w.asked - before == asked
        np.testing.assert_array_equal(got, w.claim_pads(ids, k))

    check(k, 3)
    w.pads_version += 1
    w.j0.update(v0=9, v1=16)          # inside their runs: nothing asked
    check(k, 0)
    w.pads_version += 1
    w.j0.update(v2=30)                # left its run: that row
    check(k, 1)
    w.pads_version += 1
    w.j0.update(v0=10)                # left its run, and v1's waypoint changed: two rows
    check(np.array([3, 6, 7]), 2)
    check(np.array([3, 6, 7]), 0)     # same version: the memo
    assert m.asked == 6 and m.served == 3 * 5 - 6
