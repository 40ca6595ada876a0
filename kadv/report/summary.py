"""The two JSON files of a run directory, as typed dataclasses: ``summary.json`` and ``partial/init<i>.json``.

Both carry :data:`SCHEMA_VERSION`; a file of another version (or none) is refused on reading with
an error naming it, so a report never reads a field that changed meaning and a resumed run never
reuses a result of another shape.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

from kadv.attack import InitView, InitViewResult, ViewRecord
from kadv.attack.records import Agreement, Budget
from kadv.io import write_json

__all__ = [
    "SCHEMA_VERSION",
    "AnytimePoint",
    "InitViewSummary",
    "RunInfo",
    "RunSummary",
    "ViewMetrics",
    "read_partial",
    "write_partial",
]

# bumped whenever a field below, InitViewResult or ViewRecord changes shape
SCHEMA_VERSION = 4


def _check_schema(data: object, path: Path) -> dict:
    if not isinstance(data, dict) or data.get("schema") != SCHEMA_VERSION:
        found = data.get("schema", "none") if isinstance(data, dict) else "none"
        raise ValueError(f"{path}: schema version {found}, this kadv reads {SCHEMA_VERSION}")
    return data


def _read_json(path: Path) -> dict:
    try:
        return _check_schema(json.loads(path.read_text()), path)
    except json.JSONDecodeError as error:
        raise ValueError(f"{path}: not JSON ({error})") from error


@dataclass
class ViewMetrics:
    """One evaluated view as a summary reports it: the objective's terms, accuracy and pose, and its
    horizontal field of view in degrees (None: its init view's, in a summary written without it)."""

    l_depth: float
    l_dist: float
    objective: float
    loss: float
    delta1: float
    abs_rel: float
    theta: list[float]
    centre: list[float]
    step: int
    restart: int
    png: str
    fov_x_deg: float | None = None

    @classmethod
    def of(cls, record: ViewRecord, png: str) -> ViewMetrics:
        return cls(
            record.l_depth,
            record.l_dist,
            record.objective,
            record.loss,
            record.delta1,
            record.abs_rel,
            record.theta,
            record.centre,
            record.step,
            record.restart,
            png,
            None if math.isnan(record.fov_x_deg) else record.fov_x_deg,
        )


@dataclass
class AnytimePoint:
    """The best valid view so far (by the run's loss), each time it improved: after how many model
    passes and seconds, and its measures."""

    passes: int
    seconds: float
    l_depth: float
    delta1: float
    abs_rel: float
    loss: float


@dataclass
class InitViewSummary:
    """One init view's search: where it started, the adversarial views kept, what it cost, and how
    many of its independent runs reached its worst view (``agreement``; None in a result made
    without :func:`~kadv.attack.restarts.restarted_search`)."""

    index: int
    name: str
    source: str
    note: str
    fov_x_deg: float
    init_world_T_cam: list[list[float]]
    init: ViewMetrics
    adversarial: list[ViewMetrics]
    adversarial_mean: dict[str, float | None]
    l_depth_gain: float
    anytime: list[AnytimePoint]
    invalid_views: int
    uninformative_views: int
    guarded_steps: int
    budget: Budget
    agreement: Agreement | None = None

    @classmethod
    def from_dict(cls, data: dict) -> InitViewSummary:
        agreement = data.get("agreement")
        return cls(
            **data
            | {
                "init": ViewMetrics(**data["init"]),
                "adversarial": [ViewMetrics(**a) for a in data["adversarial"]],
                "anytime": [AnytimePoint(**p) for p in data["anytime"]],
                "budget": Budget.from_dict(data["budget"]),
                "agreement": None if agreement is None else Agreement.from_dict(agreement),
            }
        )


@dataclass
class RunInfo:
    """What a run was: scene, model, loss, seed, device, image size, the init views it resumed, the
    model passes that chose its init views (counted apart from the searches' budgets) and the
    range of horizontal fields of view the search could set (``envelope.fov_deg``; None: each view
    kept its init view's), and whether the model received the camera's intrinsics (``given``,
    ``withheld``, or ``not taken`` by a model that does not take them: ``model.intrinsics``)."""

    scene: str
    model: str
    loss: str
    seed: int
    device: str
    height: int
    width: int
    resumed_init_views: list[int]
    init_passes: int
    fov_deg: list[float] | None = field(default=None, kw_only=True)
    intrinsics: str = field(default="not taken", kw_only=True)


@dataclass
class RunSummary(RunInfo):
    """``summary.json``: a finished run. Written last, so a run directory holding it is complete.

    The means are over the init views that kept an adversarial view; ``budget`` is the run's total.
    ``profile``: a profile run's (``attack.radii``) :meth:`kadv.attack.Profile.to_dict`, else None.
    ``alignment``: how every delta1 and AbsRel here met the ground truth (``loss.alignment``:
    ``scale_shift``, ``scale`` or ``none``), and ``space``: where it was fitted (``disparity`` or
    ``depth``: the model's output kind's own, :func:`kadv.losses.kind_fit`).
    """

    method: str
    init_l_depth: float
    init_delta1: float
    adversarial_l_depth: float
    adversarial_delta1: float
    budget: Budget
    versions: dict[str, str]
    init_views: list[InitViewSummary]
    complete: bool = True
    schema: int = SCHEMA_VERSION
    profile: dict | None = None
    alignment: str = "scale_shift"
    space: str = "disparity"

    def to_dict(self) -> dict:
        """Everything as plain JSON values, each budget with its passes."""
        out = asdict(self)
        out["budget"] = self.budget.to_dict()
        for view, summary in zip(out["init_views"], self.init_views):
            view["budget"] = summary.budget.to_dict()
            view["agreement"] = None if summary.agreement is None else summary.agreement.to_dict()
        return out

    @classmethod
    def from_dict(cls, data: dict) -> RunSummary:
        return cls(
            **data
            | {
                "budget": Budget.from_dict(data["budget"]),
                "init_views": [InitViewSummary.from_dict(v) for v in data["init_views"]],
            }
        )

    def write(self, path: str | Path) -> Path:
        return write_json(Path(path), self.to_dict())

    @classmethod
    def read(cls, path: str | Path) -> RunSummary:
        """The summary in ``path``.

        Raises:
            ValueError: the file is not JSON, has another schema version, or fields of another shape.
        """
        path = Path(path)
        try:
            return cls.from_dict(_read_json(path))
        except (KeyError, TypeError) as error:
            raise ValueError(f"{path}: not a kadv run summary ({error})") from error


def write_partial(path: str | Path, result: InitViewResult) -> Path:
    """Save one init view's full search result (``partial/init<i>.json``), to resume from."""
    return write_json(
        Path(path),
        {
            "schema": SCHEMA_VERSION,
            "init": result.init.to_dict(),
            "records": [asdict(r) for r in result.records],
            "top": [[r.run, r.step, r.restart] for r in result.top],
            "path": [[r.run, r.step, r.restart] for r in result.path],
            "budget": result.budget.to_dict(),
            "agreement": None if result.agreement is None else result.agreement.to_dict(),
        },
    )


def read_partial(path: str | Path) -> InitViewResult:
    """The result :func:`write_partial` saved.

    Raises:
        ValueError: the file is not JSON, has another schema version, or fields of another shape.
    """
    path = Path(path)
    data = _read_json(path)
    try:
        records = [ViewRecord(**r) for r in data["records"]]
        by_key = {(r.run, r.step, r.restart): r for r in records}
        agreement = data["agreement"]
        return InitViewResult(
            InitView.from_dict(data["init"]),
            records,
            [by_key[tuple(key)] for key in data["top"]],
            Budget.from_dict(data["budget"]),
            [by_key[tuple(key)] for key in data["path"]],
            None if agreement is None else Agreement.from_dict(agreement),
        )
    except (KeyError, TypeError) as error:
        raise ValueError(f"{path}: not a kadv partial result ({error})") from error
