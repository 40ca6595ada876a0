"""The scorecard as a suite run: its probes, built at its seeds, frozen into a suite
(:mod:`kadv.bench`) with a model-free init-view rule; each model's run of that suite written as an
entry (run units, resumable, verifiable with ``kadv-bench verify``); the typical views drawn beside
each unit's init view; and each probe's :class:`~kadv.attack.profile.Profile` made from them."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kadv.attack.profile import Profile
from kadv.attack.radii import draw_typical, radius_budgets
from kadv.bench import BenchError, Entry, Protocol, SceneSpec, Suite, freeze_suite
from kadv.bench.entry import assemble_entry, claim_run_folder, run_units, suite_settings
from kadv.bench.verify import cell_context, verified_record
from kadv.io import file_slug
from kadv.losses import kind_fit
from kadv.testing.inputs import RobustnessInputError
from kadv.testing.session import current

__all__ = ["ModelRun", "probe_suite", "profiles", "run_model"]


def probe_suite(probes: list[str], seeds: tuple[int, ...], settings) -> Suite:
    """The suite of ``probes`` each built at each of ``seeds`` (scene ``probe/<name>/seed<k>``),
    under the protocol of a profile's ``settings`` (:class:`kadv.testing.profile.ProfileSettings`):
    its radii, pass split, method, envelope, render and loss; as many search seeds as it takes.

    Raises:
        RobustnessInputError: an envelope that is no preset (a suite names its envelope), or a
            probe without enough valid init views.
    """
    from kadv.penalties import ENVELOPES

    checked, envelope = settings.checked, settings.config.envelope
    preset = envelope.name if ENVELOPES.get(envelope.name) == envelope else None
    if preset is None:
        raise RobustnessInputError(
            f"envelope {envelope.name!r}: a scorecard runs a suite, whose protocol names an envelope preset "
            "(free, upright, handheld, robot)"
        )
    budget = max(2, round(checked.budget_passes * current().budget_factor))
    protocol = Protocol(
        method=checked.method,
        radii=settings.radii,
        radius_passes=tuple(radius_budgets(budget, len(settings.radii), settings.config.radius_shares)),
        envelope=preset,
        min_seeds=settings.search_seeds,
        size=checked.size,
        lighting=checked.lighting,
        loss=checked.loss,
        alignment=checked.alignment,
        space=None,
        restarts=checked.restarts,
    )
    specs = [
        SceneSpec(f"probe/{probe}/seed{seed}", {"kind": "probe", "name": probe, "seed": seed})
        for probe in probes
        for seed in seeds
    ]
    try:
        return freeze_suite("probes", specs, protocol, views_per_scene=checked.init_count)
    except BenchError as error:
        raise RobustnessInputError(str(error)) from None


@dataclass
class ModelRun:
    """One model's run of a scorecard's suite.

    Attributes:
        entry: its entry (every unit's worst per radius).
        draws: per (scene, view), per radius, the delta1 of each valid view drawn uniformly there.
        draw_passes: per (scene, view), the model passes the draws spent.
        pictures: per scene, per radius, the picture of the worst view found under search seed 0.
        folder: where its units and entry are.
    """

    entry: Entry | None
    draws: dict[tuple[int, int], list[list[float]]]
    draw_passes: dict[tuple[int, int], int]
    pictures: dict[int, list[str]]
    folder: Path


def run_model(suite: Suite, model, typical_views: int, folder: Path, progress: bool = False) -> ModelRun:
    """``model``'s run of ``suite`` under search seeds 0 .. min_seeds - 1 (its units written to
    ``folder/entries/<model>-<suite hash>/``, so that a run stopped part-way resumes), with
    ``typical_views`` uniform draws per init view and radius, the same views for every model, and
    a picture of each scene's worst view per radius in ``folder``."""
    from kadv.attack import Study

    out = Path(folder) / "entries" / f"{file_slug(model.name)}-{suite.hash[:12]}"
    claim_run_folder(out, suite, model)
    seeds = tuple(range(suite.protocol.min_seeds))
    settings = suite_settings(suite, "cpu")
    run = ModelRun(None, {}, {}, {}, out)
    for s, scene in enumerate(suite.scenes):
        study = Study.build(scene.load(), model, settings)
        keys = [(s, v, j) for v in range(len(scene.views)) for j in seeds]
        units = [unit for unit in run_units(study, suite, keys, out) if unit.seed == 0]
        for v, frozen in enumerate(scene.views):
            run.draws[(s, v)], run.draw_passes[(s, v)] = _draw(
                study, suite, frozen.init_view(), scene.node["seed"], v, typical_views
            )
        run.pictures[s] = [
            _worst_picture(study, suite, s, units, k, Path(folder)) for k in range(len(suite.protocol.radii))
        ]
        if progress:
            worst = " ".join(
                f"{np.mean([u.cells[k].delta1 for u in units]):.3f}" for k in range(len(suite.protocol.radii))
            )
            print(f"{scene.name} x {model.name}: worst {worst}", flush=True)
    run.entry = assemble_entry(suite, model, seeds, out)
    return run


