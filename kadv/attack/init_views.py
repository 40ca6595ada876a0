"""Init views (the study's "init-params"): benign starting views where the model is accurate.

Sources: the scene file's cameras (moved along their optical axis until clear of surfaces), a
scan's capture trajectory, an automatic seeded sampler that keeps the candidates the model predicts
best, or an ``init_params.json`` written by an earlier run.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import kornia
import numpy as np
import torch

from kadv.geometry import (
    axis_angle_to_matrix,
    check_world_T_cam,
    intrinsics_from_fov,
    look_at,
    perturb_world_T_cam,
    scaled_size,
    yaw_pitch_roll,
)
from kadv.io import write_json
from kadv.losses import depth_metrics
from kadv.models import DepthModel
from kadv.penalties import (
    PenaltyConfig,
    ViewValidity,
    distance_to_surface,
    plane_counts,
    step_guard,
    view_validity,
)
from kadv.penalties.envelope import Envelope
from kadv.penalties.validity import SCAN_TOP_TOLERANCE, VALID
from kadv.render import ExactRenderer

__all__ = [
    "CandidateTally",
    "InitView",
    "InitViewConfig",
    "InitViewError",
    "ViewScores",
    "captured_init_views",
    "check_init_views",
    "clear_file_camera",
    "file_init_views",
    "fit_into_envelope",
    "load_init_params",
    "sample_init_views",
    "sample_valid_views",
    "save_init_params",
    "score_views",
]


# Candidates are drawn in rounds until enough pass; a scene whose bounds are mostly outdoors or
# solid needs several rounds, one with no free space at eye height needs all of them.
_SAMPLING_ROUNDS = 30
# A file camera too near a surface moves along its axis in steps of at least 5 mm (the distance
# field's resolution near a surface), each 5% past the shortfall so that rounding cannot leave it
# a hair inside the margin.
_MIN_CLEARING_STEP = 0.005
_CLEARING_OVERSHOOT = 1.05
# Candidate centres: half within this many metres (horizontally) of a file camera, the rest over
# the camera region; points are drawn this many times over, since only those inside are kept.
_NEAR_CAMERA = 3.0
_OVERSAMPLE = 4
# Missed pixels hold depth 0; a view's depth range divides by at least this.
_MIN_DEPTH = 1e-6


class InitViewError(ValueError):
    """An init view that cannot serve: inside an object, outside the scene, or stuck at a surface."""


@dataclass(frozen=True)
class InitView:
    """A starting view.

    Attributes:
        name: a label ("file0", "sampled3", ...).
        source: "file", "sampled" or "given".
        world_T_cam: (4, 4) float64 pose.
        fov_x_deg: horizontal field of view.
        delta1: the model's accuracy there (None until scored).
        note: how the view was obtained (e.g. how far a file camera was moved).
    """

    name: str
    source: str
    world_T_cam: torch.Tensor
    fov_x_deg: float
    delta1: float | None = None
    note: str = ""

    def to_dict(self) -> dict:
        out = asdict(self)
        out["world_T_cam"] = self.world_T_cam.tolist()
        return out

    @classmethod
    def from_dict(cls, data: dict) -> InitView:
        return cls(**{**data, "world_T_cam": torch.tensor(data["world_T_cam"], dtype=torch.float64)})


@dataclass(frozen=True)
class InitViewConfig:
    """How init views are chosen (``conf/init/``, the ``init`` node).

    Attributes:
        count: init views in all: the file's cameras first (if ``file_cameras``), then sampled ones.
        params: an ``init_params.json`` to start from instead (None: choose them).
        file_cameras: start from the scene file's cameras.
        candidates: M, sampled candidates to score with the model.
        clearance: minimum distance of a sampled centre to any surface; None: 2 * penalty.d_th.
        eye_height: range of the centre's height above the surface straight below it, metres.
        pitch_deg, roll_deg: ranges of the view's pitch (positive: up) and roll.
        fov_x_deg: horizontal field of view of sampled views.
        min_hit_fraction: a sampled view must see a surface in at least this fraction of pixels.
        content_weight: weight of what a sampled view shows (distinct surfaces, depth range, image
            structure; each scored in [0, 1]) beside the model's delta1 when ranking candidates.
        source: where the views after the file's cameras come from: ``captured`` (the scan's
            capture trajectory, :attr:`kadv.scenes.Scene.trajectory`), ``sampled`` (drawn in the
            free space), or ``auto``: captured where the scene has a trajectory, else sampled.
        spacing: captured candidates lie at least this far apart, metres, or turned this many
            times 10 degrees from each other (a trajectory's neighbouring frames show one view).
    """

    count: int = 3
    params: str | None = None
    file_cameras: bool = True
    candidates: int = 32
    clearance: float | None = None
    eye_height: tuple[float, float] = (1.0, 1.8)
    pitch_deg: tuple[float, float] = (-25.0, 10.0)
    roll_deg: tuple[float, float] = (-5.0, 5.0)
    fov_x_deg: float = 70.0
    min_hit_fraction: float = 0.8
    content_weight: float = 0.5
    source: str = "auto"
    spacing: float = 0.5

    def __post_init__(self) -> None:
        if self.count < 1:
            raise ValueError(f"init.count must be >= 1, got {self.count}")
        if self.candidates < 1:
            raise ValueError(f"init.candidates must be >= 1, got {self.candidates}")
        for name in ("eye_height", "pitch_deg", "roll_deg"):
            low, high = getattr(self, name)
            if not low <= high:
                raise ValueError(f"init.{name}: expected [low, high] with low <= high, got {[low, high]}")
        if not 0.0 <= self.min_hit_fraction <= 1.0:
            raise ValueError(f"init.min_hit_fraction must be in [0, 1], got {self.min_hit_fraction}")
        if not (math.isfinite(self.content_weight) and self.content_weight >= 0):
            raise ValueError(f"init.content_weight must be >= 0, got {self.content_weight}")
        if self.source not in ("auto", "captured", "sampled"):
            raise ValueError(f"init.source must be auto, captured or sampled, got {self.source!r}")
        if not (math.isfinite(self.spacing) and self.spacing > 0):
            raise ValueError(f"init.spacing must be positive, got {self.spacing}")
        intrinsics_from_fov(self.fov_x_deg, 1, 1)


def clear_file_camera(
    renderer: ExactRenderer, world_T_cam: torch.Tensor, margin: float, max_move: float = 1.0
) -> tuple[torch.Tensor, float]:
    """Move a camera along its optical axis until its centre is at least ``margin`` from every surface.

    It moves the way the nearest surface's normal points (forward when a wall is behind it, back
    when one is in front), in steps the step guard accepts.

    Returns:
        The pose (4, 4) and the signed distance moved along the optical axis (metres).

    Raises:
        InitViewError: if no clear position lies within ``max_move``.
    """
    pose = world_T_cam.double().clone()
    centre = pose[:3, 3].clone()
    axis = pose[:3, 2]
    distance = float(distance_to_surface(renderer, centre[None])[0])
    if distance >= margin:
        return pose, 0.0
    # the distance's gradient points away from the nearest surface; follow its component on the axis
    probe = centre[None].clone().requires_grad_(True)
    distance_to_surface(renderer, probe).sum().backward()
    sign = 1.0 if float(probe.grad[0] @ axis) >= 0 else -1.0
    moved = 0.0
    while distance < margin:
        step = max(margin - distance, _MIN_CLEARING_STEP) * _CLEARING_OVERSHOOT
        proposed = centre + sign * step * axis
        check = step_guard(renderer, centre[None], proposed[None], margin=0.0)
        if not bool(check.allowed[0]) or abs(moved) + step > max_move:
            raise InitViewError(
                f"a camera {distance:.3f} m from a surface cannot be moved clear along its "
                f"optical axis within {max_move} m"
            )
        centre, moved = proposed, moved + sign * step
        distance = float(distance_to_surface(renderer, centre[None])[0])
    pose[:3, 3] = centre
    return pose, moved


def file_init_views(renderer: ExactRenderer, margin: float) -> list[InitView]:
    """The scene file's cameras as init views, each moved clear of surfaces by ``margin``."""
    views = []
    for index, camera in enumerate(renderer.scene.cameras):
        pose, moved = clear_file_camera(renderer, camera.world_T_cam, margin)
        note = f"moved {moved:+.3f} m along the optical axis to clear {margin} m" if moved else "as in the file"
        views.append(InitView(f"file{index}", "file", pose, float(camera.fov_x_deg), note=note))
    return views


