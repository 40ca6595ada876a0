from __future__ import annotations

import ast
from pathlib import Path

import pytest

from kadv import box_room, load_model
from kadv.attack import AttackConfig, RandomSettings, Study, StudySettings, attack, file_init_views
from kadv.losses import AlignedLoss, LossConfig
from kadv.render import DiffRenderConfig, Shading

PACKAGE = Path(__file__).resolve().parents[2] / "kadv"


@pytest.fixture(scope="module")
def study() -> Study:
    settings = StudySettings(
        size=(48, 64),
        shading=Shading(lighting="direct"),
        render=DiffRenderConfig(silhouette=False),
        loss=LossConfig(kind="ssim", window_size=7),
        attack=AttackConfig(
            "random", RandomSettings(population=4), budget_passes=9, max_angle_deg=10, max_distance=0.2
        ),
        progress=False,
    )
    return Study.build(box_room(seed=0), load_model("kadv_tiny"), settings)


def test_a_study_wires_its_settings_into_each_part(study) -> None:
    settings = study.settings
    assert study.renderer.shading == settings.shading and study.renderer.scene is study.scene
    assert study.objective.renderer is study.renderer and study.objective.penalty == settings.penalty
    assert study.objective.space == "disparity" and study.objective.alignment == "scale_shift"
    assert study.objective.loss.keywords == {"window_size": 7}  # the SSIM loss at the settings' window
    assert study.differentiable.renderer is study.renderer and study.differentiable.config == settings.render
    assert study.model is study.objective.model


def test_a_study_s_search_is_the_search_of_its_parts(study) -> None:
    views = file_init_views(study.renderer, study.settings.penalty.margin)[:1]
    by_study = study.attack(views, seed=3)
    height, width = study.settings.size
    by_parts = attack(
        study.objective, study.differentiable, views, height, width, study.settings.attack, 3, progress=False
    )
    ours, theirs = by_study.views[0].records, by_parts.views[0].records
    assert len(ours) == len(theirs) >= 5
    assert all(a.params == b.params and a.loss == b.loss for a, b in zip(ours, theirs))


def test_a_variant_shares_the_exact_renderer_and_swaps_the_model_or_the_loss(study) -> None:
    other = study.variant(model=load_model("kadv_tiny_dpt"), loss=LossConfig(kind="delta1", alignment="scale"))
    assert other.renderer is study.renderer
    assert other.model.name == "kadv_tiny_dpt" and study.model.name == "kadv_tiny"
    assert isinstance(other.objective.loss, AlignedLoss) and other.objective.alignment == "scale"
    assert other.settings.render == study.settings.render and other.differentiable is not study.differentiable
    same_loss = study.variant(model=load_model("kadv_tiny_dpt"))
    assert same_loss.objective.loss is study.objective.loss  # one loss function while its settings stay


def test_a_bad_loss_setting_is_refused_naming_its_key(study) -> None:
    with pytest.raises(ValueError, match=r"loss\.window_size must be an odd integer"):
        study.variant(loss=LossConfig(kind="ssim", window_size=4))
    with pytest.raises(ValueError, match=r"loss\.space must be 'disparity' or 'depth'"):
        study.variant(loss=LossConfig(space="log"))


def test_the_commands_the_checks_and_the_report_build_no_renderer_or_objective_of_their_own() -> None:
    built = []
    for folder in ("cli", "testing", "report"):
        for path in sorted((PACKAGE / folder).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.Call):
                    name = getattr(node.func, "id", getattr(node.func, "attr", None))
                    if name in ("ExactRenderer", "Objective", "DifferentiableRenderer"):
                        built.append(f"{path.relative_to(PACKAGE)}:{node.lineno} {name}(")
    assert built == [], "build them with kadv.attack.Study: " + ", ".join(built)
