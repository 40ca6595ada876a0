"""Shared helpers for the benchmark scripts (timing, scene discovery); imported first by each,
it also takes ``--record`` (:mod:`record`)."""

from __future__ import annotations

import os

from kadv.runtime import configure_runtime

configure_runtime()

import record

record.start_if_asked()

import argparse
import statistics
import time
from collections.abc import Callable
from pathlib import Path

import torch
import yaml

from kadv.device import resolve_device
from kadv.render import DiffRenderConfig
from kadv.render.backends import resolve_backend
from kadv.scenes import Scene, box_room, load_scene

REAL_SCENES = ("grey_white_room", "modern_hall", "japanese_classroom")


def scenes_root() -> Path:
    return Path(os.environ.get("KADV_TEST_SCENES", Path(__file__).resolve().parents[2] / "shared" / "scenes"))


def add_backend_option(parser: argparse.ArgumentParser) -> None:
    """``--backend``: the exact renderer's ray caster."""
    parser.add_argument("--backend", default="auto", help="the exact render's ray caster: auto, open3d or warp")


def checked_backend(parser: argparse.ArgumentParser, backend: str, device: str | torch.device) -> str:
    """The caster ``backend`` names on ``device``; a bad name ends the script in one line, exit 2."""
    try:
        return resolve_backend(backend, device)
    except ValueError as error:
        parser.exit(2, f"{parser.prog}: error: {error}\n")  # as the commands answer


def device_and_backend(
    description: str, parser: argparse.ArgumentParser | None = None
) -> tuple[torch.device, str, argparse.Namespace]:
    """The ``--device`` (auto, cpu or cuda) and ``--backend`` a benchmark is run with, and all its
    parsed options (``parser``: one with the benchmark's own options); a bad device or backend ends it
    in one line with exit status 2, as the commands answer."""
    parser = parser or argparse.ArgumentParser(description=description)
    parser.add_argument("--device", default="cpu", help="auto, cpu or cuda")
    add_backend_option(parser)
    args = parser.parse_args()
    try:
        device = resolve_device(args.device)
    except ValueError as error:
        parser.exit(2, f"{parser.prog}: error: {error}\n")
    return device, checked_backend(parser, args.backend, device), args


def check_names(parser: argparse.ArgumentParser, options: dict[str, tuple[list[str], tuple[str, ...]]]) -> None:
    """End the script in one line (exit status 2) when an option names something unknown:
    ``options`` maps each option to the names given and the names known."""
    for option, (given, known) in options.items():
        if set(given) - set(known):
            parser.error(f"{option}: no {', '.join(sorted(set(given) - set(known)))}; choose from {', '.join(known)}")


def integer_list(
    parser: argparse.ArgumentParser, option: str, text: str, least: int = 0, empty: bool = False
) -> list[int]:
    """The integers of a comma-separated option, each at least ``least`` (``empty``: '' gives none);
    a bad one ends the script in one line (exit status 2)."""
    items = [item.strip() for item in text.split(",")] if text or not empty else []
    if not all(item.isdigit() and int(item) >= least for item in items):
        kind = "non-negative integers" if least == 0 else f"integers of at least {least}"
        parser.error(f"{option}: {kind}, comma-separated, got {text!r}")
    return [int(item) for item in items]


def default_lighting() -> str:
    """The lighting the commands render the benchmarks' scenes with by default (``render.lighting`` in
    conf/render/exact.yaml; ``auto`` is ``baked`` for a scene that is not a scan)."""
    path = Path(__file__).resolve().parents[1] / "conf" / "render" / "exact.yaml"
    lighting = yaml.safe_load(path.read_text())["lighting"]
    return "baked" if lighting == "auto" else lighting


def bench_scenes() -> list[Scene]:
    """The box room and the three real scenes."""
    return [box_room(seed=0)] + [load_scene(scenes_root() / name / "scene.xml") for name in REAL_SCENES]


def timings(fn: Callable[[], object], repeats: int, warmup: int = 1) -> list[float]:
    """Seconds of ``repeats`` calls of ``fn`` after ``warmup`` untimed ones."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return times


def median_seconds(fn: Callable[[], object], repeats: int = 7, warmup: int = 1) -> float:
    return statistics.median(timings(fn, repeats, warmup))


def fastest_seconds(fn: Callable[[], object], repeats: int = 3, warmup: int = 1) -> float:
    """The fastest of ``repeats`` calls: on a shared machine, noise only ever adds time."""
    return min(timings(fn, repeats, warmup))


def scene_file(name: str) -> Path:
    """A shared scene's XML by name, else the path as given (a scene file of the user's)."""
    path = scenes_root() / name / "scene.xml"
    return path if name in REAL_SCENES or path.is_file() else Path(name)


def load_bench_scene(name: str) -> Scene:
    """A real scene by name or path (:func:`scene_file`), or the procedural box room for "box_room"."""
    return box_room(seed=0) if name == "box_room" else load_scene(scene_file(name))


def render_preset(name: str) -> DiffRenderConfig:
    """The DiffRenderConfig a ``render=<name>`` preset in conf/render/ gives the attack."""
    folder = Path(__file__).resolve().parents[1] / "conf" / "render"
    preset = yaml.safe_load((folder / f"{name}.yaml").read_text())
    base = yaml.safe_load((folder / "exact.yaml").read_text())
    options = {**base["differentiable"], **preset.get("differentiable", {})}
    return DiffRenderConfig(supersample=preset.get("supersample", base["supersample"]), **options)
