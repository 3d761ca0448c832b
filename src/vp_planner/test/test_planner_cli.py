"""python -m vp_planner.cli: plan.json and noisy_points.npy, errors with exit code 2."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from vp_planner.cli import main
from vp_planner.request import PlanRequest
from vp_planner.reward import noisy_reward
from vp_planner.reward_models import DEFAULT_REWARD_MODEL, make_reward
from vp_scene.camera import CameraModel, poses_to_cameras


def test_cli_writes_plan(tmp_path: Path) -> None:
    out = tmp_path / "run"
    rc = main(["--scenario", "one_plant", "--method", "random", "--cameras", "3", "--evals", "12",
               "--seed", "3", "--out", str(out), "--points-per-plant", "600", "--realizations", "2",
               "--no-progress"])
    assert rc == 0
    plan = json.loads((out / "plan.json").read_text())
    for key in ("scenario", "method", "cameras", "poses", "reward", "trace", "evaluations", "seed", "seconds",
                "scene", "fov", "theta_match", "simple_regret"):
        assert key in plan, key
    assert plan["method"] == "random" and plan["seed"] == 3 and plan["evaluations"] == 12
    # the request as it wrote itself: every field but the arrays, what from_dict rebuilds
    assert PlanRequest.from_dict(plan["request"]) == PlanRequest.of("random", 3, evaluations=12, seed=3)
    assert len(plan["trace"]) == 12 and len(plan["simple_regret"]) == 12
    cams = np.array(plan["cameras"])
    assert cams.shape == (3, 6) and np.array(plan["poses"]).shape == (3, 7)
    back = poses_to_cameras(np.array(plan["poses"]))
    c, u = back[:, :3], back[:, 3:]
    np.testing.assert_allclose(c, cams[:, :3], atol=1e-12)
    np.testing.assert_allclose(u, cams[:, 3:] / np.linalg.norm(cams[:, 3:], axis=1, keepdims=True), atol=1e-9)
    scene = plan["scene"]
    for key in ("scenario", "models", "seed", "points_per_plant", "plant_spacing", "row_spacing", "levels",
                "realizations", "wind_variance", "wind_direction"):
        assert key in scene, key
    pts = np.load(out / "noisy_points.npy")
    assert pts.ndim == 3 and pts.shape[0] == 2 and pts.shape[2] == 3
    assert plan["reward_model"] == DEFAULT_REWARD_MODEL and plan["image_size"] == [2000, 1500]
    expected = make_reward(plan["reward_model"], pts, plan["fov"], plan["theta_match"],
                           CameraModel(*plan["image_size"], plan["fov"]))(cams[None])[0]
    assert plan["reward"] == pytest.approx(float(expected), abs=1e-6)
    # the scene dict rebuilds the identical realizations
    from vp_scene.scenario import make_scene
    from vp_scene.wind import WindConfig, make_noisy_scene

    s = make_scene(scene["scenario"], models=None, seed=scene["seed"], points_per_plant=scene["points_per_plant"],
                   plant_spacing=scene["plant_spacing"], row_spacing=scene["row_spacing"])
    cfg = WindConfig(levels=scene["levels"], realizations=scene["realizations"], variance=scene["wind_variance"],
                     direction=scene["wind_direction"])
    np.testing.assert_allclose(make_noisy_scene(s, cfg, scene["seed"]).points, pts)


def test_a_plan_is_not_overwritten_without_overwrite(tmp_path: Path, capsys) -> None:
    """Planning again into an OUT that holds a plan is refused (one line,
    exit 2, the hint --overwrite; the plan untouched, also its noisy_points.npy); --overwrite
    replaces both; files of others in OUT (a reconstruction) are left as they are."""
    out = tmp_path / "run"
    args = ["--scenario", "one_plant", "--method", "random", "--cameras", "2", "--evals", "3",
            "--points-per-plant", "150", "--realizations", "2", "--no-progress", "--out", str(out)]
    assert main(args + ["--seed", "1"]) == 0
    (out / "recon.json").write_text("{}")
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    capsys.readouterr()
    assert main(args + ["--seed", "2"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"plan: error: {out} already holds a result (noisy_points.npy, plan.json)") and \
        "--overwrite" in err and err.count("\n") == 1, err
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert main(args + ["--seed", "2", "--overwrite"]) == 0
    assert json.loads((out / "plan.json").read_text())["seed"] == 2
    assert sorted(p.name for p in out.iterdir()) == ["noisy_points.npy", "plan.json", "recon.json"]
    assert (out / "recon.json").read_text() == "{}"


def test_cli_errors(tmp_path: Path) -> None:
    env = dict(os.environ)
    src = str(Path(__file__).resolve().parents[1])
    env["PYTHONPATH"] = src + os.pathsep + env.get("PYTHONPATH", "")
    base = [sys.executable, "-m", "vp_planner.cli", "--out", str(tmp_path / "x"), "--no-progress",
            "--points-per-plant", "300", "--realizations", "1"]
    p = subprocess.run(base + ["--cameras", "1", "--method", "random"], capture_output=True, text=True, env=env,
                       timeout=120)
    assert p.returncode == 2
    lines = [ln for ln in p.stderr.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and "num_cameras" in lines[0]
    p = subprocess.run(base + ["--method", "egp", "--evals", "5", "--init", "10"], capture_output=True, text=True,
                       env=env, timeout=120)
    assert p.returncode == 2 and "initial design" in p.stderr
    assert main(["--out", str(tmp_path / "y"), "--models", str(tmp_path / "missing"), "--no-progress"]) == 2


def test_cli_refuses_an_unbounded_budget_in_one_line(tmp_path: Path) -> None:
    """`--method circle --evals 100000000` allocated 2.5 GB; `--method egp --evals
    1000000000` ended in a 28-line traceback. Now both are refused in one line, exit 2, before
    anything is allocated (the child's address space is capped at 6 GiB: a regression fails
    here instead of taking the machine down)."""
    import resource

    def cap() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (6 << 30, 6 << 30))

    for method, evals in (("circle", "100000000"), ("egp", "1000000000")):
        p = subprocess.run([sys.executable, "-m", "vp_planner.cli", "--method", method, "--cameras", "4",
                            "--evals", evals, "--out", str(tmp_path / method), "--no-progress"],
                           capture_output=True, text=True, timeout=120, preexec_fn=cap)
        assert p.returncode == 2, p.stderr[-3000:]
        lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
        assert len(lines) == 1 and "above the bound" in lines[0], p.stderr[-3000:]
        assert not (tmp_path / method / "plan.json").exists()


def test_cli_argparse_error_is_one_line(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit) as info:
        main(["--method", "nope", "--out", "x"])
    assert info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "invalid choice" in err[0]


def test_cli_paper_reward_and_score(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """--reward paper plans on eqs. 2-7; `score` prints a plan's reward as the last number on stdout."""
    out = tmp_path / "run"
    rc = main(["--scenario", "one_plant", "--method", "circle", "--cameras", "3", "--evals", "9", "--seed", "1",
               "--out", str(out), "--points-per-plant", "500", "--realizations", "2", "--reward", "paper",
               "--no-progress"])
    assert rc == 0
    plan = json.loads((out / "plan.json").read_text())
    pts = np.load(out / "noisy_points.npy")
    assert plan["reward_model"] == "paper"
    assert plan["reward"] == pytest.approx(float(noisy_reward(np.array(plan["cameras"]), pts)), abs=1e-9)
    capsys.readouterr()
    assert main(["score", "--plan", str(out / "plan.json")]) == 0
    last = capsys.readouterr().out.split()[-1]
    assert float(last) == pytest.approx(plan["reward"], abs=1e-6)          # the plan's own model
    assert main(["score", "--plan", str(out / "plan.json"), "--reward", "coverage"]) == 0
    cov = float(capsys.readouterr().out.split()[-1])
    expected = make_reward("coverage", pts)(np.array(plan["cameras"])[None])[0]
    assert cov == pytest.approx(float(expected), abs=1e-6) and cov != pytest.approx(plan["reward"])
    # a flight plan given as poses, without a scene: the scene comes from the options, named
    flight = tmp_path / "flight.json"
    flight.write_text(json.dumps({"poses": plan["poses"]}))
    assert main(["score", "--plan", str(flight), "--reward", "paper", "--scenario", "one_plant",
                 "--points-per-plant", "500", "--realizations", "2", "--seed", "1"]) == 0
    assert float(capsys.readouterr().out.split()[-1]) == pytest.approx(plan["reward"], abs=1e-6)


