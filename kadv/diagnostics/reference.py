"""Render reliability against an independent path tracer (Mitsuba 3): the study's Table 1, automated.

Each view is rendered by Mitsuba (path tracing, the file's emitters kept) and by kadv's
:class:`ExactRenderer`, then compared: z-depth at pixel centres (Mitsuba's own sensor rays and
``scene.ray_intersect``, so no jitter or filter blurs it and the camera conversion is checked), the
images (PSNR and SSIM after exposure matching) and a model's predictions on the two images (delta1
after alignment).

Mitsuba 3 is an optional extra (``pip install kadv[reference]``). It loads the 0.5/0.6-era gallery
files only through a sanitised copy (:mod:`kadv.scenes.mitsuba_sanitiser`), from which properties
it no longer knows are removed as it names them.
"""

from __future__ import annotations

import logging
import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import torch
from kornia.metrics import psnr, ssim

from kadv.geometry import intrinsics_from_fov
from kadv.losses import aligned_depth, depth_metrics
from kadv.models import DepthModel
from kadv.render import ExactRenderer
from kadv.report.figures import depth_colour_map, depth_range, save_figure
from kadv.scenes.mitsuba_sanitiser import sanitised_scene_root
from kadv.scenes.textures import linear_to_srgb, srgb_to_linear

__all__ = ["ReferenceComparison", "compare_view", "load_mitsuba_scene", "mitsuba_depth", "save_comparison"]

log = logging.getLogger(__name__)


def _mitsuba():
    """Mitsuba with a CPU variant set: ``scalar_rgb`` unless the caller chose another.

    ``llvm_ad_rgb`` is not the default: it needs a recent libLLVM, and with Debian 12's LLVM 14/15
    Dr.Jit's generated code fails to compile (``Cannot select: fmaximum``), killing the process.
    """
    try:
        import mitsuba as mi
    except ImportError as error:
        raise ImportError("the reference renderer needs Mitsuba 3: pip install 'kadv[reference]'") from error
    if mi.variant() is None:
        mi.set_variant("scalar_rgb")
    return mi


_UNREFERENCED = re.compile(r'unreferenced propert(?:y|ies) in (\w+) plugin of type "(\w+)"')
_PROPERTY = re.compile(r'^\s*- \w+ "(\w+)"', re.MULTILINE)


def _snake(name: str) -> str:
    return re.sub(r"(?<=[a-z0-9])([A-Z])", r"_\1", name).lower()


def load_mitsuba_scene(path: str | Path, views: list[tuple[np.ndarray, float]], height: int, width: int, spp: int):
    """Load the sanitised scene in Mitsuba (textures and meshes resolve relative to the file).

    Older files carry properties Mitsuba 3 no longer knows (a rough conductor's ``extEta``); each one
    Mitsuba names as unreferenced is dropped from every plugin of that type, with a log line.
    """
    mi = _mitsuba()
    resolver = mi.file_resolver()
    folder = str(Path(path).resolve().parent)
    if folder not in [str(p) for p in resolver]:
        resolver.prepend(folder)
    root = sanitised_scene_root(Path(path), views, height, width, spp)
    while True:
        try:
            return mi.load_string(ET.tostring(root, encoding="unicode"))
        except RuntimeError as error:
            found = _UNREFERENCED.search(str(error))
            if found is None:
                raise
            tag, kind = found.groups()
            names = set(_PROPERTY.findall(str(error)))
            log.info("%s: dropping %s properties Mitsuba 3 does not know: %s", path, kind, sorted(names))
            for plugin in root.iter(tag):
                if plugin.get("type") == kind:
                    for child in [c for c in plugin if _snake(c.get("name") or "") in names]:
                        plugin.remove(child)


def mitsuba_depth(scene, sensor: int, height: int, width: int) -> np.ndarray:
    """(H, W) z-depth seen by one of the scene's sensors at pixel centres; 0 where the ray misses.

    The rays come from Mitsuba's own sensor (its pose and field of view as the XML gave them), and
    the hits from ``scene.ray_intersect``, so no pixel jitter or reconstruction filter enters and
    the camera conversion is checked, not assumed. z is measured along the sensor's own optical axis.
    """
    mi = _mitsuba()
    camera = scene.sensors()[sensor]
    to_world = camera.world_transform()
    eye = np.array(to_world @ mi.Point3f(0.0, 0.0, 0.0))
    axis = np.array(to_world @ mi.Vector3f(0.0, 0.0, 1.0))
    axis /= np.linalg.norm(axis)
    depth = np.zeros((height, width))
    for row in range(height):
        for column in range(width):
            ray, _ = camera.sample_ray(
                0.0, 0.5, mi.Point2f((column + 0.5) / width, (row + 0.5) / height), mi.Point2f(0.5, 0.5)
            )
            hit = scene.ray_intersect(ray)
            if hit.is_valid():
                depth[row, column] = float(np.dot(np.array(hit.p) - eye, axis))
    return depth


