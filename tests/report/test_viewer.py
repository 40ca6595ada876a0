"""kadv-view: the viewer's scene, cameras and controls through viser's API, in headless Chromium,
and its bad inputs."""

from __future__ import annotations

import base64
import io
import json
import shutil
import socket
import subprocess
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from viser import CameraFrustumHandle
from websockets.sync.client import connect

from kadv.cli.attack import main as attack_main
from kadv.cli.view import main as view_main
from kadv.report import view
from kadv.report.viewer import _display_mesh, scene_colours
from kadv.scenes import procedural_room
from tests.cli.in_process import call_main

SMALL = [
    "render.height=48",
    "render.width=64",
    "render.lighting=direct",
    "attack=random",
    "attack.budget_passes=9",
    "attack.top_n=2",
    "init.count=2",
    "init.candidates=8",
    "progress=false",
    "video=false",
]


def _attack(run_dir: Path, *overrides: str) -> Path:
    ran = call_main(attack_main, ["kadv-attack", f"hydra.run.dir={run_dir}", *SMALL, *overrides])
    assert ran.returncode == 0, ran.stderr
    return run_dir


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@pytest.fixture(scope="module")
def sweep(tmp_path_factory) -> Path:
    """A two-model sweep of small finished runs on the box room."""
    root = tmp_path_factory.mktemp("sweep")
    _attack(root / "tiny", "model=kadv_tiny")
    _attack(root / "dpt", "model=kadv_tiny_dpt")
    return root


def _cameras(run: Path) -> list[str]:
    summary = json.loads((run / "summary.json").read_text())
    names = []
    for init in summary["init_views"]:
        names += [f"init{init['index']}"] + [f"init{init['index']}_adv{k}" for k in range(len(init["adversarial"]))]
    return names


def test_a_run_shows_every_camera_and_selecting_one_shows_its_panel(sweep: Path) -> None:
    run = sweep / "tiny"
    viewer = view(run, port=_free_port())
    try:
        assert sorted(viewer.frusta) == sorted(_cameras(run))  # one frustum per init and kept adversarial view
        # viser's own scene holds exactly those, besides the slider's marker
        nodes = viewer.server.scene._handle_from_node_name  # viser lists its nodes nowhere public
        frusta = sorted(name for name, handle in nodes.items() if isinstance(handle, CameraFrustumHandle))
        assert frusta == sorted([f"/cameras/{name}" for name in _cameras(run)] + ["/step"])
        assert (
            sum(len(records) for records in viewer.records.values()) == sum(1 for _ in open(run / "trajectory.csv")) - 1
        )
        chosen = next(name for name in viewer.frusta if "_adv" in name)
        camera = viewer.select(chosen)
        panel = np.asarray(Image.open(camera.panel).convert("RGB"))
        assert viewer.view_choice.value == chosen and np.array_equal(viewer.panel.image, panel)
        assert f"**{chosen}**" in viewer.metrics.content
        start = viewer.step_text.content
        viewer.step.value = 3  # the slider steps through the search
        assert viewer.step_text.content != start and viewer.step_text.content.startswith("step ")
        first = np.array(json.loads((run / "summary.json").read_text())["init_views"][0]["init_world_T_cam"])
        eye, target = np.array(viewer.server.initial_camera.position), np.array(viewer.server.initial_camera.look_at)
        # the viewer opens just behind the first init view, looking the way it looks
        assert np.linalg.norm(eye - first[:3, 3]) < 1.0
        assert np.dot(target - eye, first[:3, 2]) > 0.9 * np.linalg.norm(target - eye)
    finally:
        viewer.stop()


def test_each_camera_and_step_shows_its_own_field_of_view(tmp_path: Path) -> None:
    run = _attack(tmp_path / "wide", "envelope.fov_deg=[40,100]")
    summary = json.loads((run / "summary.json").read_text())
    viewer = view(run, port=_free_port())
    try:
        for init in summary["init_views"]:
            for k, kept in enumerate(init["adversarial"]):
                assert viewer.views[f"init{init['index']}_adv{k}"].fov_x_deg == kept["fov_x_deg"]
        chosen = next(name for name in viewer.frusta if "_adv" in name)
        viewer.select(chosen)
        assert f"field of view {viewer.views[chosen].fov_x_deg:.1f}°" in viewer.metrics.content
        records = viewer.records[viewer.views[chosen].init_index]
        moved = next(i for i, r in enumerate(records) if abs(r.fov_x_deg - 70.0) > 1.0)
        viewer.step.value = moved
        assert f"field of view {records[moved].fov_x_deg:.1f}°" in viewer.step_text.content
    finally:
        viewer.stop()


def test_a_sweep_opens_and_choosing_another_run_shows_its_cameras(sweep: Path) -> None:
    viewer = view(sweep, port=_free_port())
    try:
        assert len(viewer.run_names) == 2
        before = {name: handle.position.copy() for name, handle in viewer.frusta.items()}
        other = next(name for name in viewer.run_names if name != viewer.run_choice.value)
        viewer.run_choice.value = other  # as the panel's run list does
        index = viewer.run_names.index(other)
        assert sorted(viewer.frusta) == sorted(_cameras(viewer.runs[index].path))
        after = {name: handle.position for name, handle in viewer.frusta.items()}
        moved = [name for name in before if name in after and not np.allclose(before[name], after[name])]
        assert moved  # the other model's sampled init views and adversarial views stand elsewhere
    finally:
        viewer.stop()


