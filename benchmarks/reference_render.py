"""Render reliability against Mitsuba 3 (the study's Table 1): depth, images and predictions, per lighting.

For each scene (the three ../shared scenes by default; ``--scenes`` takes names or paths to Mitsuba
XML files), the file camera (moved clear of walls as the attack does) plus ``--sampled`` init views
sampled with kadv-tiny are rendered by Mitsuba 3 (path tracing, the file's emitters, denoised with
Open Image Denoise) and by kadv's exact renderer under each lighting (``direct``; ``baked`` with
``render.shading.reflections=false``; ``reflections``: baked with the coats' and metals'
reflections, the commands' default and what it measures unless ``--lightings`` says otherwise). Per
view: the median relative z-depth error (Mitsuba's ray intersection at our pixel centres), PSNR
and SSIM of the images after exposure matching, and delta1 between kadv-tiny's predictions on the
two images. The reference's noise floor is two independent Mitsuba renders of the file camera
against each other. Writes Markdown/CSV tables and a side-by-side PNG per view under ``--out``.

With ``--budget``, each view's error budget against Mitsuba under baked lighting
(:mod:`kadv.diagnostics.budget`: the dB each light term, the albedo, the exposure and each pixel
class would gain were it exact) goes into ``budget_terms`` and ``budget_classes`` tables, per scene
and over scenes, with an error-map PNG per view.

Needs the ``reference`` extra (Mitsuba 3, Open Image Denoise). Run:
.venv/bin/python benchmarks/reference_render.py
.venv/bin/python benchmarks/reference_render.py --scenes japanese_classroom --sampled 0 --views-only
    # no attack: docs/lighting_three_ways.png is its reference_out/japanese_classroom/file0.png
.venv/bin/python benchmarks/reference_render.py --lightings baked --views-only --budget
"""

from __future__ import annotations

import argparse
import math
import statistics
import subprocess
import sys
from pathlib import Path

from common import REAL_SCENES, default_lighting, scene_file

from tqdm import tqdm

from kadv.attack import InitViewConfig, PenaltyConfig, file_init_views, sample_init_views
from kadv.diagnostics.budget import TERMS, KadvTerms, MitsubaTerms, ViewBudget, error_budget, save_budget_figure
from kadv.diagnostics.reference import (
    PIXEL_CLASSES,
    compare_view,
    load_mitsuba_scene,
    noise_floor,
    render_reference,
    save_comparison,
    survival,
    survival_table,
)
from kadv.geometry import intrinsics_from_fov
from kadv.models import load_model
from kadv.render import ExactRenderer, Shading
from kadv.report.summary import RunSummary
from kadv.report.sweep import Table
from kadv.scenes import load_scene

_METRICS = ["psnr", "ssim", "pred_delta1"]
# a default attack (the demo's loss and search) on another scene, made small: kadv-tiny, 2 init views
# of 123 views at 120x160
_ATTACK = ["model=kadv_tiny", "render.height=120", "render.width=160", "init.count=2"]
_ATTACK += ["attack.budget_passes=123", "video=false"]


# each lighting compared: its shading, and the attack's overrides that select it
_LIGHTINGS = {
    "direct": (Shading(lighting="direct"), ["render.lighting=direct"]),
    "baked": (
        Shading(lighting="baked", reflections=False),
        ["render.lighting=baked", "render.shading.reflections=false"],
    ),
    "reflections": (
        Shading(lighting="baked", reflections=True),
        ["render.lighting=baked", "render.shading.reflections=true"],
    ),
}


def _attack(path: Path, lighting: str, out: Path) -> RunSummary:
    """Run the default attack, made small (_ATTACK), on a scene file under a lighting; its summary."""
    command = [str(Path(sys.executable).parent / "kadv-attack"), "scene=file", f"scene.path={path}", *_ATTACK]
    command += [*_LIGHTINGS[lighting][1], f"hydra.run.dir={out}"]
    subprocess.run(command, check=True, capture_output=True)
    return RunSummary.read(out / "summary.json")


