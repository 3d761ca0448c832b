"""The arguments that build a scene and their defaults, in one place: :class:`SceneSpec`.

A scene is built from a layout (a built-in name or a layout file, with the spacings of the
built-in grids), the plant models, a seed, the points sampled per plant and the wind model
(:func:`vp_scene.build.build_noisy_scene`, whose keyword arguments these are). A plan file's
``scene`` holds them (:data:`SCENE_KEYS`), the scene node takes them as parameters, the
command lines as flags; each of them, and the layout, the scenario and the wind model below
them, reads its defaults here (:data:`SCENE`). Each field's metadata gives its help and, for a
number, its inclusive range (``range``; an upper end of None: none) and what the range cannot
say (``limits``); the scene's checks live where the values are used (:class:`vp_scene.wind.WindConfig`,
:func:`vp_scene.layout.resolve_layout`, :func:`vp_scene.limits.check_scene_size`). ROS-free,
standard library only.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any, Optional

from .limits import MAX_POINTS_PER_PLANT, MAX_REALIZATIONS, MAX_SEED

__all__ = ["SceneSpec", "SCENE", "SCENE_KEYS"]


def _arg(default: Any, help: str, range: Optional[tuple] = None, limits: str = "") -> Any:
    return field(default=default, metadata={"help": help, "range": range, "limits": limits})


@dataclass(frozen=True)
class SceneSpec:
    """The keyword arguments of :func:`vp_scene.build.build_noisy_scene` (module docstring)."""

    scenario: Any = _arg("one_plant", "one_plant | three_row | six_rect | grid_3x3 | row_12, or a layout file "
                                      "(.yaml, .yml, .json)")
    models: Optional[str] = _arg(None, "folder of PLY plant models (None: built-in procedural corn)")
    seed: int = _arg(0, "seed of the layout (yaw, scale, model choice) and of the wind draws", (0, MAX_SEED))
    points_per_plant: int = _arg(4000, "points sampled per plant", (1, MAX_POINTS_PER_PLANT))
    plant_spacing: float = _arg(0.6, "m between plants in a row", (0.0, math.inf), "> 0")
    row_spacing: float = _arg(0.76, "m between rows", (0.0, math.inf), "> 0")
    levels: int = _arg(10, "L, height levels of the wind model", (1, None))
    realizations: int = _arg(5, "K, wind realizations", (1, MAX_REALIZATIONS))
    wind_variance: float = _arg(0.002, "variance of n_wind ~ N(0, variance)", (0.0, math.inf))
    wind_direction: float = _arg(0.0, "wind direction, rad from +x")

    def as_dict(self) -> dict:
        """The arguments by name (a plan file's ``scene``, ``build_noisy_scene(**spec.as_dict())``)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


#: The defaults of a scene.
SCENE = SceneSpec()
#: The arguments of a scene, in order (the keys of a plan file's ``scene``).
SCENE_KEYS: tuple[str, ...] = tuple(f.name for f in fields(SceneSpec))
