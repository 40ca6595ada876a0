"""The docs' tables of figures are made from benchmark records, and say when their code changed since."""

from __future__ import annotations

import importlib
import json
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


@pytest.fixture
def figures(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    return importlib.import_module("figures")


def _record(benchmark: str, date: str, value: float, files: list[str], hash_: str, cpu: str = "CPU A") -> dict:
    table = {"header": ["scene", "ms"], "rows": [["box", str(value)]]}
    return {
        "schema": "kadv-benchmark-record-1",
        "benchmark": benchmark,
        "date": date,
        "commit": "0123456789abcdef",
        "dirty": False,
        "source": {"files": files, "hash": hash_},
        "machine": {"cpu": cpu, "cores": 2, "threads": 2, "torch": "2.13.0+cpu", "device": "cpu", "gpu": None,
                    "busy_at_start": 0.1, "others_running": False},
        "args": ["--fast"],
        "result": {"line": f"{benchmark} ms={value}", "fields": {"ms": value}, "tables": [table]},
        "imported": False,
    }  # fmt: skip


@pytest.fixture
def measured(figures, tmp_path) -> tuple[Path, str]:
    """A module a benchmark measured, in a repository at ``tmp_path``, and the hash of its source."""
    source = tmp_path / "kadv" / "thing.py"
    source.parent.mkdir()
    source.write_text("x = 1\n")
    return source, figures.source_hash(["kadv/thing.py"], tmp_path)


def test_the_pages_are_what_their_records_make(figures) -> None:
    assert figures.stale_pages() == [], "run make figures"


def test_a_block_shows_the_latest_record_per_machine_and_says_when_its_code_changed(
    figures, measured, tmp_path
) -> None:
    source, hash_ = measured
    records = [
        _record("speed", "2026-12-01T00:00:00Z", 10.0, ["kadv/thing.py"], hash_),
        _record("speed", "2026-12-02T00:00:00Z", 12.0, ["kadv/thing.py"], hash_),
        _record("speed", "2026-12-03T00:00:00Z", 99.0, ["kadv/thing.py"], hash_, cpu="CPU B"),
    ]
    results = tmp_path / "benchmarks" / "results"
    results.mkdir(parents=True)
    (results / "speed.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    page = tmp_path / "page.md"
    page.write_text("Figures:\n<!-- figures speed --fast | table 1 -->\nold\n<!-- /figures -->\nend\n")
    assert figures.stale_pages(["page.md"], tmp_path) == ["page.md"]
    made = figures.generate(page.read_text(), figures.read_records(results), tmp_path)
    assert "| box | 12.0 |" in made and "| box | 10.0 |" not in made and "| box | 99.0 |" in made
    assert "`python benchmarks/speed.py --fast --record`" in made and "Stale" not in made
    page.write_text(made)
    assert figures.stale_pages(["page.md"], tmp_path) == []
    source.write_text("x = 2\n")  # the code it measured changed
    assert figures.stale_pages(["page.md"], tmp_path) == ["page.md"]
    assert "**Stale**" in figures.generate(made, figures.read_records(results), tmp_path)


def test_a_summary_takes_each_figure_from_its_own_latest_record_and_names_the_missing(
    figures, measured, tmp_path
) -> None:
    _, hash_ = measured
    records = [
        _record("speed", "2026-12-01T00:00:00Z", 10.0, ["kadv/thing.py"], hash_),
        _record("speed", "2026-12-02T00:00:00Z", 12.0, ["kadv/thing.py"], "an older hash"),
        {**_record("size", "2026-12-03T00:00:00Z", 3.0, ["kadv/thing.py"], hash_), "args": []},
    ]
    rows = (
        figures.Figure("how fast", "speed", ("--fast",), "{ms} ms"),
        figures.Figure("how big", "size", (), "{ms} GiB"),
        figures.Figure("how far", "reach", (), "{m} m"),
        figures.Figure("a field no record holds", "size", (), "{volume}"),
    )
    made = figures.render_summary(rows, records, tmp_path)
    assert "| how fast | 12.0 ms | 0123456, 2026-12-02 **stale** | `python benchmarks/speed.py --fast` |" in made
    assert "| how big | 3.0 GiB | 0123456, 2026-12-03 | `python benchmarks/size.py` |" in made
    assert "*CPU A, 2 cores; each command run with `--record`.*" in made and "**stale**: the code" in made
    assert "Not recorded yet" in made and "`python benchmarks/reach.py`" in made
    assert "a field no record holds" not in made  # the size record holds no `volume`: no row, but named
    assert made.count("`python benchmarks/size.py`") == 2


def test_a_record_imported_from_prose_says_so_and_names_what_made_it(figures, tmp_path) -> None:
    imported = {
        **_record("speed", "2026-11-01T00:00:00Z", 7.0, [], ""),
        "imported": True,
        "commit": "",
        "command": "a script of the time",
        "machine": {"cpu": "CPU A", "cores": 2, "threads": None, "torch": None, "device": "cpu", "gpu": None,
                    "busy_at_start": None, "others_running": None},
    }  # fmt: skip
    del imported["source"]
    made = figures.render_block("speed --fast | table 1", [imported], tmp_path)
    assert "| box | 7.0 |" in made and "Imported from the docs' prose" in made
    assert "`a script of the time`; CPU A, 2 cores; commit not given, 2026-11-01" in made
    assert "nothing else running" not in made and "Stale" not in made
    # a block shows the latest record that holds what it asks for: a later record without a table
    later = {
        **_record("speed", "2026-12-05T00:00:00Z", 9.0, [], ""),
        "result": {"line": "", "fields": {}, "tables": []},
    }
    assert "| box | 7.0 |" in figures.render_block("speed --fast | table 1", [imported, later], tmp_path)