@dataclass
class ViewScores:
    """What N candidate views show and how well the model predicts them; tensors (N,).

    Attributes:
        delta1: the model's accuracy after scale-and-shift alignment.
        surfaces: distinct planes each covering at least 5% of the view's surface pixels.
        depth_range: log(max / min) of the view's ground-truth z-depth.
        structure: mean Sobel gradient magnitude of the image's luminance.
    """

    delta1: torch.Tensor
    surfaces: torch.Tensor
    depth_range: torch.Tensor
    structure: torch.Tensor

    def content(self) -> torch.Tensor:
        """What a view shows, in [0, 1]: the mean of its surfaces (6 or more score 1), its depth
        range (a far/near ratio of 4 or more scores 1) and its image structure (a mean gradient of
        0.1 or more scores 1): saturating terms, so no single one buys a view its place."""
        return (
            torch.clamp(self.surfaces / _FULL_SURFACES, max=1.0)
            + torch.clamp(self.depth_range / math.log(_FULL_DEPTH_RATIO), max=1.0)
            + torch.clamp(self.structure / _FULL_STRUCTURE, max=1.0)
        ) / 3.0


# where each content term saturates (see ViewScores.content)
_FULL_SURFACES, _FULL_DEPTH_RATIO, _FULL_STRUCTURE = 6.0, 4.0, 0.1
# a plane counts as a distinct surface of a view from this share of its surface pixels
_SURFACE_SHARE = 0.05


