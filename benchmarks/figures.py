"""The docs' tables of figures, made from the records in ``benchmarks/results/`` (``make figures``).

A page marks each generated block with an opening and a closing comment::

    <!-- figures marigold_cost --resolutions 768,384 | table 1 -->
    ...
    <!-- /figures -->

Between them this script writes, for the latest record of that benchmark with those arguments on
each machine class (:func:`record.machine_class`), the record's printed table (``table N``,
counted from 1), or its last line's fields (``fields``, the default), then the command, the
machine, the commit and the date. ``<!-- figures summary NAME -->`` writes the table
:data:`SUMMARIES` names: one figure a row, each from the latest record of its own benchmark, one
table per machine class. A record whose source has changed since it was made (its files' hash is no
longer its ``source.hash``) is marked stale on the page, naming the command to run again; a record
imported from prose says that it was measured before records were kept, on the commit the prose
gave. ``--check`` writes nothing and exits 1 where a block is not what the records make.

Run: .venv/bin/python benchmarks/figures.py [--check]
"""

from __future__ import annotations

import argparse
import json
import re
import shlex
import string
import sys
from dataclasses import dataclass
from pathlib import Path

from record import RESULTS, ROOT, machine_class, printed_fields, source_hash

__all__ = ["PAGES", "SUMMARIES", "Figure", "generate", "latest_records", "render_block", "stale_pages"]

PAGES = (
    "README.md",
    "docs/performance.md",
    "docs/attack.md",
    "docs/testing.md",
    "docs/benchmark.md",
    "docs/models.md",
    "docs/lighting.md",
)


@dataclass(frozen=True)
class Figure:
    """One row of a summary table: ``value`` formats the last-line fields of the latest record of
    ``benchmark`` run with ``args`` (``{name}`` a field, as :meth:`str.format` reads it)."""

    label: str
    benchmark: str
    args: tuple[str, ...]
    value: str

    def fields(self) -> set[str]:
        return {name for _, name, _, _ in string.Formatter().parse(self.value) if name}


SUMMARIES: dict[str, tuple[Figure, ...]] = {
    # docs/performance.md's current figures
    "current": (
        Figure("`make demo` from a fresh clone (creating `.venv`, baking)", "make_timings", (), "{demo_s} s"),
        Figure("`make test` from a fresh clone", "make_timings", (), "{test_s} s, {tests_passed} passed"),
        Figure(
            "one attack step, kadv-tiny + SSIM, 240x320, grey_white_room: (step - networks) / networks",
            "attack_step",
            (),
            "{overhead_tiny}",
        ),
        Figure(
            "the same with DA-V2-Small + perceptual: overhead; its networks; the render forward + backward",
            "attack_step",
            (),
            "{overhead}; {networks_ms} ms; {render_ms} ms",
        ),
        Figure(
            "black-box evaluations a second (exact renders of 8 views, s = 2, and kadv-tiny)",
            "attack_step",
            (),
            "{evals_per_s}",
        ),
        Figure(
            "exact render; differentiable render forward + backward (the default), 240x320, s = 2, mean over the "
            "four bench scenes' file cameras",
            "render",
            (),
            "{exact_ms_mean} ms; {differentiable_default_ms_mean} ms",
        ),
        Figure(
            "the same with Warp's caster on the CPU",
            "render",
            ("--backend", "warp"),
            "{exact_ms_mean} ms; {differentiable_default_ms_mean} ms",
        ),
        Figure(
            "operations a kadv-tiny step dispatches (Warp's caster), of them outside the views; what a captured "
            "step launches",
            "step_ops",
            ("--backend", "warp"),
            "{total}, {non_view}; {captured_launches}",
        ),
        Figure(
            "baked lighting, one bake: box room, generated room, grey_white_room, modern_hall, japanese_classroom",
            "bake",
            (),
            "{box_room_s} s, {procedural_s} s, {grey_white_room_s} s, {modern_hall_s} s, {japanese_classroom_s} s",
        ),
        Figure(
            "a 2.3-million-triangle scene (the grey room tiled 4x4): peak memory, bake included",
            "large_scenes",
            (),
            "{peak_gib_4x4} GiB",
        ),
        Figure(
            "gradient check, direct light: least median cosine, interior; full, box room; full, grey_white_room "
            "(thresholds 0.99, 0.95, 0.95)",
            "gradcheck",
            (),
            "{interior_median_cos:.3f}, {full_box_median_cos:.3f}, {full_real_median_cos:.3f}",
        ),
        Figure(
            "the same under baked light",
            "gradcheck",
            ("--lighting", "baked"),
            "{interior_median_cos:.3f}, {full_box_median_cos:.3f}, {full_real_median_cos:.3f}",
        ),
        Figure(
            "the focal length's derivative, direct light (the same three)",
            "gradcheck",
            (),
            "{focal_interior_median_cos:.3f}, {focal_full_box_median_cos:.3f}, {focal_full_real_median_cos:.3f}",
        ),
        Figure(
            "embedded models' delta1 on the shared scenes: kadv-tiny, kadv-tiny-dpt",
            "tiny_accuracy",
            (),
            "{kadv_tiny_real:.3f}, {kadv_tiny_dpt_real:.3f}",
        ),
    ),
}
_BLOCK = re.compile(r"(<!-- figures (?P<spec>[^>]*?) -->\n)(?P<body>.*?)(<!-- /figures -->)", re.S)


