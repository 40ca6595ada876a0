"""The layouts of the field's scanned rooms, recognised by their file names, and their conventions.

ScanNet and ScanNet++, ARKitScenes, Replica, Matterport3D, 3RScan and HM3D are all Z-up in metres,
and their colour is the light the sensor captured (shown as it is: ``render.lighting=scanned``).
ScanNet's aligned frame is a matrix in the scene's ``.txt`` beside the mesh
(``axisAlignment = m00 m01 ... m33``, row-major). kadv ships none of these datasets: each is
licensed for research or non-commercial use only.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["ScanLayout", "recognise_scan", "scannet_alignment"]


@dataclass(frozen=True)
class ScanLayout:
    """A recognised scan's layout and what kadv assumes of it.

    Attributes:
        dataset: the dataset whose layout the file has ("ScanNet", "ARKitScenes", ...).
        up_axis: the file's up axis.
        scale: metres per file unit.
        alignment: (4, 4) transform into the dataset's aligned frame (ScanNet's
            ``axisAlignment``), or None (identity).
        alignment_source: where the alignment was read, for the log.
    """

    dataset: str
    up_axis: str = "z"
    scale: float = 1.0
    alignment: np.ndarray | None = None
    alignment_source: str | None = None

    def describe(self) -> str:
        """One line for the log: the dataset, the axes and units chosen, the alignment."""
        aligned = (
            f"axisAlignment from {self.alignment_source}"
            if self.alignment is not None
            else "no axisAlignment (identity)"
            if self.dataset == "ScanNet"
            else "no alignment"
        )
        return f"a {self.dataset} scan: {self.up_axis} up, {self.scale:g} m per unit, {aligned}"


# (dataset, file-name pattern), matched against the file's name, first match wins
_PATTERNS = (
    ("ScanNet", r"scene\d{4}_\d{2}_vh_clean(_2)?\.ply"),
    ("ScanNet++", r"mesh_aligned_0\.05\.ply"),
    ("ARKitScenes", r"\d+_3dod_mesh\.ply"),
    ("Replica", r"mesh\.ply"),
    ("3RScan", r"mesh\.refined(\.v2)?\.obj"),
    ("HM3D", r".+\.basis\.glb"),
    ("Matterport3D", r"[0-9a-f]{32}\.obj"),
)


def scannet_alignment(path: Path) -> tuple[np.ndarray, Path] | None:
    """ScanNet's ``axisAlignment`` (4, 4) from ``<scene>.txt`` beside the mesh ``<scene>_vh_clean*.ply``,
    and that file; None when there is no such file or line.

    Raises:
        ValueError: a line that does not hold 16 finite numbers, naming the file.
    """
    scene = re.sub(r"_vh_clean(_2)?$", "", path.stem)
    info = path.with_name(f"{scene}.txt")
    if not info.is_file():
        return None
    for line in info.read_text(errors="replace").splitlines():
        key, _, value = line.partition("=")
        if key.strip() == "axisAlignment":
            try:
                matrix = np.array([float(v) for v in value.split()], np.float64)
            except ValueError:
                matrix = np.zeros(0)
            if matrix.shape != (16,) or not np.isfinite(matrix).all():
                raise ValueError(f"{info}: axisAlignment must be 16 finite numbers, got {value.strip()!r}")
            return matrix.reshape(4, 4), info
    return None


def recognise_scan(path: str | Path) -> ScanLayout | None:
    """The scan layout a file's name has (its dataset's conventions), or None for any other file."""
    path = Path(path)
    for dataset, pattern in _PATTERNS:
        if re.fullmatch(pattern, path.name):
            if dataset == "ScanNet":
                found = scannet_alignment(path)
                if found is not None:
                    return ScanLayout(dataset, alignment=found[0], alignment_source=found[1].name)
            return ScanLayout(dataset)
    return None