def score_views(
    model: DepthModel | None,
    renderer: ExactRenderer,
    poses: torch.Tensor,
    fov_x_deg: torch.Tensor,
    height: int,
    width: int,
    batch_size: int = 8,
    alignment: str = "scale_shift",
) -> ViewScores:
    """Score N views at poses (N, 4, 4) with fields of view (N,) at the given size (delta1 after
    ``alignment``, :func:`kadv.losses.depth_metrics`; NaN with no ``model``: what the views show
    alone, as a suite's model-free choice of init views reads it)."""
    scores: dict[str, list[torch.Tensor]] = {"delta1": [], "surfaces": [], "depth_range": [], "structure": []}
    with torch.no_grad():
        for start in range(0, len(poses), batch_size):
            chunk = slice(start, start + batch_size)
            K = torch.stack([intrinsics_from_fov(float(f), height, width) for f in fov_x_deg[chunk]])
            out = renderer.render(poses[chunk], K, height, width)
            depth = out.depth.double()
            if model is None:
                scores["delta1"].append(torch.full((len(depth),), math.nan, dtype=torch.float64))
            else:
                prediction = model(out.rgb, K).double()
                metrics = depth_metrics(prediction, depth, out.mask, model.output_kind, alignment=alignment)
                scores["delta1"].append(metrics["delta1"])
            far = torch.where(out.mask, depth, torch.zeros_like(depth)).amax(dim=(1, 2, 3))
            near = torch.where(out.mask, depth, torch.full_like(depth, torch.inf)).amin(dim=(1, 2, 3))
            scores["depth_range"].append(torch.log(far.clamp_min(_MIN_DEPTH) / near.clamp_min(_MIN_DEPTH)))
            ids = out.triangle_ids.reshape(len(depth), height * width)
            least = _SURFACE_SHARE * (ids >= 0).sum(dim=1).clamp_min(1).double()
            scores["surfaces"].append((plane_counts(renderer, ids) >= least[:, None]).sum(dim=1).double())
            gradient = kornia.filters.sobel(kornia.color.rgb_to_grayscale(out.rgb.float()))
            scores["structure"].append(gradient.mean(dim=(1, 2, 3)).double())
    empty = torch.zeros(0, dtype=torch.float64)
    return ViewScores(**{key: torch.cat([empty, *values]).cpu() for key, values in scores.items()})


