"""Render timings: exact render and cast per scene and size; DifferentiableRenderer forward+backward.

Run: .venv/bin/python benchmarks/render.py [--backend auto|open3d|warp] [--device cpu|cuda]
"""

from __future__ import annotations

import argparse
import statistics

from common import add_backend_option, bench_scenes, checked_backend, median_seconds

import torch

from kadv.geometry import pixel_rays
from kadv.render import DifferentiableRenderer, DiffRenderConfig, ExactRenderer

SIZES = ((240, 320), (480, 640))


def exact_timings(scenes, backend: str, device: str) -> None:
    print("| scene | size | triangles | render ms | cast ms |\n|---|---|---|---|---|")
    for scene in scenes:
        renderer = ExactRenderer(scene, backend=backend, device=device)
        camera = scene.cameras[0]
        for height, width in SIZES:
            K = camera.intrinsics(height, width)
            origins, directions = pixel_rays(camera.world_T_cam, K, height, width)
            render = median_seconds(lambda: renderer.render(camera.world_T_cam, K, height, width))
            cast = median_seconds(lambda: renderer.cast(origins, directions))
            row = [scene.name, f"{height}x{width}", scene.num_triangles, f"{render * 1e3:.1f}", f"{cast * 1e3:.1f}"]
            print("| " + " | ".join(map(str, row)) + " |")


def differentiable_timings(
    scenes, backend: str, device: str, height: int = 240, width: int = 320
) -> dict[str, list[float]]:
    """Prints the table; returns per-scene ms of the exact render and of the default configuration."""
    print(f"\nDifferentiableRenderer forward+backward at {height}x{width} (supersample 2, guard band 16)")
    summary: dict[str, list[float]] = {"exact": [], "default": []}
    print("| scene | mode | ms |\n|---|---|---|")
    for scene in scenes:
        renderer = ExactRenderer(scene, backend=backend, device=device)
        camera = scene.cameras[0]
        K = camera.intrinsics(height, width)
        base = camera.world_T_cam[None]
        exact_ms = median_seconds(lambda: renderer.render(base, K, height, width, supersample=2), repeats=3) * 1e3
        print(f"| {scene.name} | exact render alone (s=2) | {exact_ms:.0f} |")
        summary["exact"].append(exact_ms)
        for values, refresh in (("exact", "always"), ("warp", "every_k")):
            for silhouette in (False, True):
                config = DiffRenderConfig(values=values, refresh=refresh, silhouette=silhouette)
                differentiable = DifferentiableRenderer(renderer, config)

                def step() -> None:
                    params = torch.zeros(1, 6, dtype=torch.float64, requires_grad=True)
                    out = differentiable(params, base, K, height, width)
                    (out.rgb.sum() + out.depth.sum()).backward()

                # every_k: the median of three calls at one pose is a step between refreshes (the first refreshes)
                label = f"values={values} refresh={refresh} sil={'on' if silhouette else 'off'}"
                label += " (warped)" if refresh == "every_k" else ""
                step_ms = median_seconds(step, repeats=3) * 1e3
                print(f"| {scene.name} | {label} | {step_ms:.0f} |")
                if config == DiffRenderConfig():
                    summary["default"].append(step_ms)
    return summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_backend_option(parser)
    parser.add_argument("--device", default="cpu", help="where the rays are cast (cpu, cuda)")
    args = parser.parse_args()
    backend = checked_backend(parser, args.backend, args.device)
    scenes = bench_scenes()
    exact_timings(scenes, backend, args.device)
    summary = differentiable_timings(scenes, backend, args.device)
    print(
        f"render exact_ms_mean={statistics.mean(summary['exact']):.0f} "
        f"differentiable_default_ms_mean={statistics.mean(summary['default']):.0f} backend={backend}"
    )


if __name__ == "__main__":
    main()
