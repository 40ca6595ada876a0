"""Failures of metric depth under a free field of view: kadv-tiny-metric scored unaligned
(``loss.alignment=none``), searched with the field of view free in [40, 100] degrees against the
field of view fixed at the init view's, at equal model passes.

Per scene (the box room and the shared scenes), two init views, the default search with
``--budget`` passes per init view and seed 0, the delta1 loss, within the profile's smallest
radius (5 degrees, 0.1 m: a move that alone barely changes a good view) and its largest (45
degrees, 1 m): the worst metric delta1 each search finds, its worst view's field of view, and the
share of the metric drop (init view to worst view) that a scale-and-shift alignment of the same
views would have hidden: ``1 - drop_aligned / drop_metric`` (1 or more: alignment hides the whole
drop). ``--picture`` writes the box room's free-field-of-view worst view of the largest metric
drop at the small radius beside its init view (metric prediction, no alignment).

The init views are the scene's file camera and a sampled view that the model gets right in
metres (chosen under ``none``); a file camera may be one it gets wrong. Last line:
``metric_fov worst_fixed_5deg= worst_free_5deg= hidden_fixed_5deg= ...``: medians per radius over
the init views it gets right in metres (delta1 unaligned at least ``RIGHT``; ``views=`` of them).

``--camera``: a check that the wiring carries K, not a model's measurement. kadv-tiny-metric
wrapped to scale its depth by fx / f_ref, as Depth Anything 3 and Metric3D scale theirs by the
focal length (f_ref: the focal of a 60-degree view), is searched with the field of view free, its
K given (``model.intrinsics=given``: each view's own) against withheld (as at 60 degrees); at the
worst view the K-given search found, the ratio of the model's depth with K given to its depth
with K withheld, against fx / f_ref there. Last line: ``metric_fov_camera worst_given_5deg=
worst_withheld_5deg= ... ratio_error_max=`` (medians over every init view; the largest relative
difference between the ratio and fx / f_ref).

Run: .venv/bin/python benchmarks/metric_fov.py [--budget 123] [--picture docs/metric_fov.png] [--camera]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import common  # first: kadv's runtime settings, before torch starts its thread pool

import numpy as np
import torch

from kadv.attack import AttackConfig, InitView, ViewRecord, attack
from kadv.geometry import intrinsics_from_fov
from kadv.losses import aligned_depth, depth_metrics
from kadv.models import load_model, wrap_model
from kadv.penalties import Envelope
from kadv.report.figures import save_four_panel
from kadv.testing.options import CheckOptions, setup, worst_record

FOV_RANGE = (40.0, 100.0)
SIZE = (96, 128)
RADII = ((5.0, 0.1), (45.0, 1.0))  # degrees, metres
RIGHT = 0.5  # an init view the model gets right in metres: delta1 unaligned at least this
REFERENCE_FOV = 60.0  # degrees: the field of view at which the focal-scaled model is kadv-tiny-metric


class FocalScaled(torch.nn.Module):
    """kadv-tiny-metric's depth times fx / f_ref, f_ref the focal of a REFERENCE_FOV view; without
    K, kadv-tiny-metric's depth as it is."""

    def __init__(self) -> None:
        super().__init__()
        self.tiny = load_model("kadv_tiny_metric")

    def forward(self, rgb: torch.Tensor, K: torch.Tensor | None = None) -> torch.Tensor:
        depth = self.tiny(rgb)
        if K is None:
            return depth
        reference = 0.5 * rgb.shape[-1] / math.tan(math.radians(REFERENCE_FOV) / 2)
        return depth * (K.reshape(-1, 3, 3)[:, 0, 0] / reference).reshape(-1, 1, 1, 1).to(depth)


def rescored(built, init: InitView, record: ViewRecord) -> dict[str, object]:
    """The view rendered again at its field of view: its maps and delta1 unaligned and aligned."""
    pose = record.world_T_cam(init.world_T_cam)[None]
    K = intrinsics_from_fov(record.fov(init.fov_x_deg), *SIZE)
    with torch.no_grad():
        out = built.renderer.render(pose, K, *SIZE, supersample=2).to("cpu")
        prediction = built.objective.model(out.rgb, K).double()
    truth = (out.depth.double(), out.mask)
    delta1 = {
        a: float(depth_metrics(prediction, *truth, "depth", alignment=a)["delta1"]) for a in ("none", "scale_shift")
    }
    return {"out": out, "prediction": prediction, "delta1": delta1, "fov": record.fov(init.fov_x_deg)}


