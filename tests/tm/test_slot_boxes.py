"""Claim slots as unions of oriented boxes (tm/slot_boxes.py): index moves, compaction and world
boxes against brute force (the test of two slots meeting: tests/tm/test_kernels.py).  Exact
comparisons: the index moves copy floats; the world boxes are compared with the same float
expressions."""

import numpy as np
from hypothesis import given, settings, strategies as st

from tm.slot_boxes import SlotBoxes


def _random(rng, n, K):
    count = rng.integers(0, 4, (n, K))
    q = int(count.sum())
    perm = rng.permutation(n * K)  # slots' runs in a shuffled order of the flat list
    start = np.zeros(n * K, dtype=np.intp)
    o = 0
    for f in perm:
        start[f] = o
        o += count.ravel()[f]
    return SlotBoxes(rng.uniform(-20, 20, (q, 2)), rng.uniform(-np.pi, np.pi, q), rng.uniform(0.1, 3.0, (q, 2)),
                     start.reshape(n, K), count)


def _boxes_of(sb, i, k):
    return list(range(sb.start[i, k], sb.start[i, k] + sb.count[i, k]))


def _assert_world_boxes(sb, box):
    """``box`` ((4, n, K), :meth:`SlotBoxes.aabb`) is, slot by slot, the bounds of that slot's own
    boxes by brute force (the same float expressions: exact); empty slots inverted."""
    n, K = sb.shape
    for i in range(n):
        for k in range(K):
            ids = _boxes_of(sb, i, k)
            if not ids:
                assert box[0, i, k] == np.inf and box[1, i, k] == -np.inf
                assert box[2, i, k] == np.inf and box[3, i, k] == -np.inf
                continue
            c, s = np.abs(np.cos(sb.heading[ids])), np.abs(np.sin(sb.heading[ids]))
            ex = c * sb.half[ids, 0] + s * sb.half[ids, 1]
            ey = s * sb.half[ids, 0] + c * sb.half[ids, 1]
            assert box[0, i, k] == (sb.centre[ids, 0] - ex).min() and box[1, i, k] == (sb.centre[ids, 0] + ex).max()
            assert box[2, i, k] == (sb.centre[ids, 1] - ey).min() and box[3, i, k] == (sb.centre[ids, 1] + ey).max()


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_slot_boxes_against_brute_force(seed):
    rng = np.random.default_rng(seed)
    n, K = int(rng.integers(1, 5)), int(rng.integers(1, 5))
    a, b = _random(rng, n, K), _random(rng, n, K)
    box = a.aabb()
    _assert_world_boxes(a, box)
    # index moves and compaction keep every slot's boxes
    c = a.compact()
    assert len(c.heading) == int(a.count.sum())
    for i2 in range(n):
        for k in range(K):
            assert np.array_equal(a.centre[_boxes_of(a, i2, k)], c.centre[_boxes_of(c, i2, k)])
    sh = a.shift()
    assert np.array_equal(sh.count[:, :-1], a.count[:, 1:]) and np.array_equal(sh.count[:, -1], a.count[:, -1])
    sb = sh.aabb()  # the last slot's run is used twice: the world boxes take the other reduction
    assert np.array_equal(sb[:, :, :-1], box[:, :, 1:]) and np.array_equal(sb[:, :, -1], box[:, :, -1])
    rows = rng.permutation(n)
    asm = SlotBoxes.assemble(2 * n, K, [(np.arange(n), a.take(rows)), (np.arange(n, 2 * n), b)])
    for r in range(n):
        for k in range(K):
            assert np.array_equal(asm.half[_boxes_of(asm, r, k)], a.half[_boxes_of(a, rows[r], k)])
            assert np.array_equal(asm.half[_boxes_of(asm, n + r, k)], b.half[_boxes_of(b, r, k)])
    cat = SlotBoxes.concat(a.pad(K), b)
    assert cat.shape == (2 * n, K) and len(cat.heading) == len(a.heading) + len(b.heading)
    for r in range(n):
        for k in range(K):
            assert np.array_equal(cat.half[_boxes_of(cat, r, k)], a.half[_boxes_of(a, r, k)])
            assert np.array_equal(cat.centre[_boxes_of(cat, n + r, k)], b.centre[_boxes_of(b, r, k)])


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_world_boxes_of_runs_of_shared_slots(seed):
    """Slots that share their boxes with the slot before (runs, as a vehicle at rest has and
    ``aabb`` bounds once per run) get the same world boxes as brute force over each slot's own
    boxes, slot by slot (exact: the same float expressions), empty runs included."""
    rng = np.random.default_rng(seed)
    n, K = int(rng.integers(1, 5)), int(rng.integers(1, 9))
    a = _random(rng, n, K)
    start, count = a.start.copy(), a.count.copy()
    for i in range(n):
        for k in range(1, K):
            if rng.random() < 0.6:  # the slot repeats the one before
                start[i, k], count[i, k] = start[i, k - 1], count[i, k - 1]
    if K > 1:  # at least one run
        start[0, 1], count[0, 1] = start[0, 0], count[0, 0]
    sb = SlotBoxes(a.centre, a.heading, a.half, start, count)
    _assert_world_boxes(sb, sb.aabb())


def test_from_frames_one_box_per_non_empty_slot():
    lo = np.array([[[-1.0, -1.0], [1.0, 0.0]]])
    hi = np.array([[[1.0, 2.0], [0.0, 1.0]]])  # slot 2 empty (lo > hi along)
    sb = SlotBoxes.from_frames(np.array([[10.0, 0.0]]), np.array([0.5 * np.pi]), lo, hi)
    assert sb.count.tolist() == [[1, 0]]
    np.testing.assert_allclose(sb.centre[0], [10.0 - 0.5, 0.0], atol=1e-12)  # (0, 0.5) turned by 90 deg
    np.testing.assert_allclose(sb.half[0], [1.0, 1.5])


def test_claims_concatenate_with_an_empty_part():
    """Reach claims with slot-box unions (path-frame vehicles) concatenated with an empty set (no
    vehicle in the network, or none admitted this round): the other part, unchanged -- from_frames
    refused an empty set (its slot axis cannot be inferred from zero rows), so every caller had to
    skip empty parts itself."""
    from tm.reach import ReachClaims

    empty = SlotBoxes.from_frames(np.zeros((0, 2)), np.zeros(0), np.zeros((0, 3, 2)), np.zeros((0, 3, 2)))
    assert empty.count.shape == (0, 3) and len(empty.centre) == 0
    lo = np.array([[[-1.0, -1.0], [0.0, -1.0], [1.0, -1.0]]])
    hi = lo + 2.0
    tight = SlotBoxes.from_frames(np.array([[5.0, 1.0]]), np.array([0.3]), lo, hi)
    one = ReachClaims(np.array([[5.0, 1.0]]), np.array([0.3]), lo, hi, tight)
    none = ReachClaims(np.zeros((0, 2)), np.zeros(0), np.zeros((0, 3, 2)), np.zeros((0, 3, 2)))
    for both in (ReachClaims.concat(none, one), ReachClaims.concat(one, none)):
        assert len(both) == 1
        np.testing.assert_array_equal(both.lo, one.lo)
        np.testing.assert_array_equal(both.slot_boxes, one.slot_boxes)
        np.testing.assert_array_equal(both.slot_union().count, tight.count)
