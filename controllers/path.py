"""Path frame: coordinates along a route polyline (the road-frame classes' planned plant frame).

A vehicle's state in path coordinates is ``(s, n, v_s, v_n)``: ``s`` the arc length along its
route polyline, ``n`` the signed lateral offset (left of the direction of travel positive).  The
controller and its sets need not change (along factor = ``s``, across = ``n``, heading 0
everywhere); only the map to the world does, and that map is this module.

Construction
    :class:`PathFrame` takes the route polyline ``W`` (P, 2): consecutive waypoints.  Points
    must be finite; consecutive points closer than ``PATH_DUP_TOL_M`` are one; fewer than two
    distinct points is an error (:class:`PathError`).  Collinear runs are merged: a vertex goes
    when it and every vertex merged before it since the last kept one lie within
    ``PATH_COLLINEAR_TOL_M`` of the chord from that kept vertex to the next point, in order along
    it (a reversal is a kink, never merged).  So every input point lies within
    ``PATH_COLLINEAR_TOL_M`` of the frame's polyline, and a subsampled straight is one segment.

The map
    Segment ``i`` runs from vertex ``V_i`` (arc ``S_i``) to ``V_{i+1}`` with unit tangent ``T_i``,
    left normal ``N_i`` and heading ``theta_i``.  A parameter ``s`` belongs to the segment that
    *leaves* the last vertex at or before it (right-continuous: ``S_i <= s < S_{i+1}``); ``s < 0``
    to the first segment and ``s >= S_end`` to the last, both extended as straight lines beyond
    the route's ends.  Then

        to_world(s, n) = V_i + (s - S_i) T_i + n N_i,    body heading = theta_i + lean_i.

Body lean
    A body need not lie along its segment: on a lane change SUMO keeps a vehicle's body parallel to
    the lane while muvsim's route crosses it on a diagonal (:mod:`bridge.sumo_body`).  A frame may
    be given a ``lean`` per input chord, the angle from the chord to the body (0 by default); each
    segment's body heading is ``theta_i + lean_i`` and a vertex where the lean changes is never
    merged away.  The claim cover (:mod:`tm.path_cover`) lays each segment's box along the body's
    heading, and the body padding (:class:`bridge.sumo_body.PadTable`) is measured from a
    rectangle with that heading, so any lean is sound; the body's own is the tightest (a truck on
    a 30 m lane change: a box along the diagonal held the lane-parallel body with 0.7 m to spare
    across, into the oncoming lane).

Kinks (the decision)
    The heading is piecewise constant: no smoothing, so a footprint is always a rectangle aligned
    with one segment, and the claim cover (:mod:`tm.path_cover`) is exact per segment.
    For ``n = 0`` the world point is continuous in ``s`` (it runs along the polyline).  For
    ``n != 0`` it jumps where ``s`` passes a vertex that turns by ``theta``: from ``V + n N_i`` to
    ``V + n N_{i+1}``, a distance of exactly ``|n| 2 sin(theta / 2)`` (a car's cruising across
    tube, ``|n| <= 0.17 m``, at a 45 degree kink: 0.13 m); the body turns by ``theta`` at once,
    and a body point at ``(a, b)`` from the centre (along, left) jumps by
    ``|(a, n + b)| 2 sin(theta / 2)``, at most ``sqrt((L/2)^2 + (|n| + W/2)^2) 2 sin(theta / 2)``
    (:meth:`PathFrame.kink_jump_bound`).  Soundness does not suffer: a claim covers every pose of
    its closed ``s``-interval, on both sides of each vertex (:func:`tm.path_cover.path_box_cover`).
    On the inside of a kink the offset lines of the two segments cross (world points there have
    two path coordinates); on the outside a wedge of angle ``theta`` at offset ``|n|`` has none.

Projection
    :meth:`PathFrame.to_path` projects world points onto the nearest segment among those within a
    window of arc around a hint ``s_hint`` (the vehicle's last ``s``), which picks the right
    branch where a route passes near itself.  ``to_path(to_world(s, n)) == (s, n)`` wherever
    ``(s, n)`` has one preimage: ``s`` farther than ``|n| tan(theta / 2)`` from the kinks (and
    farther than ``|n|`` suffices for ``theta <= 90`` degrees).  A point with none (the outside
    wedge of a kink) gets the vertex's ``s`` and its signed distance from the vertex.
"""

from __future__ import annotations

import numpy as np

from controllers.tolerances import PATH_COLLINEAR_TOL_M, PATH_DUP_TOL_M, PATH_LEAN_TOL_RAD
from controllers.search_kernel import search_clipped

