"""Path-frame plants in the co-simulation loop: each vehicle's route as a path frame, the fleet's
frames as one stack, and the maps between the plant's path coordinates and the world.

A path-frame vehicle (:class:`bridge.cosim.CosimSettings` ``frame``) is stepped in ``(s, n, v_s,
v_n)`` along its route polyline (:mod:`controllers.path`); its controller sees waypoints ``(S_k,
0)`` with heading 0, so every route, whatever its turns, is a straight road to it.  The world
pose is ``to_world(s, n)`` with the heading of the path segment ``s`` lies on; the claims are
drawn in the world by :mod:`tm.path_claims`.
"""

from __future__ import annotations

import numpy as np

from bridge.groups import _headings
from controllers.path import PathError, PathFrame, PathStack
from tm.path_claims import PathPlace

__all__ = ["PathFleet", "FRAMES"]

#: Valid values of :attr:`bridge.cosim.CosimSettings.frame`.
FRAMES = ("auto", "road", "path")


class PathFleet:
    """The path frames of a run's vehicles and the stack of the vehicles in the network."""

    def __init__(self):
        self._frames: dict[str, PathFrame] = {}
        self._S: dict[str, np.ndarray] = {}
        self._key: list | None = None  # the groups' id lists and lengths of the last stack (:meth:`stack`)
        self._stack = PathStack([])
        self._offset: dict[int, int] = {}

    def frame(self, vid: str, W, lean=None) -> PathFrame:
        """The path frame of vehicle ``vid``'s route ``W`` (built once; ``lean``: its chords' body
        leans, :class:`~controllers.path.PathFrame`)."""
        f = self._frames.get(vid)
        if f is None:
            try:
                f = self._frames[vid] = PathFrame(W, lean)
            except PathError as exc:
                raise ValueError(f"vehicle {vid}: its route cannot be driven in the path frame: {exc}") from None
        return f

    def waypoints(self, vid: str, W, arc) -> np.ndarray:
        """The route's waypoints in path coordinates ``(S_k, 0)``: ``S_k`` the projection of each
        waypoint on its frame (``arc``: the waypoints' arc lengths, the projection's hints)."""
        S = self._S.get(vid)
        if S is None:
            f = self.frame(vid, W)
            S, _ = f.to_path(np.asarray(W, dtype=float), np.asarray(arc, dtype=float), window=1.0)
            S = self._S[vid] = np.maximum.accumulate(S)  # a route's arc never runs back
        return np.column_stack([S, np.zeros(len(S))])

    def body_headings(self, vid: str, W, arc) -> np.ndarray:
        """Body heading (K,) on the chord arriving at each of the route's waypoints ``W`` (the first:
        the first chord's), as :func:`bridge.groups._headings` gives the chords' own headings plus
        the lean of the frame's segment holding the chord's middle (:meth:`frame` first)."""
        f = self._frames[vid]
        W = np.asarray(W, dtype=float)
        S = self.waypoints(vid, W, arc)[:, 0]
        lean = f.lean[f.segment(0.5 * (S[:-1] + S[1:]))]
        return _headings(W) + (np.concatenate([lean[:1], lean]) if len(lean) else 0.0)

    def forget(self, vid: str) -> None:
        self._frames.pop(vid, None)
        self._S.pop(vid, None)

    def stack(self, groups) -> PathStack:
        """The stack of the frames of every vehicle in ``groups`` (in their order), rebuilt when
        the fleet changed; :meth:`fid` gives a group's rows in it."""
        # a group's id list changes by appending or by being replaced (bridge.groups._Group): the
        # lists themselves (kept alive here) and their lengths tell whether the fleet changed
        key = [(g.ids, len(g.ids)) for g in groups if g.ids]
        old = self._key
        if old is None or len(old) != len(key) or any(a is not b or m != n for (a, m), (b, n) in zip(old, key)):
            self._stack = PathStack([self._frames[v] for ids, _ in key for v in ids])
            self._key = key
            self._offset = {}
            o = 0
            for g in groups:
                if g.ids:
                    self._offset[id(g)] = o
                    o += len(g.ids)
        return self._stack

    def fid(self, g) -> np.ndarray:
        """Rows of group ``g``'s vehicles in the last :meth:`stack`."""
        return self._offset[id(g)] + np.arange(len(g.ids))

    def place(self, groups, g, offset: int = 0, rows=None) -> PathPlace:
        """Group ``g``'s vehicles (``rows`` of them) placed in the world: frames, and their
        waypoints ``k + offset`` in the world with the headings arriving there."""
        stack = self.stack(groups)
        cen, hd, _ = g.world_centres(offset)
        fid = self.fid(g)
        if rows is not None:
            fid, cen, hd = fid[rows], cen[rows], hd[rows]
        return PathPlace(stack, fid, cen, hd)

    def pose(self, groups, g) -> tuple[np.ndarray, np.ndarray]:
        """World centres (n, 2) and body headings (n,) of group ``g``'s vehicles."""
        stack = self.stack(groups)
        return stack.to_world(self.fid(g), g.X[:, 0], g.X[:, 1])

    def state(self, groups, g) -> np.ndarray:
        """World states ``(x, y, v_x, v_y)`` (n, 4) of group ``g``'s vehicles."""
        stack = self.stack(groups)
        fid = self.fid(g)
        xy, _ = stack.to_world(fid, g.X[:, 0], g.X[:, 1])
        return np.hstack([xy, stack.velocity(fid, g.X[:, 0], g.X[:, 2], g.X[:, 3])])

    def entry_place(self, specs, centre, heading) -> PathPlace:
        """Vehicles not yet in the network (``specs``), at rest on their first waypoints: a stack of
        their own frames, their world first waypoints ``centre`` and headings ``heading``."""
        frames = [self.frame(sp.id, sp.waypoints) for sp in specs]
        return PathPlace(PathStack(frames), np.arange(len(frames)), np.asarray(centre, dtype=float).reshape(-1, 2),
                         np.asarray(heading, dtype=float))