def test_cli_records_the_flights_reported_pose_errors_and_score_reads_them(tmp_path: Path,
                                                                           capsys: pytest.CaptureFixture) -> None:
    """A flight with plain GNSS and no ground markers tells the planner
    (--report-position-sigma, --no-ground-control); plan.json records them as ``registration``
    and `score` scores the plan under them (a plan without the record: the defaults)."""
    out = tmp_path / "run"
    rc = main(["--scenario", "one_plant", "--method", "arc", "--cameras", "4", "--evals", "1", "--out", str(out),
               "--points-per-plant", "500", "--realizations", "2", "--report-position-sigma", "0.05",
               "--report-attitude-sigma", "1", "--no-ground-control", "--no-progress"])
    assert rc == 0
    plan = json.loads((out / "plan.json").read_text())
    assert plan["registration"] == {"report_position_sigma": 0.05, "report_attitude_sigma": 1.0,
                                    "ground_control": False}
    capsys.readouterr()
    assert main(["score", "--plan", str(out / "plan.json")]) == 0
    assert float(capsys.readouterr().out.split()[-1]) == pytest.approx(plan["reward"], abs=1e-6)
    del plan["registration"]
    (out / "plan.json").write_text(json.dumps(plan))
    assert main(["score", "--plan", str(out / "plan.json")]) == 0
    assert float(capsys.readouterr().out.split()[-1]) > plan["reward"] + 0.01   # RTK and markers place it better
    plan["registration"] = {"report_position_sigma": -1}
    (out / "plan.json").write_text(json.dumps(plan))
    assert main(["score", "--plan", str(out / "plan.json")]) == 2
    err = capsys.readouterr().err
    assert "report_position_sigma must be finite and in (0, 10)" in err and len(err.strip().splitlines()) == 1


