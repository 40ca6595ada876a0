"""Colours: sRGB decoding, the tone map from exposed linear radiance to display values, and the
linear albedo that diffuse light sees under a material's dielectric coat."""

from __future__ import annotations

import math

import numpy as np
import torch
from kornia.color import linear_rgb_to_rgb, rgb_to_linear_rgb

from kadv.scenes.scene import Scene

__all__ = [
    "LUMINANCE",
    "coat_table",
    "coated_albedo",
    "exposed",
    "fresnel_diffuse_reflectance",
    "fresnel_reflectance",
    "srgb_decode",
    "srgb_encode",
    "tone_map",
    "untone",
]

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])  # of linear Rec. 709 RGB


def _channels_last(convert, values: torch.Tensor) -> torch.Tensor:
    """kornia's colour ``convert`` (which takes (*, 3, H, W)) applied to colours (..., 3)."""
    return convert(values.reshape(-1, 3).T[:, :, None])[:, :, 0].T.reshape(values.shape)


def srgb_decode(srgb: torch.Tensor) -> torch.Tensor:
    """Linear values (..., 3) of sRGB-encoded ones in [0, 1]."""
    return _channels_last(rgb_to_linear_rgb, srgb)


def srgb_encode(linear: torch.Tensor) -> torch.Tensor:
    """sRGB-encoded values (..., 3) of linear ones in [0, 1]."""
    return _channels_last(linear_rgb_to_rgb, linear.clamp(0.0, 1.0))


def tone_map(linear: torch.Tensor) -> torch.Tensor:
    """Display values (..., 3) in [0, 1] of exposed linear radiance (..., 3): a film-like shoulder ``1 - exp(-x)``
    (linear in the shadows, highlights rolling off rather than clipping, as a camera's response
    does), then sRGB-encoded. The reference comparison tone-maps the path tracer's image the same way."""
    return srgb_encode(-torch.expm1(-linear.clamp_min(0.0)))


def untone(display: torch.Tensor) -> torch.Tensor:
    """Exposed linear radiance (..., 3) that :func:`tone_map` shows as the display values (..., 3);
    white (1), which no finite radiance reaches, is read as just below it."""
    return -torch.log1p(-srgb_decode(display).clamp(0.0, 1.0 - 1e-6))


def exposed(display: float) -> float:
    """The exposed linear radiance that :func:`tone_map` shows as the linear display value ``display``."""
    return -math.log1p(-min(display, 0.999))


def fresnel_reflectance(cosine: torch.Tensor, eta: torch.Tensor | float) -> torch.Tensor:
    """The unpolarised Fresnel reflectance at cosines of incidence ``cosine`` (...) in [0, 1] on an
    interface of relative index ``eta`` (below 1: light inside the denser medium, 1 beyond the
    critical angle)."""
    sin_t2 = (1.0 - cosine**2) / eta**2
    cos_t = (1.0 - sin_t2).clamp_min(0.0).sqrt()
    rs = (cosine - eta * cos_t) / (cosine + eta * cos_t)
    rp = (eta * cosine - cos_t) / (eta * cosine + cos_t)
    return torch.where(sin_t2 >= 1.0, 1.0, 0.5 * (rs**2 + rp**2))


def fresnel_diffuse_reflectance(eta: float, samples: int = 4096) -> float:
    """The cosine-weighted hemispherical average of :func:`fresnel_reflectance` at an interface of
    relative index ``eta``; 0.092 for eta 1.5 and 0.596 for 1 / 1.5."""
    mu = (torch.arange(samples, dtype=torch.float64) + 0.5) / samples  # cosine of incidence, midpoint rule
    return float(torch.mean(2.0 * mu * fresnel_reflectance(mu, eta)))


def coat_table(scene: Scene) -> np.ndarray:
    """(M, 4) per material: the share of the base's light that its dielectric coat lets out, the
    coat's internal diffuse reflectance, its own reflectance, and 1 where internal scattering
    deepens the base's colour (Mitsuba's ``nonlinear``). A bare material is (1, 0, 0, 0)."""
    table = np.tile([1.0, 0.0, 0.0, 0.0], (len(scene.materials), 1))
    for index, material in enumerate(scene.materials):
        if material.coat_ior is not None:
            outside = fresnel_diffuse_reflectance(material.coat_ior)
            inside = fresnel_diffuse_reflectance(1.0 / material.coat_ior)
            let_out = (1.0 - outside) ** 2 / material.coat_ior**2
            table[index] = (let_out, inside, outside, float(material.coat_nonlinear))
    return table


def coated_albedo(albedo: torch.Tensor, coats: torch.Tensor) -> torch.Tensor:
    """(N, 3) linear albedo, as diffuse light sees it, of bases with linear albedo (N, 3) under
    coats (N, 4) (rows of :func:`coat_table`).

    Mitsuba's plastic with its two Fresnel transmissions averaged over the hemisphere: the base's
    light trapped and re-scattered under the coat, plus the coat's own reflection counted as if it
    were diffuse (its energy bounces on; its view-dependent highlights are not rendered).
    """
    let_out, inside, outside, nonlinear = coats.unbind(dim=1)
    trapped = inside[:, None] * torch.where(nonlinear[:, None] > 0, albedo, torch.ones_like(albedo))
    return let_out[:, None] * albedo / (1.0 - trapped) + outside[:, None]
