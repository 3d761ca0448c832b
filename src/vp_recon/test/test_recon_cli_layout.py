"""python -m vp_recon.cli on a plan whose scene is a layout (plan.json's scene.scenario holds the
layout, as the planner writes it for --scenario FILE): the scene is rebuilt through
build_noisy_scene(**plan.scene) without the layout file; a bad layout is one line, exit 2."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from vp_recon.cli import main
from vp_scene.build import build_noisy_scene
from vp_scene.layout import load_layout

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"
SCENE = {"models": None, "seed": 1, "points_per_plant": 2000, "plant_spacing": 0.6, "row_spacing": 0.76,
         "levels": 10, "realizations": 2, "wind_variance": 0.002, "wind_direction": 0.0}


def _plan(tmp_path: Path, scenario: object) -> Path:
    """Six cameras on a half ring 2.2 m around the layout's centre (0, 0.2), looking at it."""
    a = np.deg2rad(np.linspace(-150.0, -30.0, 6))
    c = np.stack([2.2 * np.cos(a), 0.2 + 2.2 * np.sin(a), np.full(6, 1.6)], axis=1)
    cams = np.concatenate([c, np.array([0.0, 0.2, 0.8]) - c], axis=1)
    path = tmp_path / "plan.json"
    path.write_text(json.dumps({"scenario": "four_plants", "method": "ring", "cameras": cams.tolist(),
                                "fov": math.pi / 2, "scene": {**SCENE, "scenario": scenario}}))
    return path


def test_recon_of_a_layout_plan(tmp_path: Path, capsys) -> None:
    layout = load_layout(EXAMPLES / "plants.json").to_dict()
    out = tmp_path / "out"
    rc = main(["--plan", str(_plan(tmp_path, layout)), "--out", str(out), "--width", "640", "--height", "480", "--capture", "ideal",
               "--realizations", "0", "--sparse-only", "--no-progress"])
    assert rc == 0, capsys.readouterr().err[-3000:]
    data = json.loads((out / "recon.json").read_text())
    (r,) = data["per_realization"]
    assert r["images"] >= 2 and r["points"] > 20 and math.isfinite(r["chamfer"])
    # scored against the layout's four plants: the reconstruction lies among them
    noisy, _ = build_noisy_scene(**{**SCENE, "scenario": layout})
    assert noisy.points.shape == (2, 4 * 2000, 3) and noisy.scene.scenario == "four_plants"
    assert 0.0 < r["accuracy"] < 10.0                                  # x 100: within centimetres of the plants


def test_bad_layout_in_plan_is_one_line(tmp_path: Path, capsys) -> None:
    plan = _plan(tmp_path, {"name": "x", "plants": [{"x": "left", "y": 0.0}]})
    out = tmp_path / "new_out"
    assert main(["--plan", str(plan), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("recon: error:"), err
    assert f"{plan}: scene.scenario.plants[0].x must be a number (metres), got 'left'" in err, err
    assert not out.exists()
