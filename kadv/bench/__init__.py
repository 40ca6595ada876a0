"""The benchmark: frozen suites, entries that store their worst poses and verify, scores with their
intervals, and a leaderboard that merges entries from any lab.

It sits after :mod:`kadv.report` and before :mod:`kadv.testing` in the package order, and never
imports Hydra.
"""

from __future__ import annotations

from kadv.bench.board import Leaderboard, leaderboard, read_entries, suite_table2
from kadv.bench.digest import COLOUR_LEVELS, LENGTH_STEP, scene_digest
from kadv.bench.entry import (
    ENTRY_FORMAT,
    CellResult,
    Entry,
    UnitResult,
    assemble_entry,
    environment,
    load_entry,
    model_identity,
    run_suite,
    suite_settings,
    suite_units,
    unit_path,
    unit_search_seed,
)
from kadv.bench.pooled import pooled_worst
from kadv.bench.scores import SuiteScore, best_known, paired_difference, pool_units, suite_score
from kadv.bench.sheet import save_suite_sheet
from kadv.bench.shipped import shipped_specs
from kadv.bench.suite import (
    SHIPPED,
    SUITE_FORMAT,
    BenchError,
    FrozenView,
    Protocol,
    SceneSpec,
    Suite,
    SuiteScene,
    freeze_suite,
    load_suite,
    scenes_root,
)
from kadv.bench.verify import Verification, verify_entry

__all__ = [
    "COLOUR_LEVELS",
    "ENTRY_FORMAT",
    "LENGTH_STEP",
    "SHIPPED",
    "SUITE_FORMAT",
    "BenchError",
    "CellResult",
    "Entry",
    "FrozenView",
    "Leaderboard",
    "Protocol",
    "SceneSpec",
    "Suite",
    "SuiteScene",
    "SuiteScore",
    "UnitResult",
    "Verification",
    "assemble_entry",
    "best_known",
    "environment",
    "freeze_suite",
    "leaderboard",
    "load_entry",
    "load_suite",
    "model_identity",
    "paired_difference",
    "pool_units",
    "pooled_worst",
    "read_entries",
    "run_suite",
    "save_suite_sheet",
    "scene_digest",
    "scenes_root",
    "shipped_specs",
    "suite_score",
    "suite_settings",
    "suite_table2",
    "suite_units",
    "unit_path",
    "unit_search_seed",
    "verify_entry",
]
