"""kadv-probe: the scorecard from the command line, and its bad input in one line with exit status 2."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from kadv.cli.probe import main
from kadv.testing import Scorecard


def test_the_scorecard_prints_its_table_and_ranking_and_writes_its_files(tmp_path: Path, capsys) -> None:
    """``hydra.run.dir=`` names the output folder as ``out=`` does."""
    main(["model=kadv_tiny", "probes=window,stairs", "budget=5", "lighting=direct", f"hydra.run.dir={tmp_path}"])
    printed = capsys.readouterr().out
    assert "| probe | model | worst delta1 5°/0.1 m | worst delta1 15°/0.3 m | worst delta1 45°/1 m |" in printed
    assert "| window | kadv_tiny | " in printed and "| stairs | kadv_tiny | " in printed
    assert "\ndelta1 after scale_shift alignment in disparity space; agreement: " in printed  # how it was scored
    assert "\nranking (worst-case area): kadv_tiny (" in printed and "\nranking (typical area): kadv_tiny (" in printed
    assert (tmp_path / "scorecard.md").read_text().strip() in printed
    assert (tmp_path / "scorecard.png").stat().st_size > 10_000
    # every profile, to rank again later: the same table read back
    again = Scorecard.from_dict(json.loads((tmp_path / "scorecard.json").read_text()))
    assert again.markdown() == (tmp_path / "scorecard.md").read_text().strip()
    # the worst view at each of the three radii, per probe, in the upright envelope by default
    assert len(list((tmp_path / "views").glob("*-upright-radius*.png"))) == 6
    # a suite run: the suite and the entry another lab can verify, named on the last line
    (suite,) = (tmp_path / "views").glob("suite-*.json")
    (entry,) = (tmp_path / "views").glob("entries/kadv_tiny-*/entry.json")
    assert printed.rstrip().splitlines()[-1].startswith(f"suite and entries: {suite}, ")
    assert json.loads(entry.read_text())["suite"]["hash"] == json.loads(suite.read_text())["hash"]


@pytest.mark.parametrize(
    ("argument", "message"),
    [
        ("probes=nope", "no probe scene 'nope'; the probes are: photo_wall, grazing_floor, thin_structures"),
        ("model=", "scorecard needs at least one model"),
        ("model=no_such_model", "unknown model 'no_such_model': not a preset"),
        ("budget=1", "budget must be an integer >= 2, got 1"),
        ("seed=x", "seed must be an integer >= 0, got 'x'"),
        ("seeds=", "seeds is empty: give one or more integers >= 0"),
        ("seeds=0,-1", "seeds must be an integer >= 0, got -1"),
        ("envelope=drone", "envelope 'drone' is not a preset; choose one of free, upright, handheld, robot"),
        ("lighting=sun", "lighting must be 'baked' or 'direct', got 'sun'"),
        ("restarts=0", "restarts must be an integer >= 1, got 0"),
        ("alignment=none", "scores the prediction as metric depth, but model kadv_tiny outputs relative disparity"),
        ("colour=red", "'colour=red': expected key=value with a key of model, probes"),
    ],
)
def test_bad_input_is_one_line_and_exit_status_2(argument: str, message: str, capsys, tmp_path: Path) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main([argument, f"out={tmp_path / 'out'}"])
    assert exit_info.value.code == 2
    error = capsys.readouterr().err
    assert error.startswith("kadv-probe: error: ") and message in error and error.count("\n") == 1
    assert not (tmp_path / "out").exists()  # nothing is written
