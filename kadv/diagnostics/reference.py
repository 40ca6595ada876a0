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

from kadv.geometry import axis_angle_to_matrix, intrinsics_from_fov
from kadv.losses import aligned_depth, depth_metrics
from kadv.models import DepthModel
from kadv.render import ExactRenderer, RenderOutput
from kadv.render.colour import exposed, tone_map
from kadv.report.figures import depth_colour_map, depth_range, save_figure
from kadv.report.sweep import Table
from kadv.scenes.mitsuba_sanitiser import MAX_DEPTH, sanitised_scene_root
from kadv.scenes.textures import srgb_to_linear

__all__ = [
    "PIXEL_CLASSES",
    "ReferenceComparison",
    "Survival",
    "compare_view",
    "display_image",
    "load_mitsuba_scene",
    "matched_exposure",
    "mitsuba_depth",
    "mitsuba_hits",
    "noise_floor",
    "render_reference",
    "render_reference_and_albedo",
    "save_comparison",
    "survival",
    "survival_table",
]

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


def load_mitsuba_scene(
    path: str | Path,
    views: list[tuple[np.ndarray, float]],
    height: int,
    width: int,
    spp: int,
    max_depth: int = MAX_DEPTH,
    suns_only: bool = False,
):
    """Load the sanitised scene in Mitsuba (textures and meshes resolve relative to the file), its
    path tracer also writing the albedo and normals that :func:`render_reference`'s denoiser reads.

    Older files carry properties Mitsuba 3 no longer knows (a rough conductor's ``extEta``); each one
    Mitsuba names as unreferenced is dropped from every plugin of that type, with a log line.

    Args:
        max_depth: the path tracer's longest path (2: direct light only).
        suns_only: keep the directional emitters (suns) only.
    """
    mi = _mitsuba()
    resolver = mi.file_resolver()
    folder = str(Path(path).resolve().parent)
    if folder not in [str(p) for p in resolver]:
        resolver.prepend(folder)
    root = sanitised_scene_root(Path(path), views, height, width, spp, max_depth, aovs=True)
    if suns_only:
        for parent in list(root.iter()):
            for emitter in parent.findall("emitter"):
                if emitter.get("type") != "directional":
                    parent.remove(emitter)
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


# what a camera ray meets first, as the error budget splits pixels (kadv.diagnostics.budget)
PIXEL_CLASSES = ("diffuse", "coated or glossy", "glass", "emitter", "sky")


def _bsdf_class(description: str) -> int:
    """Index into :data:`PIXEL_CLASSES` of a Mitsuba BSDF from its description (the first named
    material under wrappers such as ``TwoSided`` and ``Mask``)."""
    for name in re.findall(r"(\w+)\[", description):
        if name.endswith("Diffuse"):
            return 0
        if "Dielectric" in name:
            return 2
        if name.endswith(("Plastic", "Conductor")) or name.startswith("Principled"):
            return 1
    return 1


