"""``kadv-train-tiny``: train kadv-tiny on procedural rooms; writes weights and a log to the run directory."""
from __future__ import annotations

import json
import logging
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf

from kadv.cli.common import checks_group_options, reports_user_errors
from kadv.models.tiny import TINY_WEIGHTS, save_kadv_tiny
from kadv.models.train_tiny import TinyTrainConfig, train_tiny
from kadv.report import atomic_write
from kadv.runtime import configure_runtime

log = logging.getLogger(__name__)


@checks_group_options("kadv-train-tiny")
@hydra.main(version_base="1.3", config_path="../conf", config_name="kadv_train_tiny")
@reports_user_errors("kadv-train-tiny")
def main(cfg: DictConfig) -> None:
    """Train kadv-tiny; weights and the training log go into the run directory."""
    configure_runtime()
    out_dir = Path(HydraConfig.get().runtime.output_dir)
    config = TinyTrainConfig(**OmegaConf.to_container(cfg.train, resolve=True))
    network, training_log = train_tiny(config)
    summary = {k: v for k, v in training_log.items() if k != "losses"}
    weights = save_kadv_tiny(network, out_dir / "kadv_tiny.safetensors", metadata=summary)
    atomic_write(out_dir / "train_log.json", lambda tmp: tmp.write_text(json.dumps(training_log, indent=1)))
    if cfg.replace_shipped_weights:
        save_kadv_tiny(network, TINY_WEIGHTS, metadata=summary)
        log.info("replaced the shipped weights: %s", TINY_WEIGHTS)
    log.info("kadv-tiny: val delta1 %.3f, render %.0f s, train %.0f s -> %s", summary["val_delta1"],
             summary["render_seconds"], summary["train_seconds"], weights)


if __name__ == "__main__":
    main()
