"""Files written atomically, so that an interrupted run never leaves a truncated file."""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Callable
from pathlib import Path

from kadv.errors import WriteError
from kadv.interrupts import deferred_interrupts

__all__ = ["TEMPORARY_MARK", "atomic_write", "file_slug", "remove_temporaries", "save_figure", "write_json"]

# in the name of every file atomic_write has not finished: ".summary.kadv-tmp-x1y2z3.json"
TEMPORARY_MARK = ".kadv-tmp-"


def atomic_write(path: str | Path, write: Callable[[Path], None]) -> Path:
    """Call ``write(tmp_path)`` and move the result to ``path`` in one rename.

    The temporary file sits in the destination folder so the rename stays on one filesystem.

    Raises:
        WriteError: the file cannot be written (a full disk, a read-only folder, no permission),
            naming it and the system's error; nothing is left behind.
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        # the destination's suffix kept: writers choose the format by it (numpy adds ".npz" otherwise)
        handle, tmp = tempfile.mkstemp(prefix=f".{path.stem}{TEMPORARY_MARK}", suffix=path.suffix, dir=path.parent)
    except OSError as error:
        raise WriteError(path, error) from error
    os.close(handle)
    # mkstemp creates 0600 files; give the result the mode an ordinary open() would have
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    # an interruption waits for the file (kadv.interrupts.interruptible): it is written whole or not at all
    with deferred_interrupts():
        try:
            write(Path(tmp))
            os.replace(tmp, path)
        except OSError as error:
            Path(tmp).unlink(missing_ok=True)
            if isinstance(error, WriteError):
                raise
            raise WriteError(path, error) from error
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
    return path


def write_json(path: str | Path, data: object) -> Path:
    """Write ``data`` as indented JSON, atomically."""
    text = json.dumps(data, indent=1)
    return atomic_write(path, lambda tmp: tmp.write_text(text))


def remove_temporaries(folder: str | Path) -> list[Path]:
    """Delete the temporary files that writers killed mid-write left anywhere under ``folder``
    (only its owner may call this: a live writer's file would go too); returns them."""
    left = sorted(Path(folder).rglob(f".*{TEMPORARY_MARK}*"))
    for path in left:
        path.unlink(missing_ok=True)
    return left


def save_figure(path: str | Path, figure, tight: bool = True) -> Path:
    """Write a matplotlib ``figure`` as a PNG atomically and close it; ``tight`` crops it to what it
    draws (a layout pass of its own: a figure laid out by hand needs none)."""
    import matplotlib.pyplot as plt  # the pictures' modules load it; the rest of kadv need not

    bbox = "tight" if tight else None
    try:
        return atomic_write(path, lambda tmp: figure.savefig(tmp, format="png", dpi=100, bbox_inches=bbox))
    finally:
        plt.close(figure)


def file_slug(name: str) -> str:
    """A name (a model's, a scene's: ``probe/stairs``) as a file name: other characters than letters,
    digits, ``-``, ``_`` and ``.`` become ``_``, at most 80 of them."""
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name)[:80]
