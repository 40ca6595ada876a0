"""The cost of baked lighting per scene: seconds, lattice points and peak memory of one bake.

Bakes the box room, a generated room and the three shared scenes with the default settings
(``render.bake.*``), each in a fresh process (so peak memory is the bake's) and with an empty cache,
then builds the renderer again, reading the cache (``cached s``: the whole renderer's set-up).

Run: .venv/bin/python benchmarks/bake.py [--scenes box_room,procedural,grey_white_room,...]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from common import REAL_SCENES, scenes_root

_CHILD = """
import json, resource, sys, time
sys.path.insert(0, {here!r})
from common import load_bench_scene
from kadv.render import BakeConfig, ExactRenderer, Shading
from kadv.scenes import procedural_room

name, cache = sys.argv[1], sys.argv[2]
scene = procedural_room(seed=0) if name == "procedural" else load_bench_scene(name)
shading = Shading(lighting="baked", bake=BakeConfig(cache=cache))
start = time.perf_counter()
renderer = ExactRenderer(scene, shading, progress=False)
bake = time.perf_counter() - start
start = time.perf_counter()
ExactRenderer(scene, shading, progress=False)
cached = time.perf_counter() - start
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
print(json.dumps({{"triangles": scene.num_triangles, "points": len(renderer.baked.irradiance),
                  "bake_s": bake, "cached_s": cached, "peak_gib": peak}}))
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default=",".join(("box_room", "procedural", *REAL_SCENES)))
    args = parser.parse_args()
    for name in args.scenes.split(","):
        if name not in ("box_room", "procedural") and not (scenes_root() / name / "scene.xml").is_file():
            parser.error(f"--scenes: {name!r} is not box_room, procedural or a scene under {scenes_root()}")
    here = str(Path(__file__).resolve().parent)
    print(f"{'scene':<20} {'triangles':>10} {'points':>10} {'bake s':>8} {'cached s':>9} {'peak GiB':>9}")
    seconds = {}
    for name in args.scenes.split(","):
        with tempfile.TemporaryDirectory() as cache:
            child = subprocess.run(
                [sys.executable, "-c", _CHILD.format(here=here), name, cache],
                check=True,
                capture_output=True,
                text=True,
            )
        row = json.loads(child.stdout.strip().splitlines()[-1])
        seconds[name] = row["bake_s"]
        print(
            f"{name:<20} {row['triangles']:>10} {row['points']:>10} {row['bake_s']:>8.1f} "
            f"{row['cached_s']:>9.2f} {row['peak_gib']:>9.2f}"
        )
    print("bake " + " ".join(f"{name}_s={value:.1f}" for name, value in seconds.items()))


if __name__ == "__main__":
    main()
