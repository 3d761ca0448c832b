"""vp_scene.capture: what a flight does to a plan."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from vp_scene.capture import CAPTURES, IDEAL, REALISTIC, CaptureModel

PLAN = np.array([[1.5, 0.0, 1.2, -1.5, 0.0, -0.3], [0.0, 1.5, 1.2, 0.0, -1.5, -0.3], [-1.5, 0.2, 1.0, 1.5, -0.2, 0.0]])


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    return np.degrees(np.arccos(np.clip((a * b).sum(-1), -1, 1)))


def test_defaults_are_an_rtk_multirotor_and_ideal_has_no_error() -> None:
    assert CAPTURES == ("realistic", "ideal")
    assert (REALISTIC.hover_position_sigma, REALISTIC.hover_attitude_sigma) == (0.05, 0.5)
    assert (REALISTIC.report_position_sigma, REALISTIC.report_attitude_sigma) == (0.02, 0.5)
    assert REALISTIC.sensor_noise == pytest.approx(2 / 255)
    f = IDEAL.fly(PLAN, 3)
    assert np.array_equal(f.actual, PLAN) and np.array_equal(f.reported, PLAN)  # bit for bit, not normalized
    img = np.random.default_rng(0).integers(0, 256, (8, 8, 3), dtype=np.uint8)
    assert IDEAL.expose(img, 0, 0) is img
    assert IDEAL.to_dict()["kind"] == "ideal" and REALISTIC.to_dict()["hover_position_sigma"] == 0.05


def test_errors_have_the_stated_size_and_keep_the_horizon() -> None:
    """Over many draws: per-axis position std and the optical axis's turn match the figures."""
    cam = PLAN[0]
    draws = [REALISTIC.fly_camera(cam, k, i) for k in range(40) for i in range(25)]
    actual = np.array([a for a, _ in draws])
    reported = np.array([r for _, r in draws])
    assert np.std(actual[:, :3] - cam[:3], axis=0) == pytest.approx([0.05] * 3, rel=0.12)
    assert np.std(reported[:, :3] - actual[:, :3], axis=0) == pytest.approx([0.02] * 3, rel=0.12)
    turn = _angle_deg(actual[:, 3:], cam[3:])
    # the axis turns by the perpendicular part of a 3-D Gaussian rotation: Rayleigh, mean sigma sqrt(pi/2)
    assert turn.mean() == pytest.approx(0.5 * math.sqrt(math.pi / 2), rel=0.1)
    assert np.allclose(np.linalg.norm(actual[:, 3:], axis=1), 1.0)


def test_draws_are_seeded_per_realization_and_camera() -> None:
    a = REALISTIC.fly(PLAN, 2)
    b = REALISTIC.fly(PLAN, 2)
    assert np.array_equal(a.actual, b.actual) and np.array_equal(a.reported, b.reported)
    assert not np.array_equal(REALISTIC.fly(PLAN, 3).actual, a.actual)  # another realization draws again
    # one drone's capture does not depend on the others (the per-camera API of the simulated drones)
    assert np.array_equal(REALISTIC.fly_camera(PLAN[1], 2, 1)[0], a.actual[1])
    assert np.array_equal(REALISTIC.fly(PLAN[1:2], 2).actual[0], REALISTIC.fly_camera(PLAN[1], 2, 0)[0])
    assert not np.array_equal(replace(REALISTIC, seed=1).fly(PLAN, 2).actual, a.actual)


def test_sensor_noise() -> None:
    img = np.full((200, 300, 3), 128, np.uint8)
    noisy = REALISTIC.expose(img, 0, 1)
    d = noisy.astype(float) - 128
    assert d.std() == pytest.approx(2.0, rel=0.05) and noisy.dtype == np.uint8
    assert np.array_equal(noisy, REALISTIC.expose(img, 0, 1)) and not np.array_equal(noisy, REALISTIC.expose(img, 1, 1))
    assert REALISTIC.expose(np.full((4, 4, 3), 255, np.uint8), 0, 0).max() == 255  # clipped


@pytest.mark.parametrize("kw, text", [
    (dict(kind="drone"), "capture must be one of realistic, ideal"),
    (dict(hover_position_sigma=-0.1), "hover_position_sigma must be a finite number >= 0"),
    (dict(report_attitude_sigma=float("nan")), "report_attitude_sigma"),
    (dict(hover_attitude_sigma=45.0), "at most 10 degrees"),
    (dict(sensor_noise=2.0), "sensor_noise must be at most 0.5"),
    (dict(seed=-1), "seed must be an integer from 0 to 4294967295"),
    (dict(seed=2 ** 32), "seed must be an integer from 0 to 4294967295"),
])
def test_bad_figures_are_one_line(kw, text) -> None:
    with pytest.raises(ValueError, match=text):
        replace(REALISTIC, **kw).validate()


def test_named() -> None:
    assert CaptureModel.named("ideal") == IDEAL
    assert CaptureModel.named("realistic", hover_position_sigma=None) == REALISTIC
    assert CaptureModel.named("realistic", sensor_noise=0.0).sensor_noise == 0.0
    with pytest.raises(ValueError, match="ideal' has no error"):
        CaptureModel.named("ideal", hover_position_sigma=0.1)
    with pytest.raises(ValueError, match="capture must be one of"):
        CaptureModel.named("perfect")
