"""World boxes that soundly cover path-frame claims (:mod:`controllers.path`).

In the path frame a claim slot is an interval box ``[s_lo, s_hi] x [n_lo, n_hi]`` of path
coordinates plus the footprint: the rectangle ``length x width`` centred at ``to_world(s, n)`` with
the heading of the segment ``s`` lies on.  :func:`path_box_cover` lays one oriented world box per
path segment that the closed ``s``-interval meets:

    segment i, in its own frame (origin V_i, axes T_i, N_i):
    along  [a_i - S_i - L/2, b_i - S_i + L/2],   a_i = max(s_lo, S_i), b_i = min(s_hi, S_{i+1}),
    across [n_lo - W/2, n_hi + W/2],

with ``S_0 = -inf`` and ``S_M = +inf`` (the frame extends its first and last segments beyond the
route's ends).

Sound, and exact per segment: every ``(s, n)`` of the interval with ``s`` in ``[a_i, b_i]`` places
its footprint with heading ``theta_i`` at ``V_i + (s - S_i) T_i + n N_i``, i.e. the rectangle
``[s - S_i -+ L/2] x [n -+ W/2]`` of segment ``i``'s frame, which lies in box ``i``; every ``s`` of
the interval lies in some ``[a_i, b_i]``.  The ranges are closed, so a vertex inside the interval is
covered with both headings: the pose just before it (heading ``theta_i``, the world limit from the
left) and at it (``theta_{i+1}``).

The body overhang at a kink.  A body does not bend with the path: just before a vertex its front
reaches ``L/2`` beyond the vertex along the *old* tangent, outside the next segment's box (a 45
degree left kink, a car at ``n = 0``: the front-right corner lies 2.4 m right of the next segment's
axis, 0.9 m allowed).  Box ``i`` therefore keeps its full ``+- L/2`` past ``b_i`` and before
``a_i`` even where the interval goes on round the kink (boxes overlap there).  The union of the
boxes is then exactly the closure of the footprints' union, so the cover costs no area.  Clipping a box to
its segment's arc range, or laying the footprint along the path as ``[s_lo - L/2, s_hi + L/2]``,
would miss that corner (``tests/tm/test_path_cover.py`` shows the check catching it).

Leaning bodies.  Where a frame's body leans (:class:`controllers.path.PathFrame`: on a lane change
SUMO keeps the body parallel to the lane while the route crosses it on a diagonal), the footprint
at ``(s, n)`` has the body's heading ``theta_i + lean_i``, and box ``i`` lies in the body's frame:
there the reference points of the segment, the parallelogram ``[a_i, b_i] x [n_lo, n_hi]`` turned
by ``-lean_i``, are bounded by their box (its four corners' extremes), and the footprint's extents
are added to it.  Sound for the same reason (every footprint of the segment is a body-frame
rectangle centred in that box); exact for the body, loose by the parallelogram's slant
(``(b_i - a_i) |sin lean_i|`` across, ``(n_hi - n_lo) |sin lean_i|`` along).

Boxes per interval: one per segment met; a straight is one segment (the frame merges collinear
runs), a curve sampled every ``delta`` gives about ``(s_hi - s_lo) / delta + 1``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.path import PathError, PathFrame, PathStack
from tm.geometry import rectangles
from tm.kernels import cover_boxes, cover_frame_bounds

__all__ = ["PathBoxes", "path_box_cover", "stack_box_cover", "cover_bounds", "path_footprints", "points_in_boxes"]


@dataclass(frozen=True, eq=False)
class PathBoxes:
    """Oriented world boxes covering path intervals; the boxes of each interval are contiguous.

    Attributes
    ----------
    owner : ndarray of int, shape (q,)
        The interval (flat index into the broadcast inputs, C order) each box covers; increasing.
    segment : ndarray of int, shape (q,)
        Path segment of each box.
    centre : ndarray, shape (q, 2)
    heading : ndarray, shape (q,)
        Box axes: along ``heading`` and across it (rad).
    half : ndarray, shape (q, 2)
        Half extents along and across.
    start, count : ndarray of int, shape (m,)
        First box and number of boxes of each interval (0 for an empty interval).
    shape : tuple
        Shape of the broadcast inputs (``m`` = its product).
    """

    owner: np.ndarray
    segment: np.ndarray
    centre: np.ndarray
    heading: np.ndarray
    half: np.ndarray
    start: np.ndarray
    count: np.ndarray
    shape: tuple

    def __len__(self) -> int:
        return len(self.owner)

    def polygons(self) -> np.ndarray:
        """Corners (q, 4, 2), counter-clockwise (:func:`tm.geometry.rectangles`)."""
        return self.centre[:, None, :] + rectangles(self.heading, 2.0 * self.half[:, 0], 2.0 * self.half[:, 1])


def _flat(name, a, shape) -> np.ndarray:
    a = np.broadcast_to(np.asarray(a, dtype=float), shape).ravel()
    if not np.isfinite(a).all():
        raise PathError(f"path_box_cover: {name} must be finite")
    return a


def path_box_cover(frame: PathFrame, s_lo, s_hi, n_lo, n_hi, length, width) -> PathBoxes:
    """Oriented world boxes whose union holds the footprint of every ``(s, n)`` in
    ``[s_lo, s_hi] x [n_lo, n_hi]`` (module notes); vectorised over intervals (all arguments
    broadcast together; ``length``, ``width`` per interval or scalars).

    An interval with ``s_lo > s_hi`` or ``n_lo > n_hi`` is empty and gets no box (as an empty
    claim slot, which never conflicts).

    Raises
    ------
    PathError
        A value that is not finite, or a negative length or width.
    """
    shape = np.broadcast_shapes(*(np.shape(a) for a in (s_lo, s_hi, n_lo, n_hi, length, width)))
    L, W = _flat("length", length, shape), _flat("width", width, shape)
    if (L < 0).any() or (W < 0).any():
        raise PathError("path_box_cover: length and width must be >= 0")
    boxes = stack_box_cover(PathStack([frame]), np.zeros(L.size, dtype=np.intp), _flat("s_lo", s_lo, shape),
                            _flat("s_hi", s_hi, shape), _flat("n_lo", n_lo, shape), _flat("n_hi", n_hi, shape),
                            0.5 * L, 0.5 * L, 0.5 * W, 0.5 * W)
    return PathBoxes(boxes.owner, boxes.segment, boxes.centre, boxes.heading, boxes.half, boxes.start,
                     boxes.count, shape)


def stack_box_cover(stack: PathStack, fid, s_lo, s_hi, n_lo, n_hi, back, front, right, left) -> PathBoxes:
    """:func:`path_box_cover` on the frames of a :class:`~controllers.path.PathStack`, interval ``q``
    on frame ``fid[q]``, with a body that reaches ``back``/``front`` along and ``right``/``left``
    across its own axes from its centre (a footprint plus one-sided padding); 1-D arrays of one
    length (scalars broadcast).  Box ``i`` in segment ``i``'s frame: along ``[a_i - back, b_i +
    front]``, across ``[n_lo - right, n_hi + left]`` (module notes); on a segment whose body leans
    (:class:`~controllers.path.PathFrame` ``lean``), in the body's frame: the bounding box there of
    the reference points ``[a_i, b_i] x [n_lo, n_hi]`` plus the same extents.  Returns :class:`PathBoxes` with
    ``segment`` the stack's global segment index and ``shape = (m,)``."""
    sl = np.atleast_1d(np.asarray(s_lo, dtype=float))
    m = sl.size
    fid, sh, nl, nh, bk, fr, rt, lf = (np.broadcast_to(np.asarray(a, dtype=np.intp if k == 0 else float), (m,))
                                       for k, a in enumerate((fid, s_hi, n_lo, n_hi, back, front, right, left)))
    for name, a in (("s_lo", sl), ("s_hi", sh), ("n_lo", nl), ("n_hi", nh), ("extent", np.concatenate([bk, fr, rt, lf]))):
        if not np.isfinite(a).all():
            raise PathError(f"stack_box_cover: {name} must be finite")
    ok = (sl <= sh) & (nl <= nh)
    i0 = stack.first_meeting(fid, np.where(ok, sl, 0.0))   # first segment with S_{i+1} >= s_lo
    i1 = stack.segment(fid, np.where(ok, sh, 0.0))         # last segment with S_i <= s_hi
    count = np.where(ok, i1 - i0 + 1, 0)
    start = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.intp) if m else np.zeros(0, np.intp)
    owner = np.repeat(np.arange(m), count)
    seg = i0[owner] + (np.arange(len(owner)) - start[owner])
    # the leaning segments' trigonometry in numpy (the kernel does arithmetic only: tm.kernels)
    lean = stack.body_heading[seg] != stack.heading[seg]
    r = np.flatnonzero(lean)
    cos_d, sin_d, cos_b, sin_b = (np.zeros(len(seg)) for _ in range(4))
    if len(r):
        d = stack.heading[seg[r]] - stack.body_heading[seg[r]]
        cos_d[r], sin_d[r] = np.cos(d), np.sin(d)
        cos_b[r], sin_b[r] = np.cos(stack.body_heading[seg[r]]), np.sin(stack.body_heading[seg[r]])
    centre, heading, half = cover_boxes(seg, owner, fid[owner], sl, sh, nl, nh, bk, fr, rt, lf, stack.first,
                                        stack.last, stack.start, stack.end, stack.heading, stack.body_heading,
                                        stack.tangent, stack.normal, stack.vertices, lean, cos_d, sin_d, cos_b, sin_b)
    return PathBoxes(owner=owner, segment=seg, centre=centre, heading=heading, half=half, start=start, count=count,
                     shape=(m,))


