"""A run or a sweep in a local 3-D viewer (viser): the scene, every evaluated camera centre, the init
and adversarial cameras as frusta showing their images, and the searches' paths.

``kadv-view`` serves it; :func:`view` does the same from Python.
"""

from __future__ import annotations

import contextlib
import io
import socket
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import imageio.v3 as iio
import matplotlib
import numpy as np
import open3d as o3d
import torch
import trimesh

from kadv.attack.records import ViewRecord, incumbent_path
from kadv.catalogue import scene_from_node
from kadv.render.textures import MaterialTextures
from kadv.report.outputs import TRAJECTORY, read_trajectory
from kadv.report.sweep import RunRecord, collect_runs
from kadv.scenes import Scene

__all__ = ["MAX_TRIANGLES", "CameraView", "RunViewer", "scene_colours", "view"]

# Scenes above this many triangles are decimated (quadric, Open3D) before they are sent to the
# browser: a client draws a few hundred thousand smoothly, millions stutter.
MAX_TRIANGLES = 200_000
# the opening camera stands at most this far behind and above the first init view (metres)
_OPENING_BACK, _OPENING_UP = 0.5, 0.2
# frusta sizes in metres (scenes are in metres; a scene's bounds may hold a 200 m garden, so they do
# not follow the bounds)
_INIT_FRUSTUM, _ADVERSARIAL_FRUSTUM, _STEP_FRUSTUM, _FRUSTUM_LINE = 0.3, 0.24, 0.15, 0.006
_STEP_COLOUR = (255, 200, 0)


@dataclass
class CameraView:
    """One camera the viewer shows: an init view or a kept adversarial view.

    Attributes:
        name: "init0", "init0_adv1", ...
        init_index: its init view.
        world_T_cam: (4, 4) OpenCV-convention pose.
        fov_x_deg: horizontal field of view.
        delta1, l_depth: the model's accuracy there and the study's loss.
        panel: the four-panel PNG (image, depth, prediction, error).
        image: the rendered image (H, W, 3) uint8 the frustum shows.
    """

    name: str
    init_index: int
    world_T_cam: np.ndarray
    fov_x_deg: float
    delta1: float
    l_depth: float
    panel: Path
    image: np.ndarray


def camera_views(run: RunRecord) -> list[CameraView]:
    """The init and adversarial views of a run, in the summary's order; each one's pose and image
    are those its ``views/*.npz`` holds."""
    views = []
    for init in run.summary.init_views:
        kept = [(f"init{init.index}", init.init)] + [
            (f"init{init.index}_adv{k}", a) for k, a in enumerate(init.adversarial)
        ]
        for name, metrics in kept:
            arrays = np.load(run.path / Path(metrics.png).with_suffix(".npz"))
            image = (np.clip(arrays["rgb"], 0.0, 1.0) * 255 + 0.5).astype(np.uint8)
            views.append(
                CameraView(
                    name,
                    init.index,
                    arrays["world_T_cam"],
                    metrics.fov_x_deg if metrics.fov_x_deg is not None else init.fov_x_deg,
                    metrics.delta1,
                    metrics.l_depth,
                    run.path / metrics.png,
                    image,
                )
            )
    return views


def scene_colours(scene: Scene) -> np.ndarray:
    """(F, 3) uint8 display colour of each triangle: its material's colour times its texture,
    filtered to the triangle's size and read at its centroid."""
    ids = torch.arange(scene.num_triangles)
    uv = torch.from_numpy(scene.uvs.mean(axis=1).astype(np.float32))
    corners = scene.vertices[scene.faces]
    size = np.linalg.norm(corners - corners.mean(axis=1, keepdims=True), axis=2).max(axis=1)
    colour = MaterialTextures(scene).albedo(ids, uv, torch.from_numpy(size.astype(np.float32)))
    return (colour.clamp(0.0, 1.0).numpy() * 255 + 0.5).astype(np.uint8)


