"""Capture trajectories as the scan datasets ship them, read back from scan-like rooms written in
each layout, and refused in one line when a pose cannot be read."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import kadv
from kadv.datasets.scan_rooms import ScanLike, scan_like, write_scan, write_scannet
from kadv.scenes.trajectories import read_arkitscenes_traj, read_colmap_images, read_scannet_sens


@pytest.fixture(scope="module")
def scan() -> ScanLike:
    return scan_like(kadv.box_room(seed=0), seed=0)


@pytest.mark.parametrize(
    "layout, source",
    [
        ("scannet", "pose"),
        ("scannetpp", "images.txt"),
        ("arkitscenes", "lowres_wide.traj"),
        ("matterport", "1f2e3d4c5b6a79880123456789abcdef.conf"),
        ("replica", None),
    ],
)
def test_each_layouts_capture_path_loads_as_the_poses_it_was_written_from(layout, source, scan, tmp_path) -> None:
    scene = kadv.load_scene(write_scan(scan, tmp_path, layout))
    if source is None:  # Replica ships no trajectory
        assert scene.trajectory is None
        return
    assert Path(scene.trajectory_source).name == source
    # ScanNet's sensor frame and axisAlignment, the Z-up frames, OpenGL's camera axes: all undone
    np.testing.assert_allclose(scene.trajectory, scan.trajectory, atol=1e-5)


def test_a_sens_file_is_read_for_its_poses_frame_by_frame(scan, tmp_path) -> None:
    mesh = write_scannet(scan, tmp_path, "scene0001_00", sens=True)
    sens = mesh.with_name("scene0001_00.sens")
    scene = kadv.load_scene(mesh)
    assert scene.trajectory_source == str(sens)
    np.testing.assert_allclose(scene.trajectory, scan.trajectory, atol=1e-5)
    data = sens.read_bytes()
    sens.write_bytes(data[:-40])  # cut inside the last frame
    with pytest.raises(ValueError, match=r"scene0001_00.sens: ends inside frame 47"):
        read_scannet_sens(sens)


def test_malformed_and_non_rigid_poses_are_refused_naming_the_file_and_line(tmp_path) -> None:
    traj = tmp_path / "lowres_wide.traj"
    traj.write_text("1000.0 0.1 0.2 0.3 1.0 2.0 3.0\n1000.1 0.1 0.2 x 1.0 2.0 3.0\n")
    with pytest.raises(ValueError, match=r"lowres_wide.traj:2: expected 7 numbers, got '1000.1 0.1 0.2 x"):
        read_arkitscenes_traj(traj)
    images = tmp_path / "images.txt"
    images.write_text("# header\n1 0.6 0.8 0.0 0.0 1 2 3 1 a.jpg\n\n2 2.0 0.0 0.0 0.0 1 2 3 1 b.jpg\n\n")
    with pytest.raises(ValueError, match=r"images.txt:4: not a rigid camera pose"):
        read_colmap_images(images)
    pose = tmp_path / "pose"
    pose.mkdir()
    (pose / "0.txt").write_text(" ".join(["-inf"] * 16))  # tracking lost: left out, as ScanNet marks it
    (pose / "1.txt").write_text("2 0 0 0  0 1 0 0  0 0 1 0  0 0 0 1")  # a scaled rotation: not rigid
    from kadv.scenes.trajectories import read_scannet_poses

    with pytest.raises(ValueError, match=r"pose/1.txt: not a rigid camera pose"):
        read_scannet_poses(pose)


def test_kadv_attack_starts_from_the_best_captured_views_and_says_where_they_came_from(scan, tmp_path) -> None:
    import json

    from kadv.cli.attack import main as attack_main
    from tests.cli.in_process import call_main

    mesh = write_scan(scan, tmp_path, "arkitscenes")
    args = ["kadv-attack", "scene=file", f"scene.path={mesh}", "render.height=24", "render.width=32", "init.count=2"]
    args += ["attack.budget_passes=8", "video=false", "progress=false", "hydra.run.dir=run"]
    result = call_main(attack_main, args, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "init.source=captured: init views from the capture path in" in result.stdout + result.stderr
    views = json.loads((tmp_path / "run" / "init_params.json").read_text())["init_views"]
    assert [v["source"] for v in views] == ["captured", "captured"]
    poses = np.array([v["world_T_cam"] for v in views])
    assert all(np.abs(scan.trajectory - pose).max(axis=(1, 2)).min() < 1e-5 for pose in poses)  # poses of the path
    sampled = call_main(attack_main, [*args[:-1], "hydra.run.dir=sampled", "init.source=sampled"], cwd=tmp_path)
    assert sampled.returncode == 0, sampled.stderr
    assert {v["source"] for v in json.loads((tmp_path / "sampled" / "init_params.json").read_text())["init_views"]} == {
        "sampled"
    }
