"""``kadv-attack``: find camera views where a depth model fails; writes the run directory."""

from __future__ import annotations

# before anything loads torch: the wait policy is read when torch starts its thread pool
from kadv.runtime import configure_runtime

configure_runtime()

import contextlib
import dataclasses
import functools
import json
import logging
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf

from kadv.attack import (
    DEFAULT_METHOD,
    METHODS,
    AttackConfig,
    InitViewConfig,
    Objective,
    PenaltyConfig,
    Study,
    agreement_text,
    captured_init_views,
    check_init_views,
    file_init_views,
    get_method,
    load_init_params,
    sample_init_views,
    save_init_params,
)
from kadv.attack.profile import Profile
from kadv.attack.radii import WARM_STARTS, profile_views, radius_budgets, search_radii, warm_starts
from kadv.cli.common import (
    check_render_config,
    checks_overrides,
    config_int,
    frame_note,
    loss_settings,
    model_from_config,
    reports_user_errors,
    scene_from_config,
    settings_from_node,
    study_settings,
)
from kadv.device import resolve_device
from kadv.interrupts import Interrupted, interruptible
from kadv.io import atomic_write, remove_temporaries
from kadv.models import count_passes
from kadv.penalties import ENVELOPES, Envelope
from kadv.report.outputs import write_run
from kadv.report.store import (
    SUMMARY,
    check_same_settings,
    is_complete,
    load_partial_results,
    remove_partial_results,
    run_lock,
    save_partial_result,
)
from kadv.report.summary import RunInfo, RunSummary
from kadv.testing.options import check_radii

log = logging.getLogger(__name__)

INIT_PARAMS = "init_params.json"


def attack_settings(cfg: DictConfig, envelope: DictConfig | None = None) -> AttackConfig:
    """The ``attack`` node as an :class:`AttackConfig`: the shared keys, ``method``, and that method's
    ``attack.<method>`` node as its settings dataclass, with the ``envelope`` node's bounds; unknown
    keys are errors."""
    node = OmegaConf.to_container(cfg, resolve=True)
    if envelope is not None:
        bounds = settings_from_node(Envelope, OmegaConf.to_container(envelope, resolve=True), "envelope")
        if bounds.name in ENVELOPES and bounds != ENVELOPES[bounds.name]:  # a preset with a bound overridden
            bounds = dataclasses.replace(bounds, name="custom")
        node["envelope"] = bounds
    node.pop("radii", None)  # a profile run's radii: attack_radii
    method = get_method(node.pop("method", DEFAULT_METHOD))
    settings = settings_from_node(method.settings, node.pop(method.name, None), f"attack.{method.name}")
    for name in METHODS:  # the nodes of other methods (a preset may carry several) are not this run's
        node.pop(name, None)
    return settings_from_node(AttackConfig, {"method": method.name, "settings": settings, **node}, "attack")


def attack_radii(cfg: DictConfig) -> tuple[tuple[float, float], ...] | None:
    """``attack.radii``: the nested (degrees, metres) radii of a profile run, or None for none."""
    radii = cfg.get("radii")
    if radii is None:
        return None
    try:
        return check_radii(OmegaConf.to_container(radii, resolve=True) if OmegaConf.is_config(radii) else radii)
    except ValueError as error:
        raise ValueError(f"attack.{error}") from None


def _init_views(
    seed: int, run_dir: Path, objective: Objective, init_config: InitViewConfig, height: int, width: int
) -> tuple[list, int]:
    """The run's init views: those saved in the run directory (a resumed run), a given file, or chosen
    now (scored as the objective scores views: its model, after its alignment); and the model
    passes that chose them."""
    renderer, model, penalty = objective.renderer, objective.model, objective.penalty
    saved = run_dir / INIT_PARAMS
    if saved.is_file():
        return load_init_params(saved), json.loads(saved.read_text()).get("model_passes", 0)
    with count_passes(model) as count:
        if init_config.params:
            views = load_init_params(init_config.params)
        else:
            views = file_init_views(renderer, penalty.margin)[: init_config.count] if init_config.file_cameras else []
            captured = init_config.source == "captured" or (
                init_config.source == "auto" and renderer.scene.trajectory is not None
            )
            choose = captured_init_views if captured else functools.partial(sample_init_views, seed=seed)
            if captured:
                log.info(
                    "init.source=captured: init views from the capture path in %s", renderer.scene.trajectory_source
                )
            views += choose(
                renderer, model, init_config.count - len(views), config=init_config, penalty=penalty,
                height=height, width=width, alignment=objective.alignment,
            )  # fmt: skip
    check_init_views(renderer, views, penalty, height, width)
    save_init_params(saved, views, count.passes)
    return views, count.passes


