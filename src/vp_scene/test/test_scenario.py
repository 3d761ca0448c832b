"""Scene layouts (paper Sec. V-A): counts, yaw, scale, spacing, ground, determinism, bad input."""
from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest

from vp_scene.plants import PlantModel
from vp_scene.ply import load_models
from vp_scene.scenario import SCENARIOS, PlacedPlant, layout, make_scene, place_mesh, place_points

CORN50 = Path(__file__).resolve().parents[3].parent / "shared" / "data" / "corn50"
N_PLANTS = {"one_plant": 1, "three_row": 3, "six_rect": 6, "grid_3x3": 9, "row_12": 12}


@pytest.fixture(scope="module")
def six() -> object:
    return make_scene("six_rect", seed=3, points_per_plant=1500, plant_spacing=0.5, row_spacing=0.8)


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_counts_and_layout(scenario: str) -> None:
    s = make_scene(scenario, seed=1, points_per_plant=200, plant_spacing=0.6, row_spacing=0.76)
    n = N_PLANTS[scenario]
    assert s.scenario == scenario and len(s.plants) == n
    assert s.points.shape == (200 * n, 3) and s.colors.shape == (200 * n, 3) and s.colors.dtype == np.uint8
    assert s.plant_index.dtype == np.int32 and np.bincount(s.plant_index).tolist() == [200] * n
    pos = np.array([p.position for p in s.plants])
    np.testing.assert_allclose(pos[:, 2], 0.0)
    np.testing.assert_allclose(pos[:, :2].mean(axis=0), 0.0, atol=1e-12)   # centred at the origin
    for a, b in itertools.combinations(pos, 2):                            # no two stalks closer
        assert np.linalg.norm(a - b) >= min(0.6, 0.76) - 1e-9
    if scenario == "three_row":
        np.testing.assert_allclose(pos[:, 1], 0.0)
        np.testing.assert_allclose(np.diff(np.sort(pos[:, 0])), 0.6)
    if scenario == "six_rect":
        ys = np.unique(pos[:, 1].round(9))
        assert len(ys) == 2 and ys[1] - ys[0] == pytest.approx(0.76)
        for y in ys:
            np.testing.assert_allclose(np.diff(np.sort(pos[np.isclose(pos[:, 1], y), 0])), 0.6)
    assert len({p.model_name for p in s.plants}) == n                      # distinct procedural plants
    assert [p.model_index for p in s.plants] == list(range(n)) and len(s.models) == n


def test_yaw_and_scale_ranges() -> None:
    yaws, scales = [], []
    for seed in range(20):
        for p in make_scene("six_rect", models=_toy_models(), seed=seed, points_per_plant=20).plants:
            yaws.append(p.yaw)
            scales.append(p.scale)
    yaws, scales = np.array(yaws), np.array(scales)
    assert ((yaws >= 0) & (yaws < 2 * math.pi)).all() and np.ptp(yaws) > math.pi   # spread over the circle
    assert ((scales >= 0.9) & (scales <= 1.1)).all() and np.ptp(scales) > 0.1


def test_plants_stand_on_the_ground_at_their_stalks(six) -> None:
    for i, p in enumerate(six.plants):
        pts = six.points[six.plant_index == i]
        assert pts[:, 2].min() >= -1e-9 and pts[:, 2].min() < 0.05          # base on z = 0
        assert p.z_range[0] == 0.0 and pts[:, 2].max() <= p.z_range[1] + 1e-9
        assert 0.9 * 1.8 < p.z_range[1] < 1.1 * 2.2                           # ~2 m, scaled
        lowest = pts[np.argmin(pts[:, 2])]                                   # the stalk base ...
        assert np.linalg.norm(lowest[:2] - p.position[:2]) < 0.06             # ... at the position
        model = six.models[p.model_index]
        np.testing.assert_allclose(p.z_range[1], p.scale * (model.z_max - model.z_min))


def test_place_points_transform() -> None:
    plant = PlacedPlant(0, "m", yaw=math.pi / 2, scale=2.0, position=np.array([1.0, 2.0, 0.0]),
                        z_range=np.array([0.0, 4.0]), base_z=-1.0)
    out = place_points(np.array([[1.0, 0.0, -1.0], [0.0, 0.0, 1.0]]), plant)
    np.testing.assert_allclose(out, [[1.0, 4.0, 0.0], [1.0, 2.0, 4.0]], atol=1e-12)


