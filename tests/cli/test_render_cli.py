from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from PIL import Image

SCRIPT = Path(sys.executable).parent / "kadv-render"


def _run(cwd: Path, *overrides: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(SCRIPT), "hydra.run.dir=run", *overrides], cwd=cwd, capture_output=True, text=True,
                          timeout=300)


def test_installed_script_finds_its_configs_outside_the_source_tree(tmp_path: Path) -> None:
    result = _run(tmp_path, "render.height=60", "render.width=80")
    assert result.returncode == 0, result.stderr
    with Image.open(tmp_path / "run" / "rgb.png") as rgb:
        assert rgb.size == (80, 60) and rgb.mode == "RGB"
    with Image.open(tmp_path / "run" / "depth.png") as depth:
        assert depth.size[0] > 80  # the colour bar widens the figure
    summary = json.loads((tmp_path / "run" / "render.json").read_text())
    assert summary["hit_fraction"] == 1.0 and summary["scene"] == "box_room_0"


def test_look_at_override_and_clear_error_for_bad_index(tmp_path: Path) -> None:
    ok = _run(tmp_path, "render.height=30", "render.width=40", "camera.eye=[1,1.5,1]", "camera.target=[3,1,3]",
              "camera.fov_x_deg=90")
    assert ok.returncode == 0, ok.stderr
    bad = _run(tmp_path, "camera.index=5")
    assert bad.returncode != 0 and "camera.index=5" in bad.stderr + bad.stdout
