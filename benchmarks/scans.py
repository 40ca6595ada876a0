"""Scans at a scan's size: scan-like houses of 0.5, 1, 2 and 5 million triangles (a scan-like box
room, 5 cm triangles, tiled side by side), written in ScanNet's layout; per size, in fresh processes:
the load's seconds, one render at 240x320 (2 x 2 rays per pixel, scanned lighting) in milliseconds,
a short ``kadv-attack`` (one init view drawn in the house's free space, 24 evaluations, 96x128) in
seconds, and the peak resident memory of the load and render and of the attack.

``--pictures DIR`` also writes the Scans page's pictures: a scan-like room rendered as scanned
beside the baked room it was made from, and a view through its missing ceiling with its mask.

``--default-attack`` measures instead what a user's first command costs on a ScanNet-size scan
as people have them: a scan-like box room of about 130k triangles, cut at 1.4 m with a wall
missing, in ScanNet's layout with its capture path, attacked by ``kadv-attack``'s defaults (the
init views from the capture path) in a fresh process; last line ``scans_default triangles=...
attack_s=...``.

Run: .venv/bin/python benchmarks/scans.py [--sizes 0.5,1,2,5] [--pictures docs] [--default-attack]
The last line is the largest size's: ``scans triangles=... load_s=... render_ms=... attack_s=... peak_gib=...``.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import common  # noqa: F401  (first: kadv's runtime settings, before torch starts its thread pool)

import numpy as np

ROOM_EDGE = 0.05  # metres: the tile's triangles, as a fine reconstruction's
SCANNET_EDGE = 0.051  # metres: a box room of about 130k triangles once cut at 1.4 m, a ScanNet room's size


def house(triangles: float, folder: Path) -> Path:
    """A scan-like house of about ``triangles`` triangles in ScanNet's layout: copies of one
    scan-like box room side by side (10% of its width apart)."""
    import kadv
    from kadv.datasets import ScanLikeSettings, scan_like, write_scan

    room = scan_like(kadv.box_room(seed=0), seed=0, settings=ScanLikeSettings(edge=ROOM_EDGE))
    copies = max(1, round(triangles / len(room.faces)))
    columns = int(np.ceil(np.sqrt(copies)))
    step = (room.vertices.max(axis=0) - room.vertices.min(axis=0)) * 1.1
    vertices, faces, colours = [], [], []
    for k in range(copies):
        offset = np.array([(k % columns) * step[0], 0.0, (k // columns) * step[2]])
        faces.append(room.faces + k * len(room.vertices))
        vertices.append(room.vertices + offset)
        colours.append(room.colors)
    tiled = type(room)(
        np.concatenate(vertices), np.concatenate(faces), np.concatenate(colours), room.source, room.missing_ceiling
    )
    return write_scan(tiled, folder, "scannet")


def measure(path: Path) -> dict:
    """Load and render in this process (its peak memory is theirs)."""
    import kadv
    from kadv.attack import InitViewConfig, PenaltyConfig, sample_valid_views
    from kadv.geometry import intrinsics_from_fov

    peak = lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    started = time.perf_counter()
    scene = kadv.load_scene(path)
    load_s, load_peak = time.perf_counter() - started, peak()
    renderer = kadv.ExactRenderer(scene, kadv.Shading(lighting="scanned"))
    pose = sample_valid_views(renderer, 1, 0, InitViewConfig(), PenaltyConfig(), 96, 128)[0]
    K = intrinsics_from_fov(70.0, 240, 320)
    renderer.render(pose, K, 240, 320, supersample=2)  # warm
    started = time.perf_counter()
    for _ in range(3):
        renderer.render(pose, K, 240, 320, supersample=2)
    render_ms = (time.perf_counter() - started) / 3 * 1000
    return {
        "triangles": scene.num_triangles,
        "load_s": load_s,
        "load_peak_gib": load_peak,
        "render_ms": render_ms,
        "peak_gib": peak(),
    }


def attack(path: Path, out: Path) -> tuple[float, float]:
    """Seconds and peak memory (GiB) of a short kadv-attack on the scan, in a process of its own."""
    command = [sys.executable, __file__, "--attack", str(path), str(out)]
    started = time.perf_counter()
    done = subprocess.run(command, check=True, capture_output=True, text=True)
    return time.perf_counter() - started, float(done.stdout.strip().splitlines()[-1])


def run_attack(path: Path, out: Path) -> float:
    """kadv-attack's main on the scan (one init view, 24 evaluations, 96x128); its peak memory, GiB."""
    from kadv.cli.attack import main as attack_main

    sys.argv = ["kadv-attack", "scene=file", f"scene.path={path}", "render.height=96", "render.width=128"]
    sys.argv += [
        "init.count=1",
        "attack.budget_passes=24",
        "video=false",
        "progress=false",
        f"hydra.run.dir={out}",
    ]
    try:
        attack_main()
    except SystemExit as exit_:
        if exit_.code:
            raise
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20