def _display_mesh(scene: Scene, max_triangles: int) -> trimesh.Trimesh:
    """The scene with its colours: per triangle below ``max_triangles``, else per vertex of a
    quadric decimation to that many."""
    colours = scene_colours(scene)
    if scene.num_triangles <= max_triangles:
        vertices = scene.vertices[scene.faces].reshape(-1, 3)
        faces = np.arange(len(vertices)).reshape(-1, 3)
        return trimesh.Trimesh(vertices, faces, vertex_colors=np.repeat(colours, 3, axis=0), process=False)
    sums = np.zeros((len(scene.vertices), 3))
    counts = np.zeros(len(scene.vertices))
    np.add.at(sums, scene.faces.reshape(-1), np.repeat(colours, 3, axis=0).astype(np.float64))
    np.add.at(counts, scene.faces.reshape(-1), 1.0)
    mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(scene.vertices), o3d.utility.Vector3iVector(scene.faces)
    )
    mesh.vertex_colors = o3d.utility.Vector3dVector(sums / np.maximum(counts, 1.0)[:, None] / 255.0)
    mesh = mesh.simplify_quadric_decimation(max_triangles)
    return trimesh.Trimesh(
        np.asarray(mesh.vertices),
        np.asarray(mesh.triangles),
        vertex_colors=(np.asarray(mesh.vertex_colors) * 255 + 0.5).astype(np.uint8),
        process=False,
    )


