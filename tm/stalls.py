"""How long each junction token holder's stop point has stayed where it is (the stalled-holder
rules of :class:`tm.authority_gate.AuthorityGate`).  Pure Python, no simulator."""

from __future__ import annotations

from collections.abc import Iterable

__all__ = ["StallClock"]


class StallClock:
    """Per holder: its stop point and the step since which it has stayed there.

    :meth:`note` is called once per step with the holders and their current stop points; a
    vehicle that stops holding is forgotten, so one that takes a token again starts afresh.
    """

    def __init__(self) -> None:
        self._since: dict[str, tuple[int, int]] = {}

    def note(self, t: int, stop_points: Iterable[tuple[str, int]]) -> None:
        """Record step ``t``'s ``(holder, stop point)`` pairs."""
        since = {}
        for h, k in stop_points:
            if h in since:
                continue
            was = self._since.get(h)
            since[h] = was if was is not None and was[0] == k else (k, t)
        self._since = since

    def still_for(self, t: int, holder: str) -> int | None:
        """Steps ``holder``'s stop point has stayed put at step ``t`` (None: not a holder seen)."""
        was = self._since.get(holder)
        return None if was is None else t - was[1]
