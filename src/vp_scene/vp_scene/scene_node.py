"""ROS 2 node ``scene``: builds a noisy corn scene (paper Sec. V-A) and publishes it latched.

Topics (reliable, TRANSIENT_LOCAL, depth 1):
  /scene/points        sensor_msgs/PointCloud2  x, y, z, rgb              noise-free scene
  /scene/noisy_points  sensor_msgs/PointCloud2  x, y, z, rgb, realization all K wind realizations
  /scene/description   vp_interfaces/SceneDescription                     how it was built

A bad configuration at start logs the problem and exits with status 1 before publishing
anything; a bad parameter change at run time is refused with the reason, keeping the old scene.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any, Optional

import numpy as np
import rclpy
from geometry_msgs.msg import Point
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2
from vp_interfaces.msg import PlantPlacement, SceneDescription

from .build import build_noisy_scene
from .cloud import numpy_to_pointcloud2
from .wind import NoisyScene

LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)

DEFAULTS: dict[str, Any] = {
    "scenario": "one_plant",
    "models_folder": "",
    "seed": 0,
    "levels": 10,
    "realizations": 5,
    "wind_variance": 0.002,
    "wind_direction": 0.0,
    "points_per_plant": 4000,
    "plant_spacing": 0.6,
    "row_spacing": 0.76,
    "frame_id": "map",
}
_DESCRIPTIONS = {
    "scenario": "one_plant | three_row | six_rect",
    "models_folder": "folder of PLY plant models; empty: built-in procedural corn",
    "seed": "seed of the layout (yaw, scale, model choice) and of the wind draws",
    "levels": "L, height levels of the wind model",
    "realizations": "K, wind realizations",
    "wind_variance": "variance of n_wind ~ N(0, variance)",
    "wind_direction": "wind direction, rad from +x",
    "points_per_plant": "points sampled per plant",
    "plant_spacing": "m between plants in a row",
    "row_spacing": "m between rows",
    "frame_id": "frame of the published clouds",
}
_INTS = ("seed", "levels", "realizations", "points_per_plant")
_FLOATS = ("wind_variance", "wind_direction", "plant_spacing", "row_spacing")
_STRINGS = ("scenario", "models_folder", "frame_id")


def check_params(values: dict[str, Any]) -> dict[str, Any]:
    """Type-check and normalize the node's parameter values (ints as int, numbers as float)."""
    out = dict(values)
    for k in _INTS:
        v = out[k]
        if isinstance(v, bool) or not isinstance(v, int):
            raise ValueError(f"parameter '{k}' must be an integer, got {v!r}")
    for k in _FLOATS:
        v = out[k]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ValueError(f"parameter '{k}' must be a finite number, got {v!r}")
        out[k] = float(v)
    for k in _STRINGS:
        if not isinstance(out[k], str):
            raise ValueError(f"parameter '{k}' must be a string, got {out[k]!r}")
    if out["seed"] < 0:
        raise ValueError(f"parameter 'seed' must be >= 0, got {out['seed']}")
    if not out["frame_id"]:
        raise ValueError("parameter 'frame_id' must not be empty")
    if out["models_folder"]:
        out["models_folder"] = str(Path(out["models_folder"]).expanduser().resolve())
    return out


def build_from_params(values: dict[str, Any]) -> NoisyScene:
    """Build the noisy scene that the parameter values describe (ValueError naming the problem)."""
    p = check_params(values)
    noisy, _models = build_noisy_scene(
        scenario=p["scenario"], models=p["models_folder"] or None, seed=p["seed"],
        points_per_plant=p["points_per_plant"], plant_spacing=p["plant_spacing"],
        row_spacing=p["row_spacing"], levels=p["levels"], realizations=p["realizations"],
        wind_variance=p["wind_variance"], wind_direction=p["wind_direction"])
    return noisy


def summary(noisy: NoisyScene) -> str:
    """One line: plants, points, K, L, n_wind values."""
    s, c = noisy.scene, noisy.config
    names = ",".join(p.model_name for p in s.plants)
    winds = ", ".join(f"{w:+.4f}" for w in noisy.n_wind)
    return (f"scene '{s.scenario}': {len(s.plants)} plants ({names}), {len(s.points)} points, "
            f"K={c.realizations}, L={c.levels}, n_wind=[{winds}]")