__all__ = ["PathFrame", "PathStack", "PathError", "DEFAULT_PROJECTION_WINDOW_M"]

#: Arc window (m) either side of ``s_hint`` whose segments :meth:`PathFrame.to_path` considers:
#: a vehicle moves at most ~1.4 m a step (13.89 m/s, 0.1 s), so a hint one step old is well inside.
DEFAULT_PROJECTION_WINDOW_M = 10.0


class PathError(ValueError):
    """A polyline that cannot make a path frame, or path coordinates that are not numbers."""


#: Candidate vertices :func:`_merge_collinear` tests at once, first and at most (the block doubles
#: along a straight run): arrays of ``block x run`` floats.
_MERGE_BLOCK_FIRST = 8
_MERGE_BLOCK_MAX = 512


def _merge_collinear(P: np.ndarray, tol: float, fixed: np.ndarray | None = None) -> np.ndarray:
    """Indices of the vertices of ``P`` (distinct consecutive points) kept after merging collinear
    runs: a run ``a .. e`` becomes one segment when every point between lies within ``tol`` of the
    chord ``P[a] -> P[e]`` and projects inside it, in increasing order.  ``fixed`` (P,) bool: vertices
    kept whatever their neighbours.

    Greedy from each kept vertex ``a``: the next kept one is the first ``j > a`` whose chord
    ``a -> j + 1`` does not carry ``a + 1 .. j``; the candidates are tested a block at a time,
    vectorised (a loop over one candidate at a time, with numpy calls per point, took 23 ms of a
    1.5 km route's frame; ``tests/controllers/test_path.py`` holds that loop and compares)."""
    n = len(P)
    keep = [0]
    a, j = 0, 1
    B = _MERGE_BLOCK_FIRST
    while j < n - 1:
        e_hi = min(j + B, n - 1)
        J = np.arange(j, e_hi)                      # candidates j; their chords end at j + 1
        d = P[J + 1] - P[a]
        L = np.hypot(d[:, 0], d[:, 1])
        ok = L > tol
        if fixed is not None:
            ok &= ~fixed[J]
        mid = P[a + 1:e_hi] - P[a]                  # the points a + 1 .. e_hi - 1
        valid = np.arange(len(mid))[None, :] <= (J - a - 1)[:, None]  # point a + 1 + c carried by chord j
        Ls = np.where(L > 0, L, 1.0)[:, None]
        t = (mid[None, :, 0] * d[:, 0, None] + mid[None, :, 1] * d[:, 1, None]) / Ls
        off = np.abs(mid[None, :, 0] * d[:, 1, None] - mid[None, :, 1] * d[:, 0, None]) / Ls
        good = ((off <= tol) & (t > 0.0) & (t < L[:, None])) | ~valid
        ok &= good.all(axis=1)
        if mid.shape[0] > 1:
            ok &= ((t[:, 1:] > t[:, :-1]) | ~valid[:, 1:]).all(axis=1)
        bad = np.flatnonzero(~ok)
        if len(bad):                                # the first candidate not carried is a real vertex
            a = int(J[bad[0]])
            keep.append(a)
            j = a + 1
            B = _MERGE_BLOCK_FIRST
        else:                                       # all carried: on along the run, a longer block
            j = e_hi
            B = min(2 * B, _MERGE_BLOCK_MAX)
    keep.append(n - 1)
    return np.asarray(keep, dtype=np.intp)