def _table(summary: RunSummary) -> str:
    """The run's table and, under it, what each init view's search cost."""
    # the study's disparity space is the one a header leaves unsaid (make demo's table as it was)
    fit = summary.alignment if summary.space == "disparity" else f"{summary.alignment} in {summary.space}"
    searched = summary.fov_deg is not None
    fov = f" fov init | fov adv ({summary.fov_deg[0]:g}° to {summary.fov_deg[1]:g}°) |" if searched else ""
    lines = [
        f"| init view | L_depth init | L_depth adv | delta1 init ({fit}) | delta1 adv ({fit}) | agreement |{fov}",
        "|---|---|---|---|---|---|" + "---|---|" * searched,
    ]
    for view in summary.init_views:
        adv = view.adversarial_mean
        line = (
            f"| {view.name} | {view.init.l_depth:.4f} | {adv['l_depth']:.4f} | "
            f"{view.init.delta1:.3f} | {adv['delta1']:.3f} | {agreement_text(view.agreement)} |"
        )
        if searched:  # each kept view's, the worst first
            kept = ", ".join(f"{a.fov_x_deg:.0f}°" for a in view.adversarial)
            line += f" {view.fov_x_deg:.0f}° | {kept} |"
        lines.append(line)
    lines += ["", "model passes and seconds per init view:"]
    lines += [f"  {view.name}: {view.budget.text()}" for view in summary.init_views]
    lines.append(f"  (choosing the init views: {summary.init_passes} passes)")
    if summary.intrinsics != "not taken":  # a model that takes the camera: was it told?
        lines.append(f"camera intrinsics: {summary.intrinsics} (model.intrinsics)")
    return "\n".join(lines)


def _interruptible_throughout(entry: Callable[[], Any]) -> Callable[[], Any]:
    """Decorate the command so that SIGINT and SIGTERM outside a run too (while Hydra starts, or
    between a sweep's jobs) end it with one line and exit status 130 or 143, not a traceback or
    a silent kill; a run's own interruption says more (:func:`main`)."""

    @functools.wraps(entry)
    def wrapped() -> Any:
        try:
            with interruptible():
                return entry()
        except Interrupted as interruption:
            print(
                "interrupted between runs: each finished run is kept; run the same command to resume", file=sys.stderr
            )
            sys.exit(interruption.exit_status)

    return wrapped


@_interruptible_throughout
@checks_overrides("kadv-attack")
@hydra.main(version_base="1.3", config_path="../conf", config_name="kadv_attack")
@reports_user_errors("kadv-attack")
def main(cfg: DictConfig) -> float:
    """Run the configured attack; returns the mean adversarial L_depth (for Hydra sweepers).

    One run holds its run directory at a time. SIGINT and SIGTERM end the run between files, with
    one line saying what was kept, and exit status 130 or 143; in a sweep they end the sweep so (its
    finished jobs are kept, the rest resume when it is run again), except in a job that submitit
    runs: submitit's own handlers checkpoint and requeue it.
    """
    run_dir = Path(HydraConfig.get().runtime.output_dir)
    progress = {"done": 0, "total": cfg.init.get("count")}
    under_submitit = bool(os.environ.get("SUBMITIT_EXECUTOR"))
    try:
        # the handlers first: a signal that came once the lock was visible but before them would kill
        # the process with nothing said (a launcher's worker process runs jobs without the decorator)
        with contextlib.nullcontext() if under_submitit else interruptible(), run_lock(run_dir):
            return _attack(cfg, run_dir, progress)
    except Interrupted as interruption:
        print(
            f"interrupted: {progress['done']} of {progress['total']} init views done, kept in {run_dir}; "
            "run the same command to resume",
            file=sys.stderr,
        )
        sys.exit(interruption.exit_status)


# keys that change how a run shows its progress, not what it finds: a run may resume without them
_PRESENTATION = frozenset({"progress"})
# keys whose ``auto`` a run writes back resolved (render.lighting: resolve_lighting)
_RESOLVED = frozenset({"render.lighting"})


def _check_same_settings(run_dir: Path, cfg: DictConfig) -> None:
    """Refuse to skip or resume a run directory whose run (its ``config.yaml``) was made with other
    settings than ``cfg``, naming them: its results would pass for this config's."""
    path = run_dir / "config.yaml"
    if path.is_file():
        saved = OmegaConf.to_container(OmegaConf.load(path))
        now = OmegaConf.to_container(cfg, resolve=True)
        check_same_settings(run_dir, saved, now, _PRESENTATION, _RESOLVED, "set hydra.run.dir to another folder")


