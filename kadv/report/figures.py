"""Figures of an attack run: four-panel views, L_depth curves, the scene map, the trajectory video."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import imageio.v2 as imageio
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import PolyCollection
from PIL import Image, ImageDraw, ImageFont

from kadv.attack.records import InitViewResult, incumbent_path
from kadv.io import atomic_write, save_figure
from kadv.report.images import depth_colour_map, depth_range
from kadv.scenes import Scene

__all__ = [
    "PlanRaster",
    "colourise",
    "loss_label",
    "save_curves",
    "save_figure",
    "save_four_panel",
    "save_map",
    "save_video",
    "video_frame",
]


def colourise(values: np.ndarray, mask: np.ndarray, low: float, high: float) -> np.ndarray:
    """(H, W) values -> (H, W, 3) uint8 with the turbo colour map; grey where ``mask`` is False."""
    scaled = np.clip((values - low) / max(high - low, 1e-12), 0.0, 1.0)
    rgb = depth_colour_map()(scaled)[..., :3]
    rgb[~mask] = 0.5
    return (rgb * 255 + 0.5).astype(np.uint8)


# the four-panel figure's layout, in inches: fixed, so that no layout engine runs per picture (the
# constrained layout and a tight bounding box took 0.15 s of its 0.38 s)
_PANEL_WIDTH = 3.0
_PANEL_GAP = 0.08
_BAR_PAD, _BAR_WIDTH, _BAR_LABELS = 0.08, 0.12, 0.75  # a colour bar, and room for its ticks and label
_TITLE_BAND, _BOTTOM = 0.6, 0.1


def save_four_panel(
    path: str | Path,
    rgb: np.ndarray,
    depth: np.ndarray,
    prediction: np.ndarray,
    mask: np.ndarray,
    title: str,
    alignment: str = "scale_shift",
) -> Path:
    """Image | ground-truth depth | aligned prediction | relative error, as one PNG.

    Args:
        rgb: (H, W, 3) in [0, 1]; depth, prediction: (H, W) metres (the prediction aligned to the
            ground truth by ``alignment``, which its panel names: ``none`` or, e.g.,
            ``scale_shift in disparity``), sharing one colour map; mask: (H, W) valid ground truth.
        title: the figure's title (the view's metrics).
    """
    low, high = depth_range(depth, mask)
    error = np.where(mask, np.abs(prediction - depth) / np.maximum(depth, 1e-6), np.nan)
    panel_height = _PANEL_WIDTH * rgb.shape[0] / rgb.shape[1]
    bar = _BAR_PAD + _BAR_WIDTH + _BAR_LABELS
    width = 4 * _PANEL_WIDTH + 2 * _PANEL_GAP + 2 * bar
    height = panel_height + _TITLE_BAND + _BOTTOM
    figure = plt.figure(figsize=(width, height))

    def axes_at(left: float, axes_width: float) -> plt.Axes:
        return figure.add_axes((left / width, _BOTTOM / height, axes_width / width, panel_height / height))

    # three panels, the depth colour bar, the error panel and its colour bar, left to right
    lefts = [i * (_PANEL_WIDTH + _PANEL_GAP) for i in range(3)]
    depth_bar = lefts[2] + _PANEL_WIDTH + _BAR_PAD
    lefts.append(depth_bar + _BAR_WIDTH + _BAR_LABELS)
    axes = [axes_at(left, _PANEL_WIDTH) for left in lefts]
    axes[0].imshow(np.clip(rgb, 0, 1))
    axes[0].set_title("rendered image")
    shown = [np.ma.masked_where(~mask, depth), np.ma.masked_where(~mask, prediction)]
    aligned = "prediction (as predicted)" if alignment == "none" else f"prediction (aligned: {alignment})"
    for axis, values, name in zip(axes[1:3], shown, ("ground-truth depth", aligned)):
        image = axis.imshow(values, cmap=depth_colour_map(), vmin=low, vmax=high, interpolation="nearest")
        axis.set_title(name)
    figure.colorbar(image, cax=axes_at(depth_bar, _BAR_WIDTH), label="depth [m], grey: no surface")
    errors = axes[3].imshow(np.ma.masked_invalid(error), cmap="magma", vmin=0.0, vmax=0.5, interpolation="nearest")
    axes[3].set_title("|pred - gt| / gt")
    figure.colorbar(errors, cax=axes_at(lefts[3] + _PANEL_WIDTH + _BAR_PAD, _BAR_WIDTH), extend="max")
    for axis in axes:
        axis.set_axis_off()
    figure.suptitle(title, fontsize=10, y=1 - 0.12 / height, va="top")
    return save_figure(Path(path), figure, tight=False)


# the video's plan shows at least this many metres on each side of the search's centre
_PLAN_MARGIN = 3.0

_LOSS_LABELS = {
    "ssim": "L_depth (SSIM)",
    "perceptual": "L_depth (perceptual)",
    "absrel": "AbsRel (aligned)",
    "delta1": "smooth delta1 error share",
}


def _grid(count: int) -> tuple[int, int]:
    columns = min(count, 3)
    return math.ceil(count / columns), columns


def loss_label(kind: str) -> str:
    """How figures name the loss a run attacked (its ``loss.kind``)."""
    return _LOSS_LABELS.get(kind, kind)


def _pass_index(records: list) -> dict[int, int]:
    """Each record's own forward pass in its search's count of model passes (a batch's views, which
    share the count at the batch's end, in their order; backward passes leave gaps)."""
    index: dict[int, int] = {}
    for _, batch in itertools.groupby(records, key=lambda r: r.passes):
        batch = list(batch)
        for k, record in enumerate(batch):
            index[id(record)] = record.passes - len(batch) + k + 1
    return index


def save_curves(path: str | Path, results: list[InitViewResult], label: str = "L_depth") -> Path:
    """The attacked loss (named ``label``) of every evaluated view (screened ones in grey) against
    the model passes spent, the best valid one so far and the search's path, per init view, with
    the init view's value and the adversarial views marked."""
    rows, columns = _grid(len(results))
    figure, axes = plt.subplots(rows, columns, figsize=(4.6 * columns, 3.2 * rows), squeeze=False)
    for axis, result in zip(axes.flat, results):
        order = _pass_index(result.records)
        valid = [r for r in result.records if r.valid and not r.screened]
        axis.scatter([order[id(r)] for r in valid], [r.loss for r in valid], s=6, alpha=0.4, label="evaluated views")
        screened = [r for r in result.records if r.valid and r.screened]
        if screened:
            x, y = [order[id(r)] for r in screened], [r.loss for r in screened]
            axis.scatter(x, y, s=3, alpha=0.3, color="grey", label="screened (fewer rays, or the warp)")
        invalid = [r for r in result.records if not r.valid]
        if invalid:
            axis.scatter(
                [order[id(r)] for r in invalid],
                [r.loss for r in invalid],
                marker="x",
                s=10,
                color="grey",
                label="invalid or uninformative",
            )
        curve = incumbent_path(result.records)
        axis.step(
            [order[id(r)] for r in curve] + [max(order.values())],
            [r.loss for r in curve] + [curve[-1].loss],
            where="post",
            color="k",
            lw=1.5,
            label="best so far",
        )
        axis.plot(
            [order[id(r)] for r in result.path],
            [r.loss for r in result.path],
            color="tab:orange",
            lw=1.0,
            label="path",
        )
        axis.axhline(result.init_record.loss, color="k", ls="--", lw=1, label="init view")
        axis.scatter(
            [order[id(r)] for r in result.top],
            [r.loss for r in result.top],
            marker="*",
            s=120,
            color="red",
            zorder=5,
            label="adversarial views",
        )
        axis.set_title(f"{result.init.name}")
        axis.set_xlabel("model passes")
        axis.set_ylabel(label)
    for axis in list(axes.flat)[len(results) :]:
        axis.set_axis_off()
    # one legend under the panels: inside them it hid the best views, which sit top right
    legend = {label: handle for axis in axes.flat for handle, label in zip(*axis.get_legend_handles_labels())}
    figure.legend(legend.values(), legend.keys(), loc="lower center", ncol=len(legend), fontsize=8, frameon=False)
    figure.tight_layout(rect=(0, 0.07 / rows, 1, 1))
    return save_figure(Path(path), figure)


def _plan_polygons(scene: Scene, cut_height: float) -> np.ndarray:
    """Triangles (N, 3, 2) in the floor plane (x, z) between just above the floor and ``cut_height``,
    as an architectural plan cuts a building (the floor and ceiling would cover everything)."""
    corners = scene.vertices[scene.faces]
    heights = corners[:, :, 1].mean(axis=1)
    floor = scene.bounds[0, 1]
    keep = (heights > floor + 0.05) & (heights < cut_height)
    return corners[keep][:, :, [0, 2]]


def _arrow(axis: plt.Axes, pose: np.ndarray, length: float, **style) -> None:
    forward = pose[:3, 2]
    axis.annotate(
        "",
        xy=(pose[0, 3] + length * forward[0], pose[2, 3] + length * forward[2]),
        xytext=(pose[0, 3], pose[2, 3]),
        arrowprops={"arrowstyle": "->", **style},
    )


def save_map(path: str | Path, scene: Scene, results: list[InitViewResult], label: str = "L_depth") -> Path:
    """Top-down plan with every evaluated camera centre coloured by the attacked loss (named
    ``label``), the search's path (grey), the init view (black) and the adversarial views (red) with
    their view directions, one panel per init view."""
    poses = np.array([r.init.world_T_cam.numpy() for r in results])
    cut = float(poses[:, 1, 3].max()) + 0.3
    polygons = _plan_polygons(scene, cut)
    lo, hi = scene.bounds
    size = float(max(hi[0] - lo[0], hi[2] - lo[2]))
    values = [r.loss for result in results for r in result.records]
    norm = plt.Normalize(min(values), max(values))
    rows, columns = _grid(len(results))
    figure, axes = plt.subplots(rows, columns, figsize=(4.6 * columns, 4.2 * rows), squeeze=False)
    for axis, result in zip(axes.flat, results):
        axis.add_collection(PolyCollection(polygons, facecolors="0.6", edgecolors="0.45", linewidths=0.3))
        xz = np.array([[r.centre[0], r.centre[2]] for r in result.records])
        points = axis.scatter(xz[:, 0], xz[:, 1], c=[r.loss for r in result.records], cmap="viridis", norm=norm, s=8)
        trail = np.array([[r.centre[0], r.centre[2]] for r in result.path])
        axis.plot(trail[:, 0], trail[:, 1], color="0.3", lw=0.8)
        init = result.init.world_T_cam.numpy()
        axis.plot(init[0, 3], init[2, 3], "k*", ms=12, label="init view")
        _arrow(axis, init, 0.1 * size, color="k", lw=1.5)
        for rank, record in enumerate(result.top):
            pose = record.world_T_cam(result.init.world_T_cam).numpy()
            axis.plot(pose[0, 3], pose[2, 3], "r^", ms=7, label="adversarial views" if rank == 0 else None)
            _arrow(axis, pose, 0.08 * size, color="red", lw=1.2)
        axis.set_xlim(lo[0] - 0.05 * size, hi[0] + 0.05 * size)
        axis.set_ylim(hi[2] + 0.05 * size, lo[2] - 0.05 * size)
        axis.set_aspect("equal")
        axis.set_xlabel("x [m]")
        axis.set_ylabel("z [m]")
        axis.set_title(result.init.name)
        axis.legend(fontsize=7, loc="upper right")
        figure.colorbar(points, ax=axis, fraction=0.046, pad=0.02, label=label)
    for axis in list(axes.flat)[len(results) :]:
        axis.set_axis_off()
    figure.tight_layout()
    return save_figure(Path(path), figure)


def save_video(path: str | Path, frames: list[np.ndarray], fps: int = 8) -> Path:
    """Write uint8 frames (H, W, 3) as an H.264 MP4 in yuv420p, which browsers play (imageio-ffmpeg
    ships the encoder)."""
    height, width = frames[0].shape[:2]
    pad = ((0, height % 2), (0, width % 2), (0, 0))  # yuv420p halves the chroma: even sizes
    even = [np.pad(frame, pad) for frame in frames]

    def write(tmp: Path) -> None:
        imageio.mimwrite(
            tmp, even, fps=fps, format="FFMPEG", codec="libx264", pixelformat="yuv420p", macro_block_size=2
        )

    return atomic_write(path, write)


class PlanRaster:
    """A top-down plan of the scene around some points as a square image, with the world-to-pixel
    map to draw on it.

    Args:
        scene: the scene.
        cut_height: the plan's cut (see :func:`_plan_polygons`).
        size: the image's side in pixels.
        around: (N, 3) points the plan frames (a search's camera centres), with a margin of at
            least :data:`_PLAN_MARGIN` metres: a scene's bounds may hold a 200 m garden.
    """

    def __init__(self, scene: Scene, cut_height: float, size: int, around: np.ndarray) -> None:
        lo, hi = around[:, [0, 2]].min(axis=0), around[:, [0, 2]].max(axis=0)
        centre = (lo + hi) / 2
        self.half = max(0.55 * float(max(hi - lo)), _PLAN_MARGIN)
        self.origin, self.size = centre - self.half, size
        figure = plt.figure(figsize=(size / 100, size / 100), dpi=100)
        axis = figure.add_axes((0, 0, 1, 1))
        axis.add_collection(PolyCollection(_plan_polygons(scene, cut_height), facecolors="0.6", edgecolors="0.45"))
        axis.set_xlim(self.origin[0], self.origin[0] + 2 * self.half)
        axis.set_ylim(self.origin[1] + 2 * self.half, self.origin[1])  # z grows downwards, as in map.png
        axis.set_axis_off()
        figure.canvas.draw()
        self.image = np.asarray(figure.canvas.buffer_rgba())[..., :3].copy()
        plt.close(figure)

    def pixel(self, x: float, z: float) -> tuple[float, float]:
        """Where the world point (x, z) falls on the image (column, row)."""
        scale = self.size / (2 * self.half)
        return (x - self.origin[0]) * scale, (z - self.origin[1]) * scale

    def with_camera(self, trail: np.ndarray, world_T_cam: np.ndarray) -> np.ndarray:
        """The plan with the search's trail of centres (N, 3) and the camera at ``world_T_cam``."""
        image = Image.fromarray(self.image)
        draw = ImageDraw.Draw(image)
        if len(trail) > 1:
            draw.line([self.pixel(c[0], c[2]) for c in trail], fill=(60, 60, 60), width=2)
        x, z = self.pixel(world_T_cam[0, 3], world_T_cam[2, 3])
        forward = world_T_cam[:3, 2]
        length = 0.08 * self.size / max(float(np.hypot(forward[0], forward[2])), 1e-6)
        draw.line([(x, z), (x + length * forward[0], z + length * forward[2])], fill=(220, 20, 20), width=3)
        draw.ellipse((x - 5, z - 5, x + 5, z + 5), fill=(220, 20, 20))
        return np.asarray(image)


def video_frame(panels: list[np.ndarray], plan: np.ndarray, text: str, height: int = 240) -> np.ndarray:
    """Panels (each (h, w, 3) uint8) scaled to ``height`` side by side, then the plan, under a band
    of ``text``."""
    scaled = [
        np.asarray(Image.fromarray(p).resize((round(p.shape[1] * height / p.shape[0]), height), Image.NEAREST))
        for p in panels
    ]
    plan = np.asarray(Image.fromarray(plan).resize((height, height), Image.BILINEAR))
    row = np.concatenate([*scaled, plan], axis=1)
    band = Image.new("RGB", (row.shape[1], 28), (0, 0, 0))
    ImageDraw.Draw(band).text((6, 4), text, fill=(255, 255, 255), font=ImageFont.load_default(size=18))
    return np.concatenate([np.asarray(band), row], axis=0)
