"""After ``mkdocs build``: every name in ``kadv.__all__`` and in each subpackage's ``__all__`` has an
entry in the site's API reference (``site/objects.inv``, the inventory mkdocstrings writes).

Prints the missing names and exits with status 1 if there are any.
"""

from __future__ import annotations

import importlib
import pkgutil
import sys
import zlib
from pathlib import Path

import kadv


def documented(inventory: Path) -> set[str]:
    """The object names in a Sphinx-format inventory (four header lines, then zlib-compressed lines)."""
    lines = inventory.read_bytes().split(b"\n", 4)
    return {line.split(" ", 1)[0] for line in zlib.decompress(lines[4]).decode().splitlines() if line}


def public_names() -> list[str]:
    """``kadv.<name>`` for kadv's own names, ``kadv.<package>.<name>`` for each subpackage's."""
    names = [f"kadv.{name}" for name in kadv.__all__]
    for module in pkgutil.iter_modules(kadv.__path__):
        if module.ispkg and module.name != "cli":  # the entry points, documented by --help
            package = importlib.import_module(f"kadv.{module.name}")
            names += [f"kadv.{module.name}.{name}" for name in package.__all__]
    return names


def main() -> None:
    site = Path(sys.argv[1] if len(sys.argv) > 1 else "site")
    found = documented(site / "objects.inv")
    missing = [name for name in public_names() if name not in found]
    if missing:
        print(f"{len(missing)} public names missing from the API reference in {site}: {', '.join(missing)}")
        sys.exit(1)
    print(f"API reference: all {len(public_names())} public names documented")


if __name__ == "__main__":
    main()
