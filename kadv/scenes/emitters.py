"""A scene's light sources as a path tracer sees them: what the lighting bake integrates.

Radiometric units as Mitsuba uses them, in linear RGB: radiance (W m^-2 sr^-1) for area emitters
and the sky, intensity (W sr^-1) for point and spot lights, irradiance (W m^-2) for the sun. Only
ratios matter: the bake's exposure is set once per scene.

These are separate from :attr:`kadv.scenes.Scene.lights`, the positions the direct shading uses,
which stay as they were so that ``render.lighting=direct`` renders as before.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

__all__ = [
    "DEFAULT_CEILING_LIGHT_SIZE",
    "DEFAULT_LAMP_RADIANCE",
    "MISSING_ENVMAP_RADIANCE",
    "SUNSKY_SKY_PER_SCALE",
    "Emitters",
]

# An ``envmap`` whose image is absent (the gallery ships none) lights the scene as a uniform white
# sky of this radiance; the Mitsuba reference (:mod:`kadv.scenes.mitsuba_sanitiser`) does the same.
MISSING_ENVMAP_RADIANCE = 1.0
# Mitsuba 0.6's ``sunsky`` becomes a uniform sky of this radiance per unit ``skyScale`` plus a
# directional sun of ``sunScale`` irradiance, in the bake and in the reference alike.
SUNSKY_SKY_PER_SCALE = 0.1
# An emissive surface whose file gives no radiance (a generated lamp's bulb, a glTF emitter).
DEFAULT_LAMP_RADIANCE = 10.0
# The side (metres) of the square, downward-facing light that a closed room without emitters gets.
DEFAULT_CEILING_LIGHT_SIZE = 0.5


def _rgb(values: object, count: int) -> np.ndarray:
    return np.asarray(values, np.float64).reshape(count, 3)


@dataclass
class Emitters:
    """Light sources in the scene's world frame.

    Attributes:
        area_triangles: (T, 3, 3) emitting triangles; each emits on the side its winding's normal
            points to.
        area_radiance: (T, 3) radiance of each.
        point_positions: (P, 3) point and spot lights.
        point_intensity: (P, 3) their intensity.
        spot_directions: (P, 3) unit axes of spot lights (zero for point lights).
        spot_cos_cutoff: (P,) cosine of each spot's cutoff angle (-1 for point lights).
        spot_cos_beam: (P,) cosine of each spot's full-intensity beam angle (-1 for point lights).
        sky_radiance: (3,) radiance of rays that leave the scene (a uniform sky), zero for none.
        envmap: optional (H, W, 3) latitude-longitude radiance replacing the uniform sky.
        envmap_world_T_map: (3, 3) rotation of the environment map's frame into the world.
        sun_directions: (S, 3) unit vectors towards each directional light.
        sun_irradiance: (S, 3) irradiance each gives a surface facing it.
        defaulted: True when the file had no emitters and kadv placed the documented defaults.
    """

    area_triangles: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3)))
    area_radiance: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    point_positions: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    point_intensity: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    spot_directions: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    spot_cos_cutoff: np.ndarray = field(default_factory=lambda: np.zeros(0))
    spot_cos_beam: np.ndarray = field(default_factory=lambda: np.zeros(0))
    sky_radiance: np.ndarray = field(default_factory=lambda: np.zeros(3))
    envmap: np.ndarray | None = None
    envmap_world_T_map: np.ndarray = field(default_factory=lambda: np.eye(3))
    sun_directions: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    sun_irradiance: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    defaulted: bool = False

    def __post_init__(self) -> None:
        self.area_triangles = np.asarray(self.area_triangles, np.float64).reshape(-1, 3, 3)
        self.area_radiance = _rgb(self.area_radiance, len(self.area_triangles))
        self.point_positions = np.asarray(self.point_positions, np.float64).reshape(-1, 3)
        count = len(self.point_positions)
        self.point_intensity = _rgb(self.point_intensity, count)
        self.spot_directions = _rgb(self.spot_directions, count)
        self.spot_cos_cutoff = np.asarray(self.spot_cos_cutoff, np.float64).reshape(count)
        self.spot_cos_beam = np.asarray(self.spot_cos_beam, np.float64).reshape(count)
        self.sky_radiance = np.asarray(self.sky_radiance, np.float64).reshape(3)
        self.envmap_world_T_map = np.asarray(self.envmap_world_T_map, np.float64).reshape(3, 3)
        self.sun_directions = np.asarray(self.sun_directions, np.float64).reshape(-1, 3)
        self.sun_directions = self.sun_directions / np.maximum(
            np.linalg.norm(self.sun_directions, axis=1, keepdims=True), 1e-30
        )
        self.sun_irradiance = _rgb(self.sun_irradiance, len(self.sun_directions))
        if self.envmap is not None:
            self.envmap = np.asarray(self.envmap, np.float32)
        arrays = [self.area_radiance, self.point_intensity, self.sky_radiance, self.sun_irradiance]
        if any((np.asarray(a) < 0).any() or not np.isfinite(a).all() for a in arrays):
            raise ValueError("emitters: radiance, intensity and irradiance must be finite and >= 0")

    @property
    def empty(self) -> bool:
        """True when nothing emits: the bake then places the documented defaults."""
        return not (
            (self.area_radiance.max(initial=0.0) > 0)
            or (self.point_intensity.max(initial=0.0) > 0)
            or self.sky_radiance.max() > 0
            or self.envmap is not None
            or (self.sun_irradiance.max(initial=0.0) > 0)
        )

    def point(self, position: np.ndarray, intensity: np.ndarray) -> Emitters:
        """These emitters and one more point light."""
        return self._with_points(position, intensity, np.zeros(3), -1.0, -1.0)

    def spot(
        self, position: np.ndarray, intensity: np.ndarray, direction: np.ndarray, cutoff_deg: float, beam_deg: float
    ) -> Emitters:
        """These emitters and one more spot light along ``direction``."""
        direction = np.asarray(direction, np.float64) / np.linalg.norm(direction)
        return self._with_points(
            position, intensity, direction, np.cos(np.radians(cutoff_deg)), np.cos(np.radians(beam_deg))
        )

    def _with_points(self, position, intensity, direction, cos_cutoff, cos_beam) -> Emitters:
        return replace(
            self,
            point_positions=np.vstack([self.point_positions, np.reshape(position, (1, 3))]),
            point_intensity=np.vstack([self.point_intensity, np.broadcast_to(intensity, (1, 3))]),
            spot_directions=np.vstack([self.spot_directions, np.reshape(direction, (1, 3))]),
            spot_cos_cutoff=np.r_[self.spot_cos_cutoff, cos_cutoff],
            spot_cos_beam=np.r_[self.spot_cos_beam, cos_beam],
        )

    def area(self, triangles: np.ndarray, radiance: np.ndarray) -> Emitters:
        """These emitters and more emitting triangles (T, 3, 3) of one ``radiance`` (3,)."""
        triangles = np.asarray(triangles, np.float64).reshape(-1, 3, 3)
        return replace(
            self,
            area_triangles=np.concatenate([self.area_triangles, triangles]),
            area_radiance=np.vstack([self.area_radiance, np.broadcast_to(radiance, (len(triangles), 3))]),
        )

    def sun(self, direction: np.ndarray, irradiance: np.ndarray) -> Emitters:
        """These emitters and a directional light coming from ``direction`` (towards the light)."""
        return replace(
            self,
            sun_directions=np.vstack([self.sun_directions, np.reshape(direction, (1, 3))]),
            sun_irradiance=np.vstack([self.sun_irradiance, np.broadcast_to(irradiance, (1, 3))]),
        )

    def transformed(self, rotation: np.ndarray, scale: float) -> Emitters:
        """The same emitters after ``x -> scale * rotation @ x`` (the loader's up-axis and unit change).

        Intensities keep their values: a point light's irradiance then falls as 1/d^2 in the new
        metres, as the geometry it lights does.
        """
        turn = lambda v: np.asarray(v) @ rotation.T
        return replace(
            self,
            area_triangles=turn(self.area_triangles) * scale,
            point_positions=turn(self.point_positions) * scale,
            spot_directions=turn(self.spot_directions),
            envmap_world_T_map=rotation @ self.envmap_world_T_map,
            sun_directions=turn(self.sun_directions),
        )
