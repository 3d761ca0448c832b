"""Choosing among a flight folder's views (issue 41, part 3), end to end through both CLIs:
``vp_planner.cli --candidates FOLDER --prior PRIOR.ply`` names the chosen images in plan.json and
``vp_recon.cli --images FOLDER --select plan.json --reference REF.ply`` reconstructs those alone
and scores them against the reference; bad input is one line and exit 2."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

SCENE = dict(scenario="one_plant", seed=0, points_per_plant=2000, realizations=1)


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    """10 views of the procedural plant flown under the realistic capture over 180 degrees, as a
    flight folder, and its truth as a PLY (the reference and the prior)."""
    from vp_recon.flight import write_flight
    from vp_recon.outputs import write_ply
    from vp_recon.pipeline import ReconConfig, render_flight
    from vp_scene.build import build_noisy_scene

    scene = build_noisy_scene(**SCENE)[0]
    az = np.linspace(0.0, math.pi, 10)
    c = np.stack([1.6 * np.cos(az), 1.6 * np.sin(az), np.full(10, 1.3)], axis=1)
    cams = np.concatenate([c, np.array([0.0, 0.0, 0.9]) - c], axis=1)
    root = tmp_path_factory.mktemp("views")
    folder = write_flight(render_flight(scene, 0, cams, ReconConfig(width=640, height=480)), root / "flight")
    write_ply(root / "truth.ply", scene.points[0])
    return folder, root / "truth.ply"


def test_a_plan_among_a_folders_views_is_reconstructed_alone(flight, tmp_path: Path, capsys) -> None:
    from vp_planner.cli import main as plan
    from vp_recon.cli import main as recon

    folder, truth = flight
    assert plan(["--candidates", str(folder), "--prior", str(truth), "--cameras", "5", "--method", "arc",
                 "--evals", "20", "--out", str(tmp_path / "p"), "--no-progress"]) == 0
    p = json.loads((tmp_path / "p" / "plan.json").read_text())
    assert len(p["images"]) == 5 == len(p["selected"]) and "scene" not in p
    assert p["images"] == [f"view_{i:03d}.png" for i in p["selected"]] and p["num_candidates"] == 10
    assert sorted(np.diff(sorted(p["selected"])).tolist()) == [1, 1, 1, 1]  # arc: neighbours
    assert p["image_size"] == [640, 480] and p["fov"] == pytest.approx(math.pi / 2)  # the folder's camera
    assert recon(["--images", str(folder), "--select", str(tmp_path / "p" / "plan.json"), "--reference", str(truth),
                  "--out", str(tmp_path / "r"), "--no-progress", "--threads", "1"]) == 0
    r = json.loads((tmp_path / "r" / "recon.json").read_text())
    assert r["num_images"] == 5 and r["selected"] == p["images"] and r["registered_images"] >= 4
    assert r["prior"] == str(truth.resolve()) and r["mask"]["prior_box"] and r["mask"]["method"] == "exg"
    assert 0 < r["chamfer_shape_mean"] <= r["chamfer_mean"] + 1e-9 < 5.0 and r["coverage_of_prior"] > 0


def test_bad_choices_are_one_line_and_exit_2(flight, tmp_path: Path, capsys) -> None:
    from vp_planner.cli import main as plan
    from vp_recon.cli import main as recon

    folder, truth = flight
    with pytest.raises(SystemExit) as exc:
        plan(["--candidates", str(folder), "--cameras", "3", "--out", str(tmp_path / "p")])
    assert exc.value.code == 2 and "--candidates and --prior go together" in capsys.readouterr().err
    for args, text in ((["--cameras", "11"], "11 cameras cannot be chosen among 10"),
                       (["--method", "lawnmower"], "no candidates mode"),
                       (["--prior", str(tmp_path / "none.ply")], "--prior")):
        cmd = ["--candidates", str(folder), "--prior", str(truth), "--cameras", "3", "--out", str(tmp_path / "p"),
               "--no-progress"] + args
        assert plan(cmd) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("plan: error:") and text in err and len(err.splitlines()) == 1
        assert not (tmp_path / "p" / "plan.json").exists()
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"cameras": [[0, 0, 1, 1, 0, 0], [1, 0, 1, 1, 0, 0]],
                               "images": ["view_000.png", "nowhere.png"]}))
    assert recon(["--images", str(folder), "--select", str(bad), "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert "recon: error: --select" in err and "nowhere.png" in err and not (tmp_path / "r").exists()
