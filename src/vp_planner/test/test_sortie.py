"""A second sortie: planning with the cameras already flown and with what they
reconstructed (README "A second sortie")."""
from __future__ import annotations

import json
import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import trimesh

from vp_planner import optimizers, request
from vp_planner.cli import main
from vp_planner.optimizers import plan_views
from vp_planner.request import InvalidFixedCamerasError, InvalidReconstructionError, PlanRequest
from vp_planner.reward_models import (CoverageParams, make_reward, point_coverage, reconstructed_mask,
                                      reconstructed_weights)
from vp_planner.space import ViewSpace
from vp_scene import limits


def ring_camera(azimuth_deg: float, radius: float = 2.0) -> np.ndarray:
    """A camera on the horizontal circle about the origin, looking at the origin."""
    a = math.radians(azimuth_deg)
    c = np.array([radius * math.cos(a), radius * math.sin(a), 0.0])
    return np.r_[c, -c]


ONE_POINT = np.zeros((1, 1, 3))


def test_fixed_camera_in_the_paper_reward_as_a_hand_built_case_predicts() -> None:
    # one point, plan cameras at 0 and 30 degrees, a fixed one at 60 (theta_match 45 degrees):
    # pairs (0, 30) and (30, 60) give sin 30 = 0.5 each, (0, 60) is wider than theta_match: 0;
    # eq. 2 over S = 3 pairs: 1/3; without the fixed camera: 0.5 / 1 pair
    plan = np.stack([ring_camera(0), ring_camera(30)])
    fixed = ring_camera(60)[None]
    assert make_reward("paper", ONE_POINT)(plan) == pytest.approx(0.5)
    assert make_reward("paper", ONE_POINT, fixed_cameras=fixed)(plan) == pytest.approx(1 / 3)
    # batches keep their shape, the fixed cameras are appended to every plan
    np.testing.assert_allclose(make_reward("paper", ONE_POINT, fixed_cameras=fixed)(np.stack([plan, plan])),
                               [1 / 3, 1 / 3])


def test_fixed_camera_completes_a_pair_in_the_coverage_reward() -> None:
    # plan cameras 90 degrees apart: beyond the matching window (45), the point is not covered;
    # a fixed camera 15 degrees from the first makes a pair inside the window (w = 1): covered
    params = replace(CoverageParams(), occlusion=False, resolution=False)
    plan = np.stack([ring_camera(0), ring_camera(90)])
    fixed = ring_camera(15)[None]
    assert make_reward(("coverage", params), ONE_POINT)(plan) == pytest.approx(0.0)
    assert make_reward(("coverage", params), ONE_POINT, fixed_cameras=fixed)(plan) == pytest.approx(1.0, abs=1e-6)


def test_point_weights_give_the_weighted_mean() -> None:
    # two points; only the first is seen by the pair: reward = w_1 cov_1 / (w_1 + w_2)
    params = replace(CoverageParams(), occlusion=False, resolution=False)
    pts = np.array([[[0.0, 0.0, 0.0], [0.0, 0.0, 50.0]]])
    plan = np.stack([ring_camera(0), ring_camera(20)])
    assert make_reward(("coverage", params), pts)(plan) == pytest.approx(0.5, abs=1e-6)
    assert make_reward(("coverage", params), pts, point_weights=[[0.1, 1.0]])(plan) == pytest.approx(0.1 / 1.1, abs=1e-6)
    paper = make_reward("paper", pts)(plan)
    assert make_reward("paper", pts, point_weights=[[1.0, 0.0]])(plan) == pytest.approx(2 * paper)


def test_reconstructed_points_within_tau() -> None:
    R = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]])
    rec = np.array([[0.02, 0.0, 0.0], [1.0, 0.05, 0.0]])
    np.testing.assert_array_equal(reconstructed_mask(R, rec, 0.03), [[True, False, False]])
    np.testing.assert_allclose(reconstructed_weights(R, rec, 0.03, 0.1), [[0.1, 1.0, 1.0]])
    np.testing.assert_allclose(reconstructed_weights(R, np.zeros((0, 3)), 0.03, 0.1), [[1.0, 1.0, 1.0]])
    with pytest.raises(ValueError, match="non-finite"):
        reconstructed_mask(R, [[np.nan, 0, 0]])