def search(built, envelope: Envelope, radius: tuple[float, float], budget: int) -> list[tuple[dict, dict]]:
    """Per init view, the init view and the worst view within ``radius``, rescored."""
    config = AttackConfig(budget_passes=budget, envelope=envelope, max_angle_deg=radius[0], max_distance=radius[1])
    result = attack(built.objective, built.differentiable, built.views, *SIZE, config, seed=0, progress=False)
    return [
        (rescored(built, view.init, view.init_record), rescored(built, view.init, worst_record(view.records)))
        for view in result.views
    ]


def hidden_share(init: dict, worst: dict) -> float:
    """The share of the metric drop that scale-and-shift alignment hides (NaN: no metric drop)."""
    metric = init["delta1"]["none"] - worst["delta1"]["none"]
    aligned = init["delta1"]["scale_shift"] - worst["delta1"]["scale_shift"]
    return 1.0 - aligned / metric if metric > 0 else float("nan")


def picture(path: Path, pair: tuple[dict, dict]) -> None:
    """The init view above the worst view, each image | depth | metric prediction | error."""
    rows = []
    for label, view in zip(("init view", "worst view"), pair):
        out = view["out"]
        metric = aligned_depth(view["prediction"], out.depth.double(), out.mask, "depth", alignment="none")
        title = (
            f"{label}: field of view {view['fov']:.0f}°, delta1 {view['delta1']['none']:.3f} unaligned, "
            f"{view['delta1']['scale_shift']:.3f} after scale-and-shift alignment"
        )
        panel = path.with_name(f"{path.stem}_{len(rows)}.png")
        maps = (out.rgb[0].permute(1, 2, 0).numpy(), out.depth[0, 0].numpy(), metric[0, 0].float().numpy())
        save_four_panel(panel, *maps, out.mask[0, 0].numpy(), title, alignment="none")
        rows.append(panel)
    from PIL import Image

    images = [Image.open(p).convert("RGB") for p in rows]
    stacked = Image.new("RGB", (max(i.width for i in images), sum(i.height for i in images)), "white")
    top = 0
    for image in images:
        stacked.paste(image, (0, top))
        top += image.height
    stacked.save(path)
    for p in rows:
        p.unlink()


def camera(budget: int) -> None:
    """The focal-scaled model searched with its K given and withheld (see the module docstring)."""
    options = CheckOptions(init_count=2, size=SIZE, lighting=common.default_lighting(), alignment="none")
    free = Envelope("free_fov", fov_deg=FOV_RANGE)
    worst: dict[tuple[str, float], list[float]] = {}
    print(
        "| scene | init view | radius | delta1 init | worst, K given (its fov) | worst, K withheld (its fov) "
        "| depth given / withheld there | fx / f_ref |"
    )
    print("|---|---|---|---|---|---|---|---|")
    errors = []
    for scene in common.bench_scenes():
        built = setup(wrap_model(FocalScaled(), "depth", name="focal_scaled"), scene, options)
        for radius in RADII:
            pairs = {}
            for choice in ("given", "withheld"):
                built.objective.model.intrinsics = choice
                pairs[choice] = search(built, free, radius, budget)
            for index, view in enumerate(built.views):
                given, withheld = pairs["given"][index], pairs["withheld"][index]
                ratio, expected = _camera_ratio(built, given[1])
                errors.append(abs(ratio / expected - 1.0))
                print(
                    f"| {scene.name} | {view.name} | {radius[0]:g}°, {radius[1]:g} m | "
                    f"{given[0]['delta1']['none']:.3f} | "
                    f"{given[1]['delta1']['none']:.3f} ({given[1]['fov']:.0f}°) | "
                    f"{withheld[1]['delta1']['none']:.3f} ({withheld[1]['fov']:.0f}°) | {ratio:.4f} | {expected:.4f} |",
                    flush=True,
                )
                for choice, pair in (("given", given), ("withheld", withheld)):
                    worst.setdefault((choice, radius[0]), []).append(pair[1]["delta1"]["none"])
    summary = " ".join(f"worst_{c}_{r:g}deg={np.median(v):.3f}" for (c, r), v in worst.items())
    views = len(worst["given", RADII[0][0]])
    print(f"metric_fov_camera {summary} ratio_error_max={max(errors):.2e} budget_passes={budget} views={views}")


