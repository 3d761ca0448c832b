#!/usr/bin/env python3
"""Probes of the cross-host test (tests/test_across_hosts.py), one process each, run inside a
network namespace. Every event is one JSON line on stdout (``{"ev": ...}``, times from
``time.time()``: all namespaces share the machine's clock, so receive time minus the sender's
stamp is the latency). Each probe ends by itself after ``--seconds`` (the test's traffic is
bounded in time as well as in count).

    netns_probe.py listen --seconds S [--latched-only]
        subscribes /camera_plan, /scene/noisy_points, /fleet/assignment (latched, as the nodes
        publish them) and, unless --latched-only, /reconstruction/score, /probe/cloud and
        /probe/beat; one line a message ("plan", "scene", "assignment", "score", "cloud", "beat").
    netns_probe.py talk --seconds S --clouds N --points P --rate HZ [--trigger FILE]
        publishes /probe/beat (std_msgs/Header, 10 Hz) for its whole life and, once a subscriber
        of /probe/cloud is matched ("discovered": seconds from its node's creation) and FILE
        exists, N clouds of P points at HZ ("cloud_sent").
    netns_probe.py goal --seconds S --trigger FILE [--cameras N --seed K]
        waits for the /plan_views server, its services and publishers ("server": seconds), then for
        FILE to exist, sends one circle goal and prints the result ("result").
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np
import rclpy
from builtin_interfaces.msg import Time
from rclpy.executors import ExternalShutdownException
from geometry_msgs.msg import PoseArray
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Header

LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
STREAM = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
# the heartbeat keeps 30 s of beats (10 Hz): the writer resends what the link-down held back only
# while it is still in its history, and Fast DDS's reader learns of the gap from the writer's next
# HEARTBEAT (every 3 s by default). With depth 10 (1 s) the beats of a 5 s outage had left the
# history by then in one CI run of 43, and none arrived afterwards.
BEAT = QoSProfile(depth=300, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


def emit(ev: str, **fields) -> None:
    print(json.dumps({"ev": ev, "t": time.time(), **fields}), flush=True)


def seconds(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


def now_stamp() -> Time:
    t = time.time()
    return Time(sec=int(t), nanosec=int((t % 1.0) * 1e9))


def listen(node, args) -> None:
    from vp_interfaces.msg import FleetAssignment, ReconstructionScore

    def on_plan(m: PoseArray) -> None:
        emit("plan", stamp=seconds(m.header.stamp), poses=len(m.poses), frame=m.header.frame_id)

    def on_scene(m: PointCloud2) -> None:
        emit("scene", stamp=seconds(m.header.stamp), points=int(m.width) * int(m.height), bytes=len(m.data))

    def on_assignment(m: FleetAssignment) -> None:
        emit("assignment", plan_stamp=seconds(m.plan_stamp), error_code=int(m.error_code), error_msg=m.error_msg,
             entries=[{"drone": e.drone, "pose_index": int(e.pose_index),
                       "goal": [e.goal.position.x, e.goal.position.y, e.goal.position.z]} for e in m.entries])

    def on_score(m: ReconstructionScore) -> None:
        emit("score", realization=int(m.realization), error_code=int(m.error_code), error_msg=m.error_msg)

    def on_cloud(m: PointCloud2) -> None:
        emit("cloud", stamp=seconds(m.header.stamp), seq=m.header.frame_id, bytes=len(m.data))

    def on_beat(m: Header) -> None:
        emit("beat", stamp=seconds(m.stamp), seq=m.frame_id)

    node.create_subscription(PoseArray, "/camera_plan", on_plan, LATCHED)
    node.create_subscription(PointCloud2, "/scene/noisy_points", on_scene, LATCHED)
    node.create_subscription(FleetAssignment, "/fleet/assignment", on_assignment,
                             QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                                        durability=DurabilityPolicy.TRANSIENT_LOCAL))
    if not args.latched_only:
        node.create_subscription(ReconstructionScore, "/reconstruction/score", on_score, 10)
        node.create_subscription(PointCloud2, "/probe/cloud", on_cloud, STREAM)
        node.create_subscription(Header, "/probe/beat", on_beat, BEAT)
    emit("ready")
    end = time.monotonic() + args.seconds
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)


def talk(node, args) -> None:
    from vp_scene.cloud import numpy_to_pointcloud2

    created = time.monotonic()
    beats = node.create_publisher(Header, "/probe/beat", BEAT)
    clouds = node.create_publisher(PointCloud2, "/probe/cloud", STREAM)
    rng = np.random.default_rng(0)
    cloud = numpy_to_pointcloud2(rng.uniform(-1, 1, (args.points, 3)),
                                 rng.integers(0, 255, (args.points, 3), dtype=np.uint8))
    emit("cloud_size", points=args.points, bytes=len(cloud.data))
    seq = [0]

    def beat() -> None:
        beats.publish(Header(stamp=now_stamp(), frame_id=str(seq[0])))
        seq[0] += 1

    node.create_timer(0.1, beat)
    end = created + args.seconds
    discovered = None
    sent, next_cloud = 0, 0.0
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.01)
        if discovered is None and clouds.get_subscription_count() > 0:
            discovered = time.monotonic() - created
            emit("discovered", seconds=discovered)
            next_cloud = time.monotonic() + 0.5  # let the reader's match settle
        if args.trigger and not os.path.exists(args.trigger):
            continue
        if discovered is not None and sent < args.clouds and time.monotonic() >= next_cloud:
            cloud.header.stamp, cloud.header.frame_id = now_stamp(), str(sent)
            clouds.publish(cloud)
            emit("cloud_sent", seq=sent)
            sent += 1
            next_cloud = time.monotonic() + 1.0 / args.rate


def goal(node, args) -> None:
    from rclpy.action import ActionClient
    from vp_interfaces.action import PlanViews

    created = time.monotonic()
    client = ActionClient(node, PlanViews, "/plan_views")
    end = created + args.seconds
    # the server's services (server_is_ready) and its feedback and status publishers: every
    # endpoint of the action discovered, before the test takes a link down
    topics = ("/plan_views/_action/feedback", "/plan_views/_action/status")

    def ready() -> bool:
        return client.server_is_ready() and all(node.count_publishers(t) for t in topics)
    while not ready() and time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.05)
    if not ready():
        emit("error", what="no /plan_views server")
        return
    emit("server", seconds=time.monotonic() - created)
    while not os.path.exists(args.trigger) and time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.02)
    g = PlanViews.Goal()
    g.num_cameras, g.method, g.evaluations, g.seed = args.cameras, "circle", 6, args.seed
    emit("goal_sent")
    future = client.send_goal_async(g)
    while not future.done() and time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.02)
    if not future.done() or not future.result().accepted:
        emit("error", what="goal not accepted")
        return
    result = future.result().get_result_async()
    while not result.done() and time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.02)
    if not result.done():
        emit("error", what="no result")
        return
    r = result.result().result
    emit("result", error_code=int(r.error_code), error_msg=r.error_msg, stamp=seconds(r.plan.header.stamp),
         poses=len(r.plan.poses))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mode", choices=["listen", "talk", "goal"])
    ap.add_argument("--seconds", type=float, required=True, help="the probe ends after this long")
    ap.add_argument("--clouds", type=int, default=20)
    ap.add_argument("--points", type=int, default=100_000)
    ap.add_argument("--rate", type=float, default=2.0)
    ap.add_argument("--trigger", default="")
    ap.add_argument("--cameras", type=int, default=3)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--name", default="")
    ap.add_argument("--latched-only", action="store_true", help="listen: the latched topics only")
    args = ap.parse_args(argv)
    rclpy.init()
    node = rclpy.create_node(args.name or f"probe_{args.mode}")
    try:
        {"listen": listen, "talk": talk, "goal": goal}[args.mode](node, args)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        emit("end")
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