def _inside_points(
    renderer: ExactRenderer, count: int, rng: np.random.Generator, clearance: float
) -> tuple[np.ndarray, np.ndarray]:
    """Up to ``count`` points (N, 3) of the walkable inside and the height of the floor below each (N,).

    Half are drawn near the scene file's cameras (within :data:`_NEAR_CAMERA` metres
    horizontally; all of them when it has none) and half over the camera region, ``_OVERSAMPLE``
    times as many as wanted. A point is inside when a surface lies straight below it (a floor) and
    straight above it (a ceiling): a scene's bounds may hold far more than its rooms (a garden, a
    220 m ground plane), and rooms at any level of any scene still get candidates. A scene with no
    ceiling over any drawn point (a roofless ruin, a courtyard) is all outdoors: then a floor suffices.
    """
    lo, hi = renderer.scene.camera_region
    inner_lo, inner_hi = lo + clearance, np.maximum(hi - clearance, lo + clearance)
    drawn = _OVERSAMPLE * count
    points = rng.uniform(inner_lo, inner_hi, size=(drawn, 3))
    cameras = np.array([camera.world_T_cam[:3, 3].tolist() for camera in renderer.scene.cameras]).reshape(-1, 3)
    if len(cameras):
        near = rng.random(drawn) < 0.5
        offsets = rng.uniform(-_NEAR_CAMERA, _NEAR_CAMERA, size=(drawn, 3))
        around = cameras[rng.integers(0, len(cameras), drawn)] + offsets
        points[near, 0] = np.clip(around[near, 0], inner_lo[0], inner_hi[0])
        points[near, 2] = np.clip(around[near, 2], inner_lo[2], inner_hi[2])
    down = np.broadcast_to(np.array([0.0, -1.0, 0.0]), points.shape)
    below, above = renderer.cast(points, down), renderer.cast(points, -down)
    # what the host needs of the casts, in one copy
    below_hit, above_hit, below_t = torch.stack([below.hit.double(), above.hit.double(), below.t.double()]).cpu()
    below_hit, above_hit = below_hit.numpy() > 0, above_hit.numpy() > 0
    inside = below_hit & (above_hit if (below_hit & above_hit).any() else True)
    return points[inside][:count], (points[:, 1] - np.where(below_hit, below_t.numpy(), np.nan))[inside][:count]


def _candidate_poses(
    renderer: ExactRenderer, config: InitViewConfig, count: int, rng: np.random.Generator, clearance: float
) -> tuple[torch.Tensor, int, int]:
    """Up to ``count`` candidate poses; their centres stand at eye height above the floor under a
    point of the walkable inside (:func:`_inside_points`), ``clearance`` below the top of the
    camera region: a centre above it is dropped, except in a scan (``render.lighting=scanned``),
    whose eye height is held just under its top, where ``clearance`` above the floor allows (a scan
    that stops below eye height gets views within it). Also how many points were drawn, and how
    many of them had no room under the top."""
    hi = renderer.scene.camera_region[1]
    centres, floor = _inside_points(renderer, count, rng, clearance)
    drawn = len(centres)
    centres = centres.copy()
    low, high = config.eye_height
    scan = renderer.shading.lighting == "scanned"
    if scan:  # under its top, open or not, whatever the eye height asked
        room = hi[1] - 2 * SCAN_TOP_TOLERANCE - floor
        low, high = np.minimum(low, room), np.minimum(high, room)
    centres[:, 1] = floor + rng.uniform(low, high, len(centres))
    centres = centres[room > clearance if scan else centres[:, 1] < hi[1] - clearance]
    count = len(centres)
    yaw = rng.uniform(0.0, 2.0 * math.pi, count)
    pitch = np.radians(rng.uniform(*config.pitch_deg, count))
    roll = np.radians(rng.uniform(*config.roll_deg, count))
    forward = np.stack([np.cos(pitch) * np.cos(yaw), np.sin(pitch), np.cos(pitch) * np.sin(yaw)], axis=1)
    poses = look_at(torch.from_numpy(centres), torch.from_numpy(centres + forward)).double()
    zeros = torch.zeros(count, dtype=torch.float64)
    rolled = axis_angle_to_matrix(torch.stack([zeros, zeros, torch.from_numpy(roll)], dim=1))
    poses[:, :3, :3] = poses[:, :3, :3] @ rolled
    return poses, drawn, drawn - count


