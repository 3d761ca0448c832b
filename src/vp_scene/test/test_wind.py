"""Wind noise (paper Sec. V-A): level l moves by l * n_wind, n_wind ~ N(0, 0.002), K realizations."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vp_scene.scenario import make_scene
from vp_scene.wind import WindConfig, displace, draw_n_wind, levels_of, make_noisy_scene


@pytest.fixture(scope="module")
def scene():
    return make_scene("three_row", seed=2, points_per_plant=800)


def column(n: int = 101, top: float = 2.0) -> np.ndarray:
    z = np.linspace(0.0, top, n)
    return np.stack([np.zeros(n), np.zeros(n), z], 1)


def test_levels() -> None:
    z = np.array([0.0, 0.05, 0.1, 0.15, 0.55, 0.999, 1.0])
    np.testing.assert_array_equal(levels_of(z, np.array([0.0, 1.0]), 10), [1, 1, 2, 2, 6, 10, 10])
    np.testing.assert_array_equal(levels_of(np.array([0.5]), np.array([0.0, 1.0]), 1), [1])
    np.testing.assert_array_equal(levels_of(np.array([-5.0, 5.0]), np.array([0.0, 1.0]), 4), [1, 4])  # clipped


def test_shift_grows_linearly_with_level() -> None:
    p = column()
    out = displace(p, np.array([0.0, 2.0]), n_wind=0.01, levels=10, direction=0.0)
    d = out - p
    lev = levels_of(p[:, 2], np.array([0.0, 2.0]), 10)
    np.testing.assert_allclose(d[:, 0], 0.01 * lev)        # l * n_wind along +x
    np.testing.assert_allclose(d[:, 1:], 0.0)               # nothing across the wind, heights kept
    assert np.argmax(d[:, 0]) == len(p) - 1 or d[-1, 0] == d[:, 0].max()      # the top moves most
    assert d[-1, 0] == pytest.approx(10 * 0.01) and d[0, 0] == pytest.approx(0.01)
    means = [d[lev == lv, 0].mean() for lv in range(1, 11)]
    np.testing.assert_allclose(np.diff(means), 0.01)         # linear in the level
    neg = displace(p, np.array([0.0, 2.0]), n_wind=-0.01, levels=10) - p
    np.testing.assert_allclose(neg, -d)


@pytest.mark.parametrize("direction", [0.0, math.pi / 2, 2.3, -1.0])
def test_direction_respected(direction: float) -> None:
    p = column()
    d = displace(p, np.array([0.0, 2.0]), n_wind=0.02, levels=5, direction=direction) - p
    unit = np.array([math.cos(direction), math.sin(direction)])
    along = d[:, :2] @ unit
    np.testing.assert_allclose(d[:, :2], along[:, None] * unit[None], atol=1e-12)
    assert (along > 0).all() and along.max() == pytest.approx(5 * 0.02)


def test_n_wind_variance_over_seeds() -> None:
    cfg = WindConfig(realizations=5, variance=0.002)
    w = np.concatenate([draw_n_wind(cfg, seed) for seed in range(2000)])
    # 10,000 draws: std error of the sample variance is var * sqrt(2 / n), about 1.4 %
    assert np.var(w, ddof=1) == pytest.approx(0.002, rel=0.06)
    assert abs(w.mean()) < 4 * math.sqrt(0.002 / len(w))
    w2 = np.concatenate([draw_n_wind(WindConfig(realizations=5, variance=0.02), s) for s in range(2000)])
    assert np.var(w2, ddof=1) == pytest.approx(0.02, rel=0.06)   # the parameter is a variance, not a std


def test_noisy_scene(scene) -> None:
    cfg = WindConfig(levels=10, realizations=4, variance=0.002, direction=0.7)
    noisy = make_noisy_scene(scene, cfg, seed=9)
    assert noisy.points.shape == (4, len(scene.points), 3) and noisy.n_wind.shape == (4,)
    np.testing.assert_array_equal(noisy.n_wind, draw_n_wind(cfg, 9))
    assert noisy.colors is scene.colors                                    # colours kept, same order
    unit = np.array([math.cos(0.7), math.sin(0.7)])
    for k in range(4):
        d = noisy.points[k] - scene.points
        np.testing.assert_allclose(d[:, 2], 0.0)
        for i, plant in enumerate(scene.plants):                           # one n_wind for all plants
            m = scene.plant_index == i
            lev = levels_of(scene.points[m, 2], plant.z_range, 10)
            np.testing.assert_allclose(d[m, :2], (lev * noisy.n_wind[k])[:, None] * unit[None], atol=1e-12)
            top = np.argmax(scene.points[m, 2])
            assert lev[top] == 10
            assert abs(d[m][top, :2] @ unit) == pytest.approx(np.abs(d[m, :2] @ unit).max())
    assert len(np.unique(noisy.n_wind)) == 4


def test_deterministic_and_independent_of_layout(scene) -> None:
    cfg = WindConfig(realizations=3)
    a, b = make_noisy_scene(scene, cfg, 5), make_noisy_scene(scene, cfg, 5)
    np.testing.assert_array_equal(a.points, b.points)
    c = make_noisy_scene(scene, cfg, 6)
    assert not np.allclose(a.n_wind, c.n_wind)
    other = make_scene("one_plant", seed=5, points_per_plant=10)
    np.testing.assert_array_equal(make_noisy_scene(other, cfg, 5).n_wind, a.n_wind)  # own stream
    first_yaw = np.random.default_rng([5, 0]).uniform(0, 2 * math.pi)
    assert not np.isclose(np.abs(a.n_wind), first_yaw).any()


def test_zero_variance_is_noise_free(scene) -> None:
    noisy = make_noisy_scene(scene, WindConfig(realizations=2, variance=0.0), 0)
    np.testing.assert_array_equal(noisy.points[0], scene.points)


@pytest.mark.parametrize("kwargs,match", [
    ({"realizations": 0}, "realizations must be >= 1"),
    ({"levels": 0}, "levels must be >= 1"),
    ({"variance": -0.1}, "variance must be >= 0"),
    ({"levels": 2.5}, "levels must be an integer"),
    ({"direction": float("nan")}, "direction must be a finite"),
])
def test_bad_config(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        WindConfig(**kwargs)


def test_bad_displace_input() -> None:
    with pytest.raises(ValueError, match="levels"):
        displace(column(), np.array([0.0, 2.0]), 0.01, 0)
    with pytest.raises(ValueError, match="z_range"):
        displace(column(), np.zeros(3), 0.01, 3)
