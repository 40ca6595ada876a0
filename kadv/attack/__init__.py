"""The adversarial viewpoint attack: objective, init views, gradient and black-box searches."""
from __future__ import annotations

from kadv.attack.init_views import (
    InitView,
    InitViewConfig,
    InitViewError,
    check_init_views,
    clear_file_camera,
    file_init_views,
    load_init_params,
    sample_init_views,
    save_init_params,
    score_views,
)
from kadv.attack.objective import Objective, ObjectiveTerms
from kadv.penalties import PenaltyConfig
from kadv.attack.records import AttackResult, Budget, InitViewResult, ViewRecord, select_top_views, separated
from kadv.attack.runner import attack
from kadv.attack.search import METHODS, AttackConfig, SearchContext

__all__ = [
    "METHODS",
    "AttackConfig",
    "AttackResult",
    "Budget",
    "InitView",
    "InitViewConfig",
    "InitViewError",
    "InitViewResult",
    "Objective",
    "ObjectiveTerms",
    "PenaltyConfig",
    "SearchContext",
    "ViewRecord",
    "attack",
    "check_init_views",
    "clear_file_camera",
    "file_init_views",
    "load_init_params",
    "sample_init_views",
    "save_init_params",
    "score_views",
    "select_top_views",
    "separated",
]
