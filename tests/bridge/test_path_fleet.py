"""PathFleet.stack: one stack of the fleet's path frames, rebuilt exactly when the fleet changed
(a group's id list appended to, or replaced when vehicles leave), reused otherwise."""

from types import SimpleNamespace

import numpy as np

from bridge.path_fleet import PathFleet


def _fleet(ids):
    pf = PathFleet()
    for i, v in enumerate(ids):
        pf.frame(v, np.array([[0.0, 10.0 * i], [50.0, 10.0 * i], [50.0, 10.0 * i + 40.0]]))
    return pf


def test_stack_follows_the_fleet():
    pf = _fleet(["a", "b", "c", "d"])
    g1, g2 = SimpleNamespace(ids=["a", "b"]), SimpleNamespace(ids=["c"])
    s = pf.stack([g1, g2])
    assert len(s) == 3 and pf.stack([g1, g2]) is s  # unchanged fleet: the same stack
    assert pf.fid(g2).tolist() == [2]
    g2.ids.append("d")  # a vehicle enters (in place)
    s2 = pf.stack([g1, g2])
    assert s2 is not s and len(s2) == 4 and pf.fid(g2).tolist() == [2, 3]
    g1.ids = [v for v in g1.ids if v != "a"]  # a vehicle leaves (a new list)
    s3 = pf.stack([g1, g2])
    assert s3 is not s2 and len(s3) == 3 and pf.fid(g1).tolist() == [0] and pf.fid(g2).tolist() == [1, 2]
    # the stack's frames are the vehicles' own, in fleet order
    assert np.array_equal(s3.vertices[s3.first[0]], pf._frames["b"].vertices[0])
    assert np.array_equal(s3.vertices[s3.first[2]], pf._frames["d"].vertices[0])
    g1.ids = []  # a group empties
    assert len(pf.stack([g1, g2])) == 2 and pf.fid(g2).tolist() == [0, 1]
