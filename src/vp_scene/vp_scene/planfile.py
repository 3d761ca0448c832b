"""plan.json, the file a planning run writes and reconstruction and scoring read (one reader).

A plan file is a JSON object with (written by ``python -m vp_planner.cli``)

* ``cameras``: N rows [cx, cy, cz, vx, vy, vz] (:mod:`vp_scene.camera`), or ``poses``: N rows
  [x, y, z, qx, qy, qz, qw] (a flight plan from elsewhere; +x of each pose = optical axis);
* ``scene``: the arguments of :func:`vp_scene.build.build_noisy_scene` that rebuild the scene
  the plan was made for (``scenario`` required; the others default as there). ``scenario`` is a
  built-in layout name or a layout object (:meth:`vp_scene.layout.Layout.to_dict`: the planner
  writes a layout file's content here, so that the plan file is self-contained), checked here
  with the layout parser (errors name ``scene.scenario.<field>``);
* optional ``fov`` and ``theta_match`` (rad), ``image_size`` [W, H], ``method``, ``reward``,
  ``reward_model`` and anything else the planner recorded.

:func:`load_plan` validates once, at this boundary, and every error names the file and the
field. ROS-free.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional, Union

import numpy as np
from numpy.typing import NDArray

from .camera import poses_to_cameras
from .layout import LayoutError, layout_from_dict

__all__ = ["SCENE_KEYS", "PlanFileError", "PlanFile", "load_plan", "write_plan"]

#: Keys of the ``scene`` object (the keyword arguments of build_noisy_scene).
SCENE_KEYS = ("scenario", "models", "seed", "points_per_plant", "plant_spacing", "row_spacing", "levels",
              "realizations", "wind_variance", "wind_direction")

PathLike = Union[str, os.PathLike]


class PlanFileError(ValueError):
    """The plan file is missing, unreadable or malformed; the message names the file and field."""


@dataclass
class PlanFile:
    """A validated plan file.

    Attributes:
        path: where it was read from.
        cameras: (N, 6) float64 cameras, N >= 1, finite, non-zero viewing directions.
        scene: keyword arguments of build_noisy_scene (None when the file has no ``scene``).
        fov, theta_match: rad (defaults pi/2 and pi/4 when absent).
        image_size: (W, H) pixels, or None when absent.
        data: the whole JSON object.
    """

    path: Path
    cameras: NDArray[np.float64]
    scene: Optional[dict]
    fov: float = math.pi / 2
    theta_match: float = math.pi / 4
    image_size: Optional[tuple[int, int]] = None
    data: dict = field(default_factory=dict, repr=False)


def _angle(path: Path, plan: dict, key: str, default: float, hi: float) -> float:
    if key not in plan or plan[key] is None:
        return default
    v = plan[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not 0 < v < hi:
        raise PlanFileError(f"{path}: '{key}' must be a number of radians in (0, {hi:.4g}), got {v!r}")
    return float(v)


def _cameras(path: Path, plan: dict) -> NDArray[np.float64]:
    key = "cameras" if "cameras" in plan else "poses" if "poses" in plan else None
    if key is None:
        raise PlanFileError(f"{path} has no 'cameras' (or 'poses')")
    width = 6 if key == "cameras" else 7
    try:
        arr = np.asarray(plan[key], dtype=np.float64)
    except (TypeError, ValueError):
        raise PlanFileError(f"{path}: '{key}' must be a list of rows of {width} numbers") from None
    if arr.size == 0:
        raise PlanFileError(f"{path}: '{key}' is empty: the plan has no cameras")
    if arr.ndim != 2 or arr.shape[1] != width:
        raise PlanFileError(f"{path}: '{key}' must have shape (N, {width}), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise PlanFileError(f"{path}: '{key}' contains NaN or infinite values")
    if key == "poses":
        try:
            return poses_to_cameras(arr)
        except ValueError as exc:
            raise PlanFileError(f"{path}: 'poses': {exc}") from None
    bad = np.flatnonzero(np.linalg.norm(arr[:, 3:], axis=1) <= 1e-12)
    if len(bad):
        raise PlanFileError(f"{path}: 'cameras' row(s) {bad.tolist()} have a zero viewing direction")
    return arr


def _scene(path: Path, plan: dict) -> Optional[dict]:
    scene = plan.get("scene")
    if scene is None:
        return None
    if not isinstance(scene, dict) or not isinstance(scene.get("scenario"), (str, dict)):
        raise PlanFileError(f"{path}: 'scene' must be an object with a 'scenario' (a layout name, "
                            f"a layout file or a layout object)")
    unknown = sorted(set(scene) - set(SCENE_KEYS))
    if unknown:
        raise PlanFileError(f"{path}: unknown 'scene' keys {unknown}; expected some of {list(SCENE_KEYS)}")
    if isinstance(scene["scenario"], dict):
        try:
            layout_from_dict(scene["scenario"], str(path), field_prefix="scene.scenario.")
        except LayoutError as exc:
            raise PlanFileError(str(exc)) from None
    return dict(scene)


def load_plan(path: PathLike, require_scene: bool = True) -> PlanFile:
    """Read and validate a plan file; :class:`PlanFileError` naming the file and the field."""
    p = Path(path)
    if not p.is_file():
        raise PlanFileError(f"plan file not found: {p}")
    try:
        plan = json.loads(p.read_text())
    except (OSError, UnicodeDecodeError) as exc:
        raise PlanFileError(f"cannot read {p}: {exc}") from None
    except json.JSONDecodeError as exc:
        raise PlanFileError(f"{p} is not valid JSON ({exc.msg} at line {exc.lineno})") from None
    if not isinstance(plan, dict):
        raise PlanFileError(f"{p} must hold a JSON object, got {type(plan).__name__}")
    scene = _scene(p, plan)
    if require_scene and scene is None:
        raise PlanFileError(f"{p} has no 'scene' object with a 'scenario' (written by an older planner?)")
    cams = _cameras(p, plan)
    fov = _angle(p, plan, "fov", math.pi / 2, math.pi)
    theta = _angle(p, plan, "theta_match", math.pi / 4, math.pi + 1e-12)
    size = plan.get("image_size")
    if size is not None:
        if (not isinstance(size, (list, tuple)) or len(size) != 2
                or not all(isinstance(x, int) and not isinstance(x, bool) and x >= 16 for x in size)):
            raise PlanFileError(f"{p}: 'image_size' must be [width, height] in pixels (>= 16), got {size!r}")
        size = (int(size[0]), int(size[1]))
    return PlanFile(path=p, cameras=cams, scene=scene, fov=fov, theta_match=theta, image_size=size, data=plan)


def write_plan(path: PathLike, data: dict) -> Path:
    """Write ``data`` as JSON, whole or not at all (:func:`vp_scene.folders.write_atomic`:
    OutputError naming the file)."""
    from .folders import write_atomic

    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(data, indent=1)
    return write_atomic(p, lambda tmp: tmp.write_text(text))
