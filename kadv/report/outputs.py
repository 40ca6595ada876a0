"""The files of an attack's run directory: trajectory, views, figures, video, summary.

Every file is written atomically; ``summary.json`` is written last, so a run directory holding it
is complete (what a run keeps to resume from, and its lock: :mod:`kadv.report.store`).
"""

from __future__ import annotations

import csv
import io
import platform
from dataclasses import fields
from importlib import metadata
from pathlib import Path

import matplotlib
import numpy as np
import torch

from kadv.attack import AttackResult, InitView, InitViewResult, Objective, ViewRecord, best_so_far, incumbent_path
from kadv.attack.records import Budget
from kadv.attack.space import FOV
from kadv.geometry import fov_intrinsics
from kadv.io import atomic_write
from kadv.losses import aligned_depth
from kadv.penalties.validity import UNINFORMATIVE
from kadv.report.figures import (
    PlanRaster,
    colourise,
    loss_label,
    save_curves,
    save_four_panel,
    save_map,
    save_video,
    video_frame,
)
from kadv.report.images import depth_range
from kadv.report.store import SUMMARY, remove_partial_results
from kadv.report.summary import (
    AnytimePoint,
    InitViewSummary,
    RunInfo,
    RunSummary,
    ViewMetrics,
)

__all__ = [
    "PROFILE_PNG",
    "TRAJECTORY",
    "ViewRenderer",
    "read_trajectory",
    "save_view_picture",
    "trajectory_rows",
    "write_run",
]

TRAJECTORY = "trajectory.csv"
PROFILE_PNG = "profile.png"
_PACKAGES = ("kadv", "torch", "kornia", "open3d-cpu", "trimesh", "transformers", "numpy", "cma", "nevergrad")
_MAX_VIDEO_FRAMES = 200
# the video's panels are this many pixels high (upscaled from small attack renders)
_VIDEO_HEIGHT = 240


def trajectory_rows(result: AttackResult) -> list[dict]:
    """One row per evaluated view: where, the objective's terms, validity, guard and renderer agreement
    (not its clock, which differs from machine to machine and run to run)."""
    rows = []
    for index, view in enumerate(result.views):
        for r in view.records:
            row = {"init_view": index, "run": r.run, "step": r.step, "restart": r.restart}
            row.update({f"theta_{a}": v for a, v in zip("xyz", r.theta)})
            row.update({f"c_{a}": v for a, v in zip("xyz", r.centre)})
            row.update({f"omega_{a}": v for a, v in zip("xyz", r.params[:3])})
            row.update({f"delta_{a}": v for a, v in zip("xyz", r.params[3:6])})
            if len(r.params) > FOV:  # the field of view was searched
                row["fov_offset_deg"] = r.params[FOV]
            row.update(
                {
                    f.name: getattr(r, f.name)
                    for f in fields(r)
                    if f.name not in ("run", "step", "restart", "params", "theta", "centre", "seconds")
                }
            )
            rows.append(row)
    return rows


def _vector(row: dict[str, str], prefix: str) -> list[float]:
    return [float(row[f"{prefix}_{axis}"]) for axis in "xyz"]


def read_trajectory(path: str | Path) -> dict[int, list[ViewRecord]]:
    """The records a ``trajectory.csv`` (:func:`trajectory_rows`) holds, per init view index, in
    evaluation order; their ``seconds``, which the file leaves out, are NaN."""
    with open(path, newline="") as file:
        rows = list(csv.DictReader(file))
    flag = lambda text: text == "True"
    parse = {"step": int, "restart": int, "run": int, "passes": int, "verdict": str}
    parse |= {"refreshed": flag, "screened": flag}
    records: dict[int, list[ViewRecord]] = {}
    for row in rows:
        values = {f.name: parse.get(f.name, float)(row[f.name]) for f in fields(ViewRecord) if f.name in row}
        values |= {
            "theta": _vector(row, "theta"),
            "centre": _vector(row, "c"),
            "params": _vector(row, "omega") + _vector(row, "delta"),
        }
        if row.get("fov_offset_deg"):
            values["params"].append(float(row["fov_offset_deg"]))
        records.setdefault(int(row["init_view"]), []).append(ViewRecord(**values))
    return records


def _write_csv(path: Path, rows: list[dict]) -> Path:
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows({k: repr(v) if isinstance(v, float) else v for k, v in row.items()} for row in rows)
    text = buffer.getvalue()
    return atomic_write(path, lambda tmp: tmp.write_text(text))


