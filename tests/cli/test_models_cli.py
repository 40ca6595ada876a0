"""kadv-models lists every preset from the local cache alone."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from kadv.cli.models import main
from kadv.models import EMBEDDED, PRESETS, preset_table


def test_every_preset_is_listed_with_its_cache_state(tmp_path, monkeypatch: pytest.MonkeyPatch, capsys) -> None:
    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path / "empty"))
    monkeypatch.setattr("huggingface_hub.constants.HF_HUB_CACHE", str(tmp_path / "empty"))
    main([])
    rows = [line.split(" | ") for line in capsys.readouterr().out.splitlines() if line.startswith("| ")][1:]
    names = {row[0].strip("| ") for row in rows}
    assert names == {*PRESETS, *EMBEDDED}
    by_name = {row[0].strip("| "): row for row in rows}
    assert by_name["zoedepth_nk"][3] == "depth" and by_name["midas_dpt_large"][3] == "disparity"
    assert all(by_name[name][5].strip(" |") == "not cached" for name in PRESETS)


def test_a_cached_checkpoint_is_marked_cached(tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    snapshot = tmp_path / "models--apple--DepthPro-hf" / "snapshots" / ("0" * 40)
    snapshot.mkdir(parents=True)
    (snapshot / "config.json").write_text("{}")
    (tmp_path / "models--apple--DepthPro-hf" / "refs").mkdir()
    (tmp_path / "models--apple--DepthPro-hf" / "refs" / "main").write_text("0" * 40)
    monkeypatch.setattr("huggingface_hub.constants.HF_HUB_CACHE", str(tmp_path))
    rows = {row["name"]: row for row in preset_table()}
    assert rows["depth_pro"]["weights"] == "cached" and rows["glpn_nyu"]["weights"] == "not cached"


def test_listing_presets_imports_neither_torch_nor_transformers(tmp_path) -> None:
    script = (
        "import sys\nfrom kadv.cli.models import main\nmain([])\n"
        "print('HEAVY', sorted(m for m in ('torch', 'transformers', 'kornia') if m in sys.modules))"
    )
    result = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, "HF_HUB_OFFLINE": "1", "HF_HOME": str(tmp_path / "hf")},
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines()[-1] == "HEAVY []" and "| depth_pro |" in result.stdout


def test_the_embedded_model_rows_state_their_real_input_size() -> None:
    from kadv.models.tiny import TINY_PREPROCESS
    from kadv.models.tiny_dpt import TINY_DPT_PROCESSOR

    assert EMBEDDED["kadv_tiny"].input_size.startswith("x".join(map(str, TINY_PREPROCESS.size)))
    size = TINY_DPT_PROCESSOR["size"]
    assert EMBEDDED["kadv_tiny_dpt"].input_size == f"{size['height']}x{size['width']}"
