"""From a plan to a fleet: the fleet's frame, the goals' orientation and the plan's check (ROS-free).

The dispatcher node (:mod:`vp_planner.dispatcher_node`) is a thin adapter around this module and
:mod:`vp_planner.routes` (which drone flies to which poses, in which order and when).

Frames
------
Plans are in ``map``; drones report and take goals in the fleet's frame. The fleet frame is
given by a fixed transform from ``map`` (tf2 is not available from PyPI), as tf2's
``static_transform_publisher --x X --y Y --z Z --yaw YAW --frame-id map --child-frame-id fleet``
would publish it: the fleet frame's origin at (X, Y, Z) in ``map``, its axes turned by YAW about
``map``'s z axis. A point p_f in the fleet frame is p_m = R_z(YAW) p_f + (X, Y, Z) in ``map``;
plan poses go the other way (:meth:`FleetTransform.poses_to_fleet`).

Goal orientation: ``body`` keeps the plan's convention (the pose's +x axis is the optical axis,
:mod:`vp_scene.camera`); ``optical`` gives the REP-103 camera optical frame (z forward, x right,
y down, :func:`vp_scene.camera.optical_orientation`), as camera gimbal interfaces expect.

Feasibility
-----------
A plan is dispatched only if it satisfies the planner's rules (stand-off from every scene point,
altitude above the ground, separation between cameras). The rules have one home,
:class:`vp_planner.feasibility.FeasibilityRules` (torch-free; :class:`vp_planner.space.ViewSpace`
uses it too); :func:`plan_problems` asks it and, for a refused plan, explains which cameras break
what.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from vp_scene.camera import check_cameras, express_poses, optical_orientation

from .feasibility import Feasibility, FeasibilityRules

__all__ = [
    "ORIENTATIONS",
    "FleetTransform",
    "goal_orientations",
    "plan_problems",
]

#: Goal orientations: the plan's body convention (+x = optical axis) or the REP-103 optical frame.
ORIENTATIONS: tuple[str, ...] = ("body", "optical")


@dataclass(frozen=True)
class FleetTransform:
    """The fixed transform from ``map`` to the fleet's frame: the fleet frame's origin (x, y, z)
    in ``map`` and its yaw about ``map``'s z axis (rad). p_map = R_z(yaw) p_fleet + (x, y, z)."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    yaw: float = 0.0

    def __post_init__(self) -> None:
        for name in ("x", "y", "z", "yaw"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"the map -> fleet transform's {name} must be finite, got {getattr(self, name)}")

    @property
    def is_identity(self) -> bool:
        return self.x == 0.0 and self.y == 0.0 and self.z == 0.0 and math.remainder(self.yaw, 2 * math.pi) == 0.0

    def _rotation(self) -> Rotation:
        return Rotation.from_euler("z", self.yaw)

    def points_to_fleet(self, points_map: ArrayLike) -> NDArray[np.float64]:
        """Points (..., 3) in ``map`` -> the fleet frame: R^T (p - t)."""
        p = np.asarray(points_map, dtype=np.float64)
        return (p - np.array([self.x, self.y, self.z])) @ self._rotation().as_matrix()

    def points_to_map(self, points_fleet: ArrayLike) -> NDArray[np.float64]:
        """Points (..., 3) in the fleet frame -> ``map``: R p + t."""
        p = np.asarray(points_fleet, dtype=np.float64)
        return p @ self._rotation().as_matrix().T + np.array([self.x, self.y, self.z])

    def poses_to_fleet(self, poses_map: ArrayLike) -> NDArray[np.float64]:
        """Poses (N, 7) = (x, y, z, qx, qy, qz, qw) in ``map`` -> the fleet frame (qw >= 0)
        (:func:`vp_scene.camera.express_poses`)."""
        return express_poses(poses_map, self._rotation(), [self.x, self.y, self.z])


def goal_orientations(quaternions: ArrayLike, orientation: str = "body") -> NDArray[np.float64]:
    """Goal quaternions (N, 4) for plan quaternions (N, 4) in the body convention (+x = optical
    axis): unchanged for ``body``, the REP-103 optical frame for ``optical``."""
    q = np.asarray(quaternions, dtype=np.float64).reshape(-1, 4)
    if orientation == "body":
        return q.copy()
    if orientation == "optical":
        return optical_orientation(q) if len(q) else q.copy()
    raise ValueError(f"unknown orientation {orientation!r}; one of {', '.join(ORIENTATIONS)}")


def plan_problems(cameras: ArrayLike, realizations: Optional[ArrayLike], min_standoff: float = Feasibility.min_standoff,
                  min_altitude: float = Feasibility.min_altitude,
                  min_separation: float = Feasibility.min_separation) -> list[str]:
    """Why the plan breaks the planner's feasibility rules ([] when it does not).

    ``cameras`` (N, 6) = [c, v] in the scene's frame; ``realizations`` (K, P, 3) the scene's wind
    realizations, or None when no scene is known: then the stand-off rule cannot be checked and
    is left out (the caller decides whether that is acceptable). The verdict is
    :class:`vp_planner.feasibility.FeasibilityRules` (the rules' one home, torch-free; a
    one-camera plan is checked as that camera twice, with no separation rule); the returned
    sentences only explain a refusal: the cameras below ``min_altitude``, nearer than
    ``min_standoff`` to a scene point, and the pairs nearer than ``min_separation`` to each other.
    """
    cams = check_cameras(cameras)
    n = len(cams)
    plan, separation = (cams, min_separation) if n >= 2 else (np.concatenate([cams, cams]), 0.0)
    # without a scene the stand-off rule is off
    standoff = min_standoff if realizations is not None else 0.0
    rules = FeasibilityRules(realizations, len(plan), min_standoff=standoff, min_altitude=min_altitude,
                             min_separation=separation)
    if rules(plan[None])[0]:
        return []
    problems = []
    c = cams[:, :3]
    for i in np.flatnonzero(c[:, 2] < min_altitude - 1e-9):
        problems.append(f"camera {i} at {_fmt(c[i])} is {c[i, 2]:.3f} m above the ground "
                        f"(min_altitude {min_altitude:g} m)")
    if standoff > 0:
        near, _ = rules.tree.query(c, k=1)
        for i in np.flatnonzero(near < standoff - 1e-9):
            problems.append(f"camera {i} at {_fmt(c[i])} is {near[i]:.3f} m from the nearest scene point "
                            f"(min_standoff {standoff:g} m)")
    if separation > 0:
        d = np.linalg.norm(c[:, None] - c[None], axis=-1)
        for i, j in zip(*np.triu_indices(n, 1)):
            if d[i, j] < separation - 1e-9:
                problems.append(f"cameras {i} and {j} are {d[i, j]:.3f} m apart (min_separation {separation:g} m)")
    return problems or ["the plan breaks the planner's feasibility rules (vp_planner.feasibility)"]


def _fmt(p: Sequence[float]) -> str:
    return "(" + ", ".join(f"{float(x):+.2f}" for x in p) + ")"
