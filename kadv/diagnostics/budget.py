"""Where a kadv render loses PSNR against Mitsuba 3: an error budget by light term and by pixel class.

Both renderers render each term of a view's light on its own, at one exposure:

- ``direct sun``: the directional lights straight to the surface (kadv: its suns with shadow rays;
  Mitsuba: paths of two segments, the directional emitters only);
- ``other direct``: the point, spot and area lights and the sky straight to the surface (kadv: its
  point and spot lights per hit plus a bake without bounces; Mitsuba: paths of two segments, less
  the sun's);
- ``indirect``: the rest (kadv: the bake less the bounce-free bake; Mitsuba: the full render less
  the direct one).

Per view, the budget gives the dB the PSNR would gain were one part of kadv's image Mitsuba's, the
others left as they are: each term, the diffuse surfaces' ``albedo`` (textures and their filtering,
against Mitsuba's albedo AOV), the ``exposure`` (the best single scale against the median matching), and
each pixel class of :data:`~kadv.diagnostics.reference.PIXEL_CLASSES` (what the camera ray meets in
Mitsuba's scene), with each class's share of the squared error. The gains do not add up: each is
measured with the other parts wrong. The terms are of the diffuse shading: with
:attr:`~kadv.render.Shading.reflections` on, the coats' reflections stay in kadv's whole image,
outside every term.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import torch
from matplotlib.colors import ListedColormap
from matplotlib.patches import Patch

from kadv.diagnostics.reference import (
    PIXEL_CLASSES,
    display_image,
    load_mitsuba_scene,
    matched_exposure,
    mitsuba_hits,
    render_reference_and_albedo,
)
from kadv.render import ExactRenderer
from kadv.render.bake import load_or_bake
from kadv.render.colour import untone
from kadv.report.figures import save_figure
from kadv.scenes.emitters import Emitters

__all__ = ["TERMS", "KadvTerms", "MitsubaTerms", "ViewBudget", "error_budget", "save_budget_figure"]

TERMS = ("direct sun", "other direct", "indirect")
_SURFACES = (PIXEL_CLASSES.index("diffuse"), PIXEL_CLASSES.index("coated or glossy"))
# exposure multipliers the best scale is searched over: a factor 4 either way, 1% apart
_SCALES = np.geomspace(0.25, 4.0, 281)


class KadvTerms:
    """kadv's renders of a view, whole and by term, as exposed linear radiance.

    Args:
        renderer: a renderer with baked lighting; a bake of its scene without bounces is read from
            the cache, or baked there first.
    """

    def __init__(self, renderer: ExactRenderer) -> None:
        baked = renderer.baked
        if baked is None:
            raise ValueError("the error budget needs a renderer with render.lighting=baked")
        scene, shading = renderer.scene, renderer.shading
        unbounced = load_or_bake(renderer.surfaces, replace(shading.bake, bounces=0))
        emitters = scene.emitters
        suns = Emitters(sun_directions=emitters.sun_directions, sun_irradiance=emitters.sun_irradiance)
        others = replace(emitters, sun_directions=np.zeros((0, 3)), sun_irradiance=np.zeros((0, 3)))

        def lit(lights: Emitters, irradiance: np.ndarray) -> ExactRenderer:
            """A renderer of the scene under ``lights`` (per hit) and the baked ``irradiance``."""
            lighting = replace(baked, irradiance=np.ascontiguousarray(irradiance, np.float32))
            lit_scene = replace(scene, emitters=lights)
            diffuse = replace(shading, reflections=False)  # a term's own sky would show in a coat
            return ExactRenderer(lit_scene, diffuse, progress=False, device=renderer.device, baked=lighting)

        zero = np.zeros_like(baked.irradiance)
        self.renderers = {
            "full": renderer,
            "direct sun": lit(suns, zero),
            "other direct": lit(others, unbounced.irradiance),
            "indirect": lit(Emitters(), baked.irradiance - unbounced.irradiance),
            # irradiance pi / exposure shows the reflectance itself
            "albedo": lit(Emitters(), np.full_like(zero, math.pi / baked.exposure)),
        }

    def render(self, world_T_cam: torch.Tensor, K: torch.Tensor, height: int, width: int) -> dict[str, np.ndarray]:
        """Per part (``full``, each of :data:`TERMS`, ``albedo``): (H, W, 3) exposed linear radiance
        (the albedo: reflectance), 2 x 2 rays per pixel as the reference comparison renders; and
        ``mask`` (H, W) bool, where kadv's rays hit a surface."""
        parts = {}
        for name, renderer in self.renderers.items():
            output = renderer.render(world_T_cam, K, height, width, supersample=2).to("cpu")
            # a supersampled pixel's average is undone as one value
            parts[name] = untone(output.rgb[0].permute(1, 2, 0).double()).numpy()
        parts["mask"] = output.mask[0, 0].numpy()
        return parts