def mitsuba_hits(scene, sensor: int, height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """What one of the scene's sensors sees at pixel centres: z-depth (H, W), 0 where the ray
    misses, and the class (H, W) int of what it meets, an index into :data:`PIXEL_CLASSES`.

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
    classes = np.full((height, width), PIXEL_CLASSES.index("sky"))
    for row in range(height):
        for column in range(width):
            ray, _ = camera.sample_ray(
                0.0, 0.5, mi.Point2f((column + 0.5) / width, (row + 0.5) / height), mi.Point2f(0.5, 0.5)
            )
            hit = scene.ray_intersect(ray)
            if hit.is_valid():
                depth[row, column] = float(np.dot(np.array(hit.p) - eye, axis))
                shape = hit.shape
                emitter = shape.is_emitter()
                classes[row, column] = PIXEL_CLASSES.index("emitter") if emitter else _bsdf_class(str(shape.bsdf()))
    return depth, classes


def mitsuba_depth(scene, sensor: int, height: int, width: int) -> np.ndarray:
    """(H, W) z-depth seen by one of the scene's sensors at pixel centres; 0 where the ray misses
    (:func:`mitsuba_hits`)."""
    return mitsuba_hits(scene, sensor, height, width)[0]


def matched_exposure(linear: np.ndarray, target_srgb: np.ndarray) -> float:
    """One scale on linear radiance so that, tone-mapped as kadv tone-maps its baked renders
    (:func:`kadv.render.colour.tone_map`), its median brightness matches the target's.

    The median, not the mean: a window onto the sky is orders of magnitude brighter than the room and
    would otherwise set the exposure for the whole image.
    """
    brightness = np.median(linear.mean(axis=-1))
    target = exposed(float(srgb_to_linear(np.median(target_srgb.mean(axis=-1)))))
    return float(target / max(brightness, 1e-12))


def display_image(linear: np.ndarray) -> np.ndarray:
    """Display values (H, W, 3) in [0, 1] of exposed linear radiance, as kadv shows its own."""
    return tone_map(torch.from_numpy(np.ascontiguousarray(linear))).numpy().astype(np.float32)


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


def render_reference(mitsuba_scene, sensor: int, spp: int, seed: int = 0, denoise: bool = True) -> np.ndarray:
    """(H, W, 3) linear radiance that Mitsuba path-traces for one of the scene's sensors, denoised by
    Intel Open Image Denoise with Mitsuba's own albedo and normals (at 256 spp two independent
    renders of a gallery view agree to about 22 dB raw, 32 dB denoised)."""
    return render_reference_and_albedo(mitsuba_scene, sensor, spp, seed, denoise)[0]


def render_reference_and_albedo(
    mitsuba_scene, sensor: int, spp: int, seed: int = 0, denoise: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`render_reference`'s image and the albedo (H, W, 3) Mitsuba's film saw (the surfaces'
    diffuse reflectance, textures filtered over the pixel; 0 where rays leave the scene)."""
    mi = _mitsuba()
    image = np.array(mi.render(mitsuba_scene, sensor=sensor, spp=spp, seed=seed), np.float32)
    colour = np.ascontiguousarray(image[..., :3])
    albedo = np.ascontiguousarray(image[..., 3:6])
    if denoise:
        try:
            import pyoidn
        except ImportError as error:
            raise ImportError(
                "the reference's denoiser needs Open Image Denoise: pip install 'kadv[reference]'"
            ) from error
        colour = pyoidn.denoise(colour, albedo, np.ascontiguousarray(image[..., 6:9]), hdr=True)
    return np.maximum(colour, 0.0).astype(np.float64), albedo.astype(np.float64)


def _both_images(
    mitsuba_scene, sensor: int, renderer: ExactRenderer, world_T_cam: torch.Tensor, K: torch.Tensor,
    height: int, width: int, spp: int, seed: int = 0, reference: np.ndarray | None = None,
) -> tuple[RenderOutput, np.ndarray, np.ndarray]:  # fmt: skip
    """kadv's render of a view, its image (H, W, 3), and Mitsuba's image of the same ``sensor``
    exposed to match it (``reference``: Mitsuba's linear image when already rendered)."""
    ours = renderer.render(world_T_cam, K, height, width, supersample=2).to("cpu")
    linear = render_reference(mitsuba_scene, sensor, spp, seed) if reference is None else reference
    kadv_rgb = ours.rgb[0].permute(1, 2, 0).numpy()
    return ours, kadv_rgb, display_image(linear * matched_exposure(linear, kadv_rgb))


