"""kadv-models lists every preset from the local cache alone."""
from __future__ import annotations

import pytest

from kadv.cli.models import main
from kadv.models import PRESETS


def test_every_preset_is_listed_with_its_cache_state(tmp_path, monkeypatch: pytest.MonkeyPatch, capsys) -> None:
    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path / "empty"))
    monkeypatch.setattr("huggingface_hub.constants.HF_HUB_CACHE", str(tmp_path / "empty"))
    main([])
    rows = [line.split(" | ") for line in capsys.readouterr().out.splitlines() if line.startswith("| ")][1:]
    names = {row[0].strip("| ") for row in rows}
    assert names == {*PRESETS, "kadv_tiny"}
    by_name = {row[0].strip("| "): row for row in rows}
    assert by_name["zoedepth_nk"][3] == "depth" and by_name["midas_dpt_large"][3] == "disparity"
    assert all(by_name[name][5].strip(" |") == "not cached" for name in PRESETS)
