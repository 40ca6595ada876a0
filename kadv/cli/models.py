"""``kadv-models``: every model preset with its hub id, family, output kind, input size and whether
its weights are on this machine. It reads only the local cache, so it answers offline."""

from __future__ import annotations

import argparse

from kadv.models.presets import preset_table

__all__ = ["main"]


def main(argv: list[str] | None = None) -> None:
    argparse.ArgumentParser(prog="kadv-models", description=__doc__).parse_args(argv)
    rows = preset_table()
    columns = list(rows[0])
    print("| " + " | ".join(columns) + " |\n|" + "---|" * len(columns))
    for row in rows:
        print("| " + " | ".join(row[c] for c in columns) + " |")
    print(
        "\nAny other transformers depth checkpoint: model=huggingface model.name=<hub id or directory>; "
        "your own torch module: model=custom model.target=<factory>."
    )


if __name__ == "__main__":
    main()
