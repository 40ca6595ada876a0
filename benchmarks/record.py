"""Benchmark results as records: ``--record`` on any benchmark script appends one JSON object to
``benchmarks/results/<name>.jsonl`` (``name``: its last line's first word) when it ends with a
result line. ``common`` (which every script imports first) calls :func:`start_if_asked`.

A record (``"schema": "kadv-benchmark-record-1"``, documented in ``benchmarks/README.md``):
``benchmark``, ``date`` (UTC), ``commit`` and ``dirty`` (tracked files changed, records aside), ``source``
(``files``: the repository's modules the run imported, the script among them; ``hash``: SHA-256
of their bytes, to tell a stale record), ``machine`` (``cpu``, ``cores``, ``threads``, ``torch``,
``device``, ``gpu``, ``busy_at_start``: the share of the CPUs busy in the half second before
the run, and ``others_running``: whether it was a quarter or more), ``args`` (the command line
after the script),
``result`` (``line``: the last line; ``fields``: its ``key=value`` pairs; ``tables``: every
Markdown table the script printed, as header and rows) and ``imported`` (False; True for a figure
taken once from prose, with the date and commit the prose gave).
"""

from __future__ import annotations

import atexit
import datetime
import hashlib
import io
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

__all__ = ["RESULTS", "SCHEMA", "machine_class", "parse_tables", "printed_fields", "source_hash", "start_if_asked"]

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
SCHEMA = "kadv-benchmark-record-1"
_LINE = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)((?: [A-Za-z_][A-Za-z0-9_]*=\S*)+)$")
_BUSY = 0.25  # a share of the CPUs busy before the run from this up: something else was running
# the record's own plumbing, which changes no figure
_NOT_SOURCE = {"benchmarks/record.py", "benchmarks/figures.py"}


class _Tee(io.TextIOBase):
    """Writes to ``stream`` and keeps a copy."""

    def __init__(self, stream) -> None:
        self.stream, self.copy = stream, io.StringIO()

    def write(self, text: str) -> int:
        self.copy.write(text)
        return self.stream.write(text)

    def flush(self) -> None:
        self.stream.flush()

    def isatty(self) -> bool:
        return self.stream.isatty()


def start_if_asked() -> None:
    """With ``--record`` among the arguments: take it out, keep a copy of what the script prints,
    and append the record when the process ends on a result line."""
    if "--record" not in sys.argv[1:]:
        return
    sys.argv = [sys.argv[0], *(arg for arg in sys.argv[1:] if arg != "--record")]
    # the code that runs is the checkout's as the run starts; records appended since the commit are
    # data, not a change to that code
    changed = _git("status", "--porcelain", "--untracked-files=no", "--", ".", f":!{RESULTS.relative_to(ROOT)}")
    commit = {"commit": _git("rev-parse", "HEAD"), "dirty": bool(changed)}
    load, script = _busy_share(), Path(sys.argv[0]).resolve()
    tee = sys.stdout = _Tee(sys.stdout)
    failed = []
    previous = sys.excepthook
    sys.excepthook = lambda *error: (failed.append(error), previous(*error))
    atexit.register(lambda: failed or _append(tee.copy.getvalue(), load, script, commit))


