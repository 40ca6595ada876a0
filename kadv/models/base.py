"""The depth-model interface every adapter implements."""

from __future__ import annotations

import torch
from torch import nn

from kadv.checks import check_shape
from kadv.losses.align import check_kind
from kadv.models.preprocess import Preprocess

__all__ = ["INTRINSICS", "DepthModel", "check_intrinsics"]

# what a model that takes the camera receives (``model.intrinsics``): each view's own K, or none
INTRINSICS = ("given", "withheld")


def check_intrinsics(choice: str) -> str:
    """``choice`` if it is one of :data:`INTRINSICS`, else a ``ValueError`` naming ``model.intrinsics``."""
    if choice not in INTRINSICS:
        raise ValueError(f"model.intrinsics must be given or withheld, got {choice!r}")
    return choice


class DepthModel(nn.Module):
    """rgb (B, 3, H, W) in [0, 1] -> (B, 1, H, W) prediction at the input size, differentiable in rgb.

    Subclasses implement :meth:`predict` on the network input; the base class makes that input
    and brings the output back with its :class:`Preprocess` (None passes the image through as it
    is). Parameters are frozen and the module stays in eval mode.

    Attributes:
        output_kind: what the prediction holds (:data:`kadv.losses.KINDS`): "disparity" (relative
            inverse depth, affine-invariant), "depth" (metric), "affine_depth" (depth up to scale
            and shift) or "scale_depth" (depth up to scale).
        name: a label for reports.
        takes_K: whether the model takes the camera's intrinsics (Depth Pro; a custom module whose
            ``forward`` has a parameter ``K``).
        intrinsics: for a model that takes K, ``given`` (each view's own K, that of the image the
            network sees after the preprocessing's resize and padding) or ``withheld`` (None: the
            model estimates it or uses its default); ``model.intrinsics``.
    """

    output_kind: str = "disparity"
    takes_K: bool = False

    def __init__(self, preprocess: Preprocess | None, output_kind: str, name: str) -> None:
        super().__init__()
        self.preprocess = preprocess
        self.output_kind = check_kind(output_kind)
        self.name = name
        self.intrinsics = "given"

    @property
    def camera_text(self) -> str:
        """What the model was told of the camera: ``given``, ``withheld`` or ``not taken``."""
        return self.intrinsics if self.takes_K else "not taken"

    def camera(self, K: torch.Tensor | None) -> torch.Tensor | None:
        """The intrinsics the model receives: ``K`` where it takes them and they are given, else None."""
        return K if self.takes_K and self.intrinsics == "given" else None

    @property
    def differentiable(self) -> bool:
        """Whether gradient methods may search it: its prediction's gradient is its own (a Marigold
        ensemble, aligned by a non-differentiable fit, is not)."""
        return True

    def inference_settings(self) -> dict:
        """Every setting besides the weights that changes the prediction (a bench entry's model
        identity holds them): for a model that takes K, whether it is given."""
        return {"intrinsics": self.intrinsics} if self.takes_K else {}

    def freeze(self) -> DepthModel:
        for parameter in self.parameters():
            parameter.requires_grad_(False)
        return self.eval()

    def train(self, mode: bool = True) -> DepthModel:
        """Stays in eval mode: attacks need deterministic, batch-independent predictions."""
        return super().train(False)

    def predict(self, pixel_values: torch.Tensor, K: torch.Tensor | None = None) -> torch.Tensor:
        """Network output (B, h, w) or (B, 1, h, w) for normalised input (B, 3, h, w); ``K``: the
        network input's intrinsics, for a model that takes them (None: withheld or not taken)."""
        raise NotImplementedError

    def forward(self, rgb: torch.Tensor, K: torch.Tensor | None = None) -> torch.Tensor:
        """Prediction (B, 1, H, W) for images (B, 3, H, W) in [0, 1]; it runs where the model's
        parameters are and comes back on ``rgb``'s device.

        Args:
            rgb: (B, 3, H, W) images in [0, 1].
            K: (3, 3) or (B, 3, 3) pinhole intrinsics of the images, for models that take them
                (:attr:`takes_K`) while they are given; the others never see it.
        """
        check_shape(rgb, "B 3 H W", "rgb")
        parameter = next(self.parameters(), None)
        x = rgb if parameter is None else rgb.to(parameter.device)
        K = self.camera(K)
        if K is not None:
            K = K.to(device=x.device, dtype=x.dtype)
        if self.preprocess is None:
            return self._as_map(self.predict(x, K)).to(rgb.device)
        pixel_values, layout = self.preprocess.to_network(x)
        network_K = None if K is None else layout.network_K(K)
        return self.preprocess.from_network(self._as_map(self.predict(pixel_values, network_K)), layout).to(rgb.device)

    @staticmethod
    def _as_map(out: torch.Tensor) -> torch.Tensor:
        """(B, 1, h, w) from a network's (B, h, w) or (B, 1, h, w)."""
        return out.unsqueeze(1) if out.ndim == 3 else out
