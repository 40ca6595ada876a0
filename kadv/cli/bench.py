"""``kadv-bench``: frozen suites, entries, their check and the leaderboard.

    kadv-bench freeze scenes=real-v1 name=my-real out=my-real.json         (a shipped suite's scenes)
    kadv-bench freeze scenes=a/scene.xml,b/room.glb root=~/scans name=mine out=mine.json views=6
    kadv-bench run suite=offline-v1 model=kadv_tiny seeds=[0,1,2]          (a Hydra app: any model preset)
    kadv-bench run -m suite=offline-v1 shard=0,1,2,3 shards=4 hydra/launcher=joblib
    kadv-bench merge suite=offline-v1 model=kadv_tiny seeds=0,1,2 out=outputs/bench/offline-v1-kadv_tiny
    kadv-bench verify outputs/bench/offline-v1-kadv_tiny/entry.json model=kadv_tiny pictures=worst/
    kadv-bench table a/entry.json b/entry.json out=outputs/leaderboard pooled=true

``freeze`` writes a suite file and a sheet of its init views (PNG); ``run`` writes one model's
units and, once all are there, its ``entry.json``; ``merge`` assembles the entry from shards'
units; ``verify`` renders every stored worst pose again and scores it; ``table`` writes
``leaderboard.md``, ``.json``, ``.png`` and ``.html``. A suite is a shipped suite's name
(offline-v1, real-v1) or a suite file; an entry names its suite, so ``verify`` and ``table`` find a
shipped one themselves. docs/benchmark.md has the files' schemas and what each score means.
"""

from __future__ import annotations

# before anything loads torch: the wait policy is read when torch starts its thread pool
from kadv.runtime import configure_runtime

configure_runtime()

import sys
from pathlib import Path

import hydra
from omegaconf import DictConfig, OmegaConf

from kadv.cli.common import checks_overrides, config_int, model_from_config, reports_user_errors

__all__ = ["main"]

OmegaConf.register_new_resolver("suite_stem", lambda suite: Path(str(suite)).stem, replace=True)

_KEYS = {
    "freeze": {"scenes": None, "name": None, "out": None, "root": None, "views": "4", "seed": "0",
               "licence": "unknown", "passes": None, "method": None, "envelope": None, "min_seeds": None,
               "lighting": None, "size": None},
    "merge": {"suite": None, "model": "kadv_tiny", "seeds": "0,1,2", "out": None},
    "verify": {"suite": None, "model": "kadv_tiny", "scenes": None, "tolerance": None, "pictures": None},
    "table": {"suite": None, "out": "outputs/leaderboard", "pooled": "false", "scenes": None},
}  # fmt: skip


def _arguments(verb: str, argv: list[str]) -> tuple[dict[str, str | None], list[str]]:
    """The verb's key=value settings (its defaults for the others) and its positional arguments."""
    values, positional = dict(_KEYS[verb]), []
    for argument in argv:
        key, equals, value = argument.partition("=")
        if not equals:
            positional.append(argument)
        elif key in values:
            values[key] = value
        else:
            raise ValueError(f"{argument!r}: kadv-bench {verb} takes the keys {', '.join(values)}")
    return values, positional


def _required(values: dict, key: str, verb: str) -> str:
    if not values.get(key):
        raise ValueError(f"kadv-bench {verb} needs {key}=...")
    return values[key]


def _ints(text: str, key: str) -> tuple[int, ...]:
    parts = [p for p in text.strip("[]").split(",") if p.strip()]
    try:
        numbers = tuple(int(p) for p in parts)
    except ValueError:
        raise ValueError(f"{key} must be integers separated by commas, got {text!r}") from None
    if not numbers:
        raise ValueError(f"{key} is empty")
    return numbers


def _specs(text: str, root: str | None, licence: str) -> list:
    """Scene specs from ``scenes=``: a shipped suite's name, or scene files (under ``root``)."""
    from kadv.bench import SHIPPED, SceneSpec, shipped_specs

    if text in SHIPPED:
        return shipped_specs(text)
    specs = []
    base = Path(root).expanduser() if root else None
    for item in (t for t in text.split(",") if t):
        path = Path(item).expanduser()
        full = base / path if base is not None and not path.is_absolute() else path
        if not full.is_file():
            raise ValueError(f"scenes: {full} is not a file")
        relative = str(full.relative_to(base)) if base is not None and full.is_relative_to(base) else str(full)
        specs.append(
            SceneSpec(full.parent.name or full.stem, {"kind": "file", "path": relative}, {"path": relative}, licence)
        )
    return specs


def _freeze(values: dict, positional: list[str]) -> None:
    from kadv.bench import Protocol, freeze_suite, save_suite_sheet

    name, out = _required(values, "name", "freeze"), _required(values, "out", "freeze")
    protocol = {}
    if values["passes"]:
        protocol["radius_passes"] = _ints(values["passes"], "passes")
    if values["size"]:
        protocol["size"] = _ints(values["size"], "size")
    if values["min_seeds"]:
        protocol["min_seeds"] = config_int(_ints(values["min_seeds"], "min_seeds")[0], "min_seeds", 1)
    protocol |= {key: values[key] for key in ("method", "envelope", "lighting") if values[key]}
    specs = _specs(_required(values, "scenes", "freeze"), values["root"], values["licence"])
    suite = freeze_suite(
        name,
        specs,
        Protocol(**protocol),
        views_per_scene=config_int(_ints(values["views"], "views")[0], "views", 1),
        seed=_ints(values["seed"], "seed")[0],
        root=values["root"],
        progress=True,
    )
    suite.save(out)
    sheet = save_suite_sheet(suite, Path(out).with_suffix(".png"), values["root"])
    print(
        f"suite {name} ({suite.hash[:12]}): {len(suite.scenes)} scenes, {len(suite.views)} init views -> {out}, {sheet}"
    )