def _busy_share(seconds: float = 0.5) -> float:
    """The share of the machine's CPU time spent busy over ``seconds`` before the run starts (from
    /proc/stat): another job's work, as this process has not started its own."""

    def times() -> tuple[int, int]:
        values = [int(v) for v in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
        idle = values[3] + values[4]  # idle and iowait
        return sum(values) - idle, sum(values)

    (busy0, total0), _ = times(), time.sleep(seconds)
    busy1, total1 = times()
    return (busy1 - busy0) / max(total1 - total0, 1)


def printed_fields(line: str) -> dict[str, str]:
    """The ``key=value`` pairs of a result line ``name key=value ...``, as it printed them."""
    return dict(pair.split("=", 1) for pair in line.split()[1:])


def _fields(line: str) -> dict:
    """The ``key=value`` pairs of a result line, numbers as numbers."""

    def value(raw: str):
        for kind in (int, float):
            try:
                return kind(raw)
            except ValueError:
                pass
        return {"True": True, "False": False}.get(raw, raw)

    return {key: value(raw) for key, raw in printed_fields(line).items()}


def parse_tables(text: str) -> list[dict]:
    """Every Markdown table in ``text``: ``{"header": [...], "rows": [[...], ...]}``."""
    tables, block = [], []
    for line in [*text.splitlines(), ""]:
        if line.startswith("|") and line.rstrip().endswith("|"):
            block.append([cell.strip() for cell in line.strip()[1:-1].split("|")])
            continue
        if len(block) >= 2 and set("".join(block[1])) <= set("-: "):
            tables.append({"header": block[0], "rows": block[2:]})
        block = []
    return tables


def source_hash(files: list[str], root: Path = ROOT) -> str:
    """SHA-256 of the files ``files`` (paths relative to the repository ``root``), in order; a file
    that no longer exists counts as empty."""
    digest = hashlib.sha256()
    for name in files:
        path = root / name
        digest.update(name.encode() + b"\0" + (path.read_bytes() if path.is_file() else b"") + b"\0")
    return digest.hexdigest()


def _source_files(script: Path) -> list[str]:
    """The repository's modules this process imported, kadv's and the benchmarks', and ``script``."""
    paths = [Path(getattr(module, "__file__", None) or "") for module in list(sys.modules.values())]
    files = set()
    for path in [script, *(path for path in paths if path.is_absolute())]:
        if path.is_file() and path.resolve().is_relative_to(ROOT):
            relative = path.resolve().relative_to(ROOT).as_posix()
            if relative.split("/")[0] in ("kadv", "benchmarks") and relative not in _NOT_SOURCE:
                files.add(relative)
    return sorted(files)


def machine_class(machine: dict) -> str:
    """What a figure is comparable across: the CPU and its cores, or the GPU."""
    return machine.get("gpu") or f"{machine['cpu']}, {machine['cores']} cores"


def _machine(load: float) -> dict:
    # torch as the run left it; a script that never loaded it cannot load it at exit
    torch = sys.modules.get("torch")
    cpu = next(
        (
            line.split(":", 1)[1].strip()
            for line in Path("/proc/cpuinfo").read_text().splitlines()
            if "model name" in line
        ),
        "unknown CPU",
    )
    argv = sys.argv[1:]
    device = next((argv[i + 1] for i, arg in enumerate(argv[:-1]) if arg == "--device"), "cpu")
    cuda = torch is not None and device.startswith("cuda") and torch.cuda.is_available()
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "threads": torch.get_num_threads() if torch else None,
        "torch": torch.__version__ if torch else None,
        "device": device,
        "gpu": torch.cuda.get_device_name() if cuda else None,
        "busy_at_start": round(load, 2),
        "others_running": load >= _BUSY,
    }


def _git(*args: str) -> str:
    return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True).stdout.strip()


def _append(printed: str, load: float, script: Path, commit: dict) -> None:
    lines = [line for line in printed.splitlines() if line.strip()]
    match = _LINE.match(lines[-1]) if lines else None
    if match is None:
        print("--record: no result line `name key=value ...` at the end; nothing recorded", file=sys.stderr)
        return
    files = _source_files(script)
    record = {
        "schema": SCHEMA,
        "benchmark": match.group(1),
        "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        **commit,
        "source": {"files": files, "hash": source_hash(files)},
        "machine": _machine(load),
        "args": sys.argv[1:],
        "result": {"line": lines[-1], "fields": _fields(lines[-1]), "tables": parse_tables(printed)},
        "imported": False,
    }
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / f"{record['benchmark']}.jsonl"
    with path.open("a") as file:  # one line appended whole: records are never rewritten
        file.write(json.dumps(record, sort_keys=True) + "\n")
        file.flush()
        os.fsync(file.fileno())
    print(f"recorded: {path.relative_to(ROOT)}", file=sys.stderr)