class PathFrame:
    """Path coordinates along a route polyline (module notes).  Immutable; arrays read-only.

    Parameters
    ----------
    W : array_like, shape (P, 2)
        The route polyline: consecutive waypoints (world, m).
    lean : array_like, shape (P - 1,), optional
        Angle (rad, counter-clockwise) from each chord ``W[j] -> W[j + 1]`` to the body of a vehicle
        on it (module notes, "Body lean"); 0 by default.  A merged segment takes the lean of its
        first chord (its chords' leans agree within ``PATH_LEAN_TOL_RAD``).

    Attributes
    ----------
    vertices : ndarray, shape (M + 1, 2)
        The polyline after duplicate points and collinear runs are merged (M segments).
    arc : ndarray, shape (M + 1,)
        Arc length of each vertex, from 0.
    heading : ndarray, shape (M,)
        Heading of each segment (rad, counter-clockwise from +x).
    tangent, normal : ndarray, shape (M, 2)
        Unit tangent and left normal of each segment.
    turn : ndarray, shape (M - 1,)
        Signed turn at each interior vertex (rad, in (-pi, pi], left positive).
    lean, body_heading : ndarray, shape (M,)
        Each segment's body lean and its body heading ``heading + lean``.

    Raises
    ------
    PathError
        ``W`` not (P, 2), not finite, or fewer than two distinct points; ``lean`` not (P - 1,),
        not finite, or not within 90 degrees.
    """

    __slots__ = ("vertices", "arc", "heading", "tangent", "normal", "turn", "lean", "body_heading", "_inner")

    def __init__(self, W, lean=None):
        P = np.asarray(W, dtype=float)
        if P.ndim != 2 or P.shape[1] != 2:
            raise PathError(f"path polyline: must be (P, 2), got shape {P.shape}")
        bad = ~np.isfinite(P).all(axis=1)
        if bad.any():
            raise PathError(f"path polyline: point {int(np.flatnonzero(bad)[0])} is not finite: "
                            f"{P[np.flatnonzero(bad)[0]].tolist()}")
        if lean is None:
            chord_lean = np.zeros(max(len(P) - 1, 0))
        else:
            chord_lean = np.asarray(lean, dtype=float)
            if chord_lean.shape != (max(len(P) - 1, 0),):
                raise PathError(f"path lean: must be one per chord, ({max(len(P) - 1, 0)},), got shape "
                                f"{chord_lean.shape}")
            if not (np.isfinite(chord_lean).all() and (np.abs(chord_lean) < 0.5 * np.pi).all()):
                raise PathError("path lean: every lean must be finite and within 90 degrees of its chord")
        if len(P):
            step = np.hypot(*np.diff(P, axis=0).T) if len(P) > 1 else np.zeros(0)
            kept = np.concatenate([[True], step > PATH_DUP_TOL_M])
            # a chord of the kept points takes the lean of the last input chord it ends with
            chord_lean = chord_lean[np.flatnonzero(kept)[1:] - 1] if len(P) > 1 else chord_lean
            P = P[kept]
        if len(P) < 2:
            raise PathError("path polyline: needs at least two distinct points "
                            f"(farther apart than {PATH_DUP_TOL_M} m)")
        fixed = np.zeros(len(P), dtype=bool)  # vertices where the lean changes
        fixed[1:-1] = np.abs(np.diff(chord_lean)) > PATH_LEAN_TOL_RAD
        keep = _merge_collinear(P, PATH_COLLINEAR_TOL_M, fixed if fixed.any() else None)
        seg_lean = chord_lean[keep[:-1]]
        P = P[keep]
        d = np.diff(P, axis=0)
        seg = np.hypot(d[:, 0], d[:, 1])
        T = d / seg[:, None]
        h = np.arctan2(T[:, 1], T[:, 0])
        turn = np.arctan2(T[:-1, 0] * T[1:, 1] - T[:-1, 1] * T[1:, 0], np.einsum("ij,ij->i", T[:-1], T[1:]))
        arrays = dict(vertices=P, arc=np.concatenate([[0.0], np.cumsum(seg)]), heading=h, tangent=T,
                      normal=np.column_stack([-T[:, 1], T[:, 0]]), turn=turn, lean=seg_lean,
                      body_heading=h + seg_lean)
        for k, a in arrays.items():
            a = np.ascontiguousarray(a)
            a.flags.writeable = False
            object.__setattr__(self, k, a)
        inner = np.ascontiguousarray(self.arc[1:-1])  # interior vertices' arc: segment lookup
        inner.flags.writeable = False
        object.__setattr__(self, "_inner", inner)

    def __setattr__(self, name, value):
        raise AttributeError("PathFrame is immutable")

    def __repr__(self) -> str:
        return f"PathFrame({self.n_segments} segments, {self.length:.3f} m)"

    # ------------------------------------------------------------------ basics
    @property
    def length(self) -> float:
        """Arc length of the polyline (m)."""
        return float(self.arc[-1])

    @property
    def n_segments(self) -> int:
        return len(self.heading)

    def segment(self, s) -> np.ndarray:
        """Segment index of each ``s`` (right-continuous at vertices; ends extended), same shape."""
        return np.searchsorted(self._inner, np.asarray(s, dtype=float), side="right")

    def kink_jump_bound(self, n, length: float = 0.0, width: float = 0.0) -> float:
        """The largest world jump (m), over this path's kinks, of a body point of a ``length`` x
        ``width`` footprint centred at lateral offset ``n`` as ``s`` passes a vertex:
        ``sqrt((L/2)^2 + (|n| + W/2)^2) 2 sin(theta / 2)`` (the centre: ``|n| 2 sin(theta / 2)``)."""
        if not len(self.turn):
            return 0.0
        r = np.hypot(0.5 * float(length), np.abs(float(n)) + 0.5 * float(width))
        return float(r * 2.0 * np.sin(0.5 * np.abs(self.turn).max()))

    # ------------------------------------------------------------------ maps
    def to_world(self, s, n) -> tuple[np.ndarray, np.ndarray]:
        """World centres and body headings of path coordinates ``(s, n)`` (broadcast together).

        Returns
        -------
        xy : ndarray, shape (*shape, 2)
        heading : ndarray, shape
            The body heading of the segment ``s`` lies on (:meth:`segment`): its heading plus its lean.

        Raises
        ------
        PathError
            On a coordinate that is not finite.
        """
        s, n = np.broadcast_arrays(np.asarray(s, dtype=float), np.asarray(n, dtype=float))
        if not (np.isfinite(s).all() and np.isfinite(n).all()):
            raise PathError("to_world: s and n must be finite")
        i = self.segment(s)
        a = s - self.arc[i]
        xy = self.vertices[i] + a[..., None] * self.tangent[i] + n[..., None] * self.normal[i]
        return xy, self.body_heading[i]

    def to_path(self, xy, s_hint, window: float = DEFAULT_PROJECTION_WINDOW_M) -> tuple[np.ndarray, np.ndarray]:
        """Path coordinates ``(s, n)`` of world points ``xy`` (m, 2): the projection onto the
        nearest segment among those meeting ``[s_hint - window, s_hint + window]`` (the first
        and last segments extended beyond the route's ends; ties to the lower segment).

        Parameters
        ----------
        xy : array_like, shape (m, 2)
        s_hint : array_like, shape (m,) or scalar
            Arc length near each point (e.g. the vehicle's last ``s``).
        window : float
            Half-width (m, >= 0) of the arc window searched.

        Raises
        ------
        PathError
            On a bad shape or a value that is not finite.
        """
        X = np.asarray(xy, dtype=float)
        if X.ndim != 2 or X.shape[1] != 2:
            raise PathError(f"to_path: xy must be (m, 2), got shape {X.shape}")
        h = np.broadcast_to(np.asarray(s_hint, dtype=float), (len(X),))
        if not (np.isfinite(X).all() and np.isfinite(h).all()):
            raise PathError("to_path: xy and s_hint must be finite")
        if not (np.isfinite(window) and window >= 0):
            raise PathError(f"to_path: window must be a finite distance >= 0 m, got {window!r}")
        M = self.n_segments
        i0 = np.searchsorted(self._inner, h - window, side="left")   # first segment ending at or after
        i1 = np.searchsorted(self._inner, h + window, side="right")  # last segment starting at or before
        width = int((i1 - i0).max()) + 1 if len(X) else 1
        cand = i0[:, None] + np.arange(width)[None, :]               # (m, c)
        valid = cand <= i1[:, None]
        cand = np.minimum(cand, M - 1)
        V, T = self.vertices[cand], self.tangent[cand]
        rel = X[:, None, :] - V
        t = np.einsum("mcj,mcj->mc", rel, T)
        seg_len = self.arc[cand + 1] - self.arc[cand]
        lo = np.where(cand == 0, -np.inf, 0.0)
        hi = np.where(cand == M - 1, np.inf, seg_len)
        t = np.clip(t, lo, hi)
        foot = rel - t[..., None] * T
        dist = np.hypot(foot[..., 0], foot[..., 1])
        dist = np.where(valid, dist, np.inf)
        best = np.argmin(dist, axis=1)
        r = np.arange(len(X))
        seg, tb, fb, db = cand[r, best], t[r, best], foot[r, best], dist[r, best]
        side = self.tangent[seg, 0] * fb[:, 1] - self.tangent[seg, 1] * fb[:, 0]
        return self.arc[seg] + tb, np.where(side < 0.0, -db, db)


