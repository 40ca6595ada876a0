"""Every option of every config group composes, and the YAML defaults equal the library's."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest
from hydra import compose, initialize_config_module
from omegaconf import OmegaConf

from kadv.attack import DEFAULT_METHOD, AttackConfig, InitViewConfig, StudySettings, get_method
from kadv.cli.attack import attack_settings
from kadv.cli.common import (
    _open_keys,
    loss_settings,
    resolve_lighting,
    settings_from_node,
    shading_from_config,
    study_settings,
)
from kadv.losses import KINDS, LossConfig
from kadv.models import EMBEDDED, PRESETS
from kadv.penalties import PenaltyConfig
from kadv.render import DiffRenderConfig, Shading
from kadv.scenes import box_room
from kadv.training.tiny import TinyTrainConfig

CONF = Path(__file__).resolve().parents[2] / "conf"


def _options(group: str) -> list[str]:
    return sorted(p.stem for p in (CONF / group).glob("*.yaml"))


def _compose(config: str, *overrides: str):
    with initialize_config_module(config_module="kadv.conf", version_base="1.3"):
        return compose(config_name=config, overrides=list(overrides))


def _shading(render) -> Shading:
    """A ``render/`` node's shading once its ``auto`` lighting is resolved, as for the box room."""
    resolve_lighting(box_room(), render)
    return shading_from_config(render)


def _defaults(cls) -> dict:
    return {f.name: f.default for f in dataclasses.fields(cls)}


def test_every_group_option_composes_into_valid_settings() -> None:
    for group in ("scene", "model", "loss", "render", "penalty", "init", "attack", "experiment"):
        for option in _options(group):
            cfg = _compose("kadv_attack", f"{group}={option}")
            attack = attack_settings(cfg.attack)
            InitViewConfig(
                **{k: tuple(v) if isinstance(v, list) else v for k, v in OmegaConf.to_container(cfg.init).items()}
            )
            PenaltyConfig(**OmegaConf.to_container(cfg.penalty))
            DiffRenderConfig(supersample=cfg.render.supersample, **OmegaConf.to_container(cfg.render.differentiable))
            _shading(cfg.render)
            assert cfg.loss.space in (None, "disparity", "depth")  # null: the model's output kind's own
            if cfg.loss.kind != "perceptual":  # its VGG-16 weights would be a download
                loss_settings(cfg.loss).loss()
            assert (
                OmegaConf.is_missing(cfg.model, "name")
                or cfg.model.name in {*PRESETS, *EMBEDDED}
                or (
                    cfg.model.name == "custom"
                    and OmegaConf.is_missing(cfg.model, "target")
                    and cfg.model.output_kind in KINDS
                )
            )
            assert cfg.scene.kind in ("box_room", "procedural", "file")
            if group == "attack":  # each method's YAML node is its settings dataclass, defaults included
                assert attack.method == option and attack.settings == get_method(option).settings()


def test_every_preset_has_a_config_naming_its_hub_id_and_output_kind() -> None:
    assert set(_options("model")) == {*PRESETS, *EMBEDDED, "huggingface", "custom"}
    for name, preset in PRESETS.items():
        node = _compose("kadv_attack", f"model={name}").model
        assert (node.name, node.hub_id, node.output_kind) == (name, preset.hub_id, preset.output_kind)


def test_yaml_defaults_equal_the_library_defaults() -> None:
    cfg = _compose("kadv_attack", "~experiment")
    init = OmegaConf.to_container(cfg.init)
    assert attack_settings(cfg.attack) == AttackConfig()
    assert InitViewConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in init.items()}) == InitViewConfig()
    assert OmegaConf.to_container(cfg.penalty) == _defaults(PenaltyConfig)
    diff = OmegaConf.to_container(cfg.render.differentiable)
    assert DiffRenderConfig(supersample=cfg.render.supersample, **diff) == DiffRenderConfig()
    assert cfg.render.lighting == "auto"
    shading = _shading(cfg.render)
    assert shading.lighting == "baked"  # the box room is not a scan
    assert (shading.ambient, shading.diffuse, shading.lights) == (
        Shading().ambient,
        Shading().diffuse,
        Shading().lights,
    )
    assert loss_settings(cfg.loss) == LossConfig()  # loss=delta1 and its alignment
    settings = study_settings(box_room(), cfg.render)
    assert (settings.size, settings.render, settings.backend) == (StudySettings().size, DiffRenderConfig(), "auto")
    assert settings.max_rays == StudySettings().max_rays
    train = OmegaConf.to_container(_compose("kadv_train_tiny").train)
    assert TinyTrainConfig(**{**train, "channels": tuple(train["channels"])}) == TinyTrainConfig()