def _compare(
    args, scene, path: Path, renderers: dict, model, header: list[str]
) -> tuple[Table, float, float, list[ViewBudget]]:
    """The file camera and sampled init views rendered by Mitsuba and by kadv under each lighting:
    their table (one row per view), a side-by-side PNG per view, the reference's noise floor, and
    with ``--budget`` each view's error budget under baked lighting."""
    penalty = PenaltyConfig()
    direct = renderers.get("direct") or ExactRenderer(scene)
    views = file_init_views(direct, penalty.margin)[:1]
    views += sample_init_views(direct, model, args.sampled, 0, InitViewConfig(), penalty, args.height, args.width)
    poses = [(v.world_T_cam.numpy(), v.fov_x_deg) for v in views]
    if args.budget:
        mitsuba_terms = MitsubaTerms(path, poses, args.height, args.width, args.spp)
        kadv_terms = KadvTerms(renderers["baked"])
        mitsuba = mitsuba_terms.full
    else:
        mitsuba = load_mitsuba_scene(path, poses, args.height, args.width, args.spp)
    floor_psnr, floor_ssim = noise_floor(mitsuba, 0, args.spp)
    title = f"{scene.name}: Mitsuba 3 ({args.spp} spp, denoised) against kadv, {args.height}x{args.width}, kadv-tiny"
    table = Table(title, header)
    budgets = []
    for index, view in enumerate(tqdm(views, desc=scene.name)):
        if args.budget:
            theirs = mitsuba_terms.render(index)
            reference = theirs["full"]
            K = intrinsics_from_fov(view.fov_x_deg, args.height, args.width)
            budgets.append(error_budget(kadv_terms.render(view.world_T_cam, K, args.height, args.width), theirs))
        else:
            reference = render_reference(mitsuba, index, args.spp)
        comparisons = {
            lighting: compare_view(
                mitsuba, index, renderer, model, view.world_T_cam, view.fov_x_deg,
                args.height, args.width, args.spp, reference=reference,
            )
            for lighting, renderer in renderers.items()
        }  # fmt: skip
        if args.budget:
            budget = budgets[-1]
            save_budget_figure(
                args.out / scene.name / f"budget_{view.name}.png", budget, comparisons["baked"].mitsuba_rgb,
                f"{scene.name} {view.name}: error budget against Mitsuba 3, baked lighting",
            )  # fmt: skip
        depth_error = max(c.depth_rel_err for c in comparisons.values())
        table.rows.append(
            [view.name, f"{depth_error:.1e}", *(getattr(c, m) for c in comparisons.values() for m in _METRICS)]
        )
        scores = ", ".join(
            f"{lighting} {c.psnr:.1f} dB / {c.ssim:.2f} / delta1 {c.pred_delta1:.3f}"
            for lighting, c in comparisons.items()
        )
        save_comparison(args.out / scene.name / f"{view.name}.png", comparisons, f"{scene.name} {view.name}: {scores}")
    table.write(args.out / scene.name, "reference")
    print(f"\n{table.markdown()}")
    return table, floor_psnr, floor_ssim, budgets


def _budget_rows(name: str, budgets: list[ViewBudget]) -> tuple[list, list]:
    """A scene's rows of the two budget tables: by term (mean dB gained over its views) and by pixel
    class (mean share of the pixels and of the squared error, mean dB gained)."""
    mean = statistics.mean
    psnr = statistics.median(b.psnr for b in budgets)
    terms = [name, psnr, *(mean(b.gains[t] for b in budgets) for t in (*TERMS, "albedo", "exposure"))]
    terms.append(mean(b.best_exposure for b in budgets))
    classes = [name, psnr]
    for c in PIXEL_CLASSES:
        classes += [
            f"{100 * mean(b.class_pixels[c] for b in budgets):.0f}%",
            f"{100 * mean(b.class_error[c] for b in budgets):.0f}%",
            mean(b.class_gains[c] for b in budgets),
        ]
    return terms, classes


