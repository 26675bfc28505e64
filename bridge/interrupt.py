"""Ctrl-C that is never lost during a run.

Python raises ``KeyboardInterrupt`` from SIGINT wherever the main thread happens to be.  When that
is inside a finalizer (``__del__``; numba's LLVM objects take a lock there while the first steps
compile their kernels), Python prints "Exception ignored" and goes on: the run ignored the Ctrl-C
and ran to its end (measured: ``tests/bridge/test_crash_outputs.py``, the ``swap`` run, exit 0
instead of 130, on a loaded machine).  :class:`InterruptGuard` raises it at once as before and
remembers it; as a co-simulation observer it raises it again at the end of the step if it was
swallowed.  When it lands inside compiled code, numba hands it back wrapped: ``SystemError:
CPUDispatcher(...) returned a result with an exception set``, raised from the ``KeyboardInterrupt``;
the runs take such an error for the Ctrl-C it is (:func:`interrupt_behind`; measured: the same test,
``grid``, exit 1 with that message once in 5 fresh-clone CI runs).
"""

from __future__ import annotations

import signal
import threading

__all__ = ["InterruptGuard", "interrupt_behind"]


def interrupt_behind(exc: BaseException) -> bool:
    """Whether a ``KeyboardInterrupt`` lies behind ``exc`` (its ``__cause__`` / ``__context__`` chain):
    a Ctrl-C that came back wrapped in another error (module notes)."""
    seen = set()
    e = exc
    while e is not None and id(e) not in seen:
        if isinstance(e, KeyboardInterrupt):
            return True
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return False


class InterruptGuard:
    """SIGINT handler for the duration of a ``with`` block, and a :class:`bridge.cosim.Cosim` observer.

    Attributes
    ----------
    pending : bool
        A SIGINT arrived during the block.
    """

    def __init__(self) -> None:
        self.pending = False
        self._previous = None

    def __enter__(self) -> "InterruptGuard":
        if threading.current_thread() is threading.main_thread():  # (only it may set handlers)
            self._previous = signal.signal(signal.SIGINT, self._on_sigint)
        return self

    def __exit__(self, *exc) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
            self._previous = None

    def _on_sigint(self, signum, frame) -> None:
        self.pending = True
        raise KeyboardInterrupt

    def on_step(self, sim, state, decision, row) -> None:
        """Raise a Ctrl-C that Python dropped (see the module notes) at the end of the step."""
        if self.pending:
            raise KeyboardInterrupt