def test_experiment_presets() -> None:
    demo = _compose("kadv_attack", "experiment=demo")
    attack = attack_settings(demo.attack)
    assert (attack.method, attack.passes, demo.init.count, demo.loss.kind) == (DEFAULT_METHOD, 123, 2, "delta1")
    paper = _compose("kadv_attack", "experiment=paper")
    attack = attack_settings(paper.attack)  # the study's protocol keeps the gradient attack
    assert (attack.method, attack.settings.steps, attack.settings.restarts, attack.passes) == (
        "gradient",
        400,
        5,
        4005,  # 5 restarts x (400 forward and backward passes + the last view's forward pass)
    )
    assert (paper.init.count, paper.loss.kind) == (10, "perceptual")


def test_paper_sweep_is_the_study_grid() -> None:
    with initialize_config_module(config_module="kadv.conf", version_base="1.3"):
        cfg = compose(config_name="kadv_attack", overrides=["experiment=paper_sweep"], return_hydra_config=True)
    params = cfg.hydra.sweeper.params
    assert params.model.split(",") == [
        "midas_dpt_large",
        "zoedepth_nk",
        "depth_anything_v1_large",
        "depth_anything_v2_large",
    ]
    assert set(params.scene.split(",")) == {"grey_white_room", "modern_hall", "japanese_classroom"}
    attack = attack_settings(cfg.attack)
    assert (attack.settings.steps, attack.settings.restarts, cfg.init.count, cfg.loss.kind) == (
        400,
        5,
        10,
        "perceptual",
    )


def test_a_custom_models_keyword_arguments_need_no_plus() -> None:
    overrides = _open_keys(["model=custom", "model.args.width=4", "model.args.depth=2,3", "render.height=48"])
    assert overrides == ["model=custom", "++model.args.width=4", "++model.args.depth=2,3", "render.height=48"]
    cfg = _compose("kadv_attack", *overrides[:2], "++model.args.depth=2", overrides[3])
    assert OmegaConf.to_container(cfg.model.args) == {"width": 4, "depth": 2}


@pytest.mark.parametrize(
    "cls, node, prefix, named",
    [
        (PenaltyConfig, {"probe_rays": 256}, "penalty", "penalty.probe_rays was renamed penalty.enclosure_rays"),
        (PenaltyConfig, {"sphere_rays": 256}, "penalty", "unknown key(s) penalty.sphere_rays; penalty takes"),
    ],
)
def test_a_preset_s_renamed_key_is_refused_naming_the_new_one(cls, node, prefix, named) -> None:
    with pytest.raises(ValueError, match=re.escape(named)):
        settings_from_node(cls, node, prefix)
    assert settings_from_node(cls, {"enclosure_rays": 256}, prefix).enclosure_rays == 256


def test_a_settings_key_takes_its_default_s_kind_and_null_only_where_its_type_allows_it() -> None:
    from kadv.attack import AttackConfig, HalvingSettings

    halving = settings_from_node(HalvingSettings, {"lanes": 4, "grow": 2, "screen_supersample": None}, "h")
    assert (halving.lanes, halving.grow, halving.screen_supersample) == (4, 2, None)  # an integer for a number
    for node, message in [
        ({"lanes": "two"}, "h.lanes must be an integer, got 'two'"),
        ({"lanes": 2.5}, "h.lanes must be an integer, got 2.5"),
        ({"lanes": True}, "h.lanes must be an integer, got True"),
        ({"lanes": None}, "h.lanes must be an integer, got None"),
        ({"grow": "big"}, "h.grow must be a number, got 'big'"),
    ]:
        with pytest.raises(ValueError, match=re.escape(message)):
            settings_from_node(HalvingSettings, node, "h")
    # budget_passes: int | None, max_distance: float | None: null is theirs to take
    config = settings_from_node(AttackConfig, {"method": "gradient", "budget_passes": None, "max_distance": None}, "a")
    assert config.budget_passes is None and config.max_distance is None
    with pytest.raises(ValueError, match=re.escape("a.max_distance must be a number, got 'far'")):
        settings_from_node(AttackConfig, {"max_distance": "far"}, "a")
