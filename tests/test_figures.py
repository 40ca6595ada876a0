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


def test_the_pages_are_what_their_records_make(figures) -> None:
    assert figures.stale_pages() == [], "run make figures"


def test_a_block_shows_the_latest_record_per_machine_and_says_when_its_code_changed(figures, tmp_path) -> None:
    source = tmp_path / "kadv" / "thing.py"
    source.parent.mkdir()
    source.write_text("x = 1\n")
    hash_ = figures.source_hash(["kadv/thing.py"], tmp_path)
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