class PathStack:
    """Several path frames as one set of arrays: the maps of many vehicles, each on its own route,
    vectorised over the vehicles (a frame is picked per point by its index ``fid``).

    The frames' segments are concatenated; frame ``i`` owns segments ``first[i] .. last[i]`` and its
    arc is shifted by ``offset[i]`` so that the segments' starts increase over the whole stack (one
    ``searchsorted`` finds a segment); lookups are clipped to the frame's own segments, so each
    frame keeps its first and last segments extended beyond its route's ends, as :class:`PathFrame`.

    Parameters
    ----------
    frames : sequence of PathFrame
    """

    __slots__ = ("n_frames", "vertices", "heading", "body_heading", "tangent", "normal", "start", "end", "first",
                 "last", "offset", "_start_g", "_end_g")

    #: Gap (m) between consecutive frames' shifted arcs (keeps the shifted starts strictly increasing).
    GAP_M = 1.0

    def __init__(self, frames):
        frames = list(frames)
        if not all(isinstance(f, PathFrame) for f in frames):
            raise PathError("PathStack: every frame must be a PathFrame")
        M = np.array([f.n_segments for f in frames], dtype=np.intp)
        L = np.array([f.length for f in frames], dtype=float)
        first = np.concatenate([[0], np.cumsum(M)[:-1]]).astype(np.intp) if len(frames) else np.zeros(0, np.intp)
        offset = np.concatenate([[0.0], np.cumsum(L + self.GAP_M)[:-1]]) if len(frames) else np.zeros(0)
        cat = (lambda xs, shape: np.concatenate(xs) if xs else np.zeros(shape))  # noqa: E731
        arrays = dict(
            n_frames=len(frames),
            vertices=cat([f.vertices[:-1] for f in frames], (0, 2)),
            heading=cat([f.heading for f in frames], (0,)),
            body_heading=cat([f.body_heading for f in frames], (0,)),
            tangent=cat([f.tangent for f in frames], (0, 2)),
            normal=cat([f.normal for f in frames], (0, 2)),
            start=cat([f.arc[:-1] for f in frames], (0,)),
            end=cat([f.arc[1:] for f in frames], (0,)),
            first=first, last=first + M - 1, offset=offset)
        rep = np.repeat(offset, M)
        arrays["_start_g"] = arrays["start"] + rep
        arrays["_end_g"] = arrays["end"] + rep
        for k, a in arrays.items():
            if isinstance(a, np.ndarray):
                a = np.ascontiguousarray(a)
                a.flags.writeable = False
            object.__setattr__(self, k, a)

    def __setattr__(self, name, value):
        raise AttributeError("PathStack is immutable")

    def __len__(self) -> int:
        return self.n_frames

    def _fid(self, fid, shape) -> np.ndarray:
        f = np.broadcast_to(np.asarray(fid, dtype=np.intp), shape)
        if f.size and (f.min() < 0 or f.max() >= self.n_frames):
            raise PathError(f"PathStack: frame index out of 0 .. {self.n_frames - 1}")
        return f

    def segment(self, fid, s) -> np.ndarray:
        """Global segment index of ``s`` on frame ``fid`` (right-continuous at vertices, the
        frame's ends extended; :meth:`PathFrame.segment`); broadcast together."""
        s = np.asarray(s, dtype=float)
        f = self._fid(fid, np.broadcast_shapes(np.shape(fid), s.shape))
        # np.clip(searchsorted(_start_g, ..., "right") - 1, first, last), searched in the frame's rows alone
        x = s + self.offset[f]
        j = search_clipped(self._start_g, x.reshape(-1), self.first[f].reshape(-1) + 1, self.last[f].reshape(-1) + 1,
                           "right")
        return j.reshape(x.shape) - 1

    def first_meeting(self, fid, s_lo) -> np.ndarray:
        """The first segment of frame ``fid`` whose closed arc range reaches ``s_lo`` (its end
        ``>= s_lo``; the last segment beyond the route's end)."""
        f = np.asarray(fid, dtype=np.intp)
        x = np.asarray(s_lo, dtype=float) + self.offset[f]
        f = np.broadcast_to(f, x.shape)  # (as numpy's clip broadcasts them)
        return search_clipped(self._end_g, x.reshape(-1), self.first[f].reshape(-1), self.last[f].reshape(-1),
                              "left").reshape(x.shape)

    def to_world(self, fid, s, n) -> tuple[np.ndarray, np.ndarray]:
        """World centres and body headings of path coordinates ``(s, n)`` on frames ``fid``
        (:meth:`PathFrame.to_world`, vectorised over frames; broadcast together)."""
        s, n = np.broadcast_arrays(np.asarray(s, dtype=float), np.asarray(n, dtype=float))
        if not (np.isfinite(s).all() and np.isfinite(n).all()):
            raise PathError("to_world: s and n must be finite")
        i = self.segment(fid, s)
        a = s - self.start[i]
        xy = self.vertices[i] + a[..., None] * self.tangent[i] + n[..., None] * self.normal[i]
        return xy, self.body_heading[i]

    def velocity(self, fid, s, v_s, v_n) -> np.ndarray:
        """World velocities (…, 2) of path velocities ``(v_s, v_n)`` at ``s`` on frames ``fid``."""
        i = self.segment(fid, s)
        v_s, v_n = np.asarray(v_s, dtype=float), np.asarray(v_n, dtype=float)
        return v_s[..., None] * self.tangent[i] + v_n[..., None] * self.normal[i]
