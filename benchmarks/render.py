"""Median time of one exact render (cast + shading) and of the cast alone, per scene and size.

Run: .venv/bin/python benchmarks/render.py
"""
from __future__ import annotations

from common import bench_scenes, median_seconds

from kadv.geometry import pixel_rays
from kadv.render import ExactRenderer

SIZES = ((240, 320), (480, 640))


def main() -> None:
    print(f"{'scene':<22} {'size':>9} {'triangles':>10} {'render ms':>10} {'cast ms':>9}")
    for scene in bench_scenes():
        renderer = ExactRenderer(scene)
        camera = scene.cameras[0]
        for height, width in SIZES:
            K = camera.intrinsics(height, width)
            origins, directions = pixel_rays(camera.world_T_cam, K, height, width)
            render = median_seconds(lambda: renderer.render(camera.world_T_cam, K, height, width))
            cast = median_seconds(lambda: renderer.cast(origins, directions))
            print(f"{scene.name:<22} {height:>4}x{width:<4} {scene.num_triangles:>10} {render * 1e3:>10.1f} {cast * 1e3:>9.1f}")


if __name__ == "__main__":
    main()