def cover_bounds(boxes: PathBoxes, centre, heading) -> tuple[np.ndarray, np.ndarray]:
    """The bounding box, in the frame ``centre + R(heading)`` of each interval (``centre`` (m, 2),
    ``heading`` (m,), one per interval of ``boxes``), of that interval's boxes: ``lo, hi`` (m, 2);
    intervals without a box inverted (``+inf, -inf``).  Sound: it holds every box of the interval."""
    m = int(np.prod(boxes.shape)) if boxes.shape else 1
    lo = np.full((m, 2), np.inf)
    hi = np.full((m, 2), -np.inf)
    if not len(boxes):
        return lo, hi
    h = np.asarray(heading, dtype=float).reshape(-1)
    dh = boxes.heading - h[boxes.owner]
    return cover_frame_bounds(boxes.centre, boxes.half, boxes.start.reshape(-1), boxes.count.reshape(-1),
                              np.ascontiguousarray(np.asarray(centre, dtype=float).reshape(-1, 2)), np.cos(h),
                              np.sin(h), np.abs(np.cos(dh)), np.abs(np.sin(dh)))


def path_footprints(frame: PathFrame, s, n, length, width) -> np.ndarray:
    """Footprint corners (m, 4, 2) of bodies at path coordinates ``(s, n)`` (1-D, broadcast):
    ``length x width`` rectangles centred at ``to_world(s, n)`` with the segment's heading."""
    s, n = np.broadcast_arrays(np.atleast_1d(np.asarray(s, dtype=float)), np.asarray(n, dtype=float))
    xy, h = frame.to_world(s.ravel(), n.ravel())
    L = np.broadcast_to(np.asarray(length, dtype=float), h.shape)
    W = np.broadcast_to(np.asarray(width, dtype=float), h.shape)
    return xy[:, None, :] + rectangles(h, L, W)