def _as_tensor(image: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(np.ascontiguousarray(image)).permute(2, 0, 1)[None].float()


def _image_scores(ours: np.ndarray, reference: np.ndarray) -> tuple[float, float]:
    """PSNR and SSIM (11 x 11 window) of display images (H, W, 3) in [0, 1]."""
    a, b = _as_tensor(ours), _as_tensor(reference)
    return float(psnr(a, b, 1.0)), float(ssim(a, b, 11).mean())


def noise_floor(mitsuba_scene, sensor: int, spp: int, denoise: bool = True) -> tuple[float, float]:
    """PSNR and SSIM of two independent Mitsuba renders of one view against each other, exposed
    alike (the median to a mid grey): the best score any renderer can reach against one of them."""
    first, second = (render_reference(mitsuba_scene, sensor, spp, seed, denoise) for seed in (0, 1))
    scale = matched_exposure(first, np.full((1, 3), 0.5))
    return _image_scores(display_image(first * scale), display_image(second * scale))


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
    reference: np.ndarray | None = None,
) -> ReferenceComparison:
    """Render one view with Mitsuba (``sensor`` of the loaded scene) and kadv, and compare them.

    ``reference``: Mitsuba's linear image of that sensor when already rendered (several kadv
    renderers compared against one reference).
    """
    K = intrinsics_from_fov(fov_x_deg, height, width)
    ours, kadv_rgb, mitsuba_rgb = _both_images(
        mitsuba_scene, sensor, renderer, world_T_cam, K, height, width, spp, seed, reference
    )
    depth_ref = mitsuba_depth(mitsuba_scene, sensor, height, width)
    depth_ours = ours.depth[0, 0].double().numpy()
    both = (depth_ref > 0) & (depth_ours > 0)
    relative = np.abs(depth_ref[both] - depth_ours[both]) / depth_ours[both]
    depth_rel_err = float(np.median(relative)) if both.any() else math.nan
    image_psnr, image_ssim = _image_scores(kadv_rgb, mitsuba_rgb)
    with torch.no_grad():
        predictions = model(torch.cat([_as_tensor(mitsuba_rgb), _as_tensor(kadv_rgb)]))
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


def save_comparison(path: str | Path, comparisons: dict[str, ReferenceComparison], title: str) -> Path:
    """One PNG: Mitsuba's image then kadv's under each label (top row), and the model's prediction
    on each image (bottom row), aligned to kadv's ground truth and on one colour map.

    Args:
        comparisons: label (a lighting) -> comparison of one view; Mitsuba's image is the first's.
    """
    first = next(iter(comparisons.values()))
    mask = first.mask
    predictions = [first.mitsuba_pred] + [c.kadv_pred for c in comparisons.values()]
    low, high = depth_range(np.stack(predictions), np.stack([mask] * len(predictions)))
    height, width = first.kadv_rgb.shape[:2]
    columns = 1 + len(comparisons)
    figure, axes = plt.subplots(
        2, columns, figsize=(columns * 3.2, 2 * 3.2 * height / width + 1.1), layout="constrained", squeeze=False
    )
    images = [(first.mitsuba_rgb, "Mitsuba 3 (path traced)")] + [
        (c.kadv_rgb, f"kadv {label}: PSNR {c.psnr:.1f} dB, SSIM {c.ssim:.2f}") for label, c in comparisons.items()
    ]
    labels = ["prediction on Mitsuba"] + [
        f"on kadv {label}: delta1 {c.pred_delta1:.3f}" for label, c in comparisons.items()
    ]
    for axis, (image, name) in zip(axes[0], images):
        axis.imshow(image)
        axis.set_title(name, fontsize=8)
    for axis, prediction, name in zip(axes[1], predictions, labels):
        shown = axis.imshow(
            np.ma.masked_where(~mask, prediction), cmap=depth_colour_map(), vmin=low, vmax=high, interpolation="nearest"
        )
        axis.set_title(name, fontsize=8)
    for axis in axes.ravel():
        axis.set_axis_off()
    figure.colorbar(shown, ax=axes[1].tolist(), fraction=0.03, pad=0.02, label="aligned depth [m]")
    figure.suptitle(title, fontsize=9)
    return save_figure(Path(path), figure)


