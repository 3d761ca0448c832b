"""The ``viewer`` node: the run in the browser while it happens (:mod:`vp_recon.viewer`, viser on
127.0.0.1 only, opened by the URL with a token it logs).

Subscribes (reliable, transient local: what was published before it started still arrives)
``/scene/noisy_points``, ``/camera_plan``, ``/fleet/assignment``, ``/reconstruction/points``, and
every drone's ``/<drone>/pose`` (geometry_msgs/PoseStamped or nav_msgs/Odometry, found in the
graph every second); each message goes through :func:`vp_recon.viewer.show_message`, the same
path the offline replay of a ``run.mcap`` takes. Why in vp_recon: it draws the reconstruction and
its distance to the truth, and vp_recon already depends on vp_scene (camera geometry, clouds) and
vp_interfaces; vp_recon never imports vp_planner, and the viewer needs nothing from it.
Signals, exit codes and parameter types follow :mod:`vp_scene.node_runtime` (a port in use: one
line, exit 2).

    ros2 run vp_recon viewer --ros-args -p port:=8080     # then open the URL it logs (token included)
"""
from __future__ import annotations

import fnmatch

from geometry_msgs.msg import PoseArray, PoseStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from sensor_msgs.msg import PointCloud2
from vp_interfaces.msg import FleetAssignment

from vp_recon.viewer import PlanViewer, ViewerError, show_message
from vp_scene.node_runtime import INT_MAX, LATCHED, Param, declare_typed, run_node, typed_values

POSE_TYPES = {'geometry_msgs/msg/PoseStamped': PoseStamped, 'nav_msgs/msg/Odometry': Odometry}

#: The node's parameters (:class:`vp_scene.node_runtime.Param`): all read once, at start (read_only).
PARAMS = {
    'port': Param(8080, 'port of the viewer on 127.0.0.1', (1, 65535), True),
    'max_points': Param(60000, 'points shown per cloud (a random subset of bigger ones)', (1, INT_MAX), True),
    'pose_topics': Param('/*/pose', 'fnmatch pattern of the drones\' pose topics', None, True),
}


def check_parameters(values: dict) -> dict:
    v = typed_values(PARAMS, values)
    if not 1 <= v.get('port', 1) <= 65535:
        raise ValueError(f"port must be in 1..65535, got {v['port']}")
    if v.get('max_points', 1) < 1:
        raise ValueError('max_points must be >= 1')
    return v


class ViewerNode(Node):
    def __init__(self) -> None:
        super().__init__('viewer')
        v = declare_typed(self, PARAMS, check_parameters)
        try:
            self.viewer = PlanViewer(port=v['port'], max_points=v['max_points'])
        except ViewerError as exc:
            raise ValueError(str(exc)) from exc
        self._pose_pattern = v['pose_topics']
        for topic, kind in (('/scene/noisy_points', PointCloud2), ('/camera_plan', PoseArray),
                            ('/fleet/assignment', FleetAssignment), ('/reconstruction/points', PointCloud2)):
            self._follow(topic, kind, LATCHED)
        self._poses: set = set()
        self.create_timer(1.0, self._discover_drones)
        self.get_logger().info(f'viewer at {self.viewer.url}')

    def _follow(self, topic: str, kind: type, qos) -> None:
        def show(msg, topic=topic) -> None:
            try:
                show_message(self.viewer, topic, msg)
            except ValueError as exc:  # a malformed cloud or pose: said, the viewer keeps going
                self.get_logger().error(f'cannot show {topic}: {exc}')
        self.create_subscription(kind, topic, show, qos)

    def _discover_drones(self) -> None:
        for topic, types in self.get_topic_names_and_types():
            if topic in self._poses or not fnmatch.fnmatchcase(topic, self._pose_pattern) or topic.count('/') != 2:
                continue
            kind = next((POSE_TYPES[t] for t in types if t in POSE_TYPES), None)
            if kind is not None:
                self._poses.add(topic)
                self._follow(topic, kind, 10)

    def on_shutdown(self, timeout: float) -> bool:
        self.viewer.close()
        return True


def main(args=None) -> int:
    """Entry point ``viewer``."""
    return run_node('viewer', ViewerNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
