"""An entry: one model's run of a suite, as one JSON file.

A run is made of run units, (scene, init view, search seed): the radii are nested and each is
warm-started from the smaller ones, so one unit searches all of its view's radii. Each unit is
written to ``<out>/units/`` as it ends (atomically), so a run killed at any instant resumes where
it stopped, and shards of the units (``shard=(i, n)``) run as separate jobs into one folder; the
entry is assembled from the units once all are there.
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from kadv.attack import AttackConfig, Study, StudySettings
from kadv.attack.radii import search_radii
from kadv.attack.records import worst_record
from kadv.bench.suite import BenchError, Suite, read_json
from kadv.geometry import axis_angle_to_matrix
from kadv.io import write_json
from kadv.losses import LossConfig
from kadv.models import DepthModel
from kadv.models.counting import count_passes
from kadv.penalties import get_envelope
from kadv.render import Shading

__all__ = [
    "ENTRY_FORMAT",
    "CellResult",
    "Entry",
    "UnitResult",
    "assemble_entry",
    "claim_run_folder",
    "environment",
    "load_entry",
    "model_identity",
    "run_suite",
    "run_units",
    "suite_settings",
    "suite_units",
    "unit_path",
    "unit_search_seed",
]

ENTRY_FORMAT = 1


@dataclass(frozen=True)
class CellResult:
    """The worst view a unit's search found within one radius (or a smaller one: they are nested).

    Attributes:
        delta1, abs_rel, l_depth: the model's figures there.
        params: the pose-space point from the init view (omega, delta[, field of view offset]).
        world_T_cam: (4, 4) its pose.
        fov_x_deg: its horizontal field of view.
        passes, seconds: what the search at this radius spent (model passes, as its clock counts).
        agreement: the search's runs at this radius: [runs that reached their worst, runs made,
            1 if one run alone found it] (:class:`kadv.attack.Agreement`; empty: not recorded).
    """

    delta1: float
    abs_rel: float
    l_depth: float
    params: list[float]
    world_T_cam: list[list[float]]
    fov_x_deg: float
    passes: int
    seconds: float
    agreement: list[int] = field(default_factory=list)


@dataclass(frozen=True)
class UnitResult:
    """One run unit: the init view's figures and, per radius, the worst view found.

    Attributes:
        scene, view: indices into the suite's scenes and that scene's views.
        seed: the search seed.
        delta1_init, abs_rel_init, l_depth_init: the model at the init view.
        cells: one :class:`CellResult` per radius, smallest first.
        model_passes: the model's own count of its passes over the unit (forward and backward).
    """

    scene: int
    view: int
    seed: int
    delta1_init: float
    abs_rel_init: float
    l_depth_init: float
    cells: tuple[CellResult, ...]
    model_passes: int

    @classmethod
    def from_dict(cls, data: dict) -> UnitResult:
        return cls(**(data | {"cells": tuple(CellResult(**c) for c in data["cells"])}))

    @property
    def key(self) -> tuple[int, int, int]:
        return (self.scene, self.view, self.seed)


@dataclass(frozen=True)
class Entry:
    """One model's run of one suite (see the module docstring and docs/benchmark.md's schema).

    Attributes:
        suite: the suite's name and hash.
        model: the model's identity (:func:`model_identity`).
        seeds: the search seeds every unit ran under.
        units: every unit, in (scene, view, seed) order.
        kadv_version, bake_version: what ran it.
        environment: the torch build, the device and the machine (:func:`environment`).
        format: the file's format version.
    """

    suite: dict
    model: dict
    seeds: tuple[int, ...]
    units: tuple[UnitResult, ...]
    kadv_version: str
    bake_version: int
    environment: dict = field(default_factory=dict)
    format: int = ENTRY_FORMAT

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict, where: str = "entry") -> Entry:
        """The entry :meth:`to_dict` wrote.

        Raises:
            BenchError: another format or a missing field, naming ``where``.
        """
        if data.get("format") != ENTRY_FORMAT:
            raise BenchError(f"{where}: format {data.get('format')!r} is not {ENTRY_FORMAT}, the one kadv reads")
        try:
            units = tuple(UnitResult.from_dict(u) for u in data["units"])
            return cls(
                data["suite"], data["model"], tuple(data["seeds"]), units, data["kadv_version"],
                data["bake_version"], data.get("environment", {}), data["format"],
            )  # fmt: skip
        except (KeyError, TypeError) as error:
            raise BenchError(f"{where}: not an entry ({error!r} is missing or wrong)") from None

    def unit(self, key: tuple[int, int, int]) -> UnitResult | None:
        return next((u for u in self.units if u.key == key), None)


def load_entry(path: str | Path) -> Entry:
    """The entry in a file.

    Raises:
        BenchError: a missing or unreadable file, or one that is not an entry.
    """
    return Entry.from_dict(read_json(path, f"entry {path}"), f"entry {path}")


def model_identity(model: DepthModel) -> dict:
    """What says which model an entry is of: its name, class, output kind, preprocessing, its
    inference settings (:meth:`~kadv.models.DepthModel.inference_settings`), and the SHA-256 of its
    weights (every parameter and buffer by name, dtype, shape and bytes)."""
    digest = hashlib.sha256()
    for name, tensor in sorted({**dict(model.named_parameters()), **dict(model.named_buffers())}.items()):
        value = tensor.detach().cpu().contiguous()
        digest.update(f"{name}|{value.dtype}|{tuple(value.shape)}|".encode())
        digest.update(value.view(torch.uint8).numpy().tobytes() if value.numel() else b"")
    preprocess = asdict(model.preprocess) if model.preprocess is not None else None
    return {
        "name": model.name,
        "class": type(model).__name__,
        "output_kind": model.output_kind,
        "preprocessing": preprocess,
        "settings": model.inference_settings(),
        "weights": digest.hexdigest(),
    }


def environment(device: str | torch.device = "cpu") -> dict:
    """The torch build, the device and the machine a run used."""
    return {
        "torch": torch.__version__,
        "device": str(device),
        "python": platform.python_version(),
        "machine": platform.machine(),
        "processor": _processor(),
        "cores": os.cpu_count(),
        "threads": torch.get_num_threads(),
    }


def _processor() -> str:
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:
        return platform.processor()
    return next((line.split(":", 1)[1].strip() for line in lines if line.startswith("model name")), "")


def suite_units(suite: Suite, seeds: tuple[int, ...]) -> list[tuple[int, int, int]]:
    """Every (scene, view, seed) of a run of ``suite`` under ``seeds``, in order."""
    return [(s, v, seed) for s, v in suite.views for seed in seeds]


def unit_path(out: str | Path, key: tuple[int, int, int]) -> Path:
    """Where a run under ``out`` writes the unit ``key`` (scene, view, seed)."""
    return Path(out) / "units" / f"scene{key[0]:03d}-view{key[1]:02d}-seed{key[2]}.json"


def suite_settings(suite: Suite, device) -> StudySettings:
    """The study settings a suite's protocol fixes (size, lighting, loss, search), on ``device``."""
    protocol = suite.protocol
    config = AttackConfig(protocol.method, envelope=get_envelope(protocol.envelope), restarts=protocol.restarts)
    return StudySettings(
        size=protocol.size,
        shading=Shading(lighting=protocol.lighting),
        loss=LossConfig(kind=protocol.loss, space=protocol.space, alignment=protocol.alignment),
        attack=config,
        device=device,
        progress=False,
    )


