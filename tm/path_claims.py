"""Reach claims of vehicles driven in path coordinates (:mod:`controllers.path`), as world boxes.

A path-frame vehicle's plant runs in ``(s, n, v_s, v_n)``: its waypoints are ``(S_k, 0)`` with
heading 0, so its claims (:func:`tm.reach.reach_claims`) are boxes of path coordinates,
``[s_lo, s_hi] x [n_lo, n_hi]`` per slot (footprint not yet added).  In the world a slot is
covered by :func:`tm.path_cover.stack_box_cover` (one box per path segment the interval meets,
the body's full extent past every kink) and the slot's claim box is the bounding box of that cover
in the frame of the vehicle's current waypoint in the world (its position ``W[k]`` and the
heading of the segment arriving there, as a road-frame claim): sound (it holds every box of the
cover), exact on a straight and for turns by a multiple of 90 degrees, and coarse on a curve.
So the claims also keep the cover itself (:class:`tm.slot_boxes.SlotBoxes`, the claims'
``tight`` boxes): the ``timed`` check compares those, box by box; the ``union`` check and the
junction layer use the waypoint-frame boxes.

A run of equal slots (a vehicle at rest at its stop point: every slot past its index is ``T^0``'s)
is covered once and its slots share the boxes (``tests/tm/test_path_claims.py`` compares them with
slot-by-slot covers, float for float).

The claims are then :class:`tm.reach.ReachClaims` like any other, compared, shifted and reused
with the same rules: the shift ``S_{k+1}(t) ⊇ S_k(t+1)`` holds in path coordinates, and the cover
and its bounding box grow with the interval, so it holds in the world too.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from controllers.path import PathStack
from tm.path_cover import cover_bounds, stack_box_cover
from tm.reach import ReachClaims, ReachModel, reach_claims, split_pad
from tm.kernels import path_slots
from tm.slot_boxes import SlotBoxes

__all__ = ["PathPlace", "path_reach_claims", "bare_model"]


@dataclass(frozen=True, eq=False)
class PathPlace:
    """Where path-frame vehicles are in the world: their frames in ``stack`` (``fid`` (n,)) and the
    world frame their claims are drawn in (``centre`` (n, 2), ``heading`` (n,): the current, or
    requested, waypoint in the world and the heading of the segment arriving there)."""

    stack: PathStack
    fid: np.ndarray
    centre: np.ndarray
    heading: np.ndarray

    def __post_init__(self) -> None:
        n = len(self.fid)
        if np.shape(self.centre) != (n, 2) or np.shape(self.heading) != (n,):
            raise ValueError(f"PathPlace: fid ({n},) needs centre ({n}, 2) and heading ({n},), got "
                             f"{np.shape(self.centre)} and {np.shape(self.heading)}")

    def __len__(self) -> int:
        return len(self.fid)

    def take(self, idx) -> "PathPlace":
        return PathPlace(self.stack, self.fid[idx], self.centre[idx], self.heading[idx])

    @staticmethod
    def concat(*parts: "PathPlace") -> "PathPlace":
        if any(p.stack is not parts[0].stack for p in parts):
            raise ValueError("PathPlace.concat: places on different stacks")
        return PathPlace(parts[0].stack, np.concatenate([p.fid for p in parts]),
                         np.vstack([p.centre for p in parts]), np.concatenate([p.heading for p in parts]))


def bare_model(rm: ReachModel) -> ReachModel:
    """``rm`` without a footprint: its claims are the position intervals alone."""
    return replace(rm, length=0.0, width=0.0)


def path_reach_claims(rm: ReachModel, bare: ReachModel, X, centre, index, place: PathPlace,
                      body_pad=None) -> ReachClaims:
    """World claims of path-frame vehicles of one class (module notes).

    Parameters
    ----------
    rm : ReachModel
        The class's model (its footprint ``length`` x ``width`` is laid along the path).
    bare : ReachModel
        ``bare_model(rm)`` (built once by the caller).
    X : ndarray, shape (n, 4)
        Path states ``(s, n, v_s, v_n)``.
    centre : ndarray, shape (n, 2)
        The waypoints in path coordinates, ``(S_k, 0)``.
    index : ndarray of int, shape (n,)
    place : PathPlace
        The vehicles' frames and the world frames of their claims.
    body_pad : ndarray (n, 2) or (n, 4), optional
        Extra reach of the body beyond its rectangle (:func:`tm.reach.split_pad`), in the body's axes.
    """
    X = np.asarray(X, dtype=float)
    n = len(X)
    if len(place) != n:
        raise ValueError(f"path_reach_claims: {n} states but {len(place)} places")
    path = reach_claims(bare, X, centre, np.zeros(n), index, boxes=False)
    K = path.lo.shape[1]
    hl, hw = 0.5 * rm.length, 0.5 * rm.width
    if body_pad is not None:
        plo, phi = split_pad(body_pad, n)
        ext = [hl + plo[:, 0], hl + phi[:, 0], hw + plo[:, 1], hw + phi[:, 1]]
    else:
        ext = [np.full(n, hl), np.full(n, hl), np.full(n, hw), np.full(n, hw)]
    # the slots as path intervals ([s_lo, s_hi] x [n_lo, n_hi], an empty one [1, 0] x [0, 0]); a slot
    # equal to the one before (a vehicle at rest: every slot past its index is T^0's) is covered once:
    # the runs of equal slots share their boxes and bounds (tm.kernels.path_slots)
    s_lo, s_hi, n_lo, n_hi, first, run = path_slots(path.lo, path.hi,
                                                   np.ascontiguousarray(np.asarray(centre, dtype=float)[:, 0]))
    who = first // K                                  # their vehicles
    boxes = stack_box_cover(place.stack, np.asarray(place.fid)[who], s_lo, s_hi, n_lo, n_hi,
                            *(np.asarray(e)[who] for e in ext))
    wlo, whi = cover_bounds(boxes, np.asarray(place.centre)[who], np.asarray(place.heading)[who])
    # the cover itself, box by box: on a curve the waypoint's frame bounds it coarsely (a bus body
    # at 45 degrees to it reaches 4.5 m across), and it nests as the interval does
    tight = SlotBoxes(boxes.centre, boxes.heading, boxes.half, boxes.start[run].reshape(n, K),
                      boxes.count[run].reshape(n, K))
    return ReachClaims(np.asarray(place.centre, dtype=float), np.asarray(place.heading, dtype=float),
                       wlo[run].reshape(n, K, 2), whi[run].reshape(n, K, 2), tight)
