"""A run directory as a store: one live run in it at a time (a lock), what a finished run holds
(``summary.json``, written last), and what an interrupted one keeps to resume from (each init
view's result under ``partial/``, and the settings it was made with).

The lock is the operating system's (``filelock``'s ``fcntl`` lock on ``.kadv.lock``): the kernel
releases it when its process dies however it dies, so a stale lock never blocks, and NFS and Lustre
pass such locks between hosts. The holder's PID, host and start time sit beside it in
``.kadv.lock.json``, to name it to a second process, and to say when a dead one's run is taken over.

A partial result is saved as soon as its init view is done, so an interrupted run resumes without
recomputing (or rewriting) it; once the summary is written, the run needs none of it, and
``partial/`` goes (but for files set aside as unreadable).
"""

from __future__ import annotations

import contextlib
import datetime
import json
import logging
import os
import socket
from collections.abc import Iterator
from pathlib import Path

from filelock import FileLock, Timeout

from kadv.attack import InitViewResult
from kadv.report.summary import read_partial, write_partial

__all__ = [
    "LOCK_FILES",
    "SUMMARY",
    "RunDirectoryBusy",
    "check_same_settings",
    "is_complete",
    "load_partial_results",
    "remove_partial_results",
    "run_lock",
    "save_partial_result",
]

log = logging.getLogger(__name__)
SUMMARY = "summary.json"
_PARTIAL = "partial"
_LOCK = ".kadv.lock"
_HOLDER = ".kadv.lock.json"
LOCK_FILES = (_LOCK, _HOLDER)  # what :func:`run_lock` leaves in a run directory


class RunDirectoryBusy(RuntimeError):
    """Another live process holds the run directory (the message names it)."""


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


def is_complete(run_dir: str | Path) -> bool:
    """Whether the run directory holds a finished run (its ``summary.json``)."""
    return (Path(run_dir) / SUMMARY).is_file()


def save_partial_result(run_dir: str | Path, index: int, result: InitViewResult) -> Path:
    """Save one init view's search result (``partial/init<index>.json``)."""
    return write_partial(Path(run_dir) / _PARTIAL / f"init{index}.json", result)


def load_partial_results(run_dir: str | Path) -> dict[int, InitViewResult]:
    """The init views' results an earlier (possibly interrupted) run saved, by index.

    A file that cannot be read (cut short, edited, or of another schema version) is named in one
    warning, moved aside as ``init<i>.json.unreadable``, and its init view is left to be computed again.
    """
    results = {}
    for path in sorted((Path(run_dir) / _PARTIAL).glob("init*.json")):
        try:
            results[int(path.stem.removeprefix("init"))] = read_partial(path)
        except ValueError as error:
            aside = path.with_name(path.name + ".unreadable")
            path.replace(aside)
            log.warning(
                "%s cannot be read (%s): moved aside to %s; its init view is computed again",
                path,
                str(error).removeprefix(f"{path}: "),
                aside.name,
            )
    return results


def remove_partial_results(run_dir: str | Path) -> None:
    """Remove the partial results of a run whose summary is written (files set aside as unreadable
    stay for the user to look at)."""
    for path in (Path(run_dir) / _PARTIAL).glob("init*.json"):
        path.unlink()
    with contextlib.suppress(OSError):
        (Path(run_dir) / _PARTIAL).rmdir()


def check_same_settings(
    run_dir: str | Path,
    saved: dict,
    now: dict,
    ignored: frozenset[str] = frozenset(),
    resolved: frozenset[str] = frozenset(),
    elsewhere: str = "write to another folder",
) -> None:
    """Refuse to skip or resume ``run_dir``, whose run was made with the config ``saved``, under the
    config ``now`` if they differ, naming the keys: its results would pass for ``now``'s.

    Args:
        ignored: dotted keys that change how a run shows its progress, not what it finds.
        resolved: dotted keys whose ``auto`` a run writes back resolved (``now``'s ``auto`` matches any).
        elsewhere: how the caller runs it in another folder, said in the refusal.

    Raises:
        ValueError: the settings differ (the first three keys named, with both values).
    """
    old, new = _leaves(saved), _leaves(now)
    changed = [
        key
        for key in sorted(old.keys() | new.keys())
        if old.get(key) != new.get(key) and key not in ignored and not (key in resolved and new.get(key) == "auto")
    ]
    if changed:
        listed = ", ".join(f"{k}: {old.get(k, '(unset)')} -> {new.get(k, '(unset)')}" for k in changed[:3])
        more = f" and {len(changed) - 3} more" if len(changed) > 3 else ""
        raise ValueError(
            f"{run_dir} holds a run made with other settings ({listed}{more}): remove it to run again, or {elsewhere}"
        )


def _leaves(node: object, prefix: str = "") -> dict[str, object]:
    """A config's leaves by dotted key (lists are leaves)."""
    if not isinstance(node, dict) or not node:
        return {prefix: node}
    return {
        k: v for key, value in node.items() for k, v in _leaves(value, f"{prefix}.{key}" if prefix else key).items()
    }