def _run_unit(study: Study, suite: Suite, key: tuple[int, int, int]) -> UnitResult:
    """Search one unit's radii (a fresh differentiable renderer, so a unit's result does not depend
    on the units run before it in the same process)."""
    scene_index, view_index, seed = key
    protocol = suite.protocol
    view = suite.scenes[scene_index].views[view_index].init_view()
    fresh = study.variant()
    with count_passes(fresh.model) as count:
        results = search_radii(
            fresh,
            [view],
            fresh.settings.attack,
            protocol.radii,
            unit_search_seed(key),
            budgets=list(protocol.radius_passes),
        )
    init = results[0].views[0].init_record
    cells, worst = [], None
    for result in results:
        searched = result.views[0]
        found = worst_record(searched.records)
        worst = found if worst is None or found.delta1 < worst.delta1 else worst
        cells.append(_cell(worst, searched.budget, searched.agreement))
    return UnitResult(
        scene_index, view_index, seed, init.delta1, init.abs_rel, init.l_depth, tuple(cells), count.passes
    )


def unit_search_seed(key: tuple[int, int, int]) -> int:
    """The seed a run unit (scene, view, seed) searches under: drawn from all three, so that the
    cells of one seed search independently of each other. Under the seed alone every init view's
    search would draw the same design relative to its view, the cells' search noise would move
    together, and the suite score's interval over seeds, which takes the cells as independent,
    would be too narrow (measured: docs/benchmark.md)."""
    return int(np.random.SeedSequence(list(key)).generate_state(1)[0])