def blobs() -> tuple[np.ndarray, np.ndarray]:
    """Two plants 2 m apart: A (600 points) and B (200 points)."""
    rng = np.random.default_rng(0)

    def blob(cx: float, n: int) -> np.ndarray:
        return np.c_[rng.normal(cx, 0.08, n), rng.normal(0, 0.08, n), rng.uniform(0.1, 0.9, n)]
    return blob(-1.0, 600), blob(1.0, 200)


def test_a_hole_attracts_the_next_cameras() -> None:
    # without a reconstruction the bigger plant A draws the plan; with A reconstructed (its points
    # weigh 0.1) the same search (same seed, same candidates) goes to the hole B
    A, B = blobs()
    R = np.concatenate([A, B])[None]
    first = plan_views(PlanRequest.of("random", 3, evaluations=100, seed=0), R)
    cov = point_coverage(first.cameras, R)[0]
    assert cov[:600].mean() > cov[600:].mean()
    second = plan_views(PlanRequest.of("random", 3, evaluations=100, seed=0, reconstruction=A), R)
    cov = point_coverage(second.cameras, R)[0]
    assert cov[600:].mean() > 2 * cov[:600].mean()
    assert second.reconstructed_fraction == pytest.approx(0.75)


def test_every_method_counts_the_fixed_cameras_and_ignores_their_separation(realizations) -> None:
    fixed = plan_views(PlanRequest.of("circle", 3, evaluations=4, seed=0), realizations).cameras
    score = make_reward("coverage", realizations, fixed_cameras=fixed)
    for method in ("circle", "random", "lawnmower", "sa"):
        res = plan_views(PlanRequest.of(method, 2, evaluations=6, seed=1, fixed_cameras=fixed), realizations)
        assert res.fixed_cameras == 3
        assert res.reward == pytest.approx(float(score(res.cameras)), rel=1e-6), method
    # a camera on a fixed camera's position is feasible: separation is within a sortie only
    space = ViewSpace(realizations, 2, fixed_cameras=fixed)
    plan = np.stack([fixed[0], fixed[1] + [0.0, 0.0, 0.0, 0.1, 0.0, 0.0]])
    assert space.feasible(plan)
    assert space.reward(plan) == pytest.approx(float(score(plan)))


@pytest.mark.parametrize("fixed, text", [
    ([[0, 0, 1, np.nan, 0, 0]], "not finite"),
    ([[3, 0, 1, 0, 0, 0]], "zero viewing direction"),
    ([[3, 0, 1, 1, 0]], "shape"),
])
def test_bad_fixed_cameras_are_refused(realizations, fixed, text) -> None:
    with pytest.raises(InvalidFixedCamerasError, match=text):
        plan_views(PlanRequest.of("random", 2, evaluations=3, fixed_cameras=np.asarray(fixed, dtype=float)),
                   realizations)


def test_fixed_cameras_are_bounded_like_cameras() -> None:
    """10,000 cameras already flown were accepted (a goal grew the planner by gigabytes): at most
    MAX_FIXED_CAMERAS, a full sortie, checked when the request is made."""
    PlanRequest.of("random", 2, evaluations=2, fixed_cameras=np.tile(ring_camera(0), (request.MAX_FIXED_CAMERAS, 1)))
    with pytest.raises(InvalidFixedCamerasError, match=f"10000 cameras already flown are above the bound of "
                                                       f"{request.MAX_FIXED_CAMERAS}"):
        PlanRequest.of("random", 2, evaluations=2, fixed_cameras=np.tile(ring_camera(0), (10_000, 1)))


def test_fixed_cameras_beyond_the_memory_are_refused(realizations, monkeypatch) -> None:
    plan_views(PlanRequest.of("random", 2, evaluations=2, fixed_cameras=[ring_camera(0)]), realizations)
    need = request.estimate_memory(2 + 50, realizations.shape[0], realizations.shape[1], "coverage")
    monkeypatch.setattr(limits, "available_memory", lambda: int(need))  # the plan alone fits
    request.check_memory(2, realizations.shape, "coverage")
    with pytest.raises(InvalidFixedCamerasError, match="memory|GiB"):
        plan_views(PlanRequest.of("random", 2, evaluations=2, fixed_cameras=np.tile(ring_camera(0), (50, 1))),
                   realizations)