def default_attack() -> None:
    """kadv-attack with its defaults on a ScanNet-size partial scan with a capture path."""
    import kadv
    from kadv.datasets import ScanLikeSettings, scan_like, write_scan

    settings = ScanLikeSettings(edge=SCANNET_EDGE, cut_height=1.4, missing_walls=("x+",))
    scan = scan_like(kadv.box_room(seed=0), seed=0, settings=settings)
    with tempfile.TemporaryDirectory() as tmp:
        path = write_scan(scan, tmp, "scannet")
        command = [str(Path(sys.executable).with_name("kadv-attack")), "scene=file", f"scene.path={path}"]
        command += ["progress=false", f"hydra.run.dir={tmp}/run"]
        started = time.perf_counter()
        done = subprocess.run(command, check=True, capture_output=True, text=True)
        seconds = time.perf_counter() - started
    print(done.stdout.strip())
    print(f"scans_default triangles={len(scan.faces)} attack_s={seconds:.0f}")


def pictures(folder: Path) -> None:
    """The Scans page's pictures: scanned beside baked; a view through the missing ceiling."""
    import torch

    import kadv
    from kadv.datasets import scan_like, write_scan
    from kadv.report.images import save_rgb_png

    room = kadv.box_room(seed=0)
    scan = scan_like(room, seed=0)
    with tempfile.TemporaryDirectory() as tmp:
        loaded = kadv.load_scene(write_scan(scan, tmp, "scannet"))
    magenta = (1.0, 0.0, 1.0)
    baked = kadv.ExactRenderer(room, kadv.Shading(lighting="baked", reflections=False), progress=False)
    scanned = kadv.ExactRenderer(loaded, kadv.Shading(lighting="scanned", background=magenta))
    camera = room.cameras[0]
    K = kadv.intrinsics_from_fov(camera.fov_x_deg, 240, 320)
    source = baked.render(camera.world_T_cam[None], K, 240, 320, supersample=2)
    ours = scanned.render(camera.world_T_cam[None], K, 240, 320, supersample=2)
    seen = ours.mask[0, 0] & source.mask[0, 0]
    psnr = float(-10 * torch.log10(((source.rgb - ours.rgb) ** 2).mean(1)[0][seen].mean()))
    save_rgb_png(folder / "scan_like_scanned_vs_baked.png", torch.cat([source.rgb[0], ours.rgb[0]], dim=2))
    x, y, z, _ = max(scan.missing_ceiling, key=lambda patch: patch[3])
    eye = torch.tensor([x - 0.6, y - 1.2, z])
    up = kadv.look_at(eye, eye + torch.tensor([0.5, 1.0, 0.1]))
    hole = scanned.render(up[None], K, 240, 320, supersample=2)
    mask = hole.mask[0].float().expand(3, -1, -1)
    save_rgb_png(folder / "scan_like_hole_mask.png", torch.cat([hole.rgb[0], mask], dim=2))
    print(f"pictures: {folder}; scanned against baked at the room's camera: {psnr:.1f} dB PSNR where both see")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="0.5,1,2,5", help="millions of triangles")
    parser.add_argument("--pictures", default=None, help="a folder for the Scans page's pictures")
    parser.add_argument("--default-attack", action="store_true", help="kadv-attack's defaults on a ScanNet-size scan")
    parser.add_argument("--measure", default=None, help=argparse.SUPPRESS)  # a fresh process's share
    parser.add_argument("--attack", nargs=2, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.measure:
        print(json.dumps(measure(Path(args.measure))))
        return
    if args.attack:
        print(run_attack(*map(Path, args.attack)))
        return
    if args.default_attack:
        default_attack()
        return
    if args.pictures:
        pictures(Path(args.pictures))
    print("| triangles | load s | render ms (240x320) | attack s | peak GiB (load + render) | peak GiB (attack) |")
    print("|---|---|---|---|---|---|")
    row = {}
    for size in (float(s) for s in args.sizes.split(",")):
        with tempfile.TemporaryDirectory() as tmp:
            path = house(size * 1e6, Path(tmp))
            done = subprocess.run(
                [sys.executable, __file__, "--measure", str(path)], check=True, capture_output=True, text=True
            )
            row = json.loads(done.stdout.strip().splitlines()[-1])
            row["attack_s"], row["attack_peak_gib"] = attack(path, Path(tmp) / "run")
        print(
            f"| {row['triangles']:,} | {row['load_s']:.1f} | {row['render_ms']:.0f} | {row['attack_s']:.0f} | "
            f"{row['peak_gib']:.2f} | {row['attack_peak_gib']:.2f} |",
            flush=True,
        )
    print(
        f"scans triangles={row['triangles']} load_s={row['load_s']:.1f} render_ms={row['render_ms']:.0f} "
        f"attack_s={row['attack_s']:.0f} peak_gib={max(row['peak_gib'], row['attack_peak_gib']):.2f}"
    )


if __name__ == "__main__":
    main()
