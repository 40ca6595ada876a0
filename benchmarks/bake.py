"""The cost of baked lighting per scene: seconds, lattice points and peak memory of one bake, and
how many of the points its cameras see the bake discarded.

Bakes the box room, a generated room and the three shared scenes (or Mitsuba XML files given as
paths) with the default settings (``render.bake.*``), each in a fresh process (so peak memory is the
bake's) and with an empty cache, then builds the renderer again, reading the cache (``cached s``:
the whole renderer's set-up). ``seen buried``: of 4096 rays in uniform directions from each file
camera (else the camera region's centre), the share whose surface point took its light from its
neighbours (inside geometry, beyond a wall, in a crevice); a surface the cameras see directly faces
the room, so a high share is a bake that misjudged which side of its surfaces is the room's.

Run: .venv/bin/python benchmarks/bake.py [--scenes box_room,procedural,grey_white_room,path/scene.xml]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from common import REAL_SCENES, scene_file, scenes_root

_CHILD = """
import json, resource, sys, time
sys.path.insert(0, {here!r})
from common import load_bench_scene  # first: kadv's runtime settings, before torch loads
import numpy as np, torch
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
if scene.cameras:
    eyes = np.stack([camera.world_T_cam.numpy()[:3, 3] for camera in scene.cameras])
else:
    eyes = scene.camera_region.mean(axis=0, keepdims=True)
directions = np.random.default_rng(1).normal(size=(len(eyes) * 4096, 3))  # not the bake's own rays
directions /= np.linalg.norm(directions, axis=1, keepdims=True)
hits = renderer.cast(np.repeat(eyes, 4096, axis=0), directions)
back = renderer.back_facing(hits, directions)
seen = hits.hit
# bakes before version 8 kept no record of the points they discarded
buried = getattr(renderer.baked, "buried", None)
ids, bary = hits.triangle_ids[seen], hits.barycentrics[seen].double()
share = float(renderer.baked.buried_at(ids, bary, back[seen]).double().mean()) if buried is not None else float("nan")
print(json.dumps({{"triangles": scene.num_triangles, "points": len(renderer.baked.irradiance),
                  "bake_s": bake, "cached_s": cached, "peak_gib": peak, "seen_buried": share}}))
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default=",".join(("box_room", "procedural", *REAL_SCENES)))
    args = parser.parse_args()
    for name in args.scenes.split(","):
        if name not in ("box_room", "procedural") and not scene_file(name).is_file():
            parser.error(f"--scenes: {name!r} is not box_room, procedural, a scene under {scenes_root()} or a file")
    here = str(Path(__file__).resolve().parent)
    print("| scene | triangles | points | bake s | cached s | peak GiB | seen buried |\n|---|---|---|---|---|---|---|")
    seconds, buried = {}, {}
    for name in args.scenes.split(","):
        with tempfile.TemporaryDirectory() as cache:
            child = subprocess.run(
                [sys.executable, "-c", _CHILD.format(here=here), name, cache],
                check=True,
                capture_output=True,
                text=True,
            )
        row = json.loads(child.stdout.strip().splitlines()[-1])
        name = Path(name).parent.name if name.endswith(".xml") else name
        seconds[name], buried[name] = row["bake_s"], row["seen_buried"]
        print(
            f"| {name} | {row['triangles']} | {row['points']} | {row['bake_s']:.1f} | {row['cached_s']:.2f} | "
            f"{row['peak_gib']:.2f} | {row['seen_buried']:.3f} |"
        )
    figures = [f"{name}_s={value:.1f}" for name, value in seconds.items()]
    figures += [f"{name}_seen_buried={value:.3f}" for name, value in buried.items()]
    print("bake " + " ".join(figures))


if __name__ == "__main__":
    main()
