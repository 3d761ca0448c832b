"""Scenes: plants placed on the ground after a layout (paper Sec. V-A and layout files).

The layout (:mod:`vp_scene.layout`: a built-in name, a layout file or dict, or a Layout) says
where the plants stand. "Each plant was given a random rotation around its vertical axis and a
scale within 10% of the original size" (Sec. V-A): yaw ~ U[0, 2 pi), scale ~ U[0.9, 1.1], unless
the layout gives them. Plants stand on the ground (z = 0, frame ``map``, REP-103); the built-in
layouts are centred at the origin in x, y with rows along x.

ROS-free: numpy (and trimesh for placing meshes).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional, Sequence, Union

import numpy as np
import trimesh

from .layout import BUILTIN_LAYOUTS, Layout, LayoutError, PlantSpec, resolve_layout
from .limits import check_seed
from .plants import PlantModel
from .ply import load_models
from .procedural import procedural_corn, procedural_name_seed, procedural_seed
from .scene_spec import SCENE

__all__ = ["SCENARIOS", "PlacedPlant", "Scene", "layout", "make_scene", "place_points", "place_mesh",
           "scene_of_cloud"]

#: The built-in layouts (:data:`vp_scene.layout.BUILTIN_LAYOUTS`).
SCENARIOS = tuple(BUILTIN_LAYOUTS)

@dataclass(frozen=True)
class PlacedPlant:
    """One plant of a scene.

    Attributes:
        model_index: index of the model in ``Scene.models`` (the ``models`` given to
            :func:`make_scene`, or the scene's procedural plants).
        model_name: the model's name (PLY stem or ``procedural-<seed>``).
        yaw: rotation about +z, rad, in [0, 2 pi).
        scale: uniform scale, in [0.9, 1.1] (drawn) or as the layout gives it.
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
        scenario: the layout's name (one of :data:`SCENARIOS` for a built-in layout).
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


def _check_int(name: str, value: object, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    if int(value) < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value}")
    return int(value)


def layout(scenario: Union[str, dict, Layout], plant_spacing: float = SCENE.plant_spacing,
           row_spacing: float = SCENE.row_spacing) -> np.ndarray:
    """Stalk positions (n, 3) of a scenario's layout on the ground, before jitter.

    one_plant: the origin; three_row: 3 plants along x, ``plant_spacing`` apart; six_rect: two
    such rows, ``row_spacing`` apart along y; grid_3x3, row_12: 3 x 3 and 1 x 12 grids; a layout
    file, dict or Layout: its plants (:func:`vp_scene.layout.resolve_layout`).
    """
    return resolve_layout(scenario, plant_spacing, row_spacing).positions()


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


_LISTED_NAMES = 20  # model names listed in an error, at most


def _named_model(models: Sequence[PlantModel], name: str, where: str) -> int:
    """Index of the model called ``name``; LayoutError listing the names (``where`` = source and field)."""
    for k, m in enumerate(models):
        if m.name == name:
            return k
    names = [m.name for m in models]
    listed = ", ".join(names[:_LISTED_NAMES]) + (f", ... ({len(names)} in all)" if len(names) > _LISTED_NAMES else "")
    raise LayoutError(f"{where} {name!r} is not one of the models ({listed})")


def _procedural_seed_of(name: str, where: str) -> int:
    """The seed of a procedural plant's name ``procedural-<seed>``; any other name needs a models folder."""
    seed = procedural_name_seed(name)
    if seed is None:
        raise LayoutError(f"{where} {name!r} needs a models folder: without one the plants are procedural "
                          f"(models procedural-<seed>)")
    return seed


def _wrap(yaw: float) -> float:
    """yaw in [0, 2 pi) (a value already there is returned unchanged: fmod is exact)."""
    w = yaw % (2.0 * math.pi)
    return 0.0 if w >= 2.0 * math.pi else w


def make_scene(scenario: Union[str, dict, Layout], models: Union[None, str, Path, Sequence[PlantModel]] = None,
               seed: int = SCENE.seed, points_per_plant: int = SCENE.points_per_plant,
               plant_spacing: float = SCENE.plant_spacing, row_spacing: float = SCENE.row_spacing) -> Scene:
    """Build a scene (paper Sec. V-A) after a layout (:func:`vp_scene.layout.resolve_layout`:
    a built-in name with these spacings, a layout file path or a layout dict; a Layout is taken
    as it is: :func:`vp_scene.build.build_noisy_scene` resolves the layout once, checks the
    scene's size and passes it here); ``models`` may be a folder of PLY plants ('' or None:
    procedural corn), loaded after the layout and the counts are checked (a bad layout is
    reported before any model file is read).

    Each plant gets yaw ~ U[0, 2 pi) and scale ~ U[0.9, 1.1]; its model is drawn among
    ``models`` (seeded choice) or, when ``models`` is None, is a distinct procedural corn plant
    (``procedural_corn(procedural_seed(seed, i))``). The plant's points are subsampled to
    ``points_per_plant`` (without replacement when the model has enough points) and placed with
    the lowest point on the ground.

    What the layout's :class:`~vp_scene.layout.PlantSpec` gives overrides the draw: ``yaw``
    (wrapped to [0, 2 pi)), ``scale``, ``model`` (a name among ``models``; without models,
    ``procedural-<seed>`` is that procedural plant). Jitter j adds (dx, dy) ~ U[-j, j]^2 to each
    position.

    Random streams, all reproducible: plant after plant, ``default_rng([seed, 0])`` draws the
    model index (with ``models``), then yaw, then scale, *always*, even where the layout
    overrides them (so an explicit value never shifts the draws of the other plants);
    ``default_rng([seed, 2])`` subsamples; ``default_rng([seed, 3])`` draws the jitter (only
    when j > 0); the wind uses ``[seed, 1]``. A layout of a scene's own placements
    (:meth:`~vp_scene.layout.Layout.from_placements`) with the same seed, models and points
    per plant therefore rebuilds the identical scene.

    Raises:
        ValueError (LayoutError for the layout) naming the problem: unknown scenario, a bad
        layout file, an unknown model name, points_per_plant < 1, spacing <= 0, a seed outside
        0 to :data:`vp_scene.limits.MAX_SEED`, or an empty ``models`` list.
    """
    lay = scenario if isinstance(scenario, Layout) else resolve_layout(scenario, plant_spacing, row_spacing)
    n_pts = _check_int("points_per_plant", points_per_plant, 1)
    seed = check_seed("seed", seed)
    if isinstance(models, (str, Path)):
        models = load_models(models) if str(models) else None
    if models is not None:
        models = list(models)
        if not models:
            raise ValueError("models is empty: give at least one plant model, or None for procedural plants")
    rng = np.random.default_rng([seed, 0])
    rng_sub = np.random.default_rng([seed, 2])
    rng_jitter = np.random.default_rng([seed, 3])

    scene_models: list = list(models) if models is not None else []
    plants, pts, cols, idx = [], [], [], []
    for i, spec in enumerate(lay.plants):
        where = f"{lay.where}: plants[{i}].model"
        if models is not None:
            drawn = int(rng.integers(len(models)))
            mi = drawn if spec.model is None else _named_model(models, spec.model, where)
            model = models[mi]
            n_model = model.points.shape[0]
            sel = rng_sub.choice(n_model, size=n_pts, replace=n_pts > n_model)
            mp, mc = model.points[sel], model.colors[sel]
        else:
            mi = i
            pseed = procedural_seed(seed, i) if spec.model is None else _procedural_seed_of(spec.model, where)
            model = procedural_corn(pseed, n_points=n_pts)
            scene_models.append(model)
            mp, mc = model.points, model.colors
        yaw = float(rng.uniform(0.0, 2.0 * math.pi))
        scale = float(rng.uniform(0.9, 1.1))
        plant = _placed(spec, mi, model, _wrap(spec.yaw) if spec.yaw is not None else yaw,
                        spec.scale if spec.scale is not None else scale,
                        rng_jitter.uniform(-lay.jitter, lay.jitter, size=2) if lay.jitter > 0 else None)
        plants.append(plant)
        pts.append(place_points(mp, plant))
        cols.append(mc)
        idx.append(np.full(n_pts, i, dtype=np.int32))
    return Scene(scenario=lay.name, plants=plants, points=np.concatenate(pts), colors=np.concatenate(cols),
                 plant_index=np.concatenate(idx), models=scene_models)


def _placed(spec: PlantSpec, model_index: int, model: PlantModel, yaw: float, scale: float,
            shift: Optional[np.ndarray]) -> PlacedPlant:
    """The PlacedPlant of a spec: stalk at (x, y) (+ the jitter ``shift``) on the ground, the
    model's lowest point moved there, z_range = [0, scale (z_max - z_min)]."""
    position = np.array([spec.x, spec.y, 0.0], dtype=np.float64)
    if shift is not None:
        position[:2] += shift
    base_z, top_z = model.z_min, model.z_max
    return PlacedPlant(model_index=model_index, model_name=model.name, yaw=float(yaw), scale=float(scale),
                       position=position, z_range=np.array([0.0, scale * (top_z - base_z)]), base_z=base_z)


def scene_of_cloud(points: np.ndarray, colors: np.ndarray, name: str = "prior") -> Scene:
    """A scene of one coloured cloud kept where it is (a reconstruction: a first sortie's, a real
    scan's first pass), as one "plant" placed by the identity (yaw 0, scale 1, no shift), its
    z_range the cloud's own heights; the world meshes it as it meshes a scanned plant
    (:func:`vp_scene.meshing.model_mesh`). ValueError for an empty or malformed cloud."""
    model = PlantModel(name, np.asarray(points, dtype=np.float64), np.asarray(colors, dtype=np.uint8))
    z = model.points[:, 2]
    plant = PlacedPlant(model_index=0, model_name=name, yaw=0.0, scale=1.0, position=np.zeros(3),
                        z_range=np.array([float(z.min()), float(z.max())]), base_z=0.0)
    return Scene(scenario=name, plants=[plant], points=model.points.copy(), colors=model.colors.copy(),
                 plant_index=np.zeros(len(model.points), dtype=np.int32), models=[model])
