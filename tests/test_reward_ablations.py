"""The plan-quality study's ablation of ``coverage`` with z-buffer cells sized on the plant
(``bench.reward_ablations.ObjectCells``), on a hand-built case."""
from __future__ import annotations

import math

import numpy as np
import pytest

from bench.reward_ablations import ObjectCells, ablations
from vp_planner.reward_models import CoverageParams, coverage_reward, make_reward, point_coverage
from vp_scene.camera import CameraModel, look_at

IMAGE = CameraModel(2000, 1500, math.pi / 2)


def pair_at(distance: float, half_angle_deg: float, target=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Two cameras at ``distance`` from ``target``, +-half_angle in azimuth, looking at it."""
    t = np.asarray(target, float)
    a = np.radians([-half_angle_deg, half_angle_deg])
    c = t + distance * np.stack([np.cos(a), np.sin(a), np.zeros(2)], axis=1)
    return look_at(c, np.broadcast_to(t, c.shape))


def comb_over_plane() -> tuple[np.ndarray, int]:
    """A plane of points at x = 0 (1 cm apart) behind a comb of 2 cm strips every 20 cm at x = 0.3:
    (points, number of plane points first)."""
    s = np.arange(-0.3, 0.3001, 0.01)
    yy, zz = np.meshgrid(s, s)
    plane = np.stack([np.zeros(yy.size), yy.ravel(), 1.0 + zz.ravel()], axis=1)
    strip = np.abs(((yy.ravel() + 0.3) % 0.2) - 0.1) < 0.01
    comb = plane[strip] + np.array([0.3, 0.0, 0.0])
    return np.concatenate([plane, comb]), len(plane)


def test_occlusion_cells_measure_the_plant_not_the_image() -> None:
    """A leaf hides about its width behind it, whatever the distance: through a comb that covers a
    tenth of a plane, a camera 6 m away sees as much of the plane as one 2 m away. The grid fixed
    in the image (the planner's: 64 cells, 19 cm each at 6 m) hides most of it from afar."""
    pts, n_plane = comb_over_plane()
    flags = dict(max_points=0, registration=False, resolution=False)
    params = ObjectCells(cell=0.03, **flags)

    def seen(distance: float, p: CoverageParams) -> float:
        cams = pair_at(distance, 4.0, target=(0.0, 0.0, 1.0))
        return float(point_coverage(cams, pts[None], p, IMAGE)[0, :n_plane].mean())
    near, far = seen(2.0, params), seen(6.0, params)
    assert 0.4 < near < 0.9 and far > 0.8 * near
    assert seen(6.0, CoverageParams(**flags)) < 0.5 * far
    with pytest.raises(ValueError, match="cell"):
        ObjectCells(cell=-0.01)
    # eq. 7 under the ablation: each wind's grid is its own, the batch is the mean of the winds
    R = np.stack([pts, pts + np.array([0.0, 0.02, 0.0])])
    cams = pair_at(4.0, 4.0, target=(0.0, 0.0, 1.0))
    per_k = [coverage_reward(cams, R[k:k + 1], params, IMAGE) for k in range(2)]
    assert coverage_reward(cams, R, params, IMAGE) == pytest.approx(np.mean(per_k), abs=1e-6)


def test_every_ablation_is_a_coverage_spec_the_planner_scores() -> None:
    pts, _ = comb_over_plane()
    cams = pair_at(3.0, 6.0)
    values = {name: float(make_reward(spec, pts[None])(cams[None])[0]) for name, spec in ablations().items()}
    assert set(values) >= {"coverage-no-occlusion", "coverage-object-cells"}
    assert all(0.0 <= v <= 1.0 for v in values.values())
    assert values["coverage-object-cells"] != values["coverage-no-occlusion"]
