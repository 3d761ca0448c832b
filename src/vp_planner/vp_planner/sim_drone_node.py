"""A simulated drone for the dispatcher: flies straight toward its goal at a fixed speed and
publishes its pose (the tests, ``make run`` and the cross-host test run one process per drone).

Subscribes ``goal_topic`` (geometry_msgs/PoseStamped, reliable, TRANSIENT_LOCAL: a goal
published before the drone started still reaches it) and publishes ``pose_topic``
(geometry_msgs/PoseStamped, or nav_msgs/Odometry with ``pose_type:=odometry``) ``rate`` times a
second, in ``frame_id``: its position (:func:`vp_planner.fleet.fly_toward`, exactly the goal on
arrival) and the goal's orientation (identity before the first goal). A goal in another frame
is ignored with a log line. Signals, exit codes and parameter types follow
:mod:`vp_scene.node_runtime`.
"""
from __future__ import annotations

import math
import time

import numpy as np
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from vp_planner.fleet import fly_toward
from vp_scene.messages import POSE_TYPES, drone_topic, pose_array, pose_report
from vp_scene.node_runtime import Param, declare_typed, run_node, typed_values

LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)

#: The node's parameters (:class:`vp_scene.node_runtime.Param`): all read once, at start (read_only).
PARAMS = {
    'drone': Param('d0', 'the drone\'s name (the {drone} of the topic templates)', None, True, 'not empty'),
    'goal_topic': Param('/{drone}/goal_pose', 'goal topic template (as the dispatcher\'s)', None, True),
    'pose_topic': Param('/{drone}/pose', 'pose topic template (as the dispatcher\'s)', None, True),
    'pose_type': Param('pose', 'pose: geometry_msgs/PoseStamped | odometry: nav_msgs/Odometry', None, True,
                       'one of ' + ', '.join(POSE_TYPES)),
    'frame_id': Param('map', 'frame of the poses it publishes and of the goals it accepts', None, True, 'not empty'),
    'x': Param(0.0, 'm, start position', None, True),
    'y': Param(0.0, 'm, start position', None, True),
    'z': Param(0.0, 'm, start position', None, True),
    'speed': Param(2.0, 'm/s', (0.0, math.inf), True, '> 0'),
    'rate': Param(20.0, 'Hz, pose reports', (0.0, math.inf), True, '> 0'),
}


def check_parameters(values: dict) -> dict:
    """Typed and checked parameter values; ValueError naming the first bad one."""
    v = typed_values(PARAMS, values)
    if v.get('pose_type', 'pose') not in POSE_TYPES:
        raise ValueError(f"pose_type must be one of {', '.join(POSE_TYPES)}, got {v['pose_type']!r}")
    if v.get('speed', 1.0) <= 0 or v.get('rate', 1.0) <= 0:
        raise ValueError('speed and rate must be > 0')
    if not v.get('drone', 'd') or not v.get('frame_id', 'map'):
        raise ValueError('drone and frame_id must not be empty')
    return v


class SimDroneNode(Node):
    def __init__(self) -> None:
        super().__init__('sim_drone')
        v = declare_typed(self, PARAMS, check_parameters)
        self._v = v
        self._position = np.array([v['x'], v['y'], v['z']])
        self._goal = None  # (position (3,), quaternion (4,))
        self._pub = self.create_publisher(POSE_TYPES[v['pose_type']],
                                          drone_topic(v['pose_topic'], v['drone']), 10)
        self.create_subscription(PoseStamped, drone_topic(v['goal_topic'], v['drone']), self._on_goal, LATCHED)
        self._last = time.monotonic()
        self.create_timer(1.0 / v['rate'], self._tick)
        self.get_logger().info(f'sim drone {v["drone"]} at ({v["x"]:.2f}, {v["y"]:.2f}, {v["z"]:.2f}) '
                               f'in {v["frame_id"]!r}, {v["speed"]:g} m/s')

    def _on_goal(self, msg: PoseStamped) -> None:
        if msg.header.frame_id != self._v['frame_id']:
            self.get_logger().error(f'ignoring a goal in frame {msg.header.frame_id!r} (mine: {self._v["frame_id"]!r})')
            return
        goal = pose_array(msg.pose)
        self._goal = (goal[:3], tuple(goal[3:]))
        self.get_logger().info(f'goal ({goal[0]:.2f}, {goal[1]:.2f}, {goal[2]:.2f})')

    def _tick(self) -> None:
        now = time.monotonic()
        dt, self._last = now - self._last, now
        quat = (0.0, 0.0, 0.0, 1.0)
        if self._goal is not None:
            self._position = fly_toward(self._position, self._goal[0], self._v['speed'], dt)
            quat = self._goal[1]
        msg = pose_report(self._v['pose_type'], np.concatenate([self._position, quat]), self._v['frame_id'],
                          self.get_clock().now().to_msg(), f'{self._v["drone"]}/base_link')
        self._pub.publish(msg)


def main(args=None) -> int:
    """Entry point ``sim_drone``."""
    return run_node('sim_drone', SimDroneNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