def _cell(record, budget, agreement) -> CellResult:
    """A unit's worst view within a radius, with what the search there cost and how its runs agreed."""
    pose = torch.eye(4, dtype=torch.float64)
    pose[:3, :3] = axis_angle_to_matrix(torch.tensor(record.theta, dtype=torch.float64)[None])[0]
    pose[:3, 3] = torch.tensor(record.centre, dtype=torch.float64)
    return CellResult(
        record.delta1, record.abs_rel, record.l_depth, list(record.params), pose.tolist(), record.fov_x_deg,
        budget.passes, budget.seconds, [agreement.reached, agreement.runs, int(agreement.alone)],
    )  # fmt: skip


def run_suite(
    suite: Suite,
    model: DepthModel,
    seeds: tuple[int, ...],
    out: str | Path,
    shard: tuple[int, int] = (0, 1),
    root: str | Path | None = None,
    device: str | torch.device = "cpu",
    progress: bool = True,
) -> Entry | None:
    """Run ``suite`` on ``model`` under search ``seeds``: the units of ``shard`` (i, n: every n-th
    unit from the i-th) not yet written under ``out``, each written as it ends. Returns the entry,
    written to ``out/entry.json``, once every unit of the run is there; None while some are not.

    Raises:
        BenchError: fewer seeds than the protocol asks, a bad shard, or a scene that cannot load.
    """
    out = Path(out)
    seeds = tuple(seeds)
    if len(set(seeds)) < suite.protocol.min_seeds or len(set(seeds)) != len(seeds):
        raise BenchError(
            f"seeds: the suite asks for {suite.protocol.min_seeds} distinct seeds or more, got {list(seeds)}"
        )
    index, count = shard
    if not (0 <= index < count):
        raise BenchError(f"shard must be i/n with 0 <= i < n, got {index}/{count}")
    claim_run_folder(out, suite, model)
    every = suite_units(suite, seeds)
    todo = [key for k, key in enumerate(every) if k % count == index and not unit_path(out, key).is_file()]
    settings = suite_settings(suite, device)
    bar = tqdm(total=len(todo), desc=f"{suite.name} on {model.name}", unit="unit", disable=not progress)
    for scene_index in sorted({key[0] for key in todo}):
        study = Study.build(suite.scenes[scene_index].load(root), model, settings)
        run_units(study, suite, [key for key in todo if key[0] == scene_index], out, bar.update)
    bar.close()
    return assemble_entry(suite, model, seeds, out, device)


def run_units(
    study: Study, suite: Suite, keys: list[tuple[int, int, int]], out: str | Path, done=None
) -> list[UnitResult]:
    """Run the units ``keys`` of one scene on its ``study`` (the suite's settings), each written
    under ``out`` as it ends; a unit already written is read back. ``done(1)`` is called after
    each. Returns the units, in the order of ``keys``."""
    units = []
    for key in keys:
        path = unit_path(out, key)
        if path.is_file():
            units.append(_read_unit(path))
        else:
            units.append(_run_unit(study, suite, key))
            write_json(path, asdict(units[-1]))
        if done is not None:
            done(1)
    return units


def _read_unit(path: Path) -> UnitResult:
    return UnitResult.from_dict(json.loads(path.read_text()))


def claim_run_folder(out: str | Path, suite: Suite, model: DepthModel) -> None:
    """Mark ``out`` as the folder of ``model``'s run of ``suite`` (``run.json``), so that a run of
    another suite or model never resumes from its units.

    Raises:
        BenchError: ``out`` holds the units of another suite or model.
    """
    identity = model_identity(model)
    # settings only where the model has any, so that folders of models without them stay valid
    claim = {"suite": suite.hash, "weights": identity["weights"]} | (
        {"settings": identity["settings"]} if identity["settings"] else {}
    )
    path = Path(out) / "run.json"
    if path.is_file():
        held = read_json(path, f"run folder {out}")
        for key, what in (("suite", "suite"), ("weights", "model")):
            if held.get(key) != claim[key]:
                raise BenchError(
                    f"out={out} holds the run of another {what} ({key} {str(held.get(key))[:16]}, this run's "
                    f"{claim[key][:16]}): give another out"
                )
        return
    write_json(path, claim)


def assemble_entry(
    suite: Suite, model: DepthModel, seeds: tuple[int, ...], out: str | Path, device: str | torch.device = "cpu"
) -> Entry | None:
    """The entry of the units under ``out`` (written to ``out/entry.json``), or None while one of
    the run's units is missing."""
    out = Path(out)
    paths = [unit_path(out, key) for key in suite_units(suite, tuple(seeds))]
    if not all(path.is_file() for path in paths):
        return None
    import kadv

    units = tuple(_read_unit(path) for path in paths)
    entry = Entry(
        {"name": suite.name, "hash": suite.hash},
        model_identity(model),
        tuple(seeds),
        units,
        kadv.__version__,
        suite.bake_version,
        environment(device),
    )
    write_json(out / "entry.json", entry.to_dict())
    return entry
