"""A gradient step captured once in a CUDA graph and replayed (``render.differentiable.cuda_graphs``).

A step on a GPU dispatches thousands of small operations one by one, and the host's dispatching,
not the device, sets its pace. Captured, the step is one graph launch. Capture needs a step of fixed
shapes that reads nothing back to the host (``edge_search=every_pair``), an optimiser that keeps
its step count on the device (Adam's ``capturable``), and no copies from the host: the step makes
its constants (intrinsics, pixel grids) on the host and uploads them, and :class:`HostUploads`
serves those uploads, once recorded, from device copies. Where capture fails, the step runs as
written, after one warning naming why.
"""

from __future__ import annotations

import copy
import dataclasses
import traceback
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
import torch
from torch.overrides import TorchFunctionMode

__all__ = ["HostUploads", "StepGraph", "map_tensors"]


def _upload_target(func, args: tuple, kwargs: dict) -> tuple[torch.device, torch.dtype | None] | None:
    """The CUDA device (and dtype) that a call of ``Tensor.to``, ``Tensor.cuda``, ``torch.as_tensor``
    or ``torch.tensor`` copies host data to, or None when it copies none."""
    if func is torch.Tensor.to:
        source = args[0]
        if source.device.type != "cpu":
            return None
        if args[1:] and isinstance(args[1], torch.Tensor):
            device, dtype = args[1].device, args[1].dtype
        else:
            device, dtype, *_ = torch._C._nn._parse_to(*args[1:], **kwargs)
    elif func is torch.Tensor.cuda:
        if args[0].device.type != "cpu":
            return None
        device, dtype = torch.device("cuda", torch.cuda.current_device()), None
    elif func in (torch.as_tensor, torch.tensor):
        data = args[0]
        if isinstance(data, torch.Tensor) and data.device.type != "cpu":
            return None
        device, dtype = kwargs.get("device"), kwargs.get("dtype")
        if device is None and func is torch.as_tensor and len(args) > 2:
            device = args[2]
    else:
        return None
    device = torch.device(device) if device is not None else None
    return (device, dtype) if device is not None and device.type == "cuda" else None


def _value(value: Any) -> Any:
    """A hashable stand-in for an argument of an upload: host data by their bytes, a device tensor
    by its device and dtype (reading its values would wait for the device)."""
    if isinstance(value, torch.Tensor):
        if value.device.type != "cpu":
            return ("tensor", str(value.device), str(value.dtype))
        value = value.detach().contiguous().numpy()
    if isinstance(value, np.ndarray):
        return ("array", str(value.dtype), value.shape, np.ascontiguousarray(value).tobytes())
    return repr(value)


def _key(func, args: tuple, kwargs: dict) -> tuple | None:
    """What an upload copies, by value: None for what cannot be keyed (a tensor with a gradient)."""
    if isinstance(args[0], torch.Tensor) and args[0].requires_grad:
        return None
    rest = tuple((k, _value(v)) for k, v in sorted(kwargs.items()))
    return (func.__name__, tuple(_value(a) for a in args), rest)


class HostUploads(TorchFunctionMode):
    """Serves copies of host data to CUDA from device copies made while :attr:`recording`.

    A captured graph cannot copy from pageable host memory, and a copy it made from a temporary
    host buffer would read freed memory when replayed. The step's uploads are constants of the run
    (they depend on the intrinsics and the image size only), so an eager step records them, keyed by
    their values, and the capture reads the device copies instead (a device-to-device copy each, so
    a caller may write into what it got). An upload whose values were not recorded goes through,
    and the capture then fails with PyTorch's own message.
    """

    def __init__(self) -> None:
        super().__init__()
        self.recording = True
        self.uploads: dict[tuple, torch.Tensor] = {}

    def __torch_function__(self, func, types, args=(), kwargs=None):
        kwargs = kwargs or {}
        if _upload_target(func, args, kwargs) is None or (key := _key(func, args, kwargs)) is None:
            return func(*args, **kwargs)
        if self.recording:
            result = func(*args, **kwargs)
            self.uploads[key] = result.detach().clone()
            return result
        stored = self.uploads.get(key)
        return func(*args, **kwargs) if stored is None else stored.clone()


