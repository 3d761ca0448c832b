"""ROS 2 node ``scene``: builds a noisy corn scene (paper Sec. V-A) and publishes it latched.

Topics (reliable, TRANSIENT_LOCAL, depth 1):
  /scene/points        sensor_msgs/PointCloud2  x, y, z, rgb              noise-free scene
  /scene/noisy_points  sensor_msgs/PointCloud2  x, y, z, rgb, realization all K wind realizations
  /scene/description   vp_interfaces/SceneDescription                     how it was built

The parameter ``scenario`` is a built-in layout name or a layout file (:mod:`vp_scene.layout`);
/scene/description carries it as given and, in ``plants``, every plant's model, yaw, scale and
position, from which another node rebuilds the identical scene without the file.

A bad configuration at start logs the problem in one line and exits with status 2 before
publishing anything; a bad parameter change at run time is refused with the reason, keeping the
old scene. A scene above its bounds or beyond the memory (:mod:`vp_scene.limits`: realizations,
points per plant, their product with the plants) is such a configuration, refused before any of
it is allocated. A valid change is validated by building the new scene (in the set-parameters
callback) and published once the parameters are set (in the post-set callback). Signals, exit
codes and parameter types follow :mod:`vp_scene.node_runtime`.
"""
from __future__ import annotations

import sys
from dataclasses import fields
from pathlib import Path
from typing import Any, Optional

import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import PointCloud2
from vp_interfaces.msg import SceneDescription

from .build import build_noisy_scene
from .cloud import numpy_to_pointcloud2
from .limits import check_seed
from .messages import scene_description_msg
from .node_runtime import INT_MAX, LATCHED, Param, declare_typed, run_node, typed_values
from .scene_spec import SCENE_KEYS, SceneSpec
from .wind import NoisyScene


def _scene_param(f: Any) -> Param:
    """The parameter of a scene's argument (a field of :class:`vp_scene.scene_spec.SceneSpec`):
    its default, help, range (no upper end: INT_MAX) and what the range cannot say."""
    m = f.metadata
    rng = None
    if m["range"] is not None:
        lo, hi = m["range"]
        rng = (lo, INT_MAX if hi is None else hi)
    return Param(f.default, m["help"], rng, False, m["limits"])


#: The node's parameters: the arguments of a scene (:class:`vp_scene.scene_spec.SceneSpec`, the
#: ranges the scene enforces), its models as ``models_folder`` ('' for procedural corn), and the
#: frame. Every parameter is read again on a change (the scene is rebuilt), none is read_only.
SPECS = {
    **{f.name: _scene_param(f) for f in fields(SceneSpec) if f.name != "models"},
    "models_folder": Param("", "folder of PLY plant models; empty: built-in procedural corn"),
    "frame_id": Param("map", "frame of the published clouds", None, False, "not empty"),
}
DEFAULTS: dict[str, Any] = {name: spec.default for name, spec in SPECS.items()}


def check_params(values: dict[str, Any]) -> dict[str, Any]:
    """Type-check and normalize the node's parameter values (ints as int, numbers as float)."""
    out = {**dict(values), **typed_values(SPECS, values)}
    check_seed("parameter 'seed'", out["seed"])
    if not out["frame_id"]:
        raise ValueError("parameter 'frame_id' must not be empty")
    if out["models_folder"]:
        out["models_folder"] = str(Path(out["models_folder"]).expanduser().resolve())
    return out


def build_from_params(values: dict[str, Any]) -> NoisyScene:
    """Build the noisy scene that the parameter values describe (ValueError naming the problem)."""
    p = check_params(values)
    noisy, _models = build_noisy_scene(**{k: p[k] for k in SCENE_KEYS if k != "models"},
                                       models=p["models_folder"] or None)
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
        self._values = declare_typed(self, SPECS, check_params)
        self._noisy = build_from_params(self._values)          # raises before anything is published
        self._candidate: Optional[tuple[dict, NoisyScene]] = None  # validated, not yet set
        self._pub_points = self.create_publisher(PointCloud2, "/scene/points", LATCHED)
        self._pub_noisy = self.create_publisher(PointCloud2, "/scene/noisy_points", LATCHED)
        self._pub_desc = self.create_publisher(SceneDescription, "/scene/description", LATCHED)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._after_set_parameters)
        self.publish()

    @property
    def noisy_scene(self) -> NoisyScene:
        return self._noisy

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        """Validate a change by building the new scene first; refuse it (old scene kept) when
        invalid. No side effect: the scene is adopted and published by the post-set callback."""
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
        self._candidate = (values, noisy)
        return SetParametersResult(successful=True)

    def _after_set_parameters(self, params: list[Parameter]) -> None:
        """The parameters are set: adopt the scene validated for them and publish it."""
        if not any(p.name in DEFAULTS for p in params):
            return
        values = check_params({n: self.get_parameter(n).value for n in DEFAULTS})
        if self._candidate is not None and self._candidate[0] == values:
            noisy = self._candidate[1]
        else:  # not validated through _on_set_parameters (cannot happen with rclpy): build it now
            noisy = build_from_params(values)
        self._candidate = None
        self._values, self._noisy = values, noisy
        self.publish()

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
        desc = scene_description_msg(noisy, v, frame, stamp)
        self._pub_desc.publish(desc)
        self.get_logger().info(summary(noisy))


def main(args: Optional[list[str]] = None) -> int:
    """Entry point ``scene``: exit 2 (nothing published) when the scene cannot be built, 0 after
    SIGINT/SIGTERM (see :mod:`vp_scene.node_runtime`)."""
    return run_node("scene", SceneNode, args, error_prefix="cannot build the scene")


if __name__ == "__main__":
    sys.exit(main())