def test_bad_reconstructions_are_refused(realizations, monkeypatch) -> None:
    with pytest.raises(InvalidReconstructionError, match="non-finite"):
        plan_views(PlanRequest.of("random", 2, evaluations=2, reconstruction=[[0.0, np.nan, 0.0]]), realizations)
    with pytest.raises(InvalidReconstructionError, match="tau"):
        plan_views(PlanRequest.of("random", 2, evaluations=2, reconstruction=[[0.0, 0.0, 0.0]], tau=-1.0), realizations)
    with pytest.raises(InvalidReconstructionError, match="reconstructed_weight"):
        plan_views(PlanRequest.of("random", 2, evaluations=2, reconstruction=[[0.0, 0.0, 0.0]],
                                  reconstructed_weight=1.5), realizations)
    monkeypatch.setattr(limits, "available_memory", lambda: 1000)
    with pytest.raises(InvalidReconstructionError, match="GiB"):
        optimizers.sortie_weights(realizations, np.zeros((100, 3)), 0.03, 0.1)


CLI = ["--scenario", "one_plant", "--points-per-plant", "500", "--realizations", "2", "--levels", "5",
       "--no-progress", "--seed", "1"]


def test_cli_plans_a_second_sortie_and_records_it(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(CLI + ["--method", "circle", "--cameras", "3", "--evals", "4", "--out", str(tmp_path / "s1")]) == 0
    first = json.loads((tmp_path / "s1" / "plan.json").read_text())
    noisy = np.load(tmp_path / "s1" / "noisy_points.npy")
    rec = trimesh.PointCloud(noisy[0, ::3])
    rec.export(tmp_path / "rec.ply")
    assert main(CLI + ["--method", "random", "--cameras", "2", "--evals", "5", "--out", str(tmp_path / "s2"),
                       "--fixed", str(tmp_path / "s1" / "plan.json"), "--reconstructed", str(tmp_path / "rec.ply")]) == 0
    second = json.loads((tmp_path / "s2" / "plan.json").read_text())
    np.testing.assert_allclose(second["fixed_cameras"], first["cameras"])
    assert second["fixed_from"] == [str((tmp_path / "s1" / "plan.json").resolve())]
    rc = second["reconstructed"]
    assert rc["points"] == len(noisy[0, ::3]) and rc["tau"] == 0.03 and rc["reconstructed_weight"] == 0.1
    assert 0.3 < rc["fraction"] < 0.9  # the subsample marks part of every realization
    W = reconstructed_weights(noisy, noisy[0, ::3], 0.03, 0.1)
    expected = make_reward("coverage", noisy, fixed_cameras=first["cameras"], point_weights=W)(
        np.asarray(second["cameras"]))
    assert second["reward"] == pytest.approx(float(expected), rel=1e-6)
    # `plan score` scores it as it was planned: with the flown cameras and the reconstruction
    assert main(["score", "--plan", str(tmp_path / "s2" / "plan.json")]) == 0
    assert float(capsys.readouterr().out.split()[-1]) == pytest.approx(second["reward"], abs=1e-6)


def test_cli_bad_fixed_cameras_exit_2_and_nothing_planned(tmp_path: Path) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text('{"cameras": [[0, 0, 1, NaN, 0, 0]]}')
    out = tmp_path / "out"
    p = subprocess.run([sys.executable, "-m", "vp_planner.cli"] + CLI + [
        "--method", "random", "--cameras", "2", "--evals", "2", "--out", str(out), "--fixed", str(bad)],
        capture_output=True, text=True, timeout=300)
    assert p.returncode == 2 and "--fixed" in p.stderr and len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert not out.exists()
    p = subprocess.run([sys.executable, "-m", "vp_planner.cli"] + CLI + [
        "--method", "random", "--cameras", "2", "--evals", "2", "--out", str(out),
        "--reconstructed", str(tmp_path / "missing.ply")], capture_output=True, text=True, timeout=300)
    assert p.returncode == 2 and "--reconstructed" in p.stderr and "not found" in p.stderr, p.stderr
    assert not out.exists()
