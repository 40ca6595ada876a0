"""A suite: a frozen set of scenes (by content digest) and init views (as poses) with one protocol,
written once as a file and never changed (a change is a new suite, with a new hash).

Its init views are chosen once, by a rule that reads no model: the scene file's cameras (cleared of
surfaces), then views sampled as :func:`kadv.attack.sample_valid_views` draws them (valid, clear of
surfaces, seeing enough of the scene), ranked by what they show
(:meth:`kadv.attack.ViewScores.content`) and kept apart from each other; all moved into the
protocol's envelope.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from kadv.attack import InitView, InitViewConfig, InitViewError, check_init_views, file_init_views
from kadv.attack.init_views import _spaced, fit_into_envelope, sample_valid_views, score_views
from kadv.attack.radii import DEFAULT_RADII, radius_budgets
from kadv.attack.search import DEFAULT_METHOD
from kadv.bench.digest import scene_digest
from kadv.catalogue import scene_from_node
from kadv.geometry import intrinsics_from_fov
from kadv.io import write_json
from kadv.penalties import PenaltyConfig, get_envelope
from kadv.render import ExactRenderer, Shading
from kadv.scenes import Scene

__all__ = [
    "SHIPPED",
    "SUITE_FORMAT",
    "BenchError",
    "FrozenView",
    "Protocol",
    "SceneSpec",
    "Suite",
    "SuiteScene",
    "freeze_suite",
    "load_suite",
    "read_json",
    "scenes_root",
    "shipped_suite_path",
]

SUITE_FORMAT = 1
SHIPPED = ("offline-v1", "real-v1")  # the suites that ship with kadv (frozen from kadv.bench.shipped's specs)
_SHIPPED_FOLDER = Path(__file__).parent / "suites"
_CANDIDATES = 96  # sampled candidate views per scene, ranked by content
_SPACING = 0.5  # metres (and 5 degrees per 0.1 m) between two views of a scene


class BenchError(ValueError):
    """A suite, an entry or a scene that cannot serve, in one line naming the file and the field."""


@dataclass(frozen=True)
class Protocol:
    """How every entry of a suite searches and scores (the suite fixes it; an entry names its seeds).

    Attributes:
        method: the search method (:data:`kadv.attack.METHODS`).
        radii: nested (degrees, metres) bounds on the camera's move from each init view.
        radius_passes: model passes per init view at each radius (their sum: per init view).
        envelope: the camera envelope's preset name (:mod:`kadv.penalties.envelope`).
        min_seeds: the fewest search seeds an entry holds.
        size: (height, width) of the renders the model sees.
        lighting: ``baked`` or ``direct``.
        loss: the attacked loss.
        metric: the scored figure (``delta1``: the share of pixels with max(d/d̂, d̂/d) < threshold).
        threshold: the metric's ratio threshold.
        alignment: how a prediction meets the ground truth before it is scored; None: each
            model's output kind's own (:func:`kadv.losses.kind_fit`).
        space: the space the loss's alignment is fitted in; None: each model's kind's own (the
            metric is fitted in the kind's own space).
        restarts: independent runs per search.
    """

    method: str = DEFAULT_METHOD
    radii: tuple[tuple[float, float], ...] = DEFAULT_RADII
    # 96 passes a radius on average: at 48 the worst found still fell by 2-4 intervals when the
    # passes doubled, and at equal cost the deeper search with 3 seeds has the tighter interval
    # (docs/benchmark.md, Choosing the protocol)
    radius_passes: tuple[int, ...] = tuple(radius_budgets(96, 3))
    envelope: str = "upright"
    min_seeds: int = 3
    size: tuple[int, int] = (96, 128)
    lighting: str = "baked"
    loss: str = "delta1"
    metric: str = "delta1"
    threshold: float = 1.25
    alignment: str | None = "scale_shift"
    space: str | None = "disparity"
    restarts: int = 1

    @property
    def fit_text(self) -> str:
        """How its figures are fitted, as words: ``scale_shift alignment in disparity space``."""
        alignment = self.alignment or "each model's own"
        space = f"{self.space} space" if self.space else "its output kind's space"
        return f"{alignment} alignment in {space}"

    def __post_init__(self) -> None:
        object.__setattr__(self, "radii", tuple((float(d), float(m)) for d, m in self.radii))
        object.__setattr__(self, "radius_passes", tuple(int(p) for p in self.radius_passes))
        object.__setattr__(self, "size", tuple(int(s) for s in self.size))
        if len(self.radius_passes) != len(self.radii) or min(self.radius_passes) < 2:
            raise BenchError(f"protocol.radius_passes must be one count >= 2 a radius, got {list(self.radius_passes)}")
        if self.min_seeds < 1:
            raise BenchError(f"protocol.min_seeds must be >= 1, got {self.min_seeds}")
        get_envelope(self.envelope)  # a preset, or ValueError naming the presets

    @property
    def passes_per_view(self) -> int:
        """Model passes per init view and search seed, over all radii."""
        return sum(self.radius_passes)


@dataclass(frozen=True)
class FrozenView:
    """An init view as a pose: ``world_T_cam`` (4, 4), its intrinsics ``K`` (3, 3) at ``size``."""

    name: str
    world_T_cam: tuple[tuple[float, ...], ...]
    fov_x_deg: float
    K: tuple[tuple[float, ...], ...]
    size: tuple[int, int]

    def init_view(self) -> InitView:
        """The :class:`kadv.attack.InitView` a search starts from."""
        return InitView(self.name, "given", torch.tensor(self.world_T_cam, dtype=torch.float64), self.fov_x_deg)


@dataclass(frozen=True)
class SceneSpec:
    """A scene to freeze: its name, its ``scene/`` node (:func:`kadv.catalogue.scene_from_node`; a
    file's ``path`` relative to the scenes root), where to obtain it and its licence."""

    name: str
    node: dict
    source: dict = field(default_factory=dict)
    licence: str = ""


@dataclass(frozen=True)
class SuiteScene:
    """A frozen scene: its :class:`SceneSpec`'s fields, its content digest and its init views."""

    name: str
    node: dict
    source: dict
    licence: str
    digest: str
    views: tuple[FrozenView, ...]

    def load(self, root: str | Path | None = None) -> Scene:
        """The scene, checked against its digest.

        Raises:
            BenchError: a missing file, or content other than the suite froze, naming the file.
        """
        path = None
        if self.node.get("kind") == "file":
            path = scenes_root(root) / self.node["path"]
            if not path.is_file():
                raise BenchError(
                    f"scene {self.name!r}: {path} is missing; obtain it from {self.source_text()} and give "
                    "its folder as scenes=<folder> (or $KADV_TEST_SCENES)"
                )
        try:
            scene = scene_from_node(self.node, path)
        except (ValueError, FileNotFoundError) as error:
            raise BenchError(f"scene {self.name!r}: {' '.join(str(error).split())}") from None
        digest = scene_digest(scene)
        if digest != self.digest:
            where = path if path is not None else f"the generated scene {self.node}"
            raise BenchError(
                f"scene {self.name!r}: {where} has content digest {digest[:16]}, the suite froze {self.digest[:16]}: "
                "its geometry, materials, textures or lights differ"
            )
        return scene

    def source_text(self) -> str:
        """Where to obtain the scene, as one phrase."""
        if "repository" in self.source:
            return f"{self.source['repository']} at commit {self.source.get('commit', '?')}, {self.source.get('path')}"
        return self.source.get("generated", "kadv itself")


@dataclass(frozen=True)
class Suite:
    """A frozen suite (see the module docstring): scenes with their init views, and one protocol.

    Attributes:
        name: the suite's name.
        protocol: how entries search and score.
        scenes: the frozen scenes, each with its init views.
        kadv_version, bake_version: what froze it.
        format: the file's format version.
    """

    name: str
    protocol: Protocol
    scenes: tuple[SuiteScene, ...]
    kadv_version: str
    bake_version: int
    format: int = SUITE_FORMAT

    def canonical(self) -> dict:
        """The suite as plain JSON values, without its hash."""
        return asdict(self)

    @property
    def hash(self) -> str:
        """SHA-256 of the canonical form (sorted keys, no spaces)."""
        text = json.dumps(self.canonical(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()

    @property
    def cells(self) -> list[tuple[int, int, int]]:
        """Every (scene, init view, radius) index triple."""
        radii = range(len(self.protocol.radii))
        return [(s, v, k) for s, scene in enumerate(self.scenes) for v in range(len(scene.views)) for k in radii]

    @property
    def views(self) -> list[tuple[int, int]]:
        """Every (scene, init view) index pair."""
        return [(s, v) for s, scene in enumerate(self.scenes) for v in range(len(scene.views))]

    def save(self, path: str | Path) -> Path:
        """Write the suite with its hash (atomically)."""
        return write_json(path, self.canonical() | {"hash": self.hash})

    @classmethod
    def from_dict(cls, data: dict, where: str = "suite") -> Suite:
        """The suite :meth:`save` wrote, its hash checked.

        Raises:
            BenchError: another format, a missing field, or a hash that is not its content's.
        """
        if data.get("format") != SUITE_FORMAT:
            raise BenchError(f"{where}: format {data.get('format')!r} is not {SUITE_FORMAT}, the one kadv reads")
        try:
            protocol = Protocol(**data["protocol"])
            scenes = tuple(
                SuiteScene(**(s | {"views": tuple(_frozen_view(v) for v in s["views"])})) for s in data["scenes"]
            )
            suite = cls(data["name"], protocol, scenes, data["kadv_version"], data["bake_version"], data["format"])
        except (KeyError, TypeError) as error:
            raise BenchError(f"{where}: not a suite ({error!r} is missing or wrong)") from None
        if data.get("hash") != suite.hash:
            raise BenchError(f"{where}: hash {str(data.get('hash'))[:16]} is not its content's {suite.hash[:16]}")
        return suite


def _frozen_view(data: dict) -> FrozenView:
    return FrozenView(
        data["name"],
        tuple(tuple(row) for row in data["world_T_cam"]),
        data["fov_x_deg"],
        tuple(tuple(row) for row in data["K"]),
        tuple(data["size"]),
    )


def load_suite(path: str | Path) -> Suite:
    """The suite in a file, or a shipped suite by name (``offline-v1``, ``real-v1``).

    Raises:
        BenchError: a missing or unreadable file, or one that is not a suite.
    """
    path = shipped_suite_path(str(path)) or Path(path)
    return Suite.from_dict(read_json(path, f"suite {path}", "no such file (or shipped suite)"), f"suite {path}")


def read_json(path: str | Path, what: str, missing: str = "no such file") -> dict:
    """A JSON file's content, or :class:`BenchError` naming ``what`` (``suite x.json``) and why."""
    try:
        return json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise BenchError(f"{what}: {missing}") from None
    except (OSError, json.JSONDecodeError) as error:
        raise BenchError(f"{what}: cannot read it ({error})") from None


def shipped_suite_path(name: str) -> Path | None:
    """The file of a shipped suite by name, or None for another name."""
    return _SHIPPED_FOLDER / f"{name}.json" if name in SHIPPED else None


def scenes_root(root: str | Path | None = None) -> Path:
    """Where a suite's file scenes are read from: ``root``, else ``$KADV_TEST_SCENES``, else
    ``../shared/scenes``."""
    if root is not None:
        return Path(root).expanduser()
    return Path(os.environ.get("KADV_TEST_SCENES", "../shared/scenes")).expanduser()


def _frozen_views(renderer: ExactRenderer, protocol: Protocol, count: int, seed: int) -> tuple[FrozenView, ...]:
    """The scene's ``count`` init views by the model-free rule (see the module docstring)."""
    height, width = protocol.size
    penalty, config = PenaltyConfig(), InitViewConfig()
    views = file_init_views(renderer, penalty.margin)[:count]
    if len(views) < count:
        poses = sample_valid_views(renderer, _CANDIDATES, seed, config, penalty, height, width)
        fov = torch.full((len(poses),), config.fov_x_deg, dtype=torch.float64)
        content = score_views(None, renderer, poses, fov, height, width).content()
        order = sorted(range(len(poses)), key=lambda i: -float(content[i]))
        existing = [v.world_T_cam.numpy() for v in views]
        ranked = np.stack(existing + [poses[i].numpy() for i in order]) if len(order) else np.zeros((0, 4, 4))
        kept = [i - len(existing) for i in _spaced(ranked, _SPACING) if i >= len(existing)]
        views += [InitView(f"sampled{k}", "sampled", poses[order[i]], config.fov_x_deg) for k, i in enumerate(kept)]
    envelope = get_envelope(protocol.envelope)
    fitted = []
    for view in views:
        try:
            fitted.append(fit_into_envelope(renderer, view, envelope, penalty.margin))
        except InitViewError:
            continue  # a view the envelope cannot hold is not one of the suite's
    fitted = fitted[:count]
    if len(fitted) < count:
        raise BenchError(f"scene {renderer.scene.name!r}: only {len(fitted)} of {count} init views fit the rule")
    check_init_views(renderer, fitted, penalty, height, width)
    return tuple(
        FrozenView(
            f"view{k}",
            tuple(tuple(row) for row in view.world_T_cam.tolist()),
            float(view.fov_x_deg),
            tuple(tuple(row) for row in intrinsics_from_fov(view.fov_x_deg, height, width).tolist()),
            (height, width),
        )
        for k, view in enumerate(fitted)
    )


def freeze_suite(
    name: str,
    specs: list[SceneSpec],
    protocol: Protocol | None = None,
    views_per_scene: int = 4,
    seed: int = 0,
    root: str | Path | None = None,
    progress: bool = False,
) -> Suite:
    """Freeze a suite: each scene of ``specs`` loaded (a file's path under ``root``), digested, and
    given ``views_per_scene`` init views by the model-free rule under ``seed``.

    Raises:
        BenchError: a scene that cannot load, or has too few views that fit the rule, in one line.
    """
    import kadv
    from kadv.render.bake import _BAKE_VERSION

    protocol = protocol or Protocol()
    if views_per_scene < 1 or not specs:
        raise BenchError(f"a suite needs scenes and views_per_scene >= 1, got {len(specs)} and {views_per_scene}")
    scenes = []
    for spec in tqdm(specs, desc="freezing", unit="scene", disable=not progress):
        unchecked = SuiteScene(spec.name, spec.node, spec.source, spec.licence, "", ())
        try:
            path = scenes_root(root) / spec.node["path"] if spec.node.get("kind") == "file" else None
            scene = scene_from_node(spec.node, path)
        except (ValueError, FileNotFoundError, KeyError) as error:
            raise BenchError(f"scene {spec.name!r}: {' '.join(str(error).split())}") from None
        renderer = ExactRenderer(scene, Shading(lighting=protocol.lighting), progress=progress)
        try:
            views = _frozen_views(renderer, protocol, views_per_scene, seed)
        except InitViewError as error:
            raise BenchError(f"scene {spec.name!r}: {error}") from None
        scenes.append(replace(unchecked, digest=scene_digest(scene), views=views))
    return Suite(name, protocol, tuple(scenes), kadv.__version__, _BAKE_VERSION)