class ViewRenderer:
    """Re-renders recorded views exactly and predicts on them, for pictures."""

    def __init__(self, objective: Objective, height: int, width: int, supersample: int) -> None:
        self.objective, self.height, self.width, self.supersample = objective, height, width, supersample

    def __call__(self, init: InitView, records: list[ViewRecord]) -> dict[str, np.ndarray]:
        poses = torch.stack([r.world_T_cam(init.world_T_cam) for r in records])
        fov = torch.tensor([r.fov(init.fov_x_deg) for r in records], dtype=torch.float64)
        K = fov_intrinsics(fov, self.height, self.width)
        with torch.no_grad():
            out = self.objective.renderer.render(poses, K, self.height, self.width, self.supersample).to("cpu")
            prediction = self.objective.model(out.rgb, K)
            objective = self.objective
            aligned = aligned_depth(
                prediction.double(),
                out.depth.double(),
                out.mask,
                objective.model.output_kind,
                objective.metric_space,
                objective.alignment,
            )
        return {
            "rgb": out.rgb.permute(0, 2, 3, 1).numpy(),
            "depth": out.depth[:, 0].numpy(),
            "prediction": prediction[:, 0].numpy(),
            "aligned": aligned[:, 0].float().numpy(),
            "mask": out.mask[:, 0].numpy(),
            "world_T_cam": poses.numpy(),
            "K": K.numpy(),
        }


def _title(label: str, record: ViewRecord, init: InitView) -> str:
    return (
        f"{label}: L_depth {record.l_depth:.4f}, delta1 {record.delta1:.3f}, AbsRel {record.abs_rel:.3f}, "
        f"field of view {record.fov(init.fov_x_deg):.1f}° (step {record.step}, restart {record.restart})"
    )


def _four_panel(path: Path, maps: dict[str, np.ndarray], b: int, title: str, objective: Objective) -> Path:
    """View ``b`` of a :class:`ViewRenderer`'s maps as a four-panel PNG, its fit named."""
    views = (maps["rgb"][b], maps["depth"][b], maps["aligned"][b], maps["mask"][b])
    fit = "none" if objective.alignment == "none" else f"{objective.alignment} in {objective.metric_space}"
    return save_four_panel(path, *views, title, fit)


def save_view_picture(path: str | Path, render: ViewRenderer, init: InitView, record: ViewRecord, label: str) -> Path:
    """The recorded view ``record`` from ``init`` as a four-panel PNG at ``path``, titled with its metrics."""
    return _four_panel(Path(path), render(init, [record]), 0, _title(label, record, init), render.objective)


def _save_views(views_dir: Path, index: int, view: InitViewResult, render: ViewRenderer) -> list[str]:
    records = [view.init_record, *view.top]
    names = [f"init{index}"] + [f"init{index}_adv{rank}" for rank in range(len(view.top))]
    maps = render(view.init, records)
    for b, (name, record) in enumerate(zip(names, records)):
        label = "init view" if b == 0 else f"adversarial view {b}"
        _four_panel(views_dir / f"{name}.png", maps, b, _title(label, record, view.init), render.objective)
        arrays = {k: v[b] for k, v in maps.items()}
        atomic_write(views_dir / f"{name}.npz", lambda tmp, a=arrays: np.savez_compressed(str(tmp), **a))
    return [f"views/{name}.png" for name in names]


