"""What keeps a run directory whole when several processes, a person or a cluster act on it: one
live run per directory (a lock), and interruptions (SIGINT, SIGTERM) that wait for the file being
written and end the run with a line saying what was kept.

The lock is the operating system's (``filelock``'s ``fcntl`` lock on ``.kadv.lock``): the kernel
releases it when its process dies however it dies, so a stale lock never blocks, and NFS and Lustre
pass such locks between hosts. The holder's PID, host and start time sit beside it in
``.kadv.lock.json``, to name it to a second process, and to say when a dead one's run is taken over.
"""

from __future__ import annotations

import contextlib
import datetime
import json
import logging
import os
import signal
import socket
import threading
from collections.abc import Iterator
from pathlib import Path

from filelock import FileLock, Timeout

__all__ = ["LOCK_FILES", "Interrupted", "RunDirectoryBusy", "deferred_interrupts", "interruptible", "run_lock"]

log = logging.getLogger(__name__)
_LOCK = ".kadv.lock"
_HOLDER = ".kadv.lock.json"
LOCK_FILES = (_LOCK, _HOLDER)  # what :func:`run_lock` leaves in a run directory


class RunDirectoryBusy(RuntimeError):
    """Another live process holds the run directory (the message names it)."""


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


def _holder_text(holder: dict) -> str:
    return f"PID {holder.get('pid')} on {holder.get('host')} since {holder.get('started')}"


@contextlib.contextmanager
def run_lock(run_dir: str | Path) -> Iterator[None]:
    """Hold ``run_dir`` for this process for the block.

    Raises:
        RunDirectoryBusy: a live process holds it, named by PID, host and start time.
    """
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    holder_path = run_dir / _HOLDER
    lock = FileLock(run_dir / _LOCK, timeout=0)
    try:
        lock.acquire()
    except Timeout:
        holder = _read_holder(holder_path)
        raise RunDirectoryBusy(
            f"run directory {run_dir} is in use by another kadv run ({_holder_text(holder)}); "
            "wait for it to finish, or stop it first"
        ) from None
    try:
        previous = _read_holder(holder_path)
        if previous:
            # the kernel freed the lock, so its holder is gone: a kill, a crash, a node lost
            log.warning("run directory %s: taking over from a run that is gone (%s)", run_dir, _holder_text(previous))
        started = datetime.datetime.now().astimezone().isoformat(timespec="seconds")
        holder_path.write_text(json.dumps({"pid": os.getpid(), "host": socket.gethostname(), "started": started}))
        yield
    finally:
        holder_path.unlink(missing_ok=True)
        lock.release()


def _read_holder(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}


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
