"""Render reliability against Mitsuba 3 (the study's Table 1): depth, images and predictions.

For each ../shared scene, the file camera (moved clear of walls as the attack does) plus 4 init views
sampled with kadv-tiny are rendered by Mitsuba 3 (path tracing, the file's emitters) and by kadv's
exact renderer. Per view: the median relative z-depth error (Mitsuba's ray intersection at our pixel
centres), PSNR and SSIM of the images after exposure matching, and delta1 between kadv-tiny's
predictions on the two images. Writes a Markdown and CSV table per scene and a side-by-side PNG per
view under ``--out``.

Needs the ``reference`` extra (Mitsuba 3). Run: .venv/bin/python benchmarks/reference_render.py
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

from common import REAL_SCENES, load_bench_scene, scenes_root
from tqdm import tqdm

from kadv.attack import InitViewConfig, PenaltyConfig, file_init_views, sample_init_views
from kadv.diagnostics.reference import compare_view, load_mitsuba_scene, save_comparison
from kadv.models import load_model
from kadv.render import ExactRenderer
from kadv.report.sweep import Table


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--height", type=int, default=120)
    parser.add_argument("--width", type=int, default=160)
    parser.add_argument("--spp", type=int, default=256, help="Mitsuba samples per pixel")
    parser.add_argument("--sampled", type=int, default=4, help="sampled init views per scene")
    parser.add_argument("--out", type=Path, default=Path("reference_out"))
    args = parser.parse_args()
    model, penalty = load_model("kadv_tiny"), PenaltyConfig()
    header = ["view", "depth_rel_err", "psnr", "ssim", "pred_delta1"]
    overall = Table("Reference comparison, per scene (median over views; depth error: max)", ["scene", *header[1:]])
    depth_errors, file_errors, delta1s = [], [], []
    for name in REAL_SCENES:
        renderer = ExactRenderer(load_bench_scene(name))
        views = file_init_views(renderer, penalty.margin)[:1]
        views += sample_init_views(renderer, model, args.sampled, 0, InitViewConfig(), penalty, args.height, args.width)
        scene = load_mitsuba_scene(
            scenes_root() / name / "scene.xml",
            [(v.world_T_cam.numpy(), v.fov_x_deg) for v in views],
            args.height,
            args.width,
            args.spp,
        )
        table = Table(f"{name}: Mitsuba 3 ({args.spp} spp) against kadv, {args.height}x{args.width}, kadv-tiny", header)
        for index, view in enumerate(tqdm(views, desc=name)):
            c = compare_view(
                scene, index, renderer, model, view.world_T_cam, view.fov_x_deg, args.height, args.width, args.spp
            )
            table.rows.append([view.name, f"{c.depth_rel_err:.1e}", c.psnr, c.ssim, c.pred_delta1])
            save_comparison(
                args.out / name / f"{view.name}.png",
                c,
                f"{name} {view.name}: depth rel. err {c.depth_rel_err:.1e}, PSNR {c.psnr:.1f} dB, "
                f"SSIM {c.ssim:.3f}, delta1(pred Mitsuba, pred kadv) {c.pred_delta1:.3f}",
            )
            depth_errors.append(c.depth_rel_err)
            delta1s.append(c.pred_delta1)
            if view.source == "file":
                file_errors.append(c.depth_rel_err)
        table.write(args.out / name, "reference")
        print(f"\n{table.markdown()}")
        overall.rows.append(
            [
                name,
                f"{max(depth_errors[-len(views) :]):.1e}",
                *(statistics.median(r[k] for r in table.rows) for k in (2, 3, 4)),
            ]
        )
    overall.write(args.out, "reference")
    print(overall.markdown())
    print(f"file cameras: depth_rel_err_max={max(file_errors):.2e}")
    print(f"reference depth_rel_err_max={max(depth_errors):.2e} pred_delta1_mean={statistics.mean(delta1s):.3f}")


if __name__ == "__main__":
    main()
