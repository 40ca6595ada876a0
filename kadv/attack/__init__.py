"""The adversarial viewpoint attack: objective, init views, and search methods behind one registry."""

from __future__ import annotations

from kadv.attack.driver import attack
from kadv.attack.init_views import (
    InitView,
    InitViewConfig,
    InitViewError,
    ViewScores,
    captured_init_views,
    check_init_views,
    clear_file_camera,
    file_init_views,
    load_init_params,
    sample_init_views,
    sample_valid_views,
    save_init_params,
    score_views,
)
from kadv.attack.loop import Proposer, fitness, proposer_search, register_proposer
from kadv.attack.methods.cma import CMASettings
from kadv.attack.methods.gradient import GradientSettings, gradient_ascent, gradient_search
from kadv.attack.methods.halving import HalvingSettings
from kadv.attack.methods.hybrid import HybridSettings
from kadv.attack.methods.nevergrad import NevergradSettings
from kadv.attack.methods.random import RandomSettings
from kadv.attack.methods.turbo import TurboSettings
from kadv.attack.objective import Objective, ObjectiveTerms
from kadv.attack.profile import Profile
from kadv.attack.radii import DEFAULT_RADII, SeedProfile, profile_views, search_radii, warm_starts
from kadv.attack.records import (
    Agreement,
    AttackResult,
    Budget,
    InitViewResult,
    ViewRecord,
    agreement,
    agreement_text,
    best_so_far,
    incumbent_path,
    select_top_views,
    separated,
    worst_record,
)
from kadv.attack.registry import METHODS, NoSettings, SearchMethod, get_method, register_method
from kadv.attack.restarts import restarted_search
from kadv.attack.search import (
    DEFAULT_METHOD,
    DEFAULT_PASSES,
    RENAMED_BUDGET,
    AttackConfig,
    Clock,
    Measures,
    SearchContext,
)
from kadv.attack.space import FOV, PoseSpace
from kadv.attack.study import Study, StudySettings
from kadv.penalties import PenaltyConfig

__all__ = [
    "DEFAULT_METHOD",
    "DEFAULT_PASSES",
    "DEFAULT_RADII",
    "FOV",
    "METHODS",
    "RENAMED_BUDGET",
    "Agreement",
    "AttackConfig",
    "AttackResult",
    "Budget",
    "CMASettings",
    "Clock",
    "GradientSettings",
    "HalvingSettings",
    "HybridSettings",
    "InitView",
    "InitViewConfig",
    "InitViewError",
    "InitViewResult",
    "Measures",
    "NevergradSettings",
    "NoSettings",
    "Objective",
    "ObjectiveTerms",
    "PenaltyConfig",
    "PoseSpace",
    "Profile",
    "Proposer",
    "RandomSettings",
    "SearchContext",
    "SearchMethod",
    "SeedProfile",
    "Study",
    "StudySettings",
    "TurboSettings",
    "ViewRecord",
    "ViewScores",
    "agreement",
    "agreement_text",
    "attack",
    "best_so_far",
    "captured_init_views",
    "check_init_views",
    "clear_file_camera",
    "file_init_views",
    "fitness",
    "get_method",
    "gradient_ascent",
    "gradient_search",
    "incumbent_path",
    "load_init_params",
    "profile_views",
    "proposer_search",
    "register_method",
    "register_proposer",
    "restarted_search",
    "sample_init_views",
    "sample_valid_views",
    "save_init_params",
    "score_views",
    "search_radii",
    "select_top_views",
    "separated",
    "warm_starts",
    "worst_record",
]