def _draw(study, suite: Suite, init, seed: int, index: int, count: int) -> tuple[list[list[float]], int]:
    """Per radius, the delta1 of the valid views among ``count`` drawn uniformly around ``init``
    (the design seeded by the probe's seed and the view's index), and the passes spent."""
    rows, spent = [], 0
    for degrees, metres in suite.protocol.radii:
        within = dataclasses.replace(study.settings.attack, max_angle_deg=degrees, max_distance=metres)
        drawn, passes = draw_typical(study, init, within, seed, index, count)
        rows.append(drawn)
        spent += passes
    return rows, spent


def _worst_picture(study, suite: Suite, s: int, units: list, k: int, folder: Path) -> str:
    """The four-panel picture of the worst view of scene ``s`` within the ``k``-th radius over its
    init views (search seed 0), rendered and scored again."""
    from kadv.report.outputs import ViewRenderer, save_view_picture

    scene, (degrees, metres) = suite.scenes[s], suite.protocol.radii[k]
    v = min(range(len(units)), key=lambda i: units[i].cells[k].delta1)
    init = scene.views[v].init_view()
    record = verified_record(scene.name, units[v].cells[k], cell_context(study, suite, init, k), (degrees, metres))
    render = ViewRenderer(study.objective, *suite.protocol.size, supersample=2)
    name = f"{file_slug(study.model.name)}-{file_slug(scene.name)}-{suite.protocol.envelope}-radius{k}.png"
    label = f"worst within {degrees:g}°, {metres:g} m"
    return str(save_view_picture(folder / name, render, init, record, label))


def profiles(suite: Suite, run: ModelRun, probes: list[str], fail_below: float) -> dict[str, Profile]:
    """Per probe, the model's :class:`Profile` over the probe's scenes (one a seed): per radius the
    worst delta1 (mean over init views and search seeds), the typical delta1 and failure rate of
    the drawn views, the search noise (sd over search seeds), the searches' agreement and cost."""
    units = {unit.key: unit for unit in run.entry.units}
    seeds = run.entry.seeds
    radii = suite.protocol.radii
    out = {}
    for probe in probes:
        scenes = [s for s, scene in enumerate(suite.scenes) if scene.node["name"] == probe]
        rows = [_seed_row(suite, s, units, seeds, run, fail_below) for s in scenes]
        out[probe] = Profile(
            model=run.entry.model["name"],
            scene=probe,
            envelope=suite.protocol.envelope,
            radii=radii,
            seeds=tuple(suite.scenes[s].node["seed"] for s in scenes),
            delta1_init=[row["init"] for row in rows],
            worst_by_seed=[row["worst"] for row in rows],
            typical_by_seed=[row["typical"] for row in rows],
            failure_by_seed=[row["failure"] for row in rows],
            draws=[[d for row in rows for d in row["draws"][k]] for k in range(len(radii))],
            fail_below=float(fail_below),
            pictures=run.pictures[scenes[0]],
            search_noise_by_seed=[row["noise"] for row in rows],
            cost_by_seed=[row["cost"] for row in rows],
            agreement_by_seed=[row["agreement"] for row in rows],
            alignment=kind_fit(run.entry.model["output_kind"], alignment=suite.protocol.alignment)[1],
            space=kind_fit(run.entry.model["output_kind"])[0],
        )
    return out


def _seed_row(suite: Suite, s: int, units: dict, seeds: tuple[int, ...], run: ModelRun, fail_below: float) -> dict:
    """One probe scene's share of a profile (see :func:`profiles`)."""
    views = range(len(suite.scenes[s].views))
    radii = range(len(suite.protocol.radii))
    worst = np.array([[[units[(s, v, j)].cells[k].delta1 for k in radii] for v in views] for j in seeds])
    draws = [[d for v in views for d in run.draws[(s, v)][k]] for k in radii]
    cells = [cell for v in views for j in seeds for cell in units[(s, v, j)].cells]
    searches = len(views) * len(seeds)
    return {
        "init": float(np.mean([units[(s, v, 0)].delta1_init for v in views])),
        "worst": worst.mean(axis=(0, 1)).tolist(),
        "noise": worst.mean(axis=1).std(axis=0, ddof=1).tolist() if len(seeds) > 1 else [],
        "typical": [float(np.mean(d)) if d else math.nan for d in draws],
        "failure": [float(np.mean([x < fail_below for x in d])) if d else math.nan for d in draws],
        "draws": draws,
        "agreement": [
            np.sum([units[(s, v, j)].cells[k].agreement for v in views for j in seeds], axis=0).tolist() for k in radii
        ],
        "cost": {
            "search_passes": sum(c.passes for c in cells) / searches,
            "search_seconds": sum(c.seconds for c in cells) / searches,
            "draw_passes": sum(run.draw_passes[(s, v)] for v in views) / len(views),
        },
    }