class MitsubaTerms:
    """Mitsuba's renders of views, whole and by term, as linear radiance.

    Args:
        path: the scene's Mitsuba XML file.
        views: (world_T_cam (4, 4), fov_x_deg) per view; sensors in this order.
        height, width: pixels; spp: samples per pixel of each render (denoised).
    """

    def __init__(self, path: str | Path, views: list[tuple[np.ndarray, float]], height: int, width: int, spp: int):
        self.spp, self.height, self.width = spp, height, width
        self.full = load_mitsuba_scene(path, views, height, width, spp)
        self.direct = load_mitsuba_scene(path, views, height, width, spp, max_depth=2)
        suns = load_mitsuba_scene(path, views, height, width, spp, max_depth=2, suns_only=True)
        self.suns = suns if len(suns.emitters()) else None

    def render(self, sensor: int, full: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Per part (``full``, each of :data:`TERMS`, ``albedo``): (H, W, 3) linear radiance (the
        albedo: Mitsuba's AOV), and ``classes`` (H, W), indices into
        :data:`~kadv.diagnostics.reference.PIXEL_CLASSES`. ``full``: the full render when already made."""
        rendered, albedo = render_reference_and_albedo(self.full, sensor, self.spp)
        full = rendered if full is None else full
        direct = render_reference_and_albedo(self.direct, sensor, self.spp)[0]
        sun = np.zeros_like(full) if self.suns is None else render_reference_and_albedo(self.suns, sensor, self.spp)[0]
        classes = mitsuba_hits(self.full, sensor, self.height, self.width)[1]
        parts = {"full": full, "direct sun": sun, "other direct": direct - sun, "indirect": full - direct}
        return parts | {"albedo": albedo, "classes": classes}


def _psnr(ours: np.ndarray, reference: np.ndarray) -> float:
    """PSNR of display images in [0, 1]."""
    return float(10.0 * np.log10(1.0 / max(float(np.mean((ours - reference) ** 2)), 1e-12)))


@dataclass
class ViewBudget:
    """Where one view's PSNR is lost.

    Attributes:
        psnr: of kadv's image against Mitsuba's, exposure matched at the median.
        gains: dB gained were one part exact (Mitsuba's): each of :data:`TERMS`, ``albedo``, ``exposure``.
        best_exposure: the scale on Mitsuba's exposure that gives ``gains["exposure"]``.
        class_pixels, class_error, class_gains: per pixel class, its share of the pixels, its share
            of the squared error, and the dB gained were its pixels Mitsuba's.
        term_maps: per term and ``albedo``, (H, W, 3) how much making it exact moves kadv's display image.
        error: (H, W, 3) kadv's display image less Mitsuba's.
        classes: (H, W) pixel classes.
    """

    psnr: float
    gains: dict[str, float]
    best_exposure: float
    class_pixels: dict[str, float]
    class_error: dict[str, float]
    class_gains: dict[str, float]
    term_maps: dict[str, np.ndarray]
    error: np.ndarray
    classes: np.ndarray


def error_budget(ours: dict[str, np.ndarray], theirs: dict[str, np.ndarray]) -> ViewBudget:
    """The budget of one view from :meth:`KadvTerms.render` (``ours``) and :meth:`MitsubaTerms.render`
    (``theirs``): Mitsuba's radiance is exposed as the reference comparison does (its median to kadv's)."""
    shown = display_image(ours["full"])
    scale = matched_exposure(theirs["full"], shown)
    reference = display_image(theirs["full"] * scale)
    psnr = _psnr(shown, reference)
    classes = theirs["classes"]
    surface = (ours["mask"] & np.isin(classes, _SURFACES))[..., None]
    exact = {term: np.where(surface, ours["full"] - ours[term] + theirs[term] * scale, ours["full"]) for term in TERMS}
    # Mitsuba's albedo AOV is a coated base's own reflectance, not the coated albedo kadv shades with
    diffuse = surface & (classes == PIXEL_CLASSES.index("diffuse"))[..., None]
    ratio = np.divide(theirs["albedo"], ours["albedo"], out=np.ones_like(ours["albedo"]), where=ours["albedo"] > 1e-4)
    exact["albedo"] = np.where(diffuse, ours["full"] * ratio, ours["full"])
    shown_exact = {name: display_image(image) for name, image in exact.items()}
    term_maps = {name: image - shown for name, image in shown_exact.items()}
    gains = {name: _psnr(image, reference) - psnr for name, image in shown_exact.items()}
    scored = [_psnr(shown, display_image(theirs["full"] * scale * factor)) for factor in _SCALES]
    best = int(np.argmax(scored))
    gains["exposure"] = scored[best] - psnr
    squared = ((shown - reference) ** 2).sum(axis=-1)
    class_pixels, class_error, class_gains = {}, {}, {}
    for index, name in enumerate(PIXEL_CLASSES):
        inside = classes == index
        class_pixels[name] = float(inside.mean())
        class_error[name] = float(squared[inside].sum() / max(squared.sum(), 1e-30))
        class_gains[name] = _psnr(np.where(inside[..., None], reference, shown), reference) - psnr
    return ViewBudget(
        psnr, gains, float(_SCALES[best]), class_pixels, class_error, class_gains, term_maps, shown - reference, classes
    )


def save_budget_figure(path: str | Path, budget: ViewBudget, mitsuba_rgb: np.ndarray, title: str) -> Path:
    """One PNG of a view's budget: Mitsuba's image, the error map, the pixel classes (top row), and
    what making each term and the albedo exact would change (bottom row, red: brighter)."""
    kadv_rgb = mitsuba_rgb + budget.error
    height, width = budget.classes.shape
    figure, axes = plt.subplots(2, 4, figsize=(4 * 3.0, 2 * 3.0 * height / width + 1.0), layout="constrained")
    axes[0, 0].imshow(mitsuba_rgb.clip(0, 1))
    axes[0, 0].set_title("Mitsuba 3", fontsize=8)
    axes[0, 1].imshow(kadv_rgb.clip(0, 1))
    axes[0, 1].set_title(f"kadv: PSNR {budget.psnr:.1f} dB", fontsize=8)
    shown = axes[0, 2].imshow(np.abs(budget.error).mean(axis=-1), cmap="magma", vmin=0.0, vmax=0.25)
    axes[0, 2].set_title("|kadv - Mitsuba| (display)", fontsize=8)
    figure.colorbar(shown, ax=axes[0, 2], fraction=0.04, pad=0.02)
    colours = ListedColormap(["#bbbbbb", "#d95f02", "#1b9e77", "#e7298a", "#7570b3"])
    axes[0, 3].imshow(budget.classes, cmap=colours, vmin=-0.5, vmax=len(PIXEL_CLASSES) - 0.5, interpolation="nearest")
    axes[0, 3].set_title("pixel classes (share of the squared error)", fontsize=8)
    axes[0, 3].legend(
        handles=[
            Patch(color=colours(index), label=f"{name} {100 * budget.class_error[name]:.0f}%")
            for index, name in enumerate(PIXEL_CLASSES)
            if budget.class_pixels[name]
        ],
        fontsize=6,
        loc="lower left",
    )
    for axis, (name, change) in zip(axes[1], budget.term_maps.items()):
        shown = axis.imshow(change.mean(axis=-1), cmap="RdBu_r", vmin=-0.25, vmax=0.25)
        axis.set_title(f"{name} made exact: {budget.gains[name]:+.1f} dB", fontsize=8)
    figure.colorbar(shown, ax=axes[1].tolist(), fraction=0.02, pad=0.02, label="display change")
    for axis in axes.ravel():
        axis.set_axis_off()
    figure.suptitle(title, fontsize=9)
    return save_figure(Path(path), figure)
