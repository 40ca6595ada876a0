"""The two view rules' settings, measured on the box room and the three shared scenes with kadv-tiny
under the renderer's default lighting:

- ``init.content_weight``: each scene's ``init.candidates`` seeded candidate views (120 x 160)
  scored once, then ranked by delta1 + weight x content for each weight; per weight, over the
  picks (``--picks`` a scene), the mean delta1, distinct surfaces and far/near depth ratio, and the
  picks that show at most two surfaces (a bare wall or a plain corner).
- ``penalty.uninformative`` (a view whose largest plane covers more than ``max_plane_share`` of
  its surface pixels): the default search with the ``--loss`` loss from ``--views`` init views a
  scene (96 x 128, ``--budget`` passes each), the check off and on: how many of the chosen
  adversarial views are uninformative, and how many evaluated views the check judged so.

Last line: ``view_choice weight= delta1= surfaces= far_near= bare= uninformative_off=
uninformative_on= judged=`` (the default weight's row; chosen views uninformative with the
check off and on).

Run: .venv/bin/python benchmarks/view_choice.py [--weights 0,0.25,0.5,1,2] [--picks 2] [--views 3]
[--budget 200] [--loss ssim] [--seed 0]
"""

from __future__ import annotations

import argparse

from common import bench_scenes, default_lighting

import torch

from kadv.attack import AttackConfig, InitViewConfig, Study, StudySettings, sample_init_views, sample_valid_views
from kadv.attack.init_views import ViewScores, score_views
from kadv.geometry import intrinsics_from_fov
from kadv.losses import LossConfig
from kadv.models import load_model
from kadv.penalties import PenaltyConfig, plane_shares
from kadv.penalties.validity import UNINFORMATIVE
from kadv.render import ExactRenderer, Shading

INIT_SIZE, SEARCH_SIZE = (120, 160), (96, 128)


def candidate_scores(renderer: ExactRenderer, model, seed: int) -> ViewScores:
    """The model's scores of ``init.candidates`` seeded candidate views of the renderer's scene."""
    config = InitViewConfig()
    poses = sample_valid_views(renderer, config.candidates, seed, config, PenaltyConfig(), *INIT_SIZE)
    fov = torch.full((len(poses),), config.fov_x_deg, dtype=torch.float64)
    return score_views(model, renderer, poses, fov, *INIT_SIZE)


def content_weights(scored: list[ViewScores], weights: list[float], picks: int) -> dict[float, tuple]:
    """Per weight: the picks' mean delta1, surfaces and far/near ratio, and the picks with at most
    two surfaces, of ``picks`` init views a scene (``scored``: each scene's candidates)."""
    rows = {}
    for weight in weights:
        picked = [
            (float(s.delta1[i]), float(s.surfaces[i]), float(s.depth_range[i].exp()))
            for s in scored
            for i in torch.argsort(-(s.delta1 + weight * s.content()), stable=True)[:picks].tolist()
        ]
        delta1, surfaces, far_near = (sum(column) / len(picked) for column in zip(*picked))
        rows[weight] = (delta1, surfaces, far_near, sum(pick[1] <= 2 for pick in picked), len(picked))
    return rows


def search_study(scene, model, check: bool, budget: int, loss: str) -> Study:
    """The default search on ``scene`` at ``SEARCH_SIZE`` with the uninformative check ``check``."""
    settings = StudySettings(
        size=SEARCH_SIZE, shading=Shading(lighting=default_lighting()), loss=LossConfig(kind=loss),
        penalty=PenaltyConfig(uninformative=check), attack=AttackConfig(budget_passes=budget), progress=False,
    )  # fmt: skip
    return Study.build(scene, model, settings)


def uninformative_chosen(study: Study, init: list, seed: int) -> tuple[int, int, int]:
    """Of the adversarial views the study's search chooses from ``init``: how many are uninformative,
    out of how many, and how many evaluated views its check judged uninformative."""
    limit = PenaltyConfig().max_plane_share
    chosen = total = judged = 0
    for view in study.attack(init, seed).views:
        judged += sum(record.verdict == UNINFORMATIVE for record in view.records)
        poses = torch.stack([record.world_T_cam(view.init.world_T_cam) for record in view.top])
        K = intrinsics_from_fov(view.init.fov_x_deg, *SEARCH_SIZE)
        out = study.renderer.render(poses, K, *SEARCH_SIZE)
        shares = plane_shares(study.renderer, out.triangle_ids[:, 0].flatten(1))
        chosen += int((shares > limit).sum())
        total += len(view.top)
    return chosen, total, judged


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--weights", default="0,0.25,0.5,1,2", help="content weights, comma-separated")
    parser.add_argument("--picks", type=int, default=2, help="init views picked a scene")
    parser.add_argument("--views", type=int, default=3, help="init views a scene searched, check off and on")
    parser.add_argument("--budget", type=int, default=200, help="model passes per init view")
    parser.add_argument("--loss", default="ssim", choices=["ssim", "delta1", "absrel"])
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    try:
        weights = [float(w) for w in args.weights.split(",")]
    except ValueError:
        parser.error(f"--weights: numbers, comma-separated, got {args.weights!r}")
    if args.picks < 1 or args.views < 1 or args.budget < 3 or min(weights) < 0:
        parser.error("--picks and --views must be at least 1, --budget at least 3, --weights at least 0")
    model, scored, counts = load_model("kadv_tiny"), [], {False: (0, 0, 0), True: (0, 0, 0)}
    for scene in bench_scenes():
        studies = {check: search_study(scene, model, check, args.budget, args.loss) for check in (False, True)}
        renderer = studies[True].renderer
        scored.append(candidate_scores(renderer, model, args.seed))
        # the same init views either way: chosen as the commands choose them, the check on
        init = sample_init_views(
            renderer, model, args.views, args.seed, InitViewConfig(), PenaltyConfig(), *SEARCH_SIZE
        )
        for check, study in studies.items():
            counts[check] = tuple(a + b for a, b in zip(counts[check], uninformative_chosen(study, init, args.seed)))
    rows = content_weights(scored, weights, args.picks)
    print("| content_weight | mean delta1 | mean surfaces | mean far/near | picks with <= 2 surfaces |")
    print("|---|---|---|---|---|")
    for weight, (delta1, surfaces, far_near, bare, picked) in rows.items():
        print(f"| {weight:g} | {delta1:.3f} | {surfaces:.1f} | {far_near:.2f} | {bare} of {picked} |")
    off, on = counts[False], counts[True]
    print("\n| penalty.uninformative | chosen views uninformative | evaluated views judged uninformative |")
    print("|---|---|---|")
    print(f"| false | {off[0]} of {off[1]} | - |")
    print(f"| true | {on[0]} of {on[1]} | {on[2]} |")
    weight = InitViewConfig().content_weight if InitViewConfig().content_weight in rows else weights[0]
    delta1, surfaces, far_near, bare, _ = rows[weight]
    print(
        f"view_choice weight={weight:g} delta1={delta1:.3f} surfaces={surfaces:.1f} far_near={far_near:.2f} "
        f"bare={bare} uninformative_off={off[0]} uninformative_on={on[0]} judged={on[2]}"
    )


if __name__ == "__main__":
    main()
