"""The camera paths scans were captured along, as the datasets ship them: real viewpoints where the
scan has content, the most natural init views there are.

Each reader returns camera-to-file poses (N, 4, 4) in the OpenCV camera convention (x right, y down,
z forward) and the file's own frame (before any alignment), float64:

- ScanNet: ``pose/<frame>.txt`` as SensReader exports them (camera-to-world, row-major 4 x 4 text),
  or the ``<scene>.sens`` stream itself, read for its poses only (each frame's colour and depth
  bytes are skipped, never loaded). Frames whose tracking was lost carry non-finite poses there;
  they are left out.
- ARKitScenes: ``lowres_wide.traj``, one line a frame: timestamp, the world-to-camera rotation as an
  axis-angle and its translation.
- ScanNet++: COLMAP's ``images.txt`` under ``dslr/colmap/`` or ``iphone/colmap/``: world-to-camera
  quaternions (w, x, y, z) and translations, every other line a list of 2-D points.
- Matterport3D: ``undistorted_camera_parameters/<house>.conf``, ``scan`` lines ending in a
  camera-to-world 4 x 4 with OpenGL's camera axes (y up, z backward).

A pose that cannot be read, or whose rotation is not a rotation, is refused in one line naming the
file and the line (or frame).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = [
    "CapturedPath",
    "find_captured_path",
    "read_arkitscenes_traj",
    "read_colmap_images",
    "read_matterport_conf",
    "read_scannet_poses",
    "read_scannet_sens",
]

# a rotation's columns are orthonormal to this, its determinant 1 to this
_RIGID_TOLERANCE = 1e-3
# OpenGL's camera axes (y up, z backward) to OpenCV's (y down, z forward)
_GL_TO_CV = np.diag([1.0, -1.0, -1.0, 1.0])


@dataclass(frozen=True)
class CapturedPath:
    """A scan's capture trajectory.

    Attributes:
        file_T_cam: (N, 4, 4) camera-to-file poses, OpenCV camera, in the scan file's own frame.
        source: the file (or folder) they were read from.
    """

    file_T_cam: np.ndarray
    source: Path


def _check_rigid(pose: np.ndarray, where: str) -> np.ndarray:
    rotation = pose[:3, :3]
    if (
        not np.isfinite(pose).all()
        or np.abs(rotation.T @ rotation - np.eye(3)).max() > _RIGID_TOLERANCE
        or abs(np.linalg.det(rotation) - 1.0) > _RIGID_TOLERANCE
        or np.abs(pose[3] - [0, 0, 0, 1]).max() > _RIGID_TOLERANCE
    ):
        raise ValueError(f"{where}: not a rigid camera pose (its rotation is not a rotation)")
    return pose


def _numbers(text: str, count: int, where: str) -> np.ndarray:
    try:
        values = np.array([float(v) for v in text.split()], np.float64)
    except ValueError:
        values = np.zeros(0)
    if len(values) != count:
        raise ValueError(f"{where}: expected {count} numbers, got {text.strip()[:80]!r}")
    return values


def read_scannet_poses(folder: str | Path) -> np.ndarray:
    """ScanNet's ``pose/*.txt`` (camera-to-world, 4 x 4 text each), in frame order; lost frames
    (non-finite) left out."""
    files = sorted(Path(folder).glob("*.txt"), key=lambda p: (len(p.stem), p.stem))
    poses = []
    for path in files:
        pose = _numbers(path.read_text(), 16, str(path)).reshape(4, 4)
        if np.isfinite(pose).all():
            poses.append(_check_rigid(pose, str(path)))
    return np.array(poses).reshape(-1, 4, 4)


def read_scannet_sens(path: str | Path) -> np.ndarray:
    """The camera-to-world poses of a ScanNet ``.sens`` file, streamed: its header, then each
    frame's pose, timestamps and sizes, the frame's compressed colour and depth skipped. Lost frames
    (non-finite) left out."""
    path = Path(path)
    poses = []
    with path.open("rb") as stream:

        def read(fmt: str, what: str) -> tuple:
            size = struct.calcsize(fmt)
            data = stream.read(size)
            if len(data) != size:
                raise ValueError(f"{path}: ends inside {what}")
            return struct.unpack(fmt, data)

        (version,) = read("<I", "the header")
        if version != 4:
            raise ValueError(f"{path}: a .sens of version {version}; ScanNet's are version 4")
        (length,) = read("<Q", "the header")
        stream.seek(length + 4 * 16 * 4 + 2 * 4 + 4 * 4 + 4, 1)  # name, 4 matrices, compressions, sizes, shift
        (frames,) = read("<Q", "the header")
        for frame in range(frames):
            pose = np.array(read("<16f", f"frame {frame}"), np.float64).reshape(4, 4)
            _, _, colour, depth = read("<QQQQ", f"frame {frame}")
            stream.seek(colour + depth, 1)
            if np.isfinite(pose).all():
                poses.append(_check_rigid(pose, f"{path}: frame {frame}"))
    return np.array(poses).reshape(-1, 4, 4)


def read_arkitscenes_traj(path: str | Path) -> np.ndarray:
    """ARKitScenes' ``lowres_wide.traj``: per line a timestamp, an axis-angle and a translation, the
    world-to-camera transform; returned inverted, camera-to-world."""
    path = Path(path)
    poses = []
    for number, line in enumerate(path.read_text().splitlines(), start=1):
        if not line.strip():
            continue
        values = _numbers(line, 7, f"{path}:{number}")
        camera_T_world = np.eye(4)
        camera_T_world[:3, :3] = Rotation.from_rotvec(values[1:4]).as_matrix()
        camera_T_world[:3, 3] = values[4:7]
        poses.append(_check_rigid(np.linalg.inv(camera_T_world), f"{path}:{number}"))
    return np.array(poses).reshape(-1, 4, 4)


def read_colmap_images(path: str | Path) -> np.ndarray:
    """COLMAP's ``images.txt``: ``IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME`` lines (each followed
    by a line of 2-D points), the world-to-camera transform; returned camera-to-world, by image id."""
    path = Path(path)
    rows = []
    lines = [(n, line) for n, line in enumerate(path.read_text().splitlines(), start=1) if not line.startswith("#")]
    for number, line in lines[0::2]:
        fields = line.split()
        if len(fields) < 10:
            raise ValueError(f"{path}:{number}: expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME")
        values = _numbers(" ".join(fields[:8]), 8, f"{path}:{number}")
        if abs(np.linalg.norm(values[1:5]) - 1.0) > _RIGID_TOLERANCE:
            raise ValueError(f"{path}:{number}: not a rigid camera pose (its quaternion is not of unit length)")
        camera_T_world = np.eye(4)
        camera_T_world[:3, :3] = Rotation.from_quat(values[[2, 3, 4, 1]]).as_matrix()  # scipy: x, y, z, w
        camera_T_world[:3, 3] = values[5:8]
        rows.append((values[0], _check_rigid(np.linalg.inv(camera_T_world), f"{path}:{number}")))
    return np.array([pose for _, pose in sorted(rows, key=lambda row: row[0])]).reshape(-1, 4, 4)


def read_matterport_conf(path: str | Path) -> np.ndarray:
    """Matterport3D's ``undistorted_camera_parameters/<house>.conf``: the camera-to-world poses of
    its ``scan`` lines (OpenGL camera axes), returned with OpenCV's."""
    path = Path(path)
    poses = []
    for number, line in enumerate(path.read_text().splitlines(), start=1):
        fields = line.split()
        if not fields or fields[0] != "scan":
            continue
        pose = _numbers(" ".join(fields[3:]), 16, f"{path}:{number}").reshape(4, 4)
        poses.append(_check_rigid(pose, f"{path}:{number}") @ _GL_TO_CV)
    return np.array(poses).reshape(-1, 4, 4)