class SceneNode(Node):
    """The ``scene`` node. Raises ValueError from the constructor when the scene cannot be built."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__("scene", **kwargs)
        for name, default in DEFAULTS.items():
            self.declare_parameter(name, default, ParameterDescriptor(
                description=_DESCRIPTIONS[name], dynamic_typing=True))
        self._values = check_params({n: self.get_parameter(n).value for n in DEFAULTS})
        self._noisy = build_from_params(self._values)          # raises before anything is published
        self._pub_points = self.create_publisher(PointCloud2, "/scene/points", LATCHED)
        self._pub_noisy = self.create_publisher(PointCloud2, "/scene/noisy_points", LATCHED)
        self._pub_desc = self.create_publisher(SceneDescription, "/scene/description", LATCHED)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.publish()

    @property
    def noisy_scene(self) -> NoisyScene:
        return self._noisy

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        """Validate a change by building the new scene first; refuse it (old scene kept) when invalid."""
        values = dict(self._values)
        for prm in params:
            if prm.name not in DEFAULTS:
                continue
            if prm.type_ == Parameter.Type.NOT_SET:
                return SetParametersResult(successful=False, reason=f"parameter '{prm.name}' cannot be unset")
            values[prm.name] = prm.value
        try:
            values = check_params(values)
            noisy = build_from_params(values)
        except (ValueError, OSError) as exc:
            reason = f"refused: {exc}"
            self.get_logger().warning(f"parameter change {[p.name for p in params]} {reason}; keeping the old scene")
            return SetParametersResult(successful=False, reason=reason)
        self._values, self._noisy = values, noisy
        self.publish()
        return SetParametersResult(successful=True)

    def publish(self) -> None:
        """Publish the three latched topics for the current scene."""
        noisy, v = self._noisy, self._values
        scene = noisy.scene
        stamp = self.get_clock().now().to_msg()
        frame = v["frame_id"]
        k, p = noisy.points.shape[0], noisy.points.shape[1]
        self._pub_points.publish(numpy_to_pointcloud2(scene.points, scene.colors, frame_id=frame, stamp=stamp))
        self._pub_noisy.publish(numpy_to_pointcloud2(
            noisy.points.reshape(-1, 3), np.tile(scene.colors, (k, 1)),
            realization=np.repeat(np.arange(k, dtype=np.uint16), p), frame_id=frame, stamp=stamp))
        desc = SceneDescription()
        desc.header.stamp, desc.header.frame_id = stamp, frame
        desc.scenario = scene.scenario
        desc.models_folder = v["models_folder"]
        desc.seed = v["seed"]
        desc.points_per_plant = v["points_per_plant"]
        desc.plant_spacing, desc.row_spacing = v["plant_spacing"], v["row_spacing"]
        desc.levels, desc.realizations = noisy.config.levels, noisy.config.realizations
        desc.wind_variance, desc.wind_direction = noisy.config.variance, noisy.config.direction
        desc.n_wind = [float(w) for w in noisy.n_wind]
        desc.plants = [PlantPlacement(model=pl.model_name, yaw=float(pl.yaw), scale=float(pl.scale),
                                      position=Point(x=float(pl.position[0]), y=float(pl.position[1]),
                                                     z=float(pl.position[2])))
                       for pl in scene.plants]
        self._pub_desc.publish(desc)
        self.get_logger().info(summary(noisy))


def main(args: Optional[list[str]] = None) -> int:
    """Entry point ``scene``: returns 1 (nothing published) when the scene cannot be built."""
    rclpy.init(args=args)
    node: Optional[SceneNode] = None
    rc = 0
    try:
        try:
            node = SceneNode()
        except (ValueError, OSError) as exc:
            rclpy.logging.get_logger("scene").error(f"cannot build the scene: {exc}")
            rc = 1
        else:
            rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return rc


if __name__ == "__main__":
    sys.exit(main())