def test_scene_points_are_placed_model_points(six) -> None:
    p = six.plants[2]
    model = six.models[p.model_index]
    np.testing.assert_allclose(place_points(model.points, p), six.points[six.plant_index == 2])
    mesh = place_mesh(model.mesh, p)
    assert mesh.vertices.shape == model.mesh.vertices.shape and mesh.bounds[0][2] == pytest.approx(0.0, abs=1e-9)
    assert model.mesh.bounds[0][2] < -0.5                                  # the model's own mesh untouched


def test_deterministic_and_seeded() -> None:
    a = make_scene("three_row", seed=11, points_per_plant=300)
    b = make_scene("three_row", seed=11, points_per_plant=300)
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.colors, b.colors)
    c = make_scene("three_row", seed=12, points_per_plant=300)
    assert [p.yaw for p in a.plants] != [p.yaw for p in c.plants]
    # the layout (yaw, scale, model) does not depend on the number of points
    d = make_scene("three_row", seed=11, points_per_plant=50)
    assert [(p.yaw, p.scale, p.model_name) for p in a.plants] == [(p.yaw, p.scale, p.model_name) for p in d.plants]


def _toy_models() -> list[PlantModel]:
    out = []
    for k in range(3):
        rng = np.random.default_rng(k)
        z = rng.uniform(-1.0, 1.0, 500)
        pts = np.stack([0.05 * rng.normal(size=500), 0.05 * rng.normal(size=500), z], 1)
        out.append(PlantModel(f"toy{k}", pts, np.full((500, 3), 40 * k, np.uint8)))
    return out


def test_given_models_chosen_and_subsampled() -> None:
    models = _toy_models()
    names = set()
    for seed in range(6):
        s = make_scene("six_rect", models=models, seed=seed, points_per_plant=100)
        assert s.models == models
        for i, p in enumerate(s.plants):
            assert p.model_name == models[p.model_index].name
            names.add(p.model_name)
            pts = s.points[s.plant_index == i]
            assert len(pts) == 100 and pts[:, 2].min() >= -1e-9
            assert (s.colors[s.plant_index == i] == 40 * p.model_index).all()
    assert names == {"toy0", "toy1", "toy2"}                                 # all models get picked
    big = make_scene("one_plant", models=models[:1], seed=0, points_per_plant=2000)   # > 500: with replacement
    assert big.points.shape == (2000, 3)


def test_corn50_scene() -> None:
    if not CORN50.is_dir():
        pytest.skip(f"Corn50 data not found at {CORN50} (<repo>/../shared/data/corn50)")
    models = load_models(CORN50)
    s = make_scene("three_row", models=models, seed=0, points_per_plant=3000)
    for i, p in enumerate(s.plants):
        pts = s.points[s.plant_index == i]
        assert p.model_name in {m.name for m in models}
        assert 0.0 <= pts[:, 2].min() < 0.02 and 1.4 < p.z_range[1] < 2.2


@pytest.mark.parametrize("kwargs,match", [
    ({"scenario": "five_star"}, "unknown scenario 'five_star'"),
    ({"points_per_plant": 0}, "points_per_plant"),
    ({"points_per_plant": 2.5}, "points_per_plant"),
    ({"plant_spacing": 0.0}, "plant_spacing"),
    ({"plant_spacing": -0.3}, "plant_spacing"),
    ({"row_spacing": 0.0}, "row_spacing"),
    ({"row_spacing": float("nan")}, "row_spacing"),
    ({"seed": -4}, "seed"),
    ({"models": []}, "models is empty"),
])
def test_bad_input(kwargs: dict, match: str) -> None:
    args = {"scenario": "three_row", "points_per_plant": 10, **kwargs}
    with pytest.raises(ValueError, match=match):
        make_scene(**args)


def test_layout_positions() -> None:
    np.testing.assert_allclose(layout("one_plant"), [[0.0, 0.0, 0.0]])
    np.testing.assert_allclose(layout("six_rect", 1.0, 2.0)[:, :2],
                               [[-1, -1], [0, -1], [1, -1], [-1, 1], [0, 1], [1, 1]])