def _scannet(mesh: Path) -> list[tuple[Path, object]]:
    scene = mesh.name.split("_vh_clean")[0]
    return [(mesh.parent / "pose", read_scannet_poses), (mesh.parent / f"{scene}.sens", read_scannet_sens)]


def _scannetpp(mesh: Path) -> list[tuple[Path, object]]:
    root = mesh.parent.parent if mesh.parent.name == "scans" else mesh.parent
    return [(root / device / "colmap" / "images.txt", read_colmap_images) for device in ("dslr", "iphone")]


def _arkitscenes(mesh: Path) -> list[tuple[Path, object]]:
    return [(mesh.parent / "lowres_wide.traj", read_arkitscenes_traj)]


def _matterport(mesh: Path) -> list[tuple[Path, object]]:
    return [
        (folder / "undistorted_camera_parameters" / f"{folder.name}.conf", read_matterport_conf)
        for folder in mesh.parents[:3]
    ]


# where each dataset's layout keeps its trajectory, beside its mesh
_LAYOUTS = {"ScanNet": _scannet, "ScanNet++": _scannetpp, "ARKitScenes": _arkitscenes, "Matterport3D": _matterport}


def find_captured_path(mesh: str | Path, dataset: str | None) -> CapturedPath | None:
    """The capture trajectory a scan's layout keeps beside its mesh, or None where there is none
    (or the dataset ships none: Replica and others).

    Raises:
        ValueError: a trajectory file that cannot be read, naming the file and line.
    """
    mesh = Path(mesh)
    for source, reader in _LAYOUTS.get(dataset, lambda _: [])(mesh):
        if source.exists():
            poses = reader(source)
            if len(poses):
                return CapturedPath(poses, source)
    return None
