"""One call from parameters to a noisy scene (used by the scene node, CLIs and benchmarks), and the
size of that scene before it is built. ROS-free."""
from __future__ import annotations

import inspect
from pathlib import Path
from typing import Any, Mapping, Sequence, Union

from .layout import Layout, resolve_layout
from .limits import check_scene_size
from .plants import PlantModel
from .scenario import make_scene
from .scene_spec import SCENE
from .wind import NoisyScene, WindConfig, make_noisy_scene

__all__ = ["build_noisy_scene", "scene_shape"]


def build_noisy_scene(scenario: Union[str, dict, Layout] = SCENE.scenario,
                      models: Union[None, str, Path, Sequence[PlantModel]] = SCENE.models,
                      seed: int = SCENE.seed, points_per_plant: int = SCENE.points_per_plant,
                      plant_spacing: float = SCENE.plant_spacing, row_spacing: float = SCENE.row_spacing,
                      levels: int = SCENE.levels, realizations: int = SCENE.realizations,
                      wind_variance: float = SCENE.wind_variance,
                      wind_direction: float = SCENE.wind_direction) -> tuple[NoisyScene, list[PlantModel]]:
    """Build the scene and its K wind realizations (paper Sec. V-A); the arguments and their
    defaults are :class:`vp_scene.scene_spec.SceneSpec`'s.

    Args:
        scenario: a built-in layout name, a layout file (.yaml, .yml, .json), a layout dict or a
            Layout (:func:`vp_scene.layout.resolve_layout`).
        models: None or '' for procedural corn, a folder of PLY plants, or a list of models.
        (others: see :func:`vp_scene.scenario.make_scene` and :class:`vp_scene.wind.WindConfig`)

    Returns:
        (the noisy scene, the plant models that ``PlacedPlant.model_index`` refers to).

    Raises:
        ValueError (PlantModelError for model files, LayoutError for the layout,
        :class:`vp_scene.limits.SceneTooLargeError` for a scene above its bounds or beyond the
        memory) naming the problem. The cheap checks (the wind parameters, the layout, resolved
        once here, then the scene's size: :func:`vp_scene.limits.check_scene_size`) come before
        any model file is read or any point is allocated.
    """
    config, layout = _checked(scenario, points_per_plant, plant_spacing, row_spacing, levels, realizations,
                              wind_variance, wind_direction)
    scene = make_scene(layout, models=models, seed=seed, points_per_plant=points_per_plant)
    return make_noisy_scene(scene, config, seed), scene.models


#: build_noisy_scene's parameters and their defaults (scene_shape reads a scene dict with them)
_BUILD = inspect.signature(build_noisy_scene)


def _checked(scenario: Any, points_per_plant: Any, plant_spacing: Any, row_spacing: Any, levels: Any,
             realizations: Any, wind_variance: Any, wind_direction: Any) -> tuple[WindConfig, Layout]:
    """The wind and the layout of a scene, its size checked against its bounds and the memory."""
    config = WindConfig(levels=levels, realizations=realizations, variance=wind_variance, direction=wind_direction)
    layout = resolve_layout(scenario, plant_spacing, row_spacing)
    check_scene_size(len(layout.plants), points_per_plant, config.realizations)
    return config, layout


def scene_shape(scene: Mapping[str, Any]) -> tuple[int, int]:
    """(K, P), the shape of the realizations ``build_noisy_scene(**scene)`` would build (K
    realizations of P points), with every check that build makes before it allocates anything
    (the same errors); nothing is built and no model file is read. For a caller that checks what
    else the scene's size multiplies (a plan's cameras) before the scene is built."""
    bound = _BUILD.bind(**scene)
    bound.apply_defaults()
    a = bound.arguments
    config, layout = _checked(a["scenario"], a["points_per_plant"], a["plant_spacing"], a["row_spacing"], a["levels"],
                              a["realizations"], a["wind_variance"], a["wind_direction"])
    return config.realizations, len(layout.plants) * int(a["points_per_plant"])
