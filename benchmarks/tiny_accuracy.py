"""kadv-tiny delta1 (after scale-and-shift alignment) on held-out procedural views and real scenes.

The 200 procedural views come from rooms no training run uses (seed 7); the real scenes are
rendered from their file cameras and reported as measured, with no threshold.
Run: .venv/bin/python benchmarks/tiny_accuracy.py
"""
from __future__ import annotations

import sys

import torch
from common import REAL_SCENES, scenes_root

from kadv.datasets import render_procedural_views
from kadv.losses import depth_metrics
from kadv.models import load_model
from kadv.models.evaluation import evaluate
from kadv.render import ExactRenderer
from kadv.scenes import load_scene

HELD_OUT_SEED = 7


def main(weights: str | None = None) -> None:
    model = load_model("kadv_tiny", weights=weights)
    held_out = render_procedural_views(200, HELD_OUT_SEED, 240, 320, progress=False)
    procedural = evaluate(model, held_out)
    print(f"procedural held-out views: 200  delta1 {procedural:.3f}")
    real = []
    for name in REAL_SCENES:
        scene = load_scene(scenes_root() / name / "scene.xml")
        camera = scene.cameras[0]
        out = ExactRenderer(scene).render(camera.world_T_cam, camera.intrinsics(180, 320), 180, 320, supersample=2)
        with torch.no_grad():
            metrics = depth_metrics(model(out.rgb), out.depth, out.mask)
        real.append(float(metrics["delta1"][0]))
        print(f"{name:<20} file camera  delta1 {real[-1]:.3f}  abs_rel {float(metrics['abs_rel'][0]):.3f}")
    print(f"kadv_tiny delta1_procedural={procedural:.3f} delta1_real_mean={sum(real) / len(real):.3f}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)
