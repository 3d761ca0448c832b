#!/usr/bin/env python3
"""A stand-alone subscriber process, as ``ros2 topic echo /camera_plan`` on a stock install:
waits for one PoseArray on /camera_plan and writes it as JSON (used by the end-to-end tests).

    python tests/echo_camera_plan.py OUT.json [TIMEOUT_S]
"""
import json
import sys
import time

import rclpy
from geometry_msgs.msg import PoseArray
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy


def main() -> int:
    out, timeout = sys.argv[1], float(sys.argv[2]) if len(sys.argv) > 2 else 300.0
    rclpy.init()
    node = rclpy.create_node('camera_plan_echo')
    got = []
    qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    node.create_subscription(PoseArray, '/camera_plan', got.append, qos)
    deadline = time.monotonic() + timeout
    while not got and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.1)
    if got:
        msg = got[0]
        poses = [[p.position.x, p.position.y, p.position.z, p.orientation.x, p.orientation.y,
                  p.orientation.z, p.orientation.w] for p in msg.poses]
        with open(out, 'w') as fh:
            json.dump({'frame_id': msg.header.frame_id, 'poses': poses}, fh)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0 if got else 1


if __name__ == '__main__':
    sys.exit(main())
