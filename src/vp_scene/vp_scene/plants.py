"""Plant models: what a plant is to the suite (a coloured point cloud, optionally a mesh, in the
Corn50 model frame). Where they come from lives beside it: :mod:`vp_scene.ply` (Corn50 PLY files,
checked) and :mod:`vp_scene.procedural` (the built-in procedural corn).

Paper Sec. V-A builds its scenes from "real-world corn-plant reconstructions" (the Corn50 data
set, Nelson & Papanikolopoulos, IROS 2020). A model is a coloured point cloud in the Corn50
model frame: the stalk runs through the origin along +z, the centroid is at z = 0, and a plant
is about 2 units (= metres) tall, z roughly in [-1, 1]. :func:`vp_scene.procedural.procedural_corn`
builds a plant in the same frame (with a coloured triangle mesh) so that the suite runs without
any data.

ROS-free: numpy and trimesh only.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional, Union

import numpy as np
import trimesh

__all__ = ["PlantModelError", "PlantModel", "PathLike"]

PathLike = Union[str, Path]


class PlantModelError(ValueError):
    """A plant model cannot be loaded or is unusable; the message names the file and the problem."""


@dataclass
class PlantModel:
    """A coloured plant model in the Corn50 model frame (stalk along +z through the origin).

    Attributes:
        name: model name (PLY file stem, or ``procedural-<seed>``).
        points: (P, 3) float64 surface points.
        colors: (P, 3) uint8 RGB colours of the points.
        mesh: optional coloured triangle mesh (vertex colours) of the same plant, same frame.
    """

    name: str
    points: np.ndarray
    colors: np.ndarray
    mesh: Optional[trimesh.Trimesh] = field(default=None, repr=False)

    def __post_init__(self) -> None:
        self.points = np.ascontiguousarray(self.points, dtype=np.float64)
        self.colors = np.ascontiguousarray(self.colors)
        if self.points.ndim != 2 or self.points.shape[1] != 3:
            raise PlantModelError(f"{self.name}: points must have shape (P, 3), got {self.points.shape}")
        if self.points.shape[0] == 0:
            raise PlantModelError(f"{self.name}: the point cloud is empty")
        if self.colors.shape != self.points.shape:
            raise PlantModelError(
                f"{self.name}: colors must have shape {self.points.shape}, got {self.colors.shape}")
        if self.colors.dtype != np.uint8:
            raise PlantModelError(f"{self.name}: colors must be uint8, got {self.colors.dtype}")
        if not np.all(np.isfinite(self.points)):
            raise PlantModelError(f"{self.name}: the point cloud contains NaN or infinite coordinates")

    @property
    def z_min(self) -> float:
        """Lowest model-frame height of the plant (points and mesh vertices)."""
        return self._z_range()[0]

    @property
    def z_max(self) -> float:
        """Highest model-frame height of the plant (points and mesh vertices)."""
        return self._z_range()[1]

    def _z_range(self) -> tuple[float, float]:
        z = self.points[:, 2]
        if self.mesh is not None and len(self.mesh.vertices):
            z = np.concatenate([z, np.asarray(self.mesh.vertices)[:, 2]])
        return float(z.min()), float(z.max())
