"""The docs' tables of figures, made from the records in ``benchmarks/results/`` (``make figures``).

A page marks each generated block with an opening and a closing comment::

    <!-- figures marigold_cost --resolutions 768,384 | table 1 -->
    ...
    <!-- /figures -->

Between them this script writes, for the latest record of that benchmark with those arguments on
each machine class (:func:`record.machine_class`), the record's printed table (``table N``,
counted from 1), or its last line's fields (``fields``, the default), then the command, the
machine, the commit and the date. A record whose source has changed since it was made (its files'
hash is no longer its ``source.hash``) is marked stale on the page, naming the command to run
again. ``--check`` writes nothing and exits 1 where a block is not what the records make.

Run: .venv/bin/python benchmarks/figures.py [--check]
"""

from __future__ import annotations

import argparse
import json
import re
import shlex
import sys
from pathlib import Path

from record import RESULTS, ROOT, machine_class, source_hash

__all__ = ["PAGES", "generate", "latest_records", "render_block", "stale_pages"]

PAGES = ("README.md", "docs/performance.md", "docs/attack.md", "docs/testing.md", "docs/benchmark.md", "docs/models.md")
_BLOCK = re.compile(r"(<!-- figures (?P<spec>[^>]*?) -->\n)(?P<body>.*?)(<!-- /figures -->)", re.S)


def read_records(folder: Path = RESULTS) -> list[dict]:
    """Every record in ``folder``'s ``*.jsonl``, in file order (the order they were made)."""
    records = []
    for path in sorted(folder.glob("*.jsonl")):
        records += [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    return records


def latest_records(records: list[dict], benchmark: str, args: list[str]) -> list[dict]:
    """The latest record of ``benchmark`` run with ``args`` on each machine class, by date."""
    latest: dict[str, dict] = {}
    for record in records:
        if record["benchmark"] == benchmark and record["args"] == args:
            key = machine_class(record["machine"])
            if key not in latest or record["date"] >= latest[key]["date"]:
                latest[key] = record
    return [latest[key] for key in sorted(latest)]


def _markdown(header: list[str], rows: list[list]) -> list[str]:
    return ["| " + " | ".join(map(str, header)) + " |", "|---" * len(header) + "|"] + [
        "| " + " | ".join(map(str, row)) + " |" for row in rows
    ]


def _caption(record: dict, command: str, root: Path) -> str:
    machine = record["machine"]
    where = machine.get("gpu") or f"{machine['cpu']}, {machine['cores']} cores, {machine['threads']} threads"
    busy = "something else running" if machine.get("others_running") else "nothing else running"
    made = "imported from the docs' prose" if record.get("imported") else f"`{command} --record`"
    dirty = " with uncommitted changes" if record.get("dirty") else ""
    line = (
        f"*{made}; {where}, torch {machine['torch']}, {busy}; commit {record['commit'][:7]}{dirty}, "
        f"{record['date'][:10]}.*"
    )
    files = record.get("source", {}).get("files")
    if files and source_hash(files, root) != record["source"]["hash"]:
        line += f" **Stale**: the code it measures has changed since; run `{command} --record` again."
    return line


def render_block(spec: str, records: list[dict], root: Path = ROOT) -> str:
    """The block's body for its ``spec`` (``BENCHMARK [ARGS...] [| table N | fields]``)."""
    what, _, shown = spec.partition("|")
    benchmark, *args = shlex.split(what)
    command = " ".join(["python", f"benchmarks/{benchmark}.py", *map(shlex.quote, args)])
    found = latest_records(records, benchmark, args)
    if not found:
        return f"*No record of `{command}` yet: run it with `--record`.*\n"
    parts = []
    for record in found:
        shown_words = shown.split()
        if shown_words[:1] == ["table"]:
            table = record["result"]["tables"][int(shown_words[1]) - 1]
            lines = _markdown(table["header"], table["rows"])
        else:
            lines = _markdown(["field", "value"], sorted(record["result"]["fields"].items()))
        parts.append("\n".join([*lines, "", _caption(record, command, root)]) + "\n")
    return "\n".join(parts)


def generate(text: str, records: list[dict], root: Path = ROOT) -> str:
    """``text`` with every figures block made again from ``records``."""
    return _BLOCK.sub(lambda m: m.group(1) + render_block(m.group("spec"), records, root) + m.group(4), text)


def stale_pages(pages=PAGES, root: Path = ROOT, records: list[dict] | None = None) -> list[str]:
    """The pages whose figures blocks are not what their records make."""
    records = read_records(root / "benchmarks" / "results") if records is None else records
    return [
        page
        for page in pages
        if (path := root / page).is_file() and generate(path.read_text(), records, root) != path.read_text()
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="write nothing; exit 1 where a page is out of date")
    args = parser.parse_args()
    if args.check:
        stale = stale_pages()
        if stale:
            print(
                f"figures out of date with benchmarks/results: {', '.join(stale)} (run make figures)", file=sys.stderr
            )
            sys.exit(1)
        return
    records = read_records()
    for page in PAGES:
        path = ROOT / page
        text = path.read_text()
        made = generate(text, records)
        if made != text:
            path.write_text(made)
            print(f"updated {page}")


if __name__ == "__main__":
    main()
