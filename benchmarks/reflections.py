"""What the coats' and metals' reflections cost: an exact render with baked lighting, with and
without ``render.shading.reflections``, per shared scene.

The file camera at 240x320 with 2 x 2 rays per pixel (the attack's exact render), the fastest of
``--repeats`` renders of each, alternated in one process so that the machine's drift falls on both.
Run: .venv/bin/python benchmarks/reflections.py [--repeats 7]
"""

from __future__ import annotations

import argparse
import statistics
from functools import partial

from common import REAL_SCENES, fastest_seconds, load_bench_scene

from kadv.render import ExactRenderer, Shading

HEIGHT, WIDTH, SUPERSAMPLE = 240, 320, 2


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    print(f"{'scene':<22} {'baked ms':>9} {'reflections ms':>15} {'ratio':>6}")
    ratios = []
    for name in REAL_SCENES:
        scene = load_bench_scene(name)
        camera = scene.cameras[0]
        K = camera.intrinsics(HEIGHT, WIDTH)
        renderers = {
            on: ExactRenderer(scene, Shading(lighting="baked", reflections=on), progress=False) for on in (False, True)
        }
        fastest = dict.fromkeys(renderers, float("inf"))
        for repeat in range(args.repeats + 1):  # the first round warms up
            for on, renderer in renderers.items():
                render = partial(renderer.render, camera.world_T_cam, K, HEIGHT, WIDTH, supersample=SUPERSAMPLE)
                if repeat:
                    fastest[on] = min(fastest[on], fastest_seconds(render, repeats=1, warmup=0))
                else:
                    render()
        ratios.append(fastest[True] / fastest[False])
        print(f"{name:<22} {fastest[False] * 1e3:>9.0f} {fastest[True] * 1e3:>15.0f} {ratios[-1]:>6.2f}")
    print(f"reflections ratio_mean={statistics.mean(ratios):.2f} ratio_max={max(ratios):.2f}")


if __name__ == "__main__":
    main()