def _exposure(linear: np.ndarray, target_srgb: np.ndarray) -> float:
    """One scale on linear radiance so that the median brightness matches the target's.

    The median, not the mean: a window onto the sky is orders of magnitude brighter than the room and
    would otherwise set the exposure for the whole image.
    """
    brightness = np.median(linear.mean(axis=-1))
    target = srgb_to_linear(np.median(target_srgb.mean(axis=-1)))
    return float(target / max(brightness, 1e-12))


@dataclass
class ReferenceComparison:
    """One view rendered both ways.

    Attributes:
        depth_rel_err: median |z_mitsuba - z_kadv| / z_kadv over pixels valid in both.
        psnr, ssim: of kadv's image against Mitsuba's after exposure matching.
        pred_delta1: delta1 between the model's predictions on the two images, after alignment.
        mitsuba_rgb, kadv_rgb: (H, W, 3) in [0, 1]; mitsuba_pred, kadv_pred: (H, W) aligned depths.
        mask: (H, W) pixels where kadv's ray hit a surface.
    """

    depth_rel_err: float
    psnr: float
    ssim: float
    pred_delta1: float
    mitsuba_rgb: np.ndarray
    kadv_rgb: np.ndarray
    mitsuba_pred: np.ndarray
    kadv_pred: np.ndarray
    mask: np.ndarray


def compare_view(
    mitsuba_scene,
    sensor: int,
    renderer: ExactRenderer,
    model: DepthModel,
    world_T_cam: torch.Tensor,
    fov_x_deg: float,
    height: int,
    width: int,
    spp: int,
    seed: int = 0,
) -> ReferenceComparison:
    """Render one view with Mitsuba (``sensor`` of the loaded scene) and kadv, and compare them."""
    mi = _mitsuba()
    K = intrinsics_from_fov(fov_x_deg, height, width)
    ours = renderer.render(world_T_cam, K, height, width, supersample=2)
    depth_ref = mitsuba_depth(mitsuba_scene, sensor, height, width)
    depth_ours = ours.depth[0, 0].double().numpy()
    both = (depth_ref > 0) & (depth_ours > 0)
    relative = np.abs(depth_ref[both] - depth_ours[both]) / depth_ours[both]
    depth_rel_err = float(np.median(relative)) if both.any() else math.nan
    linear = np.array(mi.render(mitsuba_scene, sensor=sensor, spp=spp, seed=seed))[..., :3]
    kadv_rgb = ours.rgb[0].permute(1, 2, 0).numpy()
    mitsuba_rgb = linear_to_srgb(linear * _exposure(linear, kadv_rgb)).astype(np.float32)
    as_tensor = lambda image: torch.from_numpy(np.ascontiguousarray(image)).permute(2, 0, 1)[None].float()
    image_psnr = float(psnr(as_tensor(kadv_rgb), as_tensor(mitsuba_rgb), 1.0))
    image_ssim = float(ssim(as_tensor(kadv_rgb), as_tensor(mitsuba_rgb), 11).mean())
    with torch.no_grad():
        predictions = model(torch.cat([as_tensor(mitsuba_rgb), as_tensor(kadv_rgb)]))
    mask = ours.mask.expand(2, -1, -1, -1)
    aligned = aligned_depth(predictions.double(), ours.depth.double().expand(2, -1, -1, -1), mask, model.output_kind)
    delta1 = depth_metrics(aligned[:1], aligned[1:], ours.mask, "depth")["delta1"]
    return ReferenceComparison(
        depth_rel_err,
        image_psnr,
        image_ssim,
        float(delta1[0]),
        mitsuba_rgb,
        kadv_rgb,
        aligned[0, 0].float().numpy(),
        aligned[1, 0].float().numpy(),
        ours.mask[0, 0].numpy(),
    )


def save_comparison(path: str | Path, comparison: ReferenceComparison, title: str) -> Path:
    """Mitsuba | kadv | prediction on Mitsuba's image | prediction on kadv's, as one PNG.

    The two predictions are aligned to kadv's ground truth and share one colour map.
    """
    mask = comparison.mask
    low, high = depth_range(np.stack([comparison.mitsuba_pred, comparison.kadv_pred]), np.stack([mask, mask]))
    height, width = comparison.kadv_rgb.shape[:2]
    figure, axes = plt.subplots(1, 4, figsize=(4 * 3.2, 3.2 * height / width + 0.9), layout="constrained")
    panels = [
        (comparison.mitsuba_rgb, "Mitsuba 3 (path traced)"),
        (comparison.kadv_rgb, "kadv (exact renderer)"),
        (comparison.mitsuba_pred, "prediction on Mitsuba"),
        (comparison.kadv_pred, "prediction on kadv"),
    ]
    for axis, (image, name) in zip(axes, panels):
        if image.ndim == 3:
            axis.imshow(image)
        else:
            shown = axis.imshow(
                np.ma.masked_where(~mask, image), cmap=depth_colour_map(), vmin=low, vmax=high, interpolation="nearest"
            )
        axis.set_title(name, fontsize=9)
        axis.set_axis_off()
    figure.colorbar(shown, ax=axes[2:].tolist(), fraction=0.03, pad=0.02, label="aligned depth [m]")
    figure.suptitle(title, fontsize=9)
    return save_figure(Path(path), figure)