def _video_frames(view: InitViewResult, render: ViewRenderer, plan: PlanRaster) -> list[np.ndarray]:
    """The search in evaluation order, one frame per full-size evaluated view (evenly thinned to
    at most :data:`_MAX_VIDEO_FRAMES`): image | depth | prediction | error and the plan with the
    camera and the path of the best views so far, with the step, L_depth and delta1 written above."""
    order = {id(r): position for position, r in enumerate(view.records)}
    shown = [r for r in view.records if r.scale == 1.0 and not r.screened]
    shown = shown[:: max(1, -(-len(shown) // _MAX_VIDEO_FRAMES))]
    incumbents = incumbent_path(view.records)
    frames = []
    for start in range(0, len(shown), 16):
        chunk = shown[start : start + 16]
        maps = render(view.init, chunk)
        for b, record in enumerate(chunk):
            mask, depth, aligned = maps["mask"][b], maps["depth"][b], maps["aligned"][b]
            low, high = depth_range(depth, mask)
            error = np.where(mask, np.abs(aligned - depth) / np.maximum(depth, 1e-6), 0.0)
            panels = [
                (np.clip(maps["rgb"][b], 0, 1) * 255 + 0.5).astype(np.uint8),
                colourise(depth, mask, low, high),
                colourise(aligned, mask, low, high),
                (matplotlib.colormaps["magma"](np.clip(error / 0.5, 0, 1))[..., :3] * 255).astype(np.uint8),
            ]
            best = [r for r in incumbents if order[id(r)] <= order[id(record)]]
            text = (
                f"{view.init.name}  step {record.step}  L_depth {record.l_depth:.4f}  delta1 {record.delta1:.3f}"
                f"  fov {record.fov(view.init.fov_x_deg):.0f}°"
                f"  (best so far: delta1 {best[-1].delta1:.3f})   image | depth | prediction | |pred-gt|/gt | plan"
            )
            trail = np.array([r.centre for r in best])
            frames.append(video_frame(panels, plan.with_camera(trail, maps["world_T_cam"][b]), text, _VIDEO_HEIGHT))
    return frames


def _versions() -> dict[str, str]:
    versions = {"python": platform.python_version()}
    for package in _PACKAGES:
        try:
            versions[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            continue
    return versions


def write_run(
    run_dir: str | Path,
    result: AttackResult,
    objective: Objective,
    info: RunInfo,
    supersample: int,
    video: bool = True,
    profile=None,
) -> RunSummary:
    """Write the run's artefacts and, last, ``summary.json``; returns the summary.

    Args:
        run_dir: the run directory.
        result: the attack's result.
        objective: the objective (its renderer and model re-render the views for pictures).
        info: what the run was; its image size is the attack's.
        supersample: the attack's supersampling.
        video: also write ``trajectory.mp4`` of the run with the largest gain.
        profile: a :class:`kadv.attack.Profile` of the run (``attack.radii``): kept in the summary
            and drawn in ``profile.png``.
    """
    run_dir = Path(run_dir)
    render = ViewRenderer(objective, info.height, info.width, supersample)
    _write_csv(run_dir / TRAJECTORY, trajectory_rows(result))
    per_view = [
        _init_view_summary(index, view, _save_views(run_dir / "views", index, view, render))
        for index, view in enumerate(result.views)
    ]
    label = loss_label(info.loss)
    save_curves(run_dir / "loss.png", result.views, label)
    save_map(run_dir / "map.png", objective.renderer.scene, result.views, label)
    if video:  # the worst failure: the init view whose kept view lost the most delta1
        worst = max(result.views, key=lambda v: (v.init_record.delta1 - v.top[0].delta1) if v.top else -np.inf)
        cut = float(worst.init.world_T_cam[1, 3]) + 0.3
        centres = np.array([r.centre for r in worst.records])
        plan = PlanRaster(objective.renderer.scene, cut, _VIDEO_HEIGHT, centres)
        save_video(run_dir / "trajectory.mp4", _video_frames(worst, render, plan))
    kept = [v for v in per_view if v.adversarial]
    summary = RunSummary(
        **vars(info),
        method=result.method,
        init_l_depth=_mean(v.init.l_depth for v in kept),
        init_delta1=_mean(v.init.delta1 for v in kept),
        adversarial_l_depth=_mean(v.adversarial_mean["l_depth"] for v in kept),
        adversarial_delta1=_mean(v.adversarial_mean["delta1"] for v in kept),
        budget=sum((v.budget for v in per_view), Budget()),
        versions=_versions(),
        init_views=per_view,
        profile=None if profile is None else profile.to_dict(),
        alignment=objective.alignment,
        space=objective.metric_space,
    )
    if profile is not None:
        profile.save_png(run_dir / PROFILE_PNG)
    summary.write(run_dir / SUMMARY)
    # after the summary: a run cut short before it still finds every finished init view there
    remove_partial_results(run_dir)
    return summary


def _mean(values) -> float:
    return float(np.mean(list(values)))


def _init_view_summary(index: int, view: InitViewResult, pictures: list[str]) -> InitViewSummary:
    adversarial = [ViewMetrics.of(r, png) for r, png in zip(view.top, pictures[1:])]
    return InitViewSummary(
        index=index,
        name=view.init.name,
        source=view.init.source,
        note=view.init.note,
        fov_x_deg=view.init.fov_x_deg,
        init_world_T_cam=view.init.world_T_cam.tolist(),
        init=ViewMetrics.of(view.init_record, pictures[0]),
        adversarial=adversarial,
        adversarial_mean={
            k: _mean(getattr(a, k) for a in adversarial) if adversarial else None
            for k in ("l_depth", "delta1", "abs_rel")
        },
        l_depth_gain=(view.top[0].l_depth - view.init_record.l_depth) if view.top else 0.0,
        anytime=[AnytimePoint(*point) for point in best_so_far(view.records)],
        invalid_views=sum(not r.valid for r in view.records),
        uninformative_views=sum(r.verdict == UNINFORMATIVE for r in view.records),
        guarded_steps=sum(r.guard_fraction < 1.0 for r in view.records),
        budget=view.budget,
        agreement=view.agreement,
    )
