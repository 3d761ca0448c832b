"""plan.json, the file a planning run writes and reconstruction and scoring read (one reader).

A plan file is a JSON object with (written by ``python -m vp_planner.cli``)

* ``cameras``: N rows [cx, cy, cz, vx, vy, vz] (:mod:`vp_scene.camera`), or ``poses``: N rows
  [x, y, z, qx, qy, qz, qw] (a flight plan from elsewhere; +x of each pose = optical axis);
* ``scene``: the arguments of :func:`vp_scene.build.build_noisy_scene` that rebuild the scene
  the plan was made for (:data:`vp_scene.scene_spec.SCENE_KEYS`; ``scenario`` required, the
  others default as there). ``scenario`` is a
  built-in layout name or a layout object (:meth:`vp_scene.layout.Layout.to_dict`: the planner
  writes a layout file's content here, so that the plan file is self-contained), checked here
  with the layout parser (errors name ``scene.scenario.<field>``);
* optional ``fov`` and ``theta_match`` (rad), ``image_size`` [W, H], ``fixed_cameras`` (a
  second sortie's cameras already flown, rows [c, v]), ``method``, ``reward``, ``reward_model``
  and anything else the planner recorded.

The planner writes both ``cameras`` and ``poses``; a file with both must give the same cameras
(as many rows, the same centres and optical axes). Every coordinate is within
:data:`vp_scene.camera.MAX_COORDINATE`, ``image_size`` within
:data:`vp_scene.camera.IMAGE_SIDE_RANGE`, and a key given twice in one object is refused
(:func:`vp_scene.layout.parse_json`; JSON would keep the last silently).

:func:`load_plan` validates once, at this boundary, and every error names the file and the
field: every command that reads a plan file (``vp_planner.cli score`` and ``--fixed``,
``vp_recon.cli --plan`` and ``--select``) reads it here, so one file means one thing to all.
ROS-free.
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

from .camera import check_coordinates, check_image_side, poses_to_cameras
from .layout import LayoutError, layout_from_dict, parse_json
from .scene_spec import SCENE_KEYS

__all__ = ["AGREEMENT", "PlanFileError", "PlanFile", "load_plan", "write_plan"]


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
        fixed_cameras: (M, 6) cameras already flown (a second sortie's; M = 0 when absent).
        data: the whole JSON object.
    """

    path: Path
    cameras: NDArray[np.float64]
    scene: Optional[dict]
    fov: float = math.pi / 2
    theta_match: float = math.pi / 4
    image_size: Optional[tuple[int, int]] = None
    fixed_cameras: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 6)))
    data: dict = field(default_factory=dict, repr=False)


def _angle(path: Path, plan: dict, key: str, default: float, hi: float) -> float:
    if key not in plan or plan[key] is None:
        return default
    v = plan[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not 0 < v < hi:
        raise PlanFileError(f"{path}: '{key}' must be a number of radians in (0, {hi:.4g}), got {v!r}")
    return float(v)


def _rows(path: Path, plan: dict, key: str, width: int, allow_empty: bool = False) -> NDArray[np.float64]:
    """``plan[key]`` as an (N, width) array of numbers within MAX_COORDINATE (PlanFileError naming it)."""
    try:
        arr = np.asarray(plan[key], dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise PlanFileError(f"{path}: '{key}' must be a list of rows of {width} numbers") from None
    if arr.size == 0:
        if allow_empty:
            return np.zeros((0, width))
        raise PlanFileError(f"{path}: '{key}' is empty: the plan has no cameras")
    if arr.ndim != 2 or arr.shape[1] != width:
        raise PlanFileError(f"{path}: '{key}' must have shape (N, {width}), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise PlanFileError(f"{path}: '{key}' contains NaN or infinite values")
    try:
        check_coordinates(arr, f"{path}: '{key}'")
    except ValueError as exc:
        raise PlanFileError(str(exc)) from None
    return arr


def _directions(path: Path, key: str, cams: NDArray[np.float64]) -> NDArray[np.float64]:
    bad = np.flatnonzero(np.linalg.norm(cams[:, 3:], axis=1) <= 1e-12)
    if len(bad):
        raise PlanFileError(f"{path}: '{key}' row(s) {bad.tolist()} have a zero viewing direction")
    return cams


#: How far a file's ``cameras`` and ``poses`` may differ and still be one plan: m between centres,
#: and between unit optical axes (the planner writes the poses of its cameras; repr round-trips).
AGREEMENT = 1e-6


def _cameras(path: Path, plan: dict) -> NDArray[np.float64]:
    if "cameras" not in plan and "poses" not in plan:
        raise PlanFileError(f"{path} has no 'cameras' (or 'poses')")
    cams = _directions(path, "cameras", _rows(path, plan, "cameras", 6)) if "cameras" in plan else None
    if "poses" not in plan:
        return cams
    rows = _rows(path, plan, "poses", 7)
    try:
        from_poses = poses_to_cameras(rows)
    except ValueError as exc:
        raise PlanFileError(f"{path}: 'poses': {exc}") from None
    if cams is None:
        return from_poses
    if len(cams) != len(from_poses):
        raise PlanFileError(f"{path}: 'cameras' ({len(cams)} rows) and 'poses' ({len(from_poses)} rows) disagree: "
                            "one plan has one camera a pose")
    axes = cams[:, 3:] / np.linalg.norm(cams[:, 3:], axis=1, keepdims=True)
    off = np.maximum(np.abs(cams[:, :3] - from_poses[:, :3]).max(axis=1), np.abs(axes - from_poses[:, 3:]).max(axis=1))
    if np.any(off > AGREEMENT):
        i = int(np.argmax(off))
        raise PlanFileError(f"{path}: 'cameras' row {i} and 'poses' row {i} are not the same camera (centre or "
                            f"optical axis {off[i]:.3g} apart)")
    return cams


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
        plan = parse_json(p.read_text(encoding="utf-8-sig"), str(p))
    except (OSError, UnicodeDecodeError) as exc:
        raise PlanFileError(f"cannot read {p}: {exc}") from None
    except LayoutError as exc:
        raise PlanFileError(str(exc)) from None
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
        if not isinstance(size, (list, tuple)) or len(size) != 2 or not all(isinstance(x, int) for x in size):
            raise PlanFileError(f"{p}: 'image_size' must be [width, height] in pixels, got {size!r}")
        try:
            size = (check_image_side("'image_size' width", size[0]), check_image_side("'image_size' height", size[1]))
        except ValueError as exc:
            raise PlanFileError(f"{p}: {exc}") from None
    fixed = _directions(p, "fixed_cameras", _rows(p, plan, "fixed_cameras", 6, allow_empty=True)) \
        if plan.get("fixed_cameras") is not None else np.zeros((0, 6))
    return PlanFile(path=p, cameras=cams, scene=scene, fov=fov, theta_match=theta, image_size=size,
                    fixed_cameras=fixed, data=plan)


def write_plan(path: PathLike, data: dict) -> Path:
    """Write ``data`` as JSON, whole or not at all (:func:`vp_scene.folders.write_atomic`:
    OutputError naming the file)."""
    from .folders import write_atomic

    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(data, indent=1)
    return write_atomic(p, lambda tmp: tmp.write_text(text))
