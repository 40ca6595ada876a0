"""The sweep report on synthetic summary.json files of two methods, without a browser."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from PIL import Image

from kadv.cli.report import report


def _run(folder: Path, method: str, init: float, adversarial: float, delta1: tuple[float, float]) -> None:
    (folder / "views").mkdir(parents=True)
    Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(folder / "views" / "init0_adv0.png")
    Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(folder / "map.png")
    view = {"index": 0, "name": "file0", "init": {"l_depth": init, "delta1": delta1[0]},
            "adversarial": [{"l_depth": adversarial, "delta1": delta1[1], "png": "views/init0_adv0.png"}],
            "anytime": [{"evaluations": 1, "seconds": 0.1, "l_depth": init, "delta1": delta1[0]},
                        {"evaluations": 9, "seconds": 2.0, "l_depth": adversarial, "delta1": delta1[1]}],
            "budget": {"forward": 10, "backward": 0, "seconds": 3.0}}
    summary = {"complete": True, "method": method, "model": "kadv_tiny", "scene": "box_room_0",
               "init_l_depth": init, "adversarial_l_depth": adversarial, "init_delta1": delta1[0],
               "adversarial_delta1": delta1[1], "init_views": [view]}
    (folder / "summary.json").write_text(json.dumps(summary))


def test_tables_for_each_method_delta1_drop_and_anytime_curves(tmp_path: Path) -> None:
    _run(tmp_path / "sweep" / "a", "gradient", 0.05, 0.15, (0.98, 0.80))
    _run(tmp_path / "sweep" / "b", "random", 0.05, 0.35, (0.98, 0.40))
    written = report([str(tmp_path / "sweep")], tmp_path / "out", transfer=False, progress=False)
    names = {path.name for path in written}
    assert {"table2_gradient.md", "table2_random.md", "table3_gradient.md", "table3_random.md", "methods.md",
            "curves.png", "report.html"} <= names
    assert "| kadv_tiny | 0.3500 | 0.4000 |" in (tmp_path / "out" / "table2_random.md").read_text()
    methods = (tmp_path / "out" / "methods.csv").read_text().splitlines()
    assert methods[0].split(",")[3:5] == ["L_depth gain", "delta1 drop"]
    drops = {line.split(",")[2]: float(line.split(",")[4]) for line in methods[1:]}
    assert drops == {"gradient": 0.98 - 0.80, "random": 0.98 - 0.40}
    html = (tmp_path / "out" / "report.html").read_text()
    assert "Anytime curves" in html and "(random attack)" in html  # the gallery's worst view: random's
    assert Image.open(tmp_path / "out" / "curves.png").size[0] > 300