@dataclass
class CandidateTally:
    """What became of the candidate views a sampler drew: how many, and how many were dropped for
    each reason (a view's validity verdict, or the sampler's own tests)."""

    drawn: int = 0
    dropped: dict[str, int] = field(default_factory=dict)

    def drop(self, reason: str, count: int) -> None:
        if count:
            self.dropped[reason] = self.dropped.get(reason, 0) + count

    def drop_invalid(self, validity: ViewValidity) -> None:
        """Count the views of a batch that its validity verdicts drop, per verdict."""
        for verdict in sorted(set(validity.verdicts) - {VALID}):
            self.drop(verdict, sum(v == verdict for v in validity.verdicts))

    def reasons(self) -> str:
        """``300 outside the scene, 12 inside an object, ...``: the most frequent first."""
        return ", ".join(f"{n} {reason}" for reason, n in sorted(self.dropped.items(), key=lambda kv: -kv[1]))

    def text(self) -> str:
        """``drew 640 candidates; dropped: 300 outside the scene, 12 inside an object, ...``."""
        reasons = self.reasons()
        return f"drew {self.drawn} candidates" + (f"; dropped: {reasons}" if reasons else "")


def _small_validity(
    renderer: ExactRenderer, poses: torch.Tensor, fov_x_deg: float, penalty: PenaltyConfig, height: int, width: int
) -> ViewValidity:
    """The validity of candidate views (N, 4, 4), checked at a quarter of the size (at least 8
    pixels a side), keeping the aspect: a squarer frame would see more of the room than the view does."""
    small_h, small_w = scaled_size(height, width, max(0.25, 8.0 / min(height, width)))
    K = intrinsics_from_fov(fov_x_deg, small_h, small_w)
    return view_validity(renderer, poses, K, small_h, small_w, **penalty.validity_options())


def sample_valid_views(
    renderer: ExactRenderer,
    count: int,
    seed: int,
    config: InitViewConfig,
    penalty: PenaltyConfig,
    height: int,
    width: int,
    tally: CandidateTally | None = None,
) -> torch.Tensor:
    """Up to ``count`` seeded candidate poses (N, 4, 4), unranked, in the order drawn: centres in free
    space with clearance above ``config.clearance`` (default 2 * d_th), height, pitch and roll within
    the configured ranges, views valid (an uninformative view is not) and hitting a surface in at
    least ``config.min_hit_fraction`` of their pixels (of those not past a scan's top). ``tally``,
    when given, counts the candidates drawn and why each dropped one was."""
    rng = np.random.default_rng([seed, 7919])
    tally = tally if tally is not None else CandidateTally()
    clearance = 2.0 * penalty.d_th if config.clearance is None else config.clearance
    accepted: list[torch.Tensor] = []
    for _ in range(_SAMPLING_ROUNDS):
        needed = count - len(accepted)
        if needed <= 0:
            break
        poses, drawn, no_room = _candidate_poses(renderer, config, 8 * needed, rng, clearance)
        tally.drawn += drawn
        tally.drop("with no room for the eye height under the scene's top", no_room)
        distance = distance_to_surface(renderer, poses[:, :3, 3])
        validity = _small_validity(renderer, poses, config.fov_x_deg, penalty, height, width)
        clear = distance.cpu() > clearance
        hits_enough = validity.surface_fraction.cpu() >= config.min_hit_fraction
        tally.drop_invalid(validity)
        tally.drop(f"within {clearance:g} m of a surface", int((validity.valid & ~clear).sum()))
        tally.drop(
            f"seeing a surface in under {config.min_hit_fraction:.0%} of their pixels",
            int((validity.valid & clear & ~hits_enough).sum()),
        )
        keep = validity.valid & clear & hits_enough
        accepted += list(poses[keep][:needed])
    return torch.stack(accepted) if accepted else torch.zeros(0, 4, 4, dtype=torch.float64)