def _opening_camera(scene: Scene, world_T_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eye and target of the viewer's first camera: the init view's pose, moved back and up by up to
    :data:`_OPENING_BACK` and :data:`_OPENING_UP` metres (half way to a surface behind or above, so
    it stays in the room), looking where the view looks; its own frustum then sits in front of it."""
    caster = o3d.t.geometry.RaycastingScene()
    caster.add_triangles(
        o3d.core.Tensor(scene.vertices.astype(np.float32)), o3d.core.Tensor(scene.faces.astype(np.uint32))
    )
    centre, forward, up = world_T_cam[:3, 3], world_T_cam[:3, 2], np.array([0.0, 1.0, 0.0])
    rays = np.array([[*centre, *(-forward)], [*centre, *up]], np.float32)
    free = caster.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()
    eye = centre - min(_OPENING_BACK, 0.5 * free[0]) * forward + min(_OPENING_UP, 0.5 * free[1]) * up
    return eye, centre + 2.0 * forward


def _rgb(values: np.ndarray, cmap: str, low: float, high: float) -> np.ndarray:
    scaled = (np.asarray(values, np.float64) - low) / max(high - low, 1e-12)
    return (matplotlib.colormaps[cmap](np.clip(scaled, 0.0, 1.0))[..., :3] * 255).astype(np.uint8)


def _wxyz(rotation: np.ndarray) -> np.ndarray:
    import viser.transforms as tf

    return tf.SO3.from_matrix(rotation).wxyz


class RunViewer:
    """The viewer of one or more runs: a viser server, its scene and controls.

    Args:
        runs: the runs (a sweep's, or one).
        scene_of: builds a run's scene (default: from its saved config; see :func:`view`).
        host, port: where the server listens.
        max_triangles: see :data:`MAX_TRIANGLES`.
    """

    def __init__(
        self,
        runs: list[RunRecord],
        scene_of: Callable[[RunRecord], Scene],
        host: str = "127.0.0.1",
        port: int = 8080,
        max_triangles: int = MAX_TRIANGLES,
    ) -> None:
        import viser

        self.runs, self.scene_of, self.max_triangles = runs, scene_of, max_triangles
        with contextlib.redirect_stdout(io.StringIO()):  # viser prints its own banner; kadv-view prints the URL
            self.server = viser.ViserServer(host=host, port=port, verbose=False)
        self.server.scene.set_up_direction("+y")
        self.run_names = [f"{r.model} x {r.scene} x {r.method} ({r.path.name})" for r in runs]
        self.views: dict[str, CameraView] = {}
        self.frusta: dict[str, object] = {}
        self.records: dict[int, list[ViewRecord]] = {}  # the run's evaluated views per init view
        self._steps: list[ViewRecord] = []  # the selected view's search
        gui = self.server.gui
        self.run_choice = gui.add_dropdown("run", self.run_names, initial_value=self.run_names[0])
        self.view_choice = gui.add_dropdown("view", ["-"], initial_value="-")
        self.fly = gui.add_button("fly to this view")
        self.metrics = gui.add_markdown("")
        self.panel = gui.add_image(np.zeros((8, 32, 3), np.uint8), label="image | depth | prediction | error")
        self.step = gui.add_slider("search step", 0, 1, 1, 0)
        self.step_text = gui.add_markdown("")
        self.run_choice.on_update(lambda _: self._build_run(self.run_names.index(self.run_choice.value)))
        self.view_choice.on_update(lambda _: self._show_view(self.view_choice.value))
        self.fly.on_click(lambda event: self.fly_to(self.view_choice.value, event.client))
        self.step.on_update(lambda _: self.show_step(int(self.step.value)))
        self._build_run(0)

    @property
    def url(self) -> str:
        return f"http://{self.server.get_host()}:{self.server.get_port()}"

    def show_run(self, index: int) -> None:
        """Show run ``index`` as choosing it in the panel does: its scene, evaluated centres, paths
        and cameras."""
        if self.run_choice.value != self.run_names[index]:
            self.run_choice.value = self.run_names[index]  # its callback builds the run
        else:
            self._build_run(index)

    def _build_run(self, index: int) -> None:
        run = self.runs[index]
        scene_api = self.server.scene
        scene_api.reset()
        scene = self.scene_of(run)
        scene_api.add_mesh_trimesh("/scene", _display_mesh(scene, self.max_triangles))
        self.records = read_trajectory(run.path / TRAJECTORY)
        evaluated = [r for records in self.records.values() for r in records]
        l_depth = np.array([r.l_depth for r in evaluated])
        scene_api.add_point_cloud(
            "/evaluated",
            np.array([r.centre for r in evaluated]),
            _rgb(l_depth, "viridis", l_depth.min(), l_depth.max()),
            point_size=0.01,
            point_shape="circle",
        )
        self.views = {v.name: v for v in camera_views(run)}
        self.frusta = {}
        for camera in self.views.values():
            frustum = self._add_frustum(
                f"/cameras/{camera.name}",
                camera,
                camera.world_T_cam,
                _ADVERSARIAL_FRUSTUM if "_adv" in camera.name else _INIT_FRUSTUM,
                tuple(int(c) for c in _rgb([camera.delta1], "RdYlGn", 0.0, 1.0)[0]),
                camera.image,
            )
            frustum.on_click(lambda _, name=camera.name: self.select(name))
            self.frusta[camera.name] = frustum
        for index, records in self.records.items():
            path = np.array([r.centre for r in incumbent_path(records)])
            if len(path) > 1:
                segments = np.stack([path[:-1], path[1:]], axis=1)
                scene_api.add_line_segments(f"/paths/init{index}", segments, (40, 40, 40), thickness=0.01)
        eye, target = _opening_camera(scene, np.array(run.summary.init_views[0].init_world_T_cam))
        self.server.initial_camera.position = tuple(eye)
        self.server.initial_camera.look_at = tuple(target)
        self.server.initial_camera.up = (0.0, 1.0, 0.0)
        self.view_choice.options = list(self.views)
        self.select(next(iter(self.views)))

    def select(self, name: str) -> CameraView:
        """Select view ``name`` as the panel's list (or a click on its frustum) does: show its
        four-panel image and metrics, and set the slider to the start of its search."""
        if self.view_choice.value != name:
            self.view_choice.value = name  # its callback shows the view
        else:
            self._show_view(name)
        return self.views[name]

    def _show_view(self, name: str) -> None:
        if name not in self.views:  # the list's options are being replaced
            return
        camera = self.views[name]
        self.panel.image = iio.imread(camera.panel)[..., :3]
        self.metrics.content = (
            f"**{name}**: delta1 {camera.delta1:.3f}, L_depth {camera.l_depth:.4f}, "
            f"field of view {camera.fov_x_deg:.1f}°, centre {np.round(camera.world_T_cam[:3, 3], 3).tolist()}"
        )
        self._steps = self.records[camera.init_index]
        self.step.max = max(len(self._steps) - 1, 1)
        self.step.value = 0
        self.show_step(0)

    def show_step(self, index: int) -> None:
        """Mark the ``index``-th evaluated view of the selected view's search."""
        if not self._steps:
            return
        record = self._steps[min(index, len(self._steps) - 1)]
        camera = self.views[self.view_choice.value]
        init = self.views[f"init{camera.init_index}"]
        pose = record.world_T_cam(torch.from_numpy(init.world_T_cam)).numpy()
        fov = record.fov(init.fov_x_deg)
        self._add_frustum("/step", camera, pose, _STEP_FRUSTUM, fov_x_deg=fov)
        self.step_text.content = (
            f"step {record.step}, lane {record.restart}: L_depth {record.l_depth:.4f}, "
            f"delta1 {record.delta1:.3f}, field of view {fov:.1f}°, {record.verdict}"
        )

    def _add_frustum(
        self,
        name: str,
        camera: CameraView,
        world_T_cam: np.ndarray,
        scale: float,
        colour: tuple[int, int, int] = _STEP_COLOUR,
        image: np.ndarray | None = None,
        fov_x_deg: float | None = None,
    ):
        """A frustum of ``camera``'s aspect at ``world_T_cam`` (4, 4), of its field of view or
        ``fov_x_deg``."""
        height, width = camera.image.shape[:2]
        fov_x_deg = camera.fov_x_deg if fov_x_deg is None else fov_x_deg
        return self.server.scene.add_camera_frustum(
            name,
            fov=float(2 * np.arctan(np.tan(np.radians(fov_x_deg) / 2) * height / width)),
            aspect=width / height,
            scale=scale,
            thickness=_FRUSTUM_LINE,
            color=colour,
            image=image,
            wxyz=_wxyz(world_T_cam[:3, :3]),
            position=world_T_cam[:3, 3],
        )

    def fly_to(self, name: str, client=None) -> None:
        """Move the viewer's camera (one client's, or every client's) to view ``name``'s pose."""
        camera = self.views[name]
        for target in [client] if client is not None else list(self.server.get_clients().values()):
            target.camera.wxyz = _wxyz(camera.world_T_cam[:3, :3])
            target.camera.position = camera.world_T_cam[:3, 3]

    def stop(self) -> None:
        self.server.stop()


def check_port_free(host: str, port: int) -> None:
    """Raise ``ValueError`` naming the port when something already listens on it."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        try:
            probe.bind((host, port))
        except OSError as error:
            raise ValueError(f"--port {port}: {host}:{port} is in use ({error.strerror}); choose another") from error


def view(
    path: str | Path,
    host: str = "127.0.0.1",
    port: int = 8080,
    scene: str | Path | None = None,
    max_triangles: int = MAX_TRIANGLES,
) -> RunViewer:
    """Serve a run or sweep directory in a local viewer; returns it running (``.server``, ``.url``).

    Args:
        path: a run directory (holding ``summary.json``) or a sweep directory of runs.
        host: the address to listen on; the default keeps it on this machine.
        port: the port.
        scene: for runs on a scene file that has moved since, the file to read instead.
        max_triangles: scenes above this are decimated (:data:`MAX_TRIANGLES`).

    Raises:
        FileNotFoundError, ValueError: not a run or sweep, a port in use, a scene file that is gone.
    """
    runs = collect_runs([path])
    check_port_free(host, port)
    scenes: dict[str, Scene] = {}

    def scene_of(run: RunRecord) -> Scene:
        node = run.config.get("scene") or {}
        if not node:
            raise ValueError(f"{run.path}: its config.yaml names no scene")
        key = repr(sorted(node.items()))
        if key not in scenes:
            if node.get("kind") == "file" and scene is None and not Path(str(node.get("path"))).expanduser().is_file():
                raise FileNotFoundError(
                    f"{run.path}: its scene file {node.get('path')} is gone; point --scene to where it is now"
                )
            scenes[key] = scene_from_node(node, path=scene if node.get("kind") == "file" else None)
        return scenes[key]

    for run in runs:  # every run's scene, before the server starts: a moved file is named now
        scene_of(run)
    return RunViewer(runs, scene_of, host, port, max_triangles)
