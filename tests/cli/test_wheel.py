"""A non-editable wheel installed into a fresh virtual environment finds its Hydra configs."""

from __future__ import annotations

import subprocess
import sys
import sysconfig
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_a_wheel_in_a_fresh_venv_ships_the_configs(tmp_path: Path) -> None:
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "--quiet",
            "-w",
            str(tmp_path / "dist"),
            str(ROOT),
        ],
        check=True,
        capture_output=True,
        timeout=300,
    )
    wheel = next((tmp_path / "dist").glob("kadv-*.whl"))
    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=True)
    python = env_dir / "bin" / "python"
    # the dependencies come from this environment (appended after the venv's own site-packages), kadv from the wheel
    site = subprocess.run(
        [str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    Path(site, "deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    subprocess.run(
        [str(python), "-m", "pip", "install", "--no-deps", "--no-index", "--quiet", str(wheel)],
        check=True,
        capture_output=True,
        timeout=300,
    )
    located = subprocess.run(
        [str(python), "-c", "import kadv, kadv.conf; print(kadv.__file__, kadv.conf.__file__)"],
        capture_output=True,
        text=True,
        check=True,
        cwd=tmp_path,
    ).stdout
    assert str(env_dir) in located and str(ROOT) not in located
    result = subprocess.run(
        [str(env_dir / "bin" / "kadv-render"), "hydra.run.dir=out", "render.height=24", "render.width=32"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    assert (tmp_path / "out" / "rgb.png").is_file()
    help_text = subprocess.run(
        [str(env_dir / "bin" / "kadv-attack"), "--help"], cwd=tmp_path, capture_output=True, text=True, timeout=300
    ).stdout
    # the wheel's config group lists every method's config
    methods = "attack: " + ", ".join(sorted(p.stem for p in (ROOT / "conf" / "attack").glob("*.yaml")))
    assert help_text.startswith("kadv-attack:") and methods in help_text