def _search_settings(cfg: DictConfig) -> tuple[AttackConfig, tuple | None, list | None]:
    """The run's search (``attack``, ``envelope``), and for a profile run (``attack.radii``) its
    radii and each radius's pass budget: the run itself then searches the largest radius, with its
    share of the passes (``attack.radius_shares``)."""
    attack_config = attack_settings(cfg.attack, cfg.get("envelope"))
    radii = attack_radii(cfg.attack)
    if radii is None:
        if attack_config.radius_shares is not None:
            raise ValueError("attack.radius_shares splits a profile's passes over its radii: it needs attack.radii")
        return attack_config, None, None
    budgets = radius_budgets(attack_config.budget_passes, len(radii), attack_config.radius_shares)
    largest = {"max_angle_deg": radii[-1][0], "max_distance": radii[-1][1], "budget_passes": budgets[-1]}
    return dataclasses.replace(attack_config, **largest), radii, budgets


def _profile(study: Study, views: list, radii: tuple, seed: int, results: list) -> Profile:
    """The profile of a profile run: its searches' ``results`` at every radius, and the typical views."""
    config = study.settings.attack
    seeded = profile_views(
        study, views, config, radii, seed, progress=study.settings.progress, searched=dict(enumerate(results))
    )
    names = (study.model.name, study.scene.name, config.envelope.name)
    objective = study.objective
    return Profile.of(*names, radii, (seed,), [seeded], alignment=objective.alignment, space=objective.metric_space)


def _attack(cfg: DictConfig, run_dir: Path, progress: dict) -> float:
    """The run itself; ``progress`` counts the init views done (for the line an interruption prints)."""
    # a run killed mid-write (SIGKILL, a lost node) leaves the file it was writing as a temporary
    for path in remove_temporaries(run_dir):
        log.info("removed %s, left by a run killed while writing it", path)
    _check_same_settings(run_dir, cfg)
    if is_complete(run_dir):
        remove_partial_results(run_dir)  # left by a run killed between its summary and their removal
        summary = RunSummary.read(run_dir / SUMMARY)
        print(f"already complete, skipped: {run_dir}\n{_table(summary)}")
        return summary.adversarial_l_depth
    device = resolve_device(cfg.device)
    seed = config_int(cfg.seed, "seed")
    height, width, supersample = check_render_config(cfg.render)
    attack_config, radii, budgets = _search_settings(cfg)
    init_config = settings_from_node(InitViewConfig, OmegaConf.to_container(cfg.init, resolve=True), "init")
    penalty = settings_from_node(PenaltyConfig, OmegaConf.to_container(cfg.penalty, resolve=True), "penalty")
    attack_config.check_run(get_method(attack_config.method).check, supersample)
    scene = scene_from_config(cfg.scene)
    if (note := frame_note(scene)) is not None:
        log.info(note)
    loss = loss_settings(cfg.loss)
    settings = study_settings(
        scene, cfg.render, device, loss=loss, penalty=penalty, attack=attack_config, progress=cfg.progress
    )
    study = Study.build(scene, model_from_config(cfg.model), settings)
    objective = study.objective
    config_text = OmegaConf.to_yaml(cfg, resolve=True)  # render.lighting resolved
    atomic_write(run_dir / "config.yaml", lambda tmp: tmp.write_text(config_text))
    views, init_passes = _init_views(seed, run_dir, objective, init_config, height, width)
    completed = load_partial_results(run_dir)
    progress.update(done=len(completed), total=len(views))
    if completed:
        log.info("resuming: %d of %d init views already done", len(completed), len(views))

    def on_result(index: int, view) -> None:
        save_partial_result(run_dir, index, view)
        progress["done"] += 1

    smaller, starts = [], None
    if radii is not None:  # the smaller radii first: the largest's search starts from their worst views
        smaller = search_radii(study, views, attack_config, radii[:-1], seed, cfg.progress, budgets=budgets[:-1])
        starts = warm_starts(smaller, len(views), WARM_STARTS, attack_config)
    result = study.attack(views, seed, completed=completed, on_result=on_result, starts=starts)
    # the profile of all the radii
    profile = None if radii is None else _profile(study, views, radii, seed, [*smaller, result])
    fov = attack_config.envelope.fov_deg
    info = RunInfo(
        scene.name, study.model.name, cfg.loss.kind, seed, str(device), height, width, sorted(completed), init_passes,
        fov_deg=None if fov is None else list(fov), intrinsics=study.model.camera_text,
    )  # fmt: skip
    summary = write_run(run_dir, result, objective, info, supersample, video=cfg.video, profile=profile)
    print(f"run directory: {run_dir}\n{_table(summary)}")
    if profile is not None:
        print(profile.markdown())
    return summary.adversarial_l_depth


if __name__ == "__main__":
    main()