def test_cli_score_errors(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["score", "--plan", str(tmp_path / "missing.json")]) == 2
    assert "not found" in capsys.readouterr().err
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"cameras": [[0, 0, 1, 1, 0, 0], [1, 0, 1, 0, 0, 0]]}))
    assert main(["score", "--plan", str(bad)]) == 2
    assert "zero viewing direction" in capsys.readouterr().err
    bad.write_text(json.dumps({"cameras": [[0, 0, 1, 1, 0, 0]], "fov": "wide"}))
    assert main(["score", "--plan", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "'fov'" in err and "bad.json" in err


def test_score_reads_the_plan_as_every_command_and_names_an_infeasible_camera(tmp_path: Path,
                                                                              capsys: pytest.CaptureFixture) -> None:
    """`score` of a plan without a scene silently scored one_plant
    (recon refuses that file); the scene options beside a plan's own scene were ignored; a camera
    inside the plant scored without a word; a coordinate of 1e300 printed nan and exited 0. Now:
    a scene is the file's or one named with --scenario, never guessed nor silently replaced; an
    infeasible camera is named on stderr (the score still printed); 1e300 is refused (exit 2)."""
    scene = {"scenario": "one_plant", "points_per_plant": 500, "realizations": 2}
    a = np.radians([0.0, 25.0, 50.0, 75.0])
    c = np.stack([1.4 * np.cos(a), 1.4 * np.sin(a), np.full(4, 1.2)], axis=1)
    ring = np.concatenate([c, np.array([0.0, 0.0, 0.9]) - c], axis=1).tolist()
    path = tmp_path / "plan.json"

    def score(plan: dict, *flags: str) -> tuple[int, str, str]:
        path.write_text(json.dumps(plan))
        capsys.readouterr()
        rc = main(["score", "--plan", str(path), *flags])
        out, err = capsys.readouterr()
        return rc, out, err

    rc, out, err = score({"cameras": ring})
    assert rc == 2 and err.strip().splitlines() == [
        f"plan: error: {path} has no 'scene': name the scene it was planned for with --scenario (and its other scene "
        "options); no scene is guessed (vp_recon.cli refuses such a plan)"] and not out
    rc, out, err = score({"cameras": ring}, "--scenario", "one_plant", "--points-per-plant", "500",
                         "--realizations", "2")
    named = float(out.split()[-1])
    assert rc == 0 and "warning:" not in err and 0 < named < 1, err
    rc, out, err = score({"cameras": ring, "scene": scene})
    assert rc == 0 and float(out.split()[-1]) == pytest.approx(named, abs=1e-9)  # the same scene, the same reward
    rc, out, err = score({"cameras": ring, "scene": scene}, "--scenario", "row_12", "--seed", "3")
    assert rc == 2 and f"{path} names its scene ('scene'): --scenario, --seed are for a plan without one" in err

    inside = [[0.0, 0.0, 1.0, 1.0, 0.0, 0.0]] + ring[1:]  # camera 0 in the plant's stalk
    rc, out, err = score({"cameras": inside, "scene": scene})
    warning = [t for t in err.splitlines() if "warning:" in t]
    assert rc == 0 and 0 <= float(out.split()[-1]) < 1 and len(warning) == 1, err
    assert warning[0].startswith(f"plan score: warning: {path} breaks the planner's feasibility rules (scored all the "
                                 "same): camera 0 at (+0.00, +0.00, +1.00) is 0.0")
    assert "m from the nearest scene point (min_standoff 0.5 m)" in warning[0]
    rc, out, err = score({"cameras": inside, "scene": scene, "feasibility": {"min_standoff": 0.0, "min_altitude": 0.3,
                                                                             "min_separation": 0.5}})
    assert rc == 0 and "warning:" not in err  # the plan's own rules: planned without a stand-off

    rc, out, err = score({"cameras": [[1e300, 0.0, 1.2, -1.0, 0.0, 0.0]] + ring[1:], "scene": scene})
    assert rc == 2 and not out and "'cameras' holds 1e+300, outside [-10000, 10000]" in err, err
    rc, out, err = score({"cameras": ring, "scene": scene}, "--image-width", "100000")
    assert rc == 2 and "image width must be an integer of 16 to 16384 pixels, got 100000" in err, err


def test_cli_refuses_more_cameras_than_it_can_plan(tmp_path: Path) -> None:
    """`make plan METHOD=circle CAMERAS=1000` tried to allocate 80 GB and died
    with a traceback. Now: one line naming the bound, exit 2, before the scene is even built."""
    import time

    t0 = time.monotonic()
    out = subprocess.run([sys.executable, "-m", "vp_planner.cli", "--method", "circle", "--cameras", "1000",
                          "--reward", "paper", "--evals", "4", "--out", str(tmp_path / "run"), "--no-progress"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2, out.stderr[-3000:]
    assert out.stderr.count("\n") == 1 and "num_cameras" in out.stderr and "100" in out.stderr, out.stderr
    assert time.monotonic() - t0 < 60 and not (tmp_path / "run").exists()


EXAMPLES = Path(__file__).resolve().parents[3] / "examples"


def test_cli_layout_file_makes_a_self_contained_plan(tmp_path: Path) -> None:
    """--scenario FILE: plan.json holds the layout itself (scene.scenario) and its name (scenario);
    `python -m vp_planner.cli score` rebuilds the scene from the plan once the file is gone."""
    from vp_scene.layout import load_layout

    field = tmp_path / "my_field.yaml"
    field.write_text((EXAMPLES / "field.yaml").read_text())
    out = tmp_path / "run"
    rc = main(["--scenario", str(field), "--method", "random", "--cameras", "3", "--evals", "3", "--seed", "2",
               "--out", str(out), "--points-per-plant", "150", "--realizations", "2", "--no-progress"])
    assert rc == 0
    plan = json.loads((out / "plan.json").read_text())
    assert plan["scenario"] == "small_field"
    assert plan["scene"]["scenario"] == load_layout(field).to_dict()
    assert len(plan["scene"]["scenario"]["plants"]) == 8 and plan["scene"]["scenario"]["jitter"] == 0.05
    assert np.load(out / "noisy_points.npy").shape == (2, 8 * 150, 3)
    field.unlink()

    env = dict(os.environ)
    env["PYTHONPATH"] = str(Path(__file__).resolve().parents[1]) + os.pathsep + env.get("PYTHONPATH", "")
    p = subprocess.run([sys.executable, "-m", "vp_planner.cli", "score", "--plan", str(out / "plan.json")],
                       capture_output=True, text=True, env=env, cwd=tmp_path, timeout=300)
    assert p.returncode == 0, p.stderr[-3000:]
    assert float(p.stdout.split()[-1]) == pytest.approx(plan["reward"], abs=1e-6)
    assert "small_field" in p.stderr


@pytest.mark.parametrize("content, text", [
    ("grid: {rows: three, columns: 2}", "field.yaml: grid.rows must be an integer >= 1, got 'three'"),
    (None, "layout file not found: "),
    ("plants: [{x: 1000000000, y: 0}]", "field.yaml: plant 0 stands at x = 1e+09, y = 0 m, outside"),
])
def test_cli_bad_layout_file_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture, content, text) -> None:
    field = tmp_path / "field.yaml"
    if content is not None:
        field.write_text(content)
    with pytest.raises(SystemExit) as info:
        main(["--scenario", str(field), "--out", str(tmp_path / "x"), "--method", "random", "--no-progress"])
    assert info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--scenario" in err[0] and text in err[0] and str(field) in err[0], err
    assert not (tmp_path / "x").exists()


def test_cli_unknown_scenario_name(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit) as info:
        main(["--scenario", "nine_square", "--out", "x"])
    assert info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'nine_square' is neither a layout name (one_plant" in err[0] and "row_12" in err[0]


def test_cli_plans_a_field_by_parts_and_flies_a_lawnmower(tmp_path: Path) -> None:
    """egp on a row of 4 plants with 4 cameras and --parts 2: plan.json records the two parts and
    counts their evaluations; --method lawnmower records its survey settings (one evaluation)."""
    field = tmp_path / "row4.json"
    field.write_text(json.dumps({"grid": {"rows": 1, "columns": 4, "plant_spacing": 1.2}}))
    common = ["--scenario", str(field), "--cameras", "4", "--seed", "1", "--points-per-plant", "100",
              "--realizations", "2", "--no-progress"]
    out = tmp_path / "egp"
    assert main(common + ["--method", "egp", "--evals", "8", "--init", "4", "--parts", "2", "--sim-flights", "0",
                          "--out", str(out)]) == 0
    plan = json.loads((out / "plan.json").read_text())
    assert [p["cameras"] for p in plan["parts"]] == [2, 2] and plan["evaluations"] == 2 * 8 + 4
    assert len(plan["cameras"]) == 4 and len(plan["trace"]) == 20 and plan["lawnmower"] is None
    out = tmp_path / "lawn"
    assert main(common + ["--method", "lawnmower", "--lawnmower-tilt", "0.5", "--out", str(out)]) == 0
    plan = json.loads((out / "plan.json").read_text())
    assert plan["evaluations"] == 1 and plan["lawnmower"] == {"overlap": 0.7, "tilt": 0.5} and plan["parts"] is None
    assert main(common + ["--method", "lawnmower", "--lawnmower-overlap", "1.2", "--out", str(out)]) == 2


def test_a_full_disk_is_one_line_naming_the_file_and_leaves_out_as_it_was(tmp_path: Path) -> None:
    """numpy's words for a short write ('480128 requested and 65536 written') were the whole
    message. A plan whose files cannot all be written says the disk is full, naming the file, in
    one line, exit 2, and OUT keeps what it held (no half plan, no stage). The child's file size
    is capped (RLIMIT_FSIZE: writes past it stop short, as on a full disk)."""
    import resource

    def cap() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (64 << 10, 64 << 10))

    out = tmp_path / "run"
    out.mkdir()
    (out / "notes.txt").write_text("the user's")
    p = subprocess.run([sys.executable, "-m", "vp_planner.cli", "--method", "circle", "--cameras", "4", "--evals", "5",
                        "--out", str(out), "--no-progress"],  # noisy_points.npy: 5 x 4000 x 3 doubles, 480 kB
                       capture_output=True, text=True, timeout=120, preexec_fn=cap)
    lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
    assert p.returncode == 2 and len(lines) == 1, p.stderr[-3000:]
    assert lines[0].startswith(f"plan: error: could not write {out}/.partial-plan-") and \
        "noisy_points.npy: the disk is full (a short write: " in lines[0], lines[0]
    assert sorted(x.name for x in out.iterdir()) == ["notes.txt"]


def test_a_refused_request_writes_nothing_and_the_corrected_one_runs(tmp_path: Path, capsys) -> None:
    """Nothing is written before a request is valid: a refused plan (a missing --fixed file, a
    bad flag value) leaves OUT as it was, and the corrected run into it is not refused as one
    that already holds a result."""
    out = tmp_path / "run"
    out.mkdir()
    (out / "notes.txt").write_text("the user's")
    args = ["--scenario", "one_plant", "--method", "circle", "--cameras", "3", "--evals", "4",
            "--points-per-plant", "300", "--realizations", "2", "--no-progress", "--out", str(out)]
    for bad in (["--fixed", str(tmp_path / "missing.json")], ["--realizations", "0"]):
        assert main(args + bad) == 2
        err = capsys.readouterr().err
        assert err.startswith("plan: error:") and err.count("\n") == 1, err
        assert sorted(x.name for x in out.iterdir()) == ["notes.txt"]
    assert main(args) == 0, capsys.readouterr().err
    assert sorted(x.name for x in out.iterdir()) == ["noisy_points.npy", "notes.txt", "plan.json"]


def test_cli_checks_its_plans_by_simulated_flights_on_a_local_cluster(tmp_path: Path, capsys) -> None:
    """--sim-flights: the plans are flown (the reconstruction's simulator, found by its entry point)
    on a local Dask cluster, one line a flight on stderr, and plan.json records every flight tried
    (its plan, source, draw, score or failure, seconds), the plans flown and how the plan was chosen."""
    out = tmp_path / "run"
    rc = main(["--scenario", "one_plant", "--method", "egp", "--cameras", "3", "--evals", "12", "--init", "6",
               "--seed", "2", "--points-per-plant", "1500", "--realizations", "2", "--sim-flights", "4",
               "--flight-width", "640", "--flight-height", "480", "--flight-sift-octave", "-1",
               "--flight-dense-scale", "1.0", "--workers", "2", "--out", str(out), "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 0, err[-3000:]
    assert [line.split(":")[0] for line in err.splitlines() if line.startswith("flight ")] == \
        [f"flight {i}/4" for i in range(1, 5)]
    plan = json.loads((out / "plan.json").read_text())
    assert plan["sim_flights"] == 4 and len(plan["flights"]) == 4
    assert plan["flight_settings"] == {"width": 640, "height": 480, "sift_first_octave": -1, "dense_scale": 1.0}
    sources = [f["source"] for f in plan["flights"]]  # in the order they came back
    assert {"circle", "arc", "structured"} <= set(sources), sources
    for f in plan["flights"]:
        assert f["draw"]["capture_seed"] >= 2 ** 31 and f["seconds"] > 0
        assert f["failed"] == (f["chamfer"] is None) and (f["reason"] != "") == f["failed"]
    if plan["chosen_by"] == "flights":
        chosen = [p for p in plan["flight_plans"] if p["cameras"] == plan["cameras"]]
        assert chosen and chosen[0]["score"] == plan["flight_score"]
    else:
        assert plan["flights_note"]