def read_records(folder: Path = RESULTS) -> list[dict]:
    """Every record in ``folder``'s ``*.jsonl``, in file order (the order they were made)."""
    records = []
    for path in sorted(folder.glob("*.jsonl")):
        records += [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    return records


def latest_records(records: list[dict], benchmark: str, args: list[str], holds=lambda record: True) -> list[dict]:
    """The latest record of ``benchmark`` run with ``args`` on each machine class, by date, of those
    that hold what a block shows (``holds``: a record's fields or its N-th table)."""
    latest: dict[str, dict] = {}
    for record in records:
        if record["benchmark"] == benchmark and record["args"] == args and holds(record):
            key = machine_class(record["machine"])
            if key not in latest or record["date"] >= latest[key]["date"]:
                latest[key] = record
    return [latest[key] for key in sorted(latest)]


def _markdown(header: list[str], rows: list[list]) -> list[str]:
    return ["| " + " | ".join(map(str, header)) + " |", "|---" * len(header) + "|"] + [
        "| " + " | ".join(map(str, row)) + " |" for row in rows
    ]


def _command(benchmark: str, args: list[str]) -> str:
    return " ".join(["python", f"benchmarks/{benchmark}.py", *map(shlex.quote, args)])


def _where(machine: dict) -> str:
    """The machine as a caption names it; what a record imported from prose lacks is left out."""
    parts = [machine.get("gpu") or f"{machine['cpu']}, {machine['cores']} cores"]
    if machine.get("threads"):
        parts.append(f"{machine['threads']} thread{'s' if machine['threads'] > 1 else ''}")
    if machine.get("torch"):
        parts.append(f"torch {machine['torch']}")
    if machine.get("others_running") is not None:
        parts.append("something else running" if machine["others_running"] else "nothing else running")
    return ", ".join(parts)


def _when(record: dict) -> str:
    """The commit a record measured and its day."""
    dirty = " with uncommitted changes" if record.get("dirty") else ""
    commit = f"commit {record['commit'][:7]}{dirty}" if record["commit"] else "commit not given"
    return f"{commit}, {record['date'][:10]}"


def _stale(record: dict, root: Path) -> bool:
    """Whether the code ``record`` measured has changed since (a record without source files, one
    imported from prose, cannot be checked and says so instead)."""
    files = record.get("source", {}).get("files")
    return bool(files) and source_hash(files, root) != record["source"]["hash"]


def _caption(record: dict, command: str, root: Path) -> str:
    when = _when(record)
    if record.get("imported"):
        script = root / "benchmarks" / f"{record['benchmark']}.py"
        rerun = f" To measure today's code: `{command} --record`." if script.is_file() else ""
        return (
            f"*Imported from the docs' prose, measured before records were kept and not checked against "
            f"today's code: `{record.get('command') or command}`; {_where(record['machine'])}; {when}.*{rerun}"
        )
    line = f"*`{command} --record`; {_where(record['machine'])}; {when}.*"
    if _stale(record, root):
        line += f" **Stale**: the code it measures has changed since; run `{command} --record` again."
    return line


def render_summary(figures: tuple[Figure, ...], records: list[dict], root: Path = ROOT) -> str:
    """One table per machine class: each figure from the latest record of its benchmark that holds
    the fields its value needs, with that record's commit and date, marked stale where its code
    changed since; then the commands of the figures no record holds yet."""
    tables: dict[str, list[list[str]]] = {}
    stale_on: set[str] = set()
    missing = []
    for figure in figures:
        command = _command(figure.benchmark, list(figure.args))
        needed = figure.fields()
        found = latest_records(
            records, figure.benchmark, list(figure.args), lambda r: needed <= r["result"]["fields"].keys()
        )
        for record in found:
            where, stale = machine_class(record["machine"]), _stale(record, root)
            measured = f"{record['commit'][:7]}, {record['date'][:10]}" + (" **stale**" if stale else "")
            if record["machine"].get("others_running"):
                measured += ", something else running"
            row = [figure.label, figure.value.format(**record["result"]["fields"]), measured, f"`{command}`"]
            tables.setdefault(where, []).append(row)
            if stale:
                stale_on.add(where)
        if not found and f"`{command}`" not in missing:
            missing.append(f"`{command}`")
    parts = []
    for where, rows in sorted(tables.items()):
        lines = _markdown(["figure", "value", "measured (commit, date)", "command"], rows)
        note = f"*{where}; each command run with `--record`.*"
        if where in stale_on:
            note += " **stale**: the code the figure measures has changed since; run its command with `--record` again."
        parts.append("\n".join([*lines, "", note]) + "\n")
    if missing:
        parts.append(f"*Not recorded yet (run with `--record`): {', '.join(missing)}.*\n")
    return "\n".join(parts)


def render_block(spec: str, records: list[dict], root: Path = ROOT) -> str:
    """The block's body for its ``spec`` (``BENCHMARK [ARGS...] [| table N | fields]``)."""
    what, _, shown = spec.partition("|")
    benchmark, *args = shlex.split(what)
    if benchmark == "summary":
        if args[0] not in SUMMARIES:
            raise SystemExit(f"figures: no summary named {args[0]!r} (there are {', '.join(SUMMARIES)})")
        return render_summary(SUMMARIES[args[0]], records, root)
    command = _command(benchmark, args)
    shown_words = shown.split()
    table = int(shown_words[1]) if shown_words[:1] == ["table"] else 0
    found = latest_records(
        records,
        benchmark,
        args,
        lambda r: len(r["result"]["tables"]) >= table if table else bool(r["result"]["fields"]),
    )
    if not found:
        return f"*No record of `{command}` yet: run it with `--record`.*\n"
    parts = []
    for record in found:
        if table:
            lines = _markdown(
                record["result"]["tables"][table - 1]["header"], record["result"]["tables"][table - 1]["rows"]
            )
        else:
            # as the line printed them (a parsed 0.990 would show as 0.99)
            printed = printed_fields(record["result"]["line"])
            lines = _markdown(["field", "value"], sorted((printed or record["result"]["fields"]).items()))
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
