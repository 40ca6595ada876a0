"""Where the networks and the per-pixel arithmetic run: ``device=auto|cpu|cuda``.

Policy. Ray casts, distance queries and the exact renderer's shading stay on the CPU (Open3D and
numpy). Per step, the exact render crosses to the device once (image, depth, mask, normals) and
the anchor once per refresh; the depth model, the loss, the reprojection and the silhouette
term's per-pixel part run on the device. The pose parameters and the pose algebra ((B, 4, 4)
matrices, float64) stay on the CPU, where the optimiser and the step guard use them, so the
objective comes back to the CPU as (B,) scalars. Dtypes: poses and geometry float64; images,
networks and the reprojection's per-sample arithmetic float32 (``benchmarks/gradcheck.py`` holds).
"""

from __future__ import annotations

import os
from pathlib import Path

import torch

__all__ = ["free_memory", "resolve_device"]


def free_memory(device: torch.device | str = "cpu") -> int:
    """Bytes free on ``device``: a CUDA device's free memory, or the memory the machine can give a
    new allocation without swapping (``MemAvailable``: free pages and the reclaimable cache)."""
    device = torch.device(device)
    if device.type == "cuda":
        return torch.cuda.mem_get_info(device)[0]
    meminfo = Path("/proc/meminfo")
    if meminfo.is_file():
        for line in meminfo.read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")


def resolve_device(name: str | torch.device) -> torch.device:
    """``auto`` (CUDA when present, else the CPU), ``cpu``, ``cuda`` or ``cuda:<index>``.

    Raises:
        ValueError: an unknown name, or CUDA asked for where none is available.
    """
    text = str(name)
    if text == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if text != "cpu" and not text.startswith("cuda"):
        raise ValueError(f"device={text!r}: expected auto, cpu, cuda or cuda:<index>")
    try:
        device = torch.device(text)
    except RuntimeError as error:
        raise ValueError(f"device={text!r}: {error}") from None
    if device.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"device={text!r}: no CUDA device is available here (use device=cpu or device=auto)")
    if device.type == "cuda" and device.index is not None and device.index >= torch.cuda.device_count():
        raise ValueError(f"device={text!r}: only {torch.cuda.device_count()} CUDA device(s) here")
    return device
