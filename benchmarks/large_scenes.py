"""Large scenes: the shared grey_white_room's GLB tiled 1x1, 2x2 and 4x4 (trimesh, copies 5% apart),
each loaded, its ray caster built, rendered once (240x320, supersample 2, direct light) and its light
baked (default settings, an empty cache), in a fresh process per tiling: seconds, and the peak
resident memory after the load and in all.

Run: .venv/bin/python benchmarks/large_scenes.py [--tilings 1 2 4]
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import scenes_root


def tile(count: int, out: Path) -> Path:
    """The grey room's GLB in a ``count`` x ``count`` grid, 5% of its size apart, as one GLB."""
    import trimesh

    room = trimesh.load(scenes_root() / "grey_white_room" / "grey_white_room.glb")
    step = (room.bounds[1] - room.bounds[0]) * 1.05
    grid = trimesh.Scene()
    for i in range(count):
        for j in range(count):
            grid.add_geometry(room.copy().apply_translation([i * step[0], 0.0, j * step[2]]))
    grid.export(out)
    return out


def measure(path: Path) -> str:
    """One scene's figures (run in a process of its own: its peak memory is this scene's)."""
    import numpy as np

    from kadv.geometry import intrinsics_from_fov
    from kadv.penalties import random_valid_poses
    from kadv.render import BakeConfig, ExactRenderer, Shading
    from kadv.scenes import load_scene

    peak = lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    start = time.perf_counter()
    scene = load_scene(path)
    load, load_peak = time.perf_counter() - start, peak()
    start = time.perf_counter()
    renderer = ExactRenderer(scene)
    build = time.perf_counter() - start
    rng = np.random.default_rng(0)
    pose = scene.cameras[0].world_T_cam if scene.cameras else random_valid_poses(renderer, 1, rng, 70.0)[0]
    start = time.perf_counter()
    renderer.render(pose, intrinsics_from_fov(70.0, 240, 320), 240, 320, 2)
    render = time.perf_counter() - start
    with tempfile.TemporaryDirectory() as cache:
        start = time.perf_counter()
        ExactRenderer(scene, Shading(lighting="baked", bake=BakeConfig(cache=cache)), progress=False)
        bake = time.perf_counter() - start
    return (
        f"triangles={scene.num_triangles} load_s={load:.1f} build_s={build:.2f} render_ms={render * 1e3:.0f} "
        f"bake_s={bake:.0f} load_peak_gib={load_peak:.2f} peak_gib={peak():.2f}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tilings", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--measure", type=Path, help=argparse.SUPPRESS)  # the per-scene child process
    args = parser.parse_args()
    if args.measure:
        print(measure(args.measure))
        return
    peaks = {}
    print("| tiling | triangles | load s | caster build s | render ms | bake s | peak after load GiB | peak GiB |")
    print("|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as folder:
        for count in args.tilings:
            glb = tile(count, Path(folder) / f"grey_{count}x{count}.glb")
            line = (
                subprocess.run(
                    [sys.executable, __file__, "--measure", str(glb)], capture_output=True, text=True, check=True
                )
                .stdout.strip()
                .splitlines()[-1]
            )
            row = dict(pair.split("=") for pair in line.split())
            print(f"| {count}x{count} | " + " | ".join(row.values()) + " |", flush=True)
            peaks[count] = float(row["peak_gib"])
    print("large_scenes " + " ".join(f"peak_gib_{c}x{c}={p:.2f}" for c, p in peaks.items()))


if __name__ == "__main__":
    main()
