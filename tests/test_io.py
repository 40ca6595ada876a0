"""kadv.io: a file that cannot be written is named with the system's error, and nothing is left."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import pytest

from kadv.errors import WriteError
from kadv.io import atomic_write


def test_a_full_disk_names_the_file_and_leaves_nothing(tmp_path: Path) -> None:
    def full(tmp: Path) -> None:
        tmp.write_text("partly")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    (tmp_path / "kept.json").write_text("before")
    with pytest.raises(WriteError) as error:
        atomic_write(tmp_path / "kept.json", full)
    assert str(error.value) == f"cannot write {tmp_path / 'kept.json'}: No space left on device"
    assert error.value.errno == errno.ENOSPC
    assert (tmp_path / "kept.json").read_text() == "before" and len(list(tmp_path.iterdir())) == 1


def test_a_folder_that_cannot_be_made_is_a_write_error(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("")
    with pytest.raises(WriteError, match=r"cannot write .*file/sub/x.json: Not a directory"):
        atomic_write(tmp_path / "file" / "sub" / "x.json", lambda tmp: tmp.write_text("{}"))
