"""Interruptions (SIGINT, SIGTERM) that wait for the file being written and end a run with a line
saying what was kept (the run directory's other guards: :mod:`kadv.report.store`)."""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator

__all__ = ["Interrupted", "deferred_interrupts", "interruptible"]


class Interrupted(BaseException):
    """The run was asked to stop (SIGINT or SIGTERM); ``signal`` says which.

    A ``BaseException``, as ``KeyboardInterrupt`` is, so that no ``except Exception`` swallows it.
    """

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signal = signum

    @property
    def exit_status(self) -> int:
        """128 + the signal's number: 130 for SIGINT, 143 for SIGTERM, as shells report them."""
        return 128 + self.signal


_writing = 0  # atomic writes under way (kadv.io.atomic_write)
_pending: list[int] = []  # a signal that came during one, raised when the last ends


@contextlib.contextmanager
def deferred_interrupts() -> Iterator[None]:
    """Within the block, an interruption waits: the file being written is written whole."""
    global _writing
    _writing += 1
    try:
        yield
    finally:
        _writing -= 1
        if not _writing and _pending:
            raise Interrupted(_pending.pop())


def _interrupt(signum: int, frame) -> None:
    if _writing:
        _pending[:] = [signum]
        return
    raise Interrupted(signum)


@contextlib.contextmanager
def interruptible() -> Iterator[None]:
    """Within the block, SIGINT and SIGTERM raise :class:`Interrupted` (between files written,
    never during one); the previous handlers come back after it. Outside the main thread, where
    Python takes no handlers, the block runs as it is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {signum: signal.signal(signum, _interrupt) for signum in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        _pending.clear()
