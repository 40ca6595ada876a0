"""Check an entry: every stored worst pose rendered again and scored, one model pass a cell."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import torch

from kadv.attack import SearchContext, Study
from kadv.bench.entry import Entry, model_identity, suite_settings, suite_units
from kadv.bench.suite import BenchError, Suite
from kadv.geometry import perturb_world_T_cam
from kadv.io import file_slug
from kadv.models import DepthModel
from kadv.report.outputs import ViewRenderer, save_view_picture

__all__ = ["TOLERANCE_PIXELS", "Verification", "cell_context", "check_complete", "verified_record", "verify_entry"]

# another CPU's rounding moves the aligned prediction by a hair, and a few pixels across delta1's
# threshold with it: a stored delta1 may differ from the one verified by this many pixels' share
TOLERANCE_PIXELS = 4.0
_POSE_TOLERANCE = 1e-6  # metres and rotation-matrix entries: a pose stored in JSON is read back exactly


@dataclass(frozen=True)
class Verification:
    """What :func:`verify_entry` saw.

    Attributes:
        cells: the cells checked (unit x radius).
        largest_pixels: the largest difference between a stored and a verified delta1, in pixels.
        tolerance_pixels: the tolerance it was checked against.
        pixels: the pixels of a render.
    """

    cells: int
    largest_pixels: float
    tolerance_pixels: float
    pixels: int

    def text(self) -> str:
        return (
            f"{self.cells} cells verified; the largest difference in delta1 is {self.largest_pixels:.1f} pixels "
            f"of {self.pixels} (tolerance {self.tolerance_pixels:g})"
        )


def check_complete(entry: Entry, suite: Suite, where: str = "entry") -> None:
    """Refuse an entry of another suite, with too few seeds, or missing a cell, in one line.

    Raises:
        BenchError: naming ``where``, the cell and the field.
    """
    if entry.suite.get("hash") != suite.hash:
        raise BenchError(
            f"{where}: suite.hash {str(entry.suite.get('hash'))[:16]} is not suite {suite.name!r}'s {suite.hash[:16]}"
        )
    if len(set(entry.seeds)) < suite.protocol.min_seeds:
        raise BenchError(f"{where}: seeds {list(entry.seeds)}: the suite asks for {suite.protocol.min_seeds} or more")
    radii = len(suite.protocol.radii)
    for key in suite_units(suite, entry.seeds):
        unit = entry.unit(key)
        if unit is None or len(unit.cells) != radii:
            scene = suite.scenes[key[0]].name
            raise BenchError(f"{where}: misses the cell of scene {scene!r}, view {key[1]}, seed {key[2]} (units)")


def verify_entry(
    entry: Entry,
    suite: Suite,
    model: DepthModel,
    root=None,
    tolerance_pixels: float = TOLERANCE_PIXELS,
    where: str = "entry",
    device: str | torch.device = "cpu",
    pictures: str | Path | None = None,
) -> Verification:
    """Render every worst pose of ``entry`` again and score ``model`` there; with ``pictures``, a
    folder, each scene's worst verified view at the largest radius as a four-panel picture there
    (``<scene>.png``: image, depth, prediction, error).

    Raises:
        BenchError: in one line naming ``where``, the cell and the field: an entry of another suite
            or model, one missing a cell, a pose that is not its parameters' or lies outside its
            radius, the envelope or the valid views, or a delta1 off by more than
            ``tolerance_pixels`` pixels' share.
    """
    check_complete(entry, suite, where)
    identity = model_identity(model)
    if entry.model.get("weights") != identity["weights"]:
        raise BenchError(f"{where}: model.weights {str(entry.model.get('weights'))[:16]} is not {model.name}'s")
    if entry.model.get("settings", {}) != identity["settings"]:
        raise BenchError(f"{where}: model.settings {entry.model.get('settings', {})} are not {identity['settings']}")
    settings = suite_settings(suite, device)
    height, width = suite.protocol.size
    largest, cells = 0.0, 0
    for scene_index, scene in enumerate(suite.scenes):
        study = Study.build(scene.load(root), model, settings)
        worst = None  # the scene's lowest verified view at the largest radius: (record, init view)
        for unit in (u for u in entry.units if u.scene == scene_index):
            init = scene.views[unit.view].init_view()
            for k, cell in enumerate(unit.cells):
                name = f"{where}: scene {scene.name!r}, view {unit.view}, seed {unit.seed}, radius {k}"
                record = verified_record(name, cell, cell_context(study, suite, init, k), suite.protocol.radii[k])
                off = abs(record.delta1 - cell.delta1) * height * width
                if not off <= tolerance_pixels:
                    raise BenchError(
                        f"{name}: delta1 {cell.delta1:.4f} verifies as {record.delta1:.4f} "
                        f"({off:.1f} pixels apart, tolerance {tolerance_pixels:g})"
                    )
                largest, cells = max(largest, off), cells + 1
                if k == len(unit.cells) - 1 and (worst is None or record.delta1 < worst[0].delta1):
                    worst = (record, init)
        if pictures is not None and worst is not None:
            degrees, metres = suite.protocol.radii[-1]
            label = f"{model.name} on {scene.name}: worst within {degrees:g}°, {metres:g} m"
            render = ViewRenderer(study.objective, height, width, supersample=2)
            save_view_picture(Path(pictures) / f"{file_slug(scene.name)}.png", render, worst[1], worst[0], label)
    return Verification(cells, largest, tolerance_pixels, height * width)


def cell_context(study: Study, suite: Suite, init, radius: int) -> SearchContext:
    """The search context of a cell: ``study``'s model from the init view within the suite's
    ``radius``-th radius (its bounds, envelope and render size)."""
    degrees, metres = suite.protocol.radii[radius]
    config = dataclasses.replace(study.settings.attack, max_angle_deg=degrees, max_distance=metres)
    return SearchContext(study.objective, study.differentiable, init, *suite.protocol.size, config)


def verified_record(name: str, cell, context: SearchContext, radius: tuple[float, float]):
    """The stored pose of ``cell`` rendered and scored again, or :class:`BenchError` naming the cell
    where it is not its parameters' pose, lies outside the radius, behind a surface, or is no valid view."""
    params = torch.tensor([cell.params], dtype=torch.float64)
    _check_pose(name, cell, context, params, *radius)
    _, fraction = context.guard(torch.zeros(1, 3, dtype=torch.float64), params[:, 3:6])
    if float(fraction[0]) < 1.0:
        raise BenchError(f"{name}: world_T_cam lies behind a surface: the camera's path to it crosses one")
    (record,) = context.score(0, params, fraction)
    if not record.valid:
        raise BenchError(f"{name}: world_T_cam is not a valid view ({record.verdict})")
    return record


def _check_pose(name: str, cell, context: SearchContext, params: torch.Tensor, degrees: float, metres: float) -> None:
    """Refuse a stored pose that is not its parameters' pose from the init view, or that lies
    outside the radius."""
    if params.shape[1] != context.space.dims or not bool(torch.isfinite(params).all()):
        raise BenchError(f"{name}: params must be {context.space.dims} finite numbers, got {cell.params}")
    pose = perturb_world_T_cam(context.base(1).cpu(), params[:, :3], params[:, 3:6])[0]
    stored = torch.tensor(cell.world_T_cam, dtype=torch.float64)
    if stored.shape != (4, 4) or not torch.allclose(pose, stored, rtol=0.0, atol=_POSE_TOLERANCE):
        raise BenchError(f"{name}: world_T_cam is not the pose its params give")
    angle, distance = math.degrees(float(params[0, :3].norm())), float(params[0, 3:6].norm())
    if angle > degrees * (1 + 1e-9) or distance > metres * (1 + 1e-9):
        raise BenchError(
            f"{name}: world_T_cam lies {angle:.2f}° and {distance:.3f} m from its init view, "
            f"outside the radius {degrees:g}°, {metres:g} m"
        )