def _survive(args, name: str, path: Path, lighting: str, renderer: ExactRenderer, model) -> tuple[float, float]:
    """Mean delta1 drop of a demo-sized attack's kept views, on kadv's renders and on Mitsuba's."""
    run = _attack(path, lighting, args.out / name / f"attack_{lighting}")
    rows = survival(path, run.init_views, renderer, model, run.height, run.width, args.survival_spp)
    title = f"{name}, {lighting}: delta1 init -> adversarial on kadv's renders and on Mitsuba's"
    survival_table(title, rows).write(args.out / name, f"survival_{lighting}")
    return statistics.mean(r.kadv_drop for r in rows), statistics.mean(r.mitsuba_drop for r in rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default=",".join(REAL_SCENES), help="comma-separated names or Mitsuba XML paths")
    parser.add_argument(
        "--lightings", default="reflections", help="direct, baked, reflections (the default: what the commands render)"
    )
    parser.add_argument("--height", type=int, default=120)
    parser.add_argument("--width", type=int, default=160)
    parser.add_argument("--spp", type=int, default=256, help="Mitsuba samples per pixel (denoised)")
    parser.add_argument("--sampled", type=int, default=4, help="sampled init views per scene")
    parser.add_argument("--out", type=Path, default=Path("reference_out"))
    parser.add_argument("--survival-spp", type=int, default=64, help="spp of the adversarial views' renders")
    parser.add_argument(
        "--views-only", action="store_true", help="compare the views only, no attack (the pictures, as in the docs)"
    )
    parser.add_argument("--budget", action="store_true", help="each view's error budget under baked lighting")
    args = parser.parse_args()
    for name in args.scenes.split(","):
        if not (scene_file(name).is_file() and scene_file(name).suffix.lower() == ".xml"):
            parser.error(f"--scenes: {name!r} is neither a shared scene's name nor a Mitsuba XML file")
    lightings = args.lightings.split(",")
    if not set(lightings) <= set(_LIGHTINGS):
        parser.error(f"--lightings: each must be one of {', '.join(_LIGHTINGS)}, got {args.lightings!r}")
    if args.budget and "baked" not in lightings:
        parser.error(f"--budget: the budget is of baked lighting, and --lightings is {args.lightings!r}")
    default = default_lighting()
    model = load_model("kadv_tiny")
    metrics = _METRICS
    header = ["view", "depth_rel_err", *(f"{m} {lighting}" for lighting in lightings for m in metrics)]
    overall = Table(
        "Reference comparison per scene: median PSNR, SSIM over views, mean prediction delta1; depth error: max",
        ["scene", "noise floor psnr", "noise floor ssim", "bake s", *header[2:]]
        + [f"delta1 drop {lighting} on {renderer}" for lighting in lightings for renderer in ("kadv", "Mitsuba")],
    )
    gains = [f"{part} dB" for part in (*TERMS, "albedo", "exposure")]
    budget_terms = Table(
        "Error budget by term: median PSNR, mean dB gained over views were one part exact (Mitsuba's)",
        ["scene", "psnr", *gains, "best exposure x"],
    )
    budget_classes = Table(
        "Error budget by pixel class: share of the pixels, share of the squared error, dB gained were its pixels exact",
        ["scene", "psnr", *(f"{c} {k}" for c in PIXEL_CLASSES for k in ("pixels", "error", "dB"))],
    )
    survive: dict[str, list[tuple[float, float]]] = {lighting: [] for lighting in lightings}
    depth_errors: list[float] = []
    scene_summary: dict[str, dict[str, list[float]]] = {lighting: {m: [] for m in metrics} for lighting in lightings}
    for name in args.scenes.split(","):
        path = scene_file(name)
        scene = load_scene(path)
        renderers, bake = {}, "-"
        for lighting in lightings:
            renderers[lighting] = ExactRenderer(scene, _LIGHTINGS[lighting][0])
            if lighting == "baked":  # 0 s: read from the cache (benchmarks/bake.py measures a bake)
                bake = f"{renderers[lighting].baked.seconds:.0f}" if renderers[lighting].baked.seconds else "cached"
        table, floor_psnr, floor_ssim, budgets = _compare(args, scene, path, renderers, model, header)
        if budgets:
            for summary, rows in zip((budget_terms, budget_classes), _budget_rows(scene.name, budgets)):
                summary.rows.append(rows)
                summary.write(args.out, summary.title.split(":")[0].lower().replace(" ", "_"))
        depth_errors += [float(r[1]) for r in table.rows]
        row = [scene.name, floor_psnr, floor_ssim, bake]
        for offset, lighting in enumerate(lightings):
            columns = [[r[2 + offset * len(metrics) + k] for r in table.rows] for k in range(len(metrics))]
            summary = [statistics.median(columns[0]), statistics.median(columns[1]), statistics.mean(columns[2])]
            for metric, value in zip(metrics, summary):
                scene_summary[lighting][metric].append(value)
            row += summary
        for lighting in lightings if not args.views_only else []:
            kadv_drop, mitsuba_drop = _survive(args, scene.name, path, lighting, renderers[lighting], model)
            survive[lighting].append((kadv_drop, mitsuba_drop))
            row += [kadv_drop, mitsuba_drop]
        overall.rows.append(row + ["-", "-"] * len(lightings) * args.views_only)
    overall.write(args.out, "reference")
    for summary in (budget_terms, budget_classes) if args.budget else ():
        print(summary.markdown())
    print(overall.markdown())
    ratio = {
        lighting: statistics.mean(m for _, m in drops) / statistics.mean(k for k, _ in drops) if drops else math.nan
        for lighting, drops in survive.items()
    }
    for lighting in lightings:
        s = scene_summary[lighting]
        print(
            f"{lighting}: psnr_min={min(s['psnr']):.2f} ssim_min={min(s['ssim']):.3f} "
            f"pred_delta1_min={min(s['pred_delta1']):.3f} survive_ratio={ratio[lighting]:.3f}"
        )
    chosen = default if default in scene_summary else lightings[0]
    s = scene_summary[chosen]
    print(
        f"reference lighting={chosen} depth_rel_err_max={max(depth_errors):.2e} psnr_min={min(s['psnr']):.2f} "
        f"ssim_min={min(s['ssim']):.3f} pred_delta1_min={min(s['pred_delta1']):.3f} "
        f"survive_ratio={ratio[chosen]:.3f}"
    )


if __name__ == "__main__":
    main()