def _camera_ratio(built, view: dict) -> tuple[float, float]:
    """At a rescored view: the median of the model's depth with K given over its depth with K
    withheld, and fx / f_ref at its field of view (what the ratio is when K reaches the model)."""
    model, rgb = built.objective.model, view["out"].rgb
    K = intrinsics_from_fov(view["fov"], *SIZE)
    with torch.no_grad():
        model.intrinsics = "given"
        given = model(rgb, K).double()
        model.intrinsics = "withheld"
        withheld = model(rgb, K).double()
    expected = math.tan(math.radians(REFERENCE_FOV) / 2) / math.tan(math.radians(view["fov"]) / 2)
    return float((given / withheld).median()), expected


def main(budget: int, picture_path: Path | None) -> None:
    scenes = {scene.name: scene for scene in common.bench_scenes()}
    options = CheckOptions(init_count=2, size=SIZE, lighting=common.default_lighting(), alignment="none")
    envelopes = {"fixed": Envelope("fixed"), "free": Envelope("free_fov", fov_deg=FOV_RANGE)}
    figures: dict[tuple[str, float], list[tuple[dict, dict]]] = {}
    print("| scene | init view | radius | delta1 init | worst, fixed | worst, free (its fov) | hidden: fixed | free |")
    print("|---|---|---|---|---|---|---|---|")
    for name, scene in scenes.items():
        started = time.perf_counter()
        built = setup("kadv_tiny_metric", scene, options)
        for radius in RADII:
            pairs = {key: search(built, envelope, radius, budget) for key, envelope in envelopes.items()}
            for index, view in enumerate(built.views):
                fixed, free = pairs["fixed"][index], pairs["free"][index]
                print(
                    f"| {name} | {view.name} | {radius[0]:g}°, {radius[1]:g} m | {fixed[0]['delta1']['none']:.3f} | "
                    f"{fixed[1]['delta1']['none']:.3f} | {free[1]['delta1']['none']:.3f} ({free[1]['fov']:.0f}°) | "
                    f"{hidden_share(*fixed):.2f} | {hidden_share(*free):.2f} |",
                    flush=True,
                )
                for key in envelopes:
                    figures.setdefault((key, radius[0]), []).append(pairs[key][index])
            if picture_path is not None and name.startswith("box_room") and radius == RADII[0]:
                # the largest metric drop, and of those the one alignment hides best
                drop = lambda pair: (
                    pair[0]["delta1"]["none"] - pair[1]["delta1"]["none"],
                    pair[1]["delta1"]["scale_shift"],
                )
                picture(picture_path, max(pairs["free"], key=drop))
        print(f"  ({name}: {time.perf_counter() - started:.0f} s)", file=sys.stderr, flush=True)
    summary = []
    right = [pair[0]["delta1"]["none"] >= RIGHT for pair in figures["fixed", RADII[0][0]]]
    for radius in RADII:
        for key in envelopes:
            pairs = [pair for pair, kept in zip(figures[key, radius[0]], right) if kept]
            tag = f"{key}_{radius[0]:g}deg"
            summary += [
                f"worst_{tag}={np.median([pair[1]['delta1']['none'] for pair in pairs]):.3f}",
                f"hidden_{tag}={np.nanmedian([hidden_share(*pair) for pair in pairs]):.2f}",
            ]
    views = sum(right)
    print(f"metric_fov {' '.join(summary)} budget_passes={budget} views={views}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--budget", type=int, default=123, help="model passes per init view and search")
    parser.add_argument("--picture", type=Path, default=None, help="where to write the box room's picture")
    parser.add_argument("--camera", action="store_true", help="K given against withheld (a check of the wiring)")
    arguments = parser.parse_args()
    if arguments.camera:
        camera(arguments.budget)
    else:
        main(arguments.budget, arguments.picture)