def sample_init_views(
    renderer: ExactRenderer,
    model: DepthModel,
    count: int,
    seed: int,
    config: InitViewConfig,
    penalty: PenaltyConfig,
    height: int,
    width: int,
    alignment: str = "scale_shift",
) -> list[InitView]:
    """Draw ``config.candidates`` seeded candidate views and keep the ``count`` best: views the model
    predicts well (its delta1 after ``alignment``: under ``none``, in metres) that show something.

    Candidates come from :func:`sample_valid_views` and are ranked by delta1 + ``content_weight`` *
    :meth:`ViewScores.content`: ranking by accuracy alone rewards views with nothing in them (a bare
    wall, a plain corner).

    Raises:
        InitViewError: if fewer than ``count`` acceptable candidates turn up.
    """
    if count <= 0:
        return []
    tally = CandidateTally()
    poses = sample_valid_views(renderer, config.candidates, seed, config, penalty, height, width, tally)
    if len(poses) < count:
        low, high = config.eye_height
        raise InitViewError(
            f"scene {renderer.scene.name!r}: only {len(poses)} of {count} sampled init views are valid "
            f"({tally.text()}); set init.eye_height (now [{low:g}, {high:g}] m above the floor), the "
            "scene's scale, or the init views themselves (init.params=<init_params.json>)"
        )
    fov = torch.full((len(poses),), config.fov_x_deg, dtype=torch.float64)
    scores = score_views(model, renderer, poses, fov, height, width, alignment=alignment)
    content = scores.content()
    rank_by = scores.delta1 + config.content_weight * content
    order = sorted(range(len(poses)), key=lambda i: -float(rank_by[i]))[:count]
    return [
        InitView(
            f"sampled{rank}",
            "sampled",
            poses[i],
            config.fov_x_deg,
            float(scores.delta1[i]),
            note=f"best {rank + 1} of {len(poses)} candidates by delta1 + {config.content_weight} x content "
            f"(content {float(content[i]):.2f})",
        )
        for rank, i in enumerate(order)
    ]


def _spaced(poses: np.ndarray, spacing: float) -> list[int]:
    """Indices of poses (N, 4, 4), in order, each at least ``spacing`` metres or ``spacing`` x 10
    degrees from every one kept before it."""
    kept: list[int] = []
    for i, pose in enumerate(poses):
        for j in kept:
            turn = np.degrees(np.arccos(np.clip((np.trace(poses[j, :3, :3].T @ pose[:3, :3]) - 1) / 2, -1.0, 1.0)))
            if np.linalg.norm(pose[:3, 3] - poses[j, :3, 3]) < spacing and turn < 10.0 * spacing:
                break
        else:
            kept.append(i)
    return kept


def captured_init_views(
    renderer: ExactRenderer,
    model: DepthModel,
    count: int,
    config: InitViewConfig,
    penalty: PenaltyConfig,
    height: int,
    width: int,
    alignment: str = "scale_shift",
) -> list[InitView]:
    """The ``count`` best views of the scan's capture trajectory (:attr:`Scene.trajectory`): its
    poses thinned to ones ``config.spacing`` apart, then evenly to at most ``config.candidates``,
    the valid ones scored by the model and ranked as sampled candidates are (delta1 after
    ``alignment`` + ``content_weight`` x content), at the configured field of view.

    Raises:
        InitViewError: the scene has no trajectory, or too few of its poses make valid views.
    """
    scene = renderer.scene
    if count <= 0:
        return []
    if scene.trajectory is None:
        raise InitViewError(
            f"scene {scene.name!r} has no captured camera path (init.source=captured): its layout keeps none beside "
            "it; use init.source=sampled"
        )
    thinned = _spaced(scene.trajectory, config.spacing)
    picks = [thinned[i] for i in np.unique(np.linspace(0, len(thinned) - 1, config.candidates).round().astype(int))]
    poses = torch.from_numpy(scene.trajectory[picks])
    validity = _small_validity(renderer, poses, config.fov_x_deg, penalty, height, width)
    keep = validity.valid.tolist()
    if sum(keep) < count:
        tally = CandidateTally(len(picks))
        tally.drop_invalid(validity)
        raise InitViewError(
            f"scene {scene.name!r}: only {sum(keep)} of {count} captured init views are valid ({len(picks)} poses "
            f"of {len(scene.trajectory)} in {scene.trajectory_source} tried; dropped: {tally.reasons()}); set "
            "init.source=sampled, or init.params=<init_params.json>"
        )
    chosen = [i for i, k in zip(picks, keep) if k]
    fov = torch.full((len(chosen),), config.fov_x_deg, dtype=torch.float64)
    trajectory = torch.from_numpy(scene.trajectory[chosen])
    scores = score_views(model, renderer, trajectory, fov, height, width, alignment=alignment)
    rank_by = scores.delta1 + config.content_weight * scores.content()
    order = sorted(range(len(chosen)), key=lambda i: -float(rank_by[i]))[:count]
    return [
        InitView(
            f"captured{rank}",
            "captured",
            torch.from_numpy(scene.trajectory[chosen[i]]),
            config.fov_x_deg,
            float(scores.delta1[i]),
            note=f"pose {chosen[i]} of {len(scene.trajectory)} in {scene.trajectory_source}, best {rank + 1} of "
            f"{len(chosen)} valid ones by delta1 + {config.content_weight} x content",
        )
        for rank, i in enumerate(order)
    ]


