"""Reward models: each ingredient of ``coverage`` on hand-built cases, and ``paper`` = eqs. 2-7."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from vp_planner.reward import noisy_reward
from vp_planner.reward_models import (DEFAULT_REWARD_MODEL, REWARD_MODELS, CoverageParams, check_reward_model,
                                      coverage_reward, make_reward, point_coverage)
from vp_scene.camera import CameraModel, look_at

IMAGE = CameraModel(2000, 1500, math.pi / 2)
ALL_ON = CoverageParams(max_points=0)


def pair_at(distance: float, half_angle_deg: float, target=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Two cameras at ``distance`` from ``target``, +-half_angle in azimuth, looking at it."""
    t = np.asarray(target, float)
    a = np.radians([-half_angle_deg, half_angle_deg])
    c = t + distance * np.stack([np.cos(a), np.sin(a), np.zeros(2)], axis=1)
    return look_at(c, np.broadcast_to(t, c.shape))


def grid_patch(x: float, half: float = 0.05, n: int = 11, z: float = 1.0) -> np.ndarray:
    """A square patch of points in the plane x = const (facing +x), centred at (x, 0, z)."""
    s = np.linspace(-half, half, n)
    yy, zz = np.meshgrid(s, s)
    return np.stack([np.full(yy.size, x), yy.ravel(), z + zz.ravel()], axis=1)


def test_model_names() -> None:
    assert set(REWARD_MODELS) == {"paper", "coverage"} and DEFAULT_REWARD_MODEL in REWARD_MODELS
    assert check_reward_model("paper") == "paper"
    with pytest.raises(ValueError, match="unknown reward model"):
        check_reward_model("magic")


def test_paper_model_is_eqs_2_to_7() -> None:
    rng = np.random.default_rng(0)
    R = rng.normal(size=(3, 200, 3)) * 0.3 + np.array([0, 0, 1.0])
    cams = np.stack([pair_at(2.0, 10.0), pair_at(2.5, 20.0)])
    got = make_reward("paper", R)(cams)
    np.testing.assert_allclose(got, noisy_reward(cams, R), atol=1e-14)


def test_point_behind_a_wall_is_not_counted() -> None:
    """Self-occlusion: a patch hidden behind a nearer wall of points gets no coverage."""
    wall = grid_patch(0.0, half=0.3, n=31)        # a dense wall at x = 0
    hidden = grid_patch(-0.5, half=0.05, n=5)     # a small patch behind it (seen from +x)
    pts = np.concatenate([wall, hidden])[None]
    cams = pair_at(2.0, 8.0, target=(0.0, 0.0, 1.0))
    with_occ = point_coverage(cams, pts, ALL_ON, IMAGE)[0, len(wall):]
    without = point_coverage(cams, pts, replace(ALL_ON, occlusion=False), IMAGE)[0, len(wall):]
    assert np.all(with_occ == 0.0)
    assert np.all(without > 0.5)
    # the wall itself stays covered
    assert point_coverage(cams, pts, ALL_ON, IMAGE)[0, :len(wall)].mean() > 0.9


def test_far_camera_scores_less_once_resolution_counts() -> None:
    pts = grid_patch(0.0, half=0.05)[None]
    near, far = pair_at(1.5, 8.0), pair_at(6.0, 8.0)
    r_near = coverage_reward(near, pts, ALL_ON, IMAGE)
    r_far = coverage_reward(far, pts, ALL_ON, IMAGE)
    assert r_far < 0.5 * r_near
    no_res = replace(ALL_ON, resolution=False)
    assert coverage_reward(far, pts, no_res, IMAGE) == pytest.approx(coverage_reward(near, pts, no_res, IMAGE),
                                                                   abs=1e-6)


def test_identical_pairs_do_not_double_a_points_score() -> None:
    """Saturation: a point a pair fully covers stays at 1 when an identical pair is added."""
    pts = grid_patch(0.0, half=0.02, n=3)[None]
    one = pair_at(1.5, 8.0)
    two = np.concatenate([one, one + np.array([0.0, 0.0, 1e-6, 0, 0, 0])])  # the same pair twice
    cov_one = point_coverage(one, pts, ALL_ON, IMAGE)
    cov_two = point_coverage(two, pts, ALL_ON, IMAGE)
    np.testing.assert_allclose(cov_one, 1.0, atol=1e-6)
    np.testing.assert_allclose(cov_two, 1.0, atol=1e-6)
    # without saturation the score is a mean over pairs: the point is not counted once per pair
    cov_sum = point_coverage(two, pts, replace(ALL_ON, saturation=False), IMAGE)
    assert np.all(cov_sum <= 1.0)


def test_matching_window() -> None:
    """Pairs too close (no triangulation) or too wide (no matches) cover less than a good one."""
    pts = grid_patch(0.0, half=0.02, n=3)[None]
    r = {a: coverage_reward(pair_at(1.5, a / 2), pts, ALL_ON, IMAGE) for a in (1, 15, 40, 60)}
    assert r[15] == pytest.approx(1.0, abs=1e-6)
    assert r[1] < 0.5 and r[60] == 0.0 and 0 < r[40] < r[15]


def test_image_frustum_is_rectangular() -> None:
    """A point 42 degrees above the axis is inside the paper's 45-degree cone but outside the
    4:3 image (vertical half-FoV 36.9 degrees)."""
    cams = pair_at(1.0, 5.0, target=(0.0, 0.0, 1.0))
    p = np.array([[0.0, 0.0, 1.0 + math.tan(math.radians(42.0)) * 1.0]])[None]
    assert coverage_reward(cams, p, ALL_ON, IMAGE) == 0.0
    assert coverage_reward(cams, p, replace(ALL_ON, frustum=False, resolution=False), IMAGE) > 0.0


def test_wind_average_and_batches() -> None:
    rng = np.random.default_rng(1)
    R = rng.normal(size=(3, 400, 3)) * 0.2 + np.array([0, 0, 1.0])
    cams = np.stack([pair_at(2.0, 8.0), pair_at(3.0, 12.0), pair_at(1.5, 20.0)])
    batch = coverage_reward(cams, R, ALL_ON, IMAGE)
    per_k = np.array([[coverage_reward(c, R[k:k + 1], ALL_ON, IMAGE) for k in range(3)] for c in cams])
    np.testing.assert_allclose(batch, per_k.mean(axis=1), atol=1e-5)  # eq. 7: the mean over the winds
    small = coverage_reward(cams, R, ALL_ON, IMAGE, max_elements=1 << 12)  # chunked: the same values
    np.testing.assert_allclose(small, batch, atol=1e-5)


def test_degenerate_inputs() -> None:
    pts = grid_patch(0.0)[None]
    with pytest.raises(ValueError):
        coverage_reward(pair_at(2.0, 8.0)[:1], pts)
    with pytest.raises(ValueError):
        coverage_reward(pair_at(2.0, 8.0), np.zeros((1, 0, 3)))
    cams = pair_at(2.0, 8.0)
    cams[1, 3:] = 0.0  # a zero viewing vector sees nothing: no pair
    assert coverage_reward(cams, pts, ALL_ON, IMAGE) == 0.0
    on_point = look_at(pts[0, :2], [[1.0, 0.0, 1.0], [1.0, 0.1, 1.0]])
    assert np.isfinite(coverage_reward(on_point, pts, ALL_ON, IMAGE))