def map_tensors(fn: Callable[[torch.Tensor], Any], value: Any) -> Any:
    """``value`` with ``fn`` applied to every tensor in it (in dataclasses, lists, tuples and dicts),
    the rest kept as it is."""
    if isinstance(value, torch.Tensor):
        return fn(value)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        result = copy.copy(value)
        for field in dataclasses.fields(value):
            object.__setattr__(result, field.name, map_tensors(fn, getattr(value, field.name)))
        return result
    if isinstance(value, (list, tuple)):
        return type(value)(map_tensors(fn, v) for v in value)
    if isinstance(value, dict):
        return {k: map_tensors(fn, v) for k, v in value.items()}
    return value


def _copied(value: Any) -> Any:
    """``value`` with every tensor in it cloned: a graph's outputs are overwritten by its next replay."""
    return map_tensors(torch.Tensor.clone, value)


def _reason(error: BaseException) -> str:
    """The first line of ``error`` and of each error it came from, and the innermost line of kadv's
    code (outside this module) that the first of them passed through."""
    reasons, where = [], ""
    while error is not None:
        text = str(error).strip()
        reasons.append(f"{type(error).__name__}: {text.splitlines()[0] if text else ''}")
        frames = [
            f
            for f in traceback.extract_tb(error.__traceback__)
            if "/kadv/" in f.filename and not f.filename.endswith("capture.py")
        ]
        if frames:
            where = f" at kadv/{frames[-1].filename.rsplit('/kadv/', 1)[-1]}:{frames[-1].lineno}"
        error = error.__cause__ or error.__context__
    return "; from ".join(reasons) + where


class StepGraph:
    """Runs ``step`` (no arguments; it returns tensors, or dataclasses and lists of them) as one CUDA
    graph after its first call.

    On the CPU, or with ``enabled`` False, every call runs ``step`` as written. On CUDA the first
    call runs it eagerly on a side stream (the warm-up PyTorch asks for; its host uploads are
    recorded); the second captures it, and that call and every later one replay the graph and
    return copies of its outputs. What ``step`` does on the host (Python state, numbers it computes)
    happens once, at capture: everything that must change from step to step has to live in device
    tensors that ``step`` updates in place. A capture that fails turns the graph off, with one
    warning, and the step runs eagerly from then on.

    Attributes:
        failure: why the capture failed (None: it did not, or was not tried).
    """

    def __init__(self, step: Callable[[], Any], device: torch.device, enabled: bool = True) -> None:
        self.step = step
        self.enabled = self.available(device, enabled)
        self.failure: str | None = None
        self._uploads = HostUploads()
        self._graph: torch.cuda.CUDAGraph | None = None
        self._outputs: Any = None
        self._warm = False

    @staticmethod
    def available(device: torch.device | str, enabled: bool = True) -> bool:
        """Whether a step on ``device`` is captured when ``enabled``: on CUDA only."""
        return enabled and torch.device(device).type == "cuda"

    @property
    def captured(self) -> bool:
        """Whether the step is replayed from a graph."""
        return self._graph is not None

    def __call__(self) -> Any:
        if not self.enabled:
            return self.step()
        if self._graph is None:
            if not self._warm:
                return self._warm_up()
            try:
                self._capture()
            except Exception as error:  # any failure to capture leaves the eager step, which is correct
                self.enabled = False
                self.failure = _reason(error)
                warnings.warn(
                    f"render.differentiable.cuda_graphs: the gradient step could not be captured ({self.failure}); "
                    "it runs uncaptured",
                    RuntimeWarning,
                    stacklevel=2,
                )
                torch.cuda.synchronize()
                return self.step()
        self._graph.replay()
        return _copied(self._outputs)

    def _warm_up(self) -> Any:
        self._warm = True
        side = torch.cuda.Stream()
        side.wait_stream(torch.cuda.current_stream())
        with torch.cuda.stream(side), self._uploads:
            outputs = self.step()
        torch.cuda.current_stream().wait_stream(side)
        self._uploads.recording = False
        return outputs

    def _capture(self) -> None:
        graph = torch.cuda.CUDAGraph()
        with self._uploads, torch.cuda.graph(graph):
            outputs = self.step()
        self._graph, self._outputs = graph, outputs
