"""Settings of the shortcut penalty, the step guard and view validity, in one place."""

from __future__ import annotations

from dataclasses import dataclass

from kadv._renamed import renamed_attribute

__all__ = ["PenaltyConfig"]


@dataclass(frozen=True)
class PenaltyConfig:
    """Shortcut penalty, step guard and view validity settings (``conf/penalty/``), metres.

    Attributes:
        d_th: L_dist = 1/d - 1/d_th below this distance to the nearest surface.
        weight: lambda in L_depth - lambda * L_dist.
        margin: step guard: a step may not end (or pass) closer than this to a surface.
        near: near plane of the view-validity check.
        min_distance: an optical centre nearer than this to a surface makes a view "too close".
        enclosure_rays: directions of the sphere of rays of the inside/outside test.
        outside_threshold: enclosure rays' escape fraction above which a centre is outside the scene.
        inside_threshold: enclosure rays' back-face fraction above which a centre is inside an object.
        uninformative: judge views that show too little depth structure "uninformative" (recorded,
            never chosen as adversarial or init views).
        max_plane_share: a view is uninformative when one plane covers more than this share of the
            pixels that hit a surface (min-max normalisation turns a lone plane's depth into a ramp
            that any model's flat guess misses, so its L_depth says nothing about the model).
        max_miss_share: a scan's view (``render.lighting=scanned``) is uninformative when more than
            this share of its pixels look through a hole or a missing ceiling (they carry no depth);
            in a modelled room a miss is sky through a window, and counts as nothing.
    """

    d_th: float = 0.2
    weight: float = 1.0
    margin: float = 0.1
    near: float = 0.05
    min_distance: float = 0.05
    enclosure_rays: int = 512
    outside_threshold: float = 0.3
    inside_threshold: float = 0.5
    uninformative: bool = True
    max_plane_share: float = 0.9
    max_miss_share: float = 0.25
    probe_rays = renamed_attribute("enclosure_rays")

    def __post_init__(self) -> None:
        for name in ("d_th", "margin", "near", "min_distance"):
            if not getattr(self, name) > 0:
                raise ValueError(f"penalty.{name} must be positive, got {getattr(self, name)}")
        if self.weight < 0:
            raise ValueError(f"penalty.weight must be >= 0, got {self.weight}")
        if self.enclosure_rays < 16:
            raise ValueError(f"penalty.enclosure_rays must be >= 16, got {self.enclosure_rays}")
        for name in ("outside_threshold", "inside_threshold", "max_plane_share", "max_miss_share"):
            if not 0 < getattr(self, name) < 1:
                raise ValueError(f"penalty.{name} must be in (0, 1), got {getattr(self, name)}")

    def validity_options(self) -> dict[str, float | int | None]:
        """Keyword arguments of :func:`kadv.penalties.view_validity`."""
        return {
            "near": self.near,
            "min_distance": self.min_distance,
            "enclosure_rays": self.enclosure_rays,
            "outside_threshold": self.outside_threshold,
            "inside_threshold": self.inside_threshold,
            "max_plane_share": self.max_plane_share if self.uninformative else None,
            "max_miss_share": self.max_miss_share if self.uninformative else None,
        }
