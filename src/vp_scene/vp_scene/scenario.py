"""Scene layouts of paper Sec. V-A: 1 plant, 3 plants in a row, 6 plants in a 2 x 3 rectangle.

"Each plant was given a random rotation around its vertical axis and a scale within 10% of the
original size" (Sec. V-A): yaw ~ U[0, 2 pi), scale ~ U[0.9, 1.1]. Plants stand on the ground
(z = 0, frame ``map``, REP-103), rows run along x, the layout is centred at the origin in x, y.

ROS-free: numpy (and trimesh for placing meshes).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np
import trimesh

from .plants import PlantModel, procedural_corn, procedural_seed

__all__ = ["SCENARIOS", "PlacedPlant", "Scene", "layout", "make_scene", "place_points", "place_mesh"]

SCENARIOS = ("one_plant", "three_row", "six_rect")


@dataclass(frozen=True)
class PlacedPlant:
    """One plant of a scene.

    Attributes:
        model_index: index of the model in ``Scene.models`` (the ``models`` given to
            :func:`make_scene`, or the scene's procedural plants).
        model_name: the model's name (PLY stem or ``procedural-<seed>``).
        yaw: rotation about +z, rad, in [0, 2 pi).
        scale: uniform scale, in [0.9, 1.1].
        position: (3,) stalk base on the ground (z = 0).
        z_range: (2,) the placed plant's min / max height (min = 0: it stands on the ground).
        base_z: model-frame height of the model's lowest point (moved to the ground).
    """

    model_index: int
    model_name: str
    yaw: float
    scale: float
    position: np.ndarray
    z_range: np.ndarray
    base_z: float = 0.0


@dataclass
class Scene:
    """A noise-free scene.

    Attributes:
        scenario: one of :data:`SCENARIOS`.
        plants: the placed plants.
        points: (P, 3) float64 scene points (plant after plant).
        colors: (P, 3) uint8 RGB colours.
        plant_index: (P,) int32, which plant each point belongs to.
        models: the plant models that ``PlacedPlant.model_index`` refers to (meshes for rendering).
    """

    scenario: str
    plants: list
    points: np.ndarray
    colors: np.ndarray
    plant_index: np.ndarray
    models: list = field(default_factory=list, repr=False)

    @property
    def z_ranges(self) -> np.ndarray:
        """(n_plants, 2) min / max height of each placed plant."""
        return np.array([p.z_range for p in self.plants], dtype=np.float64).reshape(-1, 2)


def _check_positive(name: str, value: float) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number > 0, got {value!r}") from None
    if not math.isfinite(v) or v <= 0:
        raise ValueError(f"{name} must be > 0, got {value!r}")
    return v


def _check_int(name: str, value: object, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    if int(value) < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value}")
    return int(value)


def layout(scenario: str, plant_spacing: float = 0.6, row_spacing: float = 0.76) -> np.ndarray:
    """Stalk positions (n, 3) of a scenario on the ground, centred at the origin in x, y.

    one_plant: the origin; three_row: 3 plants along x, ``plant_spacing`` apart; six_rect: two
    such rows, ``row_spacing`` apart along y.
    """
    if scenario not in SCENARIOS:
        raise ValueError(f"unknown scenario {scenario!r}; expected one of {', '.join(SCENARIOS)}")
    s = _check_positive("plant_spacing", plant_spacing)
    r = _check_positive("row_spacing", row_spacing)
    if scenario == "one_plant":
        xy = [(0.0, 0.0)]
    elif scenario == "three_row":
        xy = [(x * s, 0.0) for x in (-1, 0, 1)]
    else:
        xy = [(x * s, y * r) for y in (-0.5, 0.5) for x in (-1, 0, 1)]
    return np.array([(x, y, 0.0) for x, y in xy], dtype=np.float64)


def _rotation(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def place_points(model_points: np.ndarray, plant: PlacedPlant) -> np.ndarray:
    """Model-frame points (or mesh vertices) (M, 3) -> scene points (M, 3).

    p' = R_z(yaw) (scale (p - [0, 0, base_z])) + position: the model's lowest point goes to
    the ground, the stalk (model z axis) to ``position``.
    """
    p = np.asarray(model_points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"model_points must have shape (M, 3), got {p.shape}")
    q = (p - np.array([0.0, 0.0, plant.base_z])) * plant.scale
    return q @ _rotation(plant.yaw).T + np.asarray(plant.position, dtype=np.float64)


def place_mesh(mesh: trimesh.Trimesh, plant: PlacedPlant) -> trimesh.Trimesh:
    """A copy of a model-frame mesh placed like ``plant`` (vertex colours kept)."""
    out = mesh.copy()
    out.vertices = place_points(np.asarray(mesh.vertices), plant)
    return out


def make_scene(scenario: str, models: Optional[Sequence[PlantModel]] = None, seed: int = 0,
               points_per_plant: int = 4000, plant_spacing: float = 0.6, row_spacing: float = 0.76) -> Scene:
    """Build a scene (paper Sec. V-A).

    Each plant gets yaw ~ U[0, 2 pi) and scale ~ U[0.9, 1.1]; its model is drawn among
    ``models`` (seeded choice) or, when ``models`` is None, is a distinct procedural corn plant
    (``procedural_corn(procedural_seed(seed, i))``). The plant's points are subsampled to
    ``points_per_plant`` (without replacement when the model has enough points) and placed with
    the lowest point on the ground. Layout draws use ``default_rng([seed, 0])``, subsampling
    ``default_rng([seed, 2])`` (the wind uses ``[seed, 1]``): everything is reproducible.

    Raises:
        ValueError: unknown scenario, points_per_plant < 1, spacing <= 0, negative seed, or an
            empty ``models`` list.
    """
    positions = layout(scenario, plant_spacing, row_spacing)
    n_pts = _check_int("points_per_plant", points_per_plant, 1)
    seed = _check_int("seed", seed, 0)
    if models is not None:
        models = list(models)
        if not models:
            raise ValueError("models is empty: give at least one plant model, or None for procedural plants")
    rng = np.random.default_rng([seed, 0])
    rng_sub = np.random.default_rng([seed, 2])

    scene_models: list = list(models) if models is not None else []
    plants, pts, cols, idx = [], [], [], []
    for i, pos in enumerate(positions):
        if models is not None:
            mi = int(rng.integers(len(models)))
            model = models[mi]
            n_model = model.points.shape[0]
            sel = rng_sub.choice(n_model, size=n_pts, replace=n_pts > n_model)
            mp, mc = model.points[sel], model.colors[sel]
        else:
            mi = i
            model = procedural_corn(procedural_seed(seed, i), n_points=n_pts)
            scene_models.append(model)
            mp, mc = model.points, model.colors
        yaw = float(rng.uniform(0.0, 2.0 * math.pi))
        scale = float(rng.uniform(0.9, 1.1))
        base_z, top_z = model.z_min, model.z_max
        plant = PlacedPlant(model_index=mi, model_name=model.name, yaw=yaw, scale=scale,
                            position=pos.copy(), z_range=np.array([0.0, scale * (top_z - base_z)]),
                            base_z=base_z)
        plants.append(plant)
        pts.append(place_points(mp, plant))
        cols.append(mc)
        idx.append(np.full(n_pts, i, dtype=np.int32))
    return Scene(scenario=scenario, plants=plants, points=np.concatenate(pts), colors=np.concatenate(cols),
                 plant_index=np.concatenate(idx), models=scene_models)