def _suite_of(values: dict, entry=None):
    from kadv.bench import load_suite

    return load_suite(values["suite"] or (entry.suite["name"] if entry is not None else _required(values, "suite", "")))


def _model(name: str):
    return model_from_config({"name": name})


def _merge(values: dict, positional: list[str]) -> None:
    from kadv.bench import assemble_entry, suite_units, unit_path
    from kadv.bench.entry import claim_run_folder

    suite = _suite_of(values)
    out, seeds = Path(_required(values, "out", "merge")), _ints(values["seeds"], "seeds")
    model = _model(values["model"])
    claim_run_folder(out, suite, model)  # the shards' units are this suite's and this model's
    entry = assemble_entry(suite, model, seeds, out)
    if entry is None:
        keys = suite_units(suite, seeds)
        done = sum(unit_path(out, key).is_file() for key in keys)
        raise ValueError(f"{out}: {done} of {len(keys)} run units are there; run the other shards first")
    print(f"entry: {out / 'entry.json'}")


def _verify(values: dict, positional: list[str]) -> None:
    from kadv.bench import load_entry, verify_entry

    if len(positional) != 1:
        raise ValueError("kadv-bench verify takes one entry file")
    entry = load_entry(positional[0])
    suite = _suite_of(values, entry)
    tolerance = {"tolerance_pixels": float(values["tolerance"])} if values["tolerance"] else {}
    checked = verify_entry(
        entry,
        suite,
        _model(values["model"]),
        values["scenes"],
        where=positional[0],
        pictures=values["pictures"],
        **tolerance,
    )
    print(f"{positional[0]}: {checked.text()}")


def _table(values: dict, positional: list[str]) -> None:
    from kadv.bench import leaderboard, pooled_worst, read_entries

    if not positional:
        raise ValueError("kadv-bench table takes one or more entry files")
    if values["pooled"] not in ("true", "false"):
        raise ValueError(f"pooled must be true or false, got {values['pooled']!r}")
    entries = read_entries(positional)
    suite = _suite_of(values, next(iter(entries.values())))
    pooled = None
    if values["pooled"] == "true":  # every model scored at the others' worst poses: they must load by name
        models = {name: _model(name) for name in dict.fromkeys(e.model["name"] for e in entries.values())}
        pooled = pooled_worst(suite, entries, models, values["scenes"])
    board = leaderboard(suite, entries, pooled)
    written = board.write(values["out"])
    print(f"{board.markdown()}\n\nleaderboard: {', '.join(str(p) for p in written)}")


@checks_overrides("kadv-bench")
@hydra.main(version_base="1.3", config_path="../conf", config_name="kadv_bench")
@reports_user_errors("kadv-bench")
def _run(cfg: DictConfig) -> float | None:
    """One model's run of a suite (or one shard of it); returns the suite score once complete."""
    from kadv.bench import leaderboard, load_suite, run_suite
    from kadv.device import resolve_device

    suite = load_suite(cfg.suite)
    seeds = tuple(config_int(s, "seeds", 0) for s in (cfg.seeds if not isinstance(cfg.seeds, int) else [cfg.seeds]))
    shards = config_int(cfg.shards, "shards", 1)
    shard = config_int(cfg.shard, "shard", 0)
    device = resolve_device(cfg.device)
    out = Path(cfg.out)
    entry = run_suite(
        suite, model_from_config(cfg.model), seeds, out, (shard, shards), cfg.scenes, device, cfg.progress
    )
    if entry is None:
        print(f"shard {shard}/{shards} done; the entry is written once every shard's units are in {out / 'units'}")
        return None
    board = leaderboard(suite, {str(out / "entry.json"): entry})
    print(f"{board.markdown()}\n\nentry: {out / 'entry.json'}")
    return board.rows[0].score.overall


def main() -> None:
    """Dispatch ``kadv-bench <verb>``."""
    verbs = ("freeze", "run", "merge", "verify", "table")
    argv = sys.argv[1:]
    if argv and argv[0] in ("-h", "--help"):
        print(__doc__.strip())
        return
    verb = argv[0] if argv else ""
    if verb == "run":
        sys.argv[1:] = argv[1:]
        _run()
        return
    from kadv.bench import BenchError

    try:
        if verb not in verbs:
            raise ValueError(f"{verb!r} is not a verb of kadv-bench: give one of {', '.join(verbs)}")
        values, positional = _arguments(verb, argv[1:])
        {"freeze": _freeze, "merge": _merge, "verify": _verify, "table": _table}[verb](values, positional)
    except (BenchError, ValueError, FileNotFoundError) as error:
        print(f"kadv-bench: error: {' '.join(str(error).split())}", file=sys.stderr)
        sys.exit(2)


if __name__ == "__main__":
    main()
