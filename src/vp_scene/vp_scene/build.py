"""One call from parameters to a noisy scene (used by the scene node, CLIs and benchmarks). ROS-free."""
from __future__ import annotations

from pathlib import Path
from typing import Sequence, Union

from .layout import Layout
from .plants import PlantModel
from .scenario import make_scene
from .wind import NoisyScene, WindConfig, make_noisy_scene

__all__ = ["build_noisy_scene"]


def build_noisy_scene(scenario: Union[str, dict, Layout] = "one_plant",
                      models: Union[None, str, Path, Sequence[PlantModel]] = None,
                      seed: int = 0, points_per_plant: int = 4000, plant_spacing: float = 0.6,
                      row_spacing: float = 0.76, levels: int = 10, realizations: int = 5,
                      wind_variance: float = 0.002,
                      wind_direction: float = 0.0) -> tuple[NoisyScene, list[PlantModel]]:
    """Build the scene and its K wind realizations (paper Sec. V-A).

    Args:
        scenario: a built-in layout name, a layout file (.yaml, .yml, .json), a layout dict or a
            Layout (:func:`vp_scene.layout.resolve_layout`).
        models: None or '' for procedural corn, a folder of PLY plants, or a list of models.
        (others: see :func:`vp_scene.scenario.make_scene` and :class:`vp_scene.wind.WindConfig`)

    Returns:
        (the noisy scene, the plant models that ``PlacedPlant.model_index`` refers to).

    Raises:
        ValueError (PlantModelError for model files, LayoutError for the layout) naming the
        problem. Cheap checks (the wind parameters, then the layout, resolved once, in
        :func:`vp_scene.scenario.make_scene`) come before loading any model file.
    """
    config = WindConfig(levels=levels, realizations=realizations, variance=wind_variance,
                        direction=wind_direction)
    scene = make_scene(scenario, models=models, seed=seed, points_per_plant=points_per_plant,
                       plant_spacing=plant_spacing, row_spacing=row_spacing)
    return make_noisy_scene(scene, config, seed), scene.models