@dataclass
class Survival:
    """An adversarial view and its init view, scored on kadv's renders and on Mitsuba's.

    Attributes:
        init_view: the init view's name; view: ``adv<k>``, the k-th kept adversarial view.
        kadv_init, kadv_adversarial: the model's delta1 on kadv's renders of the two views.
        mitsuba_init, mitsuba_adversarial: the same on Mitsuba's renders (denoised, exposure-matched to
            kadv's), against the same ground truth (kadv's exact depth).
    """

    init_view: str
    view: str
    kadv_init: float
    kadv_adversarial: float
    mitsuba_init: float
    mitsuba_adversarial: float

    @property
    def kadv_drop(self) -> float:
        return self.kadv_init - self.kadv_adversarial

    @property
    def mitsuba_drop(self) -> float:
        return self.mitsuba_init - self.mitsuba_adversarial


def _pose(theta: list[float], centre: list[float]) -> torch.Tensor:
    """world_T_cam (4, 4) of a recorded view: absolute axis-angle and optical centre."""
    pose = torch.eye(4, dtype=torch.float64)
    pose[:3, :3] = axis_angle_to_matrix(torch.tensor([theta], dtype=torch.float64))[0]
    pose[:3, 3] = torch.tensor(centre, dtype=torch.float64)
    return pose


def _delta1_both(
    mitsuba_scene, sensor: int, renderer: ExactRenderer, model: DepthModel, world_T_cam, K, height, width, spp
) -> tuple[float, float]:
    """The model's delta1 against kadv's exact depth, on kadv's image and on Mitsuba's."""
    ours, kadv_rgb, mitsuba_rgb = _both_images(mitsuba_scene, sensor, renderer, world_T_cam, K, height, width, spp)
    with torch.no_grad():
        predictions = model(torch.cat([_as_tensor(kadv_rgb), _as_tensor(mitsuba_rgb)]))
    depth, mask = ours.depth.double().expand(2, -1, -1, -1), ours.mask.expand(2, -1, -1, -1)
    delta1 = depth_metrics(predictions.double(), depth, mask, model.output_kind)["delta1"]
    return float(delta1[0]), float(delta1[1])


def survival(
    scene_file: str | Path,
    init_views: list,
    renderer: ExactRenderer,
    model: DepthModel,
    height: int,
    width: int,
    spp: int,
    progress: bool = True,
) -> list[Survival]:
    """Re-render every kept adversarial view and its init view with Mitsuba 3 and score the model on
    both renderers' images: does the failure survive the path tracer?

    Args:
        scene_file: the Mitsuba XML file the run's scene was loaded from (default load options).
        init_views: a run summary's ``init_views`` (:class:`kadv.report.summary.InitViewSummary`).
        renderer: the run's exact renderer (its lighting is the one compared).
        model: the run's model.
    """
    from tqdm import tqdm

    rows = []
    for view in tqdm(init_views, desc="reference renders", unit="init view", disable=not progress):
        poses = [torch.tensor(view.init_world_T_cam, dtype=torch.float64)]
        poses += [_pose(a.theta, a.centre) for a in view.adversarial]
        scene = load_mitsuba_scene(scene_file, [(p.numpy(), view.fov_x_deg) for p in poses], height, width, spp)
        K = intrinsics_from_fov(view.fov_x_deg, height, width)
        scores = [_delta1_both(scene, i, renderer, model, p, K, height, width, spp) for i, p in enumerate(poses)]
        for k, (kadv, mitsuba) in enumerate(scores[1:]):
            rows.append(Survival(view.name, f"adv{k}", scores[0][0], kadv, scores[0][1], mitsuba))
    return rows


def survival_table(title: str, rows: list[Survival]) -> Table:
    """The delta1 of each adversarial view and its init view on both renderers, with the mean drops last."""
    table = Table(title, ["init view", "view", "kadv init", "kadv adv", "Mitsuba init", "Mitsuba adv"])
    table.rows = [
        [r.init_view, r.view, r.kadv_init, r.kadv_adversarial, r.mitsuba_init, r.mitsuba_adversarial] for r in rows
    ]
    if rows:
        kadv_drop = float(np.mean([r.kadv_drop for r in rows]))
        mitsuba_drop = float(np.mean([r.mitsuba_drop for r in rows]))
        table.rows.append(["mean drop", "", kadv_drop, "", mitsuba_drop, ""])
    return table