def points_in_boxes(boxes: PathBoxes, owner, points, tol: float) -> np.ndarray:
    """For points ``points`` (p, k, 2), each group of ``k`` points tested against the boxes of
    interval ``owner[p]``: (p, c) bool, whether all ``k`` points of group ``p`` lie in box ``c`` of
    that interval (within ``tol``, m; ``c`` up to the largest box count, padding False).  ``.any(1)``:
    the group lies in one box; with ``k = 1``, a point inside the union of the interval's boxes."""
    owner = np.asarray(owner, dtype=np.intp)
    P = np.asarray(points, dtype=float)
    cnt = boxes.count[owner]
    width = int(cnt.max()) if len(cnt) else 0
    out = np.zeros((len(owner), width), dtype=bool)
    if not width:
        return out
    j = np.arange(width)
    valid = j[None, :] < cnt[:, None]
    b = np.where(valid, boxes.start[owner][:, None] + j[None, :], 0)
    c, s = np.cos(boxes.heading[b]), np.sin(boxes.heading[b])            # (p, c)
    rel = P[:, None, :, :] - boxes.centre[b][:, :, None, :]              # (p, c, k, 2)
    u = np.abs(rel[..., 0] * c[..., None] + rel[..., 1] * s[..., None])
    v = np.abs(-rel[..., 0] * s[..., None] + rel[..., 1] * c[..., None])
    inside = (u <= boxes.half[b][..., 0, None] + tol) & (v <= boxes.half[b][..., 1, None] + tol)
    return inside.all(axis=-1) & valid