def check_init_views(
    renderer: ExactRenderer, views: list[InitView], penalty: PenaltyConfig, height: int, width: int
) -> None:
    """Raise :class:`InitViewError` naming the first init view whose view is not valid."""
    for view in views:
        K = intrinsics_from_fov(view.fov_x_deg, height, width)
        result = view_validity(renderer, view.world_T_cam, K, height, width, **penalty.validity_options())
        if not bool(result.valid[0]):
            raise InitViewError(
                f"init view {view.name!r} at {[round(v, 3) for v in view.world_T_cam[:3, 3].tolist()]} "
                f"is {result.verdicts[0]}: {result.reasons[0]}"
            )


def save_init_params(path: str | Path, views: list[InitView], model_passes: int = 0) -> Path:
    """Write init views to ``init_params.json`` (atomically), with the model passes that chose them."""
    return write_json(path, {"init_views": [v.to_dict() for v in views], "model_passes": model_passes})


def load_init_params(path: str | Path) -> list[InitView]:
    """Read init views from an ``init_params.json``.

    Raises:
        FileNotFoundError: no such file.
        ValueError: the file is not an init_params file (names the file and the problem).
    """
    path = Path(path).expanduser()
    if not path.is_file():
        raise FileNotFoundError(f"init params file not found: {path}")
    try:
        data = json.loads(path.read_text())
        views = [InitView.from_dict(v) for v in data["init_views"]]
        for view in views:
            check_world_T_cam(view.world_T_cam, f"{view.name}.world_T_cam")
            intrinsics_from_fov(view.fov_x_deg, 1, 1)
    except (ValueError, KeyError, TypeError) as error:
        raise ValueError(f"{path}: not a valid init_params file ({error})") from error
    if not views:
        raise ValueError(f"{path}: holds no init views")
    return views


def fit_into_envelope(renderer: ExactRenderer, init: InitView, envelope: Envelope, margin: float) -> InitView:
    """The init view moved into ``envelope`` (pitch and roll clamped at its yaw, the centre moved
    straight up or down through the step guard), or itself when it lies inside.

    Raises:
        InitViewError: if it cannot be moved into the envelope (no surface below it for a height
            bound, or the move up or down is blocked), naming the view, the envelope and why.
    """
    if envelope.free:
        return init
    base = init.world_T_cam.double().to(renderer.device)[None]
    params = envelope.project(renderer, base, torch.zeros(1, 6, dtype=torch.float64, device=renderer.device))
    if bool((params == 0).all()):
        moved = base
    else:
        check = step_guard(renderer, base[:, :3, 3], base[:, :3, 3] + params[:, 3:], margin)
        moved = perturb_world_T_cam(base, params[:, :3], params[:, 3:] * check.allowed[:, None].to(params))
    (reason,) = envelope.figures(renderer, moved).reasons()
    if reason is not None:
        raise InitViewError(f"init view {init.name} lies outside the envelope {envelope.describe()}: {reason}")
    if moved is base:
        return init
    angles = [round(a, 1) for a in torch.rad2deg(yaw_pitch_roll(base[0, :3, :3])[1:]).tolist()]  # no height cast
    note = f"moved into the envelope {envelope.name} (it had pitch {angles[0]}°, roll {angles[1]}°)"
    return replace(init, world_T_cam=moved[0].cpu(), note=f"{init.note}; {note}" if init.note else note)
