"""``kadv-train-tiny``: train an embedded model (kadv-tiny; kadv-tiny-dpt with ``train.architecture=dpt``;
kadv-tiny-metric with ``train.target=metric``) on generated rooms; writes its weights and a log to
the run directory."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf

from kadv.cli.common import checks_overrides, reports_user_errors
from kadv.io import atomic_write
from kadv.models.tiny import TINY_METRIC_WEIGHTS, TINY_WEIGHTS, save_kadv_tiny
from kadv.models.tiny_dpt import TINY_DPT_DIR, save_kadv_tiny_dpt
from kadv.training.tiny import TinyTrainConfig, train_tiny

log = logging.getLogger(__name__)


@checks_overrides("kadv-train-tiny")
@hydra.main(version_base="1.3", config_path="../conf", config_name="kadv_train_tiny")
@reports_user_errors("kadv-train-tiny")
def main(cfg: DictConfig) -> None:
    """Train an embedded model; its weights and the training log go into the run directory."""
    out_dir = Path(HydraConfig.get().runtime.output_dir)
    config = TinyTrainConfig(**OmegaConf.to_container(cfg.train, resolve=True))
    model, training_log = train_tiny(config)
    summary = {k: v for k, v in training_log.items() if k != "losses"}
    if config.architecture == "dpt":
        save, shipped = save_kadv_tiny_dpt, TINY_DPT_DIR
    else:
        save, shipped = save_kadv_tiny, TINY_METRIC_WEIGHTS if config.target == "metric" else TINY_WEIGHTS
    weights = save(model.network, out_dir / shipped.name, metadata=summary)
    atomic_write(out_dir / "train_log.json", lambda tmp: tmp.write_text(json.dumps(training_log, indent=1)))
    if cfg.replace_shipped_weights:
        save(model.network, shipped, metadata=summary)
        log.info("replaced the shipped weights: %s", shipped)
    metric = summary.get("val_delta1_metric")
    log.info(
        "%s: val delta1 %.3f (scale_shift)%s, render %.0f s, train %.0f s -> %s",
        model.name,
        summary["val_delta1"],
        "" if metric is None else f", {metric:.3f} (none)",
        summary["render_seconds"],
        summary["train_seconds"],
        weights,
    )


if __name__ == "__main__":
    main()
