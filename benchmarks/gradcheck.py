"""Gradient check of DifferentiableRenderer against finite differences of supersampled exact renders.

It checks the configurations the attack runs with: ``conf/render/exact.yaml`` (the default, the
library's DiffRenderConfig()), ``conf/render/warp.yaml``, and the default without silhouettes. The
warp preset is checked as far from its anchor as it ever warps: the anchor rendered just inside its
reach (``anchor_reach_deg`` and ``anchor_reach_m``: 4 degrees and 10 cm) away.

Per scene: 10 seeded poses (>= 0.3 m from any surface, >= 90% of pixels hit, reference confirmed
by halving its step to cos >= 0.99), functionals sum(W * rgb) and sum(W * depth), interior and
full, cosine of analytic vs reference 6-vectors (the smaller of the rotation and translation
blocks), and of the focal length's derivatives over 8 weight maps per functional (a searched field
of view, ``envelope.fov_deg``, moves through it), under the same thresholds. Prints a table of
medians per configuration, pose and focal length.
Run: .venv/bin/python benchmarks/gradcheck.py [--poses N] [--height H] [--width W] [--device D]
[--backend open3d|warp|auto] (the exact renders' ray caster, on the device) [--lighting direct|baked]
"""

from __future__ import annotations

import argparse
import dataclasses
import time

from common import add_backend_option, checked_backend, render_preset, scenes_root

import numpy as np

from kadv.diagnostics import FUNCTIONALS, gradient_check_poses
from kadv.render import ExactRenderer, Shading
from kadv.scenes import box_room, load_scene

CONFIGS = {
    "no silhouettes": dataclasses.replace(render_preset("exact"), silhouette=False),
    "render=exact": render_preset("exact"),
    "render=warp": render_preset("warp"),
}


def main(
    poses: int = 10,
    height: int = 96,
    width: int = 128,
    device: str = "cpu",
    backend: str = "open3d",
    lighting: str = "direct",
) -> None:
    scenes = {
        "box_room": box_room(seed=0),
        "grey_white_room": load_scene(scenes_root() / "grey_white_room" / "scene.xml"),
    }
    medians: dict[tuple[str, str], dict[str, float]] = {}
    focal: dict[tuple[str, str], dict[str, float]] = {}
    print("| scene | method | " + " | ".join(FUNCTIONALS) + " | seconds |\n" + "|---" * (len(FUNCTIONALS) + 3) + "|")
    for scene_name, scene in scenes.items():
        start = time.perf_counter()
        results = gradient_check_poses(
            ExactRenderer(scene, Shading(lighting=lighting), backend=backend, device=device),
            poses,
            seed=0,
            fov_x_deg=70.0,
            height=height,
            width=width,
            configs=CONFIGS,
            reference_supersample=8,
            steps=(2e-3, 4e-3, 2e-3),  # the focal length's too
            device=device,
        )
        seconds = time.perf_counter() - start
        for method, checks in results.items():
            medians[scene_name, method] = {f: float(np.median([c.score(f) for c in checks])) for f in FUNCTIONALS}
            focal[scene_name, method] = {f: float(np.median([c.focal_score(f) for c in checks])) for f in FUNCTIONALS}
            for label, table in (("pose", medians), ("focal length", focal)):
                row = " | ".join(f"{table[scene_name, method][f]:.3f}" for f in FUNCTIONALS)
                print(f"| {scene_name} | {method} {label} | {row} | {seconds:.0f} |")
    checked = [m for m in CONFIGS if m != "no silhouettes"]

    def least(table: dict, scene_names, functionals) -> float:
        return min(table[s, m][f] for s in scene_names for m in checked for f in functionals)

    figures = []
    for prefix, table in (("", medians), ("focal_", focal)):
        figures += [
            f"{prefix}interior_median_cos={least(table, scenes, ('rgb_interior', 'depth_interior')):.3f}",
            f"{prefix}full_box_median_cos={least(table, ['box_room'], ('rgb_full', 'depth_full')):.3f}",
            f"{prefix}full_real_median_cos={least(table, ['grey_white_room'], ('rgb_full', 'depth_full')):.3f}",
        ]
    print(f"gradcheck {' '.join(figures)} backend={backend} lighting={lighting}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=10)
    parser.add_argument("--height", type=int, default=96)
    parser.add_argument("--width", type=int, default=128)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--lighting", default="direct", choices=("direct", "baked"), help="the scenes' light")
    add_backend_option(parser)
    args = parser.parse_args()
    backend = checked_backend(parser, args.backend, args.device)
    main(args.poses, args.height, args.width, args.device, backend, args.lighting)
