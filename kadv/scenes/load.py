"""``load_scene``: one entry point for every supported scene file."""

from __future__ import annotations

from pathlib import Path

from kadv.scenes.mitsuba import parse_mitsuba
from kadv.scenes.scene import Material, Scene, assemble_scene
from kadv.scenes.trimesh_loader import TRIMESH_SUFFIXES, load_mesh_file

__all__ = ["SUPPORTED_SUFFIXES", "load_scene"]

SUPPORTED_SUFFIXES = (".xml", *TRIMESH_SUFFIXES)


def load_scene(
    path: str | Path,
    *,
    scale: float = 1.0,
    up_axis: str = "y",
    drop_transparent: bool = True,
    drop_emitters: bool = True,
    missing: str = "error",
    name: str | None = None,
) -> Scene:
    """Load a scene file: Mitsuba ``.xml``, or ``.glb/.gltf/.obj/.ply/.off/.stl`` through trimesh.

    Args:
        path: the scene file.
        scale: metres per file unit.
        up_axis: the file's up axis (``"y"`` or ``"z"``); kadv's world is y-up.
        drop_transparent: leave out glass-like materials (they would hide what is behind them).
        drop_emitters: leave out light-source surfaces; their centres become the renderer's lights.
        missing: Mitsuba only: ``"error"`` or ``"skip"`` for referenced files that do not exist.
        name: label for reports; defaults to the folder name for ``scene.xml``, else the file stem.

    Raises:
        FileNotFoundError: the path (or a file it references) does not exist.
        ValueError: unsupported extension, unreadable or empty file, NaN vertices, zero area.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"scene file not found: {path}")
    if not path.is_file():
        raise ValueError(f"scene path is not a file: {path}")
    suffix = path.suffix.lower()
    if suffix not in SUPPORTED_SUFFIXES:
        raise ValueError(f"unsupported scene format {suffix!r} for {path}; supported: {', '.join(SUPPORTED_SUFFIXES)}")
    if name is None:
        name = path.parent.name if path.stem == "scene" else path.stem
    options = {"scale": scale, "up_axis": up_axis, "drop_transparent": drop_transparent, "drop_emitters": drop_emitters}
    if suffix == ".xml":
        parts, materials, cameras, lights, emitters = parse_mitsuba(path, missing=missing)
        return assemble_scene(parts, materials, cameras, lights, name=name, emitters=emitters, **options)
    materials: list[Material] = []
    parts = load_mesh_file(path, materials)
    return assemble_scene(parts, materials, name=name, **options)
