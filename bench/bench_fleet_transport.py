#!/usr/bin/env python3
"""Transport of one capture set on loopback (issue 20, part 5, first figures): N drones' images
(sensor_msgs/Image rgb8, W x H) from N publishers to one subscriber process, with the QoS of the
camera topics (reliable, TRANSIENT_LOCAL, depth 1); the delivery time of the set (first publish
to last image received, conversions numpy -> message and back included) and the subscriber's
peak memory (max RSS) before and after receiving it.

    python bench/bench_fleet_transport.py [--drones 16 --width 2000 --height 1500 --repeats 3]

Writes results/bench_fleet_transport.json. Needs ROS_DOMAIN_ID and
ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST (as `make` sets them).
"""
from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
QOS = dict(depth=1)


def _qos():
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)


def subscriber(n: int, repeats: int) -> None:
    """Child: receive `repeats` capture sets of n images; print one JSON line per set."""
    import rclpy

    from vp_scene.messages import image_array

    rclpy.init()
    node = rclpy.create_node('bench_recv')
    got: dict = {}

    def on(i, msg):
        image_array(msg)  # the node's conversion
        got[(i, msg.header.stamp.sec)] = time.time()

    for i in range(n):
        node.create_subscription(__import__('sensor_msgs.msg', fromlist=['Image']).Image, f'/d{i}/camera/image_raw',
                                 lambda m, i=i: on(i, m), _qos())
    print(json.dumps({'ready': True, 'rss_mb': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}),
          flush=True)
    for r in range(1, repeats + 1):
        while sum(1 for (_, s) in got if s == r) < n:
            rclpy.spin_once(node, timeout_sec=0.1)
        last = max(t for (_, s), t in got.items() if s == r)
        print(json.dumps({'set': r, 'last': last,
                          'rss_mb': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}), flush=True)
    node.destroy_node()
    rclpy.shutdown()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--drones', type=int, default=16)
    ap.add_argument('--width', type=int, default=2000)
    ap.add_argument('--height', type=int, default=1500)
    ap.add_argument('--repeats', type=int, default=3)
    ap.add_argument('--child', action='store_true', help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        subscriber(args.drones, args.repeats)
        return 0
    import rclpy
    from sensor_msgs.msg import Image

    from vp_scene.messages import image_msg

    child = subprocess.Popen([sys.executable, __file__, '--child', '--drones', str(args.drones),
                              '--repeats', str(args.repeats)], stdout=subprocess.PIPE, text=True)
    ready = json.loads(child.stdout.readline())
    rclpy.init()
    node = rclpy.create_node('bench_send')
    pubs = [node.create_publisher(Image, f'/d{i}/camera/image_raw', _qos()) for i in range(args.drones)]
    deadline = time.time() + 30
    while time.time() < deadline and any(p.get_subscription_count() == 0 for p in pubs):
        rclpy.spin_once(node, timeout_sec=0.1)
    rng = np.random.default_rng(0)
    images = [rng.integers(0, 256, (args.height, args.width, 3), dtype=np.uint8) for _ in range(args.drones)]
    sets = []
    for r in range(1, args.repeats + 1):
        t0 = time.time()
        for p, im in zip(pubs, images):
            msg = image_msg(im, 'camera_optical', node.get_clock().now().to_msg())
            msg.header.stamp.sec = r
            p.publish(msg)
        line = json.loads(child.stdout.readline())
        sets.append({'seconds': line['last'] - t0, 'subscriber_max_rss_mb': line['rss_mb']})
    child.wait(timeout=60)
    node.destroy_node()
    rclpy.shutdown()
    out = {'drones': args.drones, 'width': args.width, 'height': args.height,
           'megabytes_per_set': args.drones * args.width * args.height * 3 / 1e6,
           'subscriber_rss_mb_before': ready['rss_mb'], 'sets': sets,
           'note': 'one publisher process for all drones, one subscriber process; loopback DDS (rmw default)'}
    (ROOT / 'results' / 'bench_fleet_transport.json').write_text(json.dumps(out, indent=1))
    print(json.dumps(out, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
