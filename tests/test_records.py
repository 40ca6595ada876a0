"""``--record`` on a benchmark appends one record of what it printed, the code it ran and the machine."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"

SCRIPT = """
import sys
import record

record.start_if_asked()
print("| scene | ms |")
print("|---|---|")
print("| box | 3.5 |")
if "--fail" in sys.argv:
    raise SystemExit("failed")
print("speedy ms=3.5 scene=box")
"""


def _git(repo: Path, *args: str) -> None:
    subprocess.run(["git", *args], cwd=repo, check=True, capture_output=True)


def _run(repo: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "benchmarks/speedy.py", *args], cwd=repo, capture_output=True, text=True, timeout=120
    )


def _records(repo: Path) -> list[dict]:
    path = repo / "benchmarks" / "results" / "speedy.jsonl"
    return [json.loads(line) for line in path.read_text().splitlines()] if path.is_file() else []


def test_a_run_with_record_appends_its_tables_fields_commit_and_source(tmp_path) -> None:
    repo = tmp_path / "repo"
    (repo / "benchmarks").mkdir(parents=True)
    shutil.copy(BENCHMARKS / "record.py", repo / "benchmarks" / "record.py")
    (repo / "benchmarks" / "speedy.py").write_text(SCRIPT)
    _git(repo, "init", "-q")
    _git(repo, "-c", "user.email=k@example.org", "-c", "user.name=k", "commit", "-qam", "x", "--allow-empty")
    _git(repo, "add", ".")
    _git(repo, "-c", "user.email=k@example.org", "-c", "user.name=k", "commit", "-qm", "speedy")

    assert _run(repo, "--fast").returncode == 0  # no --record: nothing kept
    assert _records(repo) == []
    first = _run(repo, "--fast", "--record")
    assert first.returncode == 0, first.stderr
    (record,) = _records(repo)
    assert record["benchmark"] == "speedy" and record["args"] == ["--fast"] and record["imported"] is False
    assert record["result"]["fields"] == {"ms": 3.5, "scene": "box"}
    assert record["result"]["tables"] == [{"header": ["scene", "ms"], "rows": [["box", "3.5"]]}]
    assert record["source"]["files"] == ["benchmarks/speedy.py"] and record["dirty"] is False
    assert len(record["commit"]) == 40 and record["machine"]["cores"] >= 1

    # a second run after the first record (the records file now differs from the commit): still clean
    _git(repo, "add", ".")  # tracked, and changed by the next append
    _git(repo, "-c", "user.email=k@example.org", "-c", "user.name=k", "commit", "-qm", "a record")
    assert _run(repo, "--record").returncode == 0
    assert _run(repo, "--record").returncode == 0
    assert [r["dirty"] for r in _records(repo)] == [False, False, False]

    (repo / "benchmarks" / "speedy.py").write_text(SCRIPT + "\n# changed\n")  # the code that runs differs
    assert _run(repo, "--record").returncode == 0
    assert _records(repo)[-1]["dirty"] is True
    assert _records(repo)[-1]["source"]["hash"] != record["source"]["hash"]

    failed = _run(repo, "--fail", "--record")  # a run that fails keeps nothing
    assert failed.returncode != 0 and len(_records(repo)) == 4