def _shares(png: bytes) -> tuple[float, int]:
    """The share of a screenshot's most common colour (the page's background) and its number of colours."""
    pixels = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).reshape(-1, 3)
    colours, counts = np.unique(pixels // 8, axis=0, return_counts=True)
    return counts.max() / len(pixels), len(colours)


def _drawn(chromium: str, url: str, folder: Path, patience_s: float = 120.0) -> tuple[float, int]:
    """Opens ``url`` in headless Chromium and screenshots it over the DevTools protocol once a second,
    in real time, until the room is drawn or ``patience_s`` pass; returns the last screenshot's shares.

    The scene reaches the page over viser's websocket in real time; a one-shot ``--screenshot`` is
    taken on Chromium's virtual clock, which on a busy machine can end before the scene arrives."""
    browser = subprocess.Popen(
        [
            chromium,
            "--headless",
            "--no-sandbox",
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",
            f"--user-data-dir={folder / 'chromium'}",
            "--window-size=1000,700",
            "--remote-debugging-port=0",
            url,
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + patience_s
        port_file = folder / "chromium" / "DevToolsActivePort"
        while not port_file.exists() or len(port_file.read_text().split()) < 2:
            assert time.monotonic() < deadline and browser.poll() is None, "headless Chromium did not start"
            time.sleep(0.2)
        port = port_file.read_text().split()[0]
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list") as listing:
            page = next(target for target in json.load(listing) if target["type"] == "page")
        with connect(page["webSocketDebuggerUrl"], max_size=None) as devtools:
            request = 0
            while True:
                request += 1
                devtools.send(json.dumps({"id": request, "method": "Page.captureScreenshot"}))
                reply = json.loads(devtools.recv())
                while reply.get("id") != request:  # events the page sends meanwhile
                    reply = json.loads(devtools.recv())
                background, colours = _shares(base64.b64decode(reply["result"]["data"]))
                if (background < 0.6 and colours > 200) or time.monotonic() > deadline:
                    return background, colours
                time.sleep(1.0)
    finally:
        browser.kill()
        browser.wait()


def test_chromium_draws_the_scene(sweep: Path, tmp_path: Path) -> None:
    chromium = shutil.which("chromium")
    assert chromium, "headless Chromium is missing: apt-get install -y chromium"
    viewer = view(sweep / "tiny", port=_free_port())
    try:
        background, colours = _drawn(chromium, viewer.url, tmp_path)
    finally:
        viewer.stop()
    assert background < 0.6 and colours > 200, (background, colours)  # the room, not an empty page


def _view_command(*args: str) -> tuple[int, str]:
    result = call_main(view_main, ["kadv-view", *args])
    return result.returncode, result.stderr


def test_bad_input_gives_one_line_and_exit_status_2(sweep: Path, tmp_path: Path) -> None:
    code, text = _view_command(str(tmp_path))
    assert code == 2 and text.startswith("kadv-view: error: no complete run") and len(text.splitlines()) == 1
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        code, text = _view_command(str(sweep / "tiny"), "--port", str(port))
    assert code == 2 and f"--port {port}" in text and "in use" in text and len(text.splitlines()) == 1
    moved = tmp_path / "moved_run"
    shutil.copytree(sweep / "tiny", moved)
    config = (moved / "config.yaml").read_text()
    (moved / "config.yaml").write_text(
        config.replace("kind: box_room", "kind: file\n  path: /gone/room.glb\n  options: {}")
    )
    code, text = _view_command(str(moved), "--port", str(_free_port()))
    assert code == 2 and "/gone/room.glb" in text and "--scene" in text and len(text.splitlines()) == 1


def test_the_scene_keeps_its_colours_and_large_scenes_are_decimated() -> None:
    scene = procedural_room(seed=3)
    colours = scene_colours(scene)
    assert colours.shape == (scene.num_triangles, 3) and len(np.unique(colours, axis=0)) > 20  # textures, not one grey
    whole = _display_mesh(scene, scene.num_triangles)
    assert len(whole.faces) == scene.num_triangles
    assert np.array_equal(whole.visual.vertex_colors[::3, :3], colours)  # each triangle its own colour
    budget = scene.num_triangles // 4
    small = _display_mesh(scene, budget)
    assert len(small.faces) <= budget and len(np.unique(small.visual.vertex_colors[:, :3], axis=0)) > 20


def test_listening_on_every_interface_is_warned_of_in_one_line(tmp_path: Path) -> None:
    code, text = _view_command(str(tmp_path), "--host", "0.0.0.0")
    warning, error = text.splitlines()
    assert warning.startswith("kadv-view: warning: --host 0.0.0.0 serves the viewer to every machine")
    assert code == 2 and error.startswith("kadv-view: error: no complete run")
    code, text = _view_command(str(tmp_path))
    assert "warning" not in text, "the default, 127.0.0.1, keeps it to this machine"
