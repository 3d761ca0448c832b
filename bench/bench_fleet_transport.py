#!/usr/bin/env python3
"""Transport of capture sets on loopback (issue 20, part 5): three measurements, one JSON.

``--mode transport`` (the first figures): N drones' images (sensor_msgs/Image rgb8, W x H) from
ONE publisher process to one subscriber process, with the QoS of the camera topics (reliable,
TRANSIENT_LOCAL, depth 1); the delivery time of the set (first publish to last image received,
conversions numpy -> message and back included) and the subscriber's peak memory (max RSS).
Writes the top-level keys of the JSON (as before).

``--mode recon``: the real recon node (``source: fleet``, beside a real scene node) collects one
capture set of N images of W x H over DDS: this process plays the dispatcher and the N drones
(/fleet/assignment, /camera_plan, and on the node's /fleet/capture trigger one image_raw,
camera_info and pose per drone). The node's peak RSS (``VmHWM`` of /proc/<pid>/status, the
kernel's max RSS of the process) is read when it is ready, when it has the set
(its log line "capture 0: N images ... collected"), when the reconstruction has checked the
images ("render done": masks computed) and ``--sparse-seconds`` into the sparse step; then the
node is stopped (the images are noise: what is measured is collection + the start of the
reconstruction, not a whole one). Key ``recon_node_memory``.

``--mode drones``: N real ``sim_drone`` processes (``camera:=true``, each at its goal) and a
real scene node; this process triggers ``--repeats`` captures (/fleet/capture) and receives
every drone's image_raw: per set the time from the trigger to the last image (the drones'
render of W x H included), and the failures counted: drones whose image did not come within
``--set-timeout`` (named) and "capture failed" lines in the drones' logs. Key ``drone_processes``,
one record per image size (``"640x480"``...).

    python bench/bench_fleet_transport.py [--mode transport|recon|drones] [--drones 16 --width 2000
        --height 1500 --repeats 3]

Writes (merges into) results/bench_fleet_transport.json. Needs ROS_DOMAIN_ID and
ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST (as `make` sets them).
"""
from __future__ import annotations

import argparse
import json
import math
import resource
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

if not __package__:  # python bench/bench_fleet_transport.py: as python -m bench.bench_fleet_transport (bench/_script.py)
    import _script  # noqa: F401
from bench.common import provenance, write_json  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / 'results' / 'bench_fleet_transport.json'
SCENE = dict(scenario='one_plant', points_per_plant=2000, realizations=2, levels=5, seed=3)
MACHINE_LOAD = 'benchmark running beside (2 cores shared): noisy'


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


def transport(args) -> dict:
    """--mode transport: the top-level keys of the JSON (module docstring)."""
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
    return {'drones': args.drones, 'width': args.width, 'height': args.height,
            'megabytes_per_set': args.drones * args.width * args.height * 3 / 1e6,
            'subscriber_rss_mb_before': ready['rss_mb'], 'sets': sets,
            'note': 'one publisher process for all drones, one subscriber process; loopback DDS (rmw default)'}


def ring(n: int, radius: float = 1.7, height: float = 1.3) -> np.ndarray:
    """n cameras [c, v] on a circle around the one_plant scene's plant, looking at it."""
    from vp_scene.camera import look_at

    az = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    c = np.stack([radius * np.cos(az), radius * np.sin(az), np.full(n, height)], axis=1)
    return look_at(c, np.tile([0.0, 0.0, 0.9], (n, 1)))


def vm_hwm_mb(pid: int) -> float:
    """The peak resident set of process ``pid`` so far (VmHWM), MB."""
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('VmHWM:'):
            return int(line.split()[1]) / 1024
    raise RuntimeError(f'no VmHWM for process {pid}')


class Harness:
    """Nodes as child processes (tools/node_process.py), an rclpy node here; stopped by close()."""

    def __init__(self, env: dict, logs: Path) -> None:
        import rclpy

        self.env, self.logs, self.procs = env, logs, []
        rclpy.init()
        self.node = rclpy.create_node('bench_fleet')
        self._stop = threading.Event()
        self._spin = threading.Thread(target=self._spinner, daemon=True)
        self._spin.start()

    def _spinner(self) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        ex = SingleThreadedExecutor()
        ex.add_node(self.node)
        while not self._stop.is_set() and rclpy.ok():
            ex.spin_once(timeout_sec=0.05)

    def start(self, pkg: str, exe: str, params: dict, name: str = None):
        from tools.node_process import NodeProcess, node_command

        proc = NodeProcess(node_command(pkg, exe, params, name=name), self.env,
                           self.logs / f'{name or exe}.log')
        self.procs.append(proc)
        return proc

    @staticmethod
    def wait(pred, timeout: float, what: str, *procs) -> object:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            value = pred()
            if value:
                return value
            for p in procs:
                if not p.alive():
                    raise RuntimeError(f'{what}: {p.cmd[0]} exited:\n{p.output()[-3000:]}')
            time.sleep(0.05)
        tails = '\n'.join(p.output()[-2000:] for p in procs)
        raise RuntimeError(f'timed out after {timeout:.0f} s waiting for {what}\n{tails}')

    def close(self) -> None:
        for p in reversed(self.procs):
            p.stop(timeout=10.0)
        self._stop.set()
        self._spin.join(timeout=5.0)
        self.node.destroy_node()
        import rclpy

        rclpy.shutdown()


def recon_memory(args, env: dict) -> dict:
    """--mode recon (module docstring)."""
    import psutil
    from geometry_msgs.msg import PoseArray, PoseStamped
    from sensor_msgs.msg import CameraInfo, Image
    from vp_interfaces.msg import CaptureTrigger, FleetAssignment

    from vp_scene.camera import CameraModel, cameras_to_poses
    from vp_scene.messages import (camera_info_msg, cameras_to_pose_array, fleet_assignment_msg, image_msg,
                                   pose_report)

    tmp = Path(tempfile.mkdtemp(prefix='bench_fleet_'))
    h = Harness(env, tmp)
    try:
        scene = h.start('vp_scene', 'scene', SCENE)
        recon = h.start('vp_recon', 'recon', {
            'source': 'fleet', 'width': args.width, 'height': args.height, 'max_realizations': 1, 'dense': False,
            'num_threads': 1, 'capture_timeout': 300.0, 'record_captures': False,
            'output_folder': str(tmp / 'out')})
        drones = [f'd{i}' for i in range(args.drones)]
        cams = ring(args.drones)
        node = h.node
        pubs = {d: (node.create_publisher(Image, f'/{d}/camera/image_raw', _qos()),
                    node.create_publisher(CameraInfo, f'/{d}/camera/camera_info', _qos()),
                    node.create_publisher(PoseStamped, f'/{d}/camera/pose', _qos())) for d in drones}
        triggers: list = []
        node.create_subscription(CaptureTrigger, '/fleet/capture', triggers.append, _qos())
        fleet_pub = node.create_publisher(FleetAssignment, '/fleet/assignment', _qos())
        plan_pub = node.create_publisher(PoseArray, '/camera_plan', _qos())
        h.wait(lambda: 'ground truth: 2 realizations' in recon.output(), 240, 'the recon node and the scene', recon,
               scene)
        proc = psutil.Process(recon.pid)
        samples: list = []
        stop = threading.Event()

        def sample() -> None:  # the RSS over time, for the record (VmHWM is the peak)
            while not stop.is_set():
                try:
                    samples.append((time.monotonic(), proc.memory_info().rss / 2 ** 20))
                except psutil.Error:
                    return
                time.sleep(0.2)
        threading.Thread(target=sample, daemon=True).start()
        marks = {'ready': vm_hwm_mb(recon.pid)}
        fleet_pub.publish(fleet_assignment_msg(7, drones, cams))
        plan = cameras_to_pose_array(cams, 'map', None)
        plan.header.stamp.sec = 7
        plan_pub.publish(plan)
        h.wait(lambda: triggers, 120, 'the capture trigger', recon)
        K = CameraModel(args.width, args.height, math.pi / 2).K
        rng = np.random.default_rng(0)
        t0 = time.monotonic()
        for d, c in zip(drones, cams):  # one drone after the other, as their captures come in
            stamp = node.get_clock().now().to_msg()
            im = rng.integers(0, 256, (args.height, args.width, 3), dtype=np.uint8)
            image, info, pose = pubs[d]
            image.publish(image_msg(im, f'{d}/camera_optical', stamp))
            info.publish(camera_info_msg(K, args.width, args.height, f'{d}/camera_optical', stamp))
            pose.publish(pose_report('pose', cameras_to_poses(c), 'map', stamp, f'{d}/base_link'))
        h.wait(lambda: 'images from the fleet' in recon.output(), 300, 'the capture set at the recon node', recon)
        collected = time.monotonic() - t0
        marks['collected'] = vm_hwm_mb(recon.pid)
        h.wait(lambda: 'render done' in recon.output() or 'plan:' in recon.output(), 300,
               'the start of the reconstruction', recon)
        marks['images_checked'] = vm_hwm_mb(recon.pid)
        end = time.monotonic() + args.sparse_seconds
        h.wait(lambda: time.monotonic() > end or 'sparse done' in recon.output() or 'plan:' in recon.output(),
               args.sparse_seconds + 5, 'the sparse step', recon)
        marks['sparse_step'] = vm_hwm_mb(recon.pid)
        stop.set()
        log = [ln.split(']: ', 1)[-1] for ln in recon.output().splitlines() if 'images from the fleet' in ln]
        return {
            'drones': args.drones, 'width': args.width, 'height': args.height,
            'megabytes_per_set': args.drones * args.width * args.height * 3 / 1e6,
            'recon_node_peak_rss_mb': {k: round(v, 1) for k, v in marks.items()},
            'rss_mb_max_sampled': round(max(r for _, r in samples), 1) if samples else None,
            'set_published_to_collected_s': round(collected, 2), 'recon_log': log,
            'measured': 'VmHWM (peak RSS) of the real recon node process (source fleet, capture realistic, '
                        'dense off, 1 thread) at: ready (scene loaded), the capture set collected, the images '
                        f'checked (masks), {args.sparse_seconds:g} s into the sparse step (SIFT of noise '
                        'images); then stopped. The images are uniform noise, published by this process '
                        'playing 16 drones one after the other.',
        }
    finally:
        h.close()


def drone_processes(args, env: dict) -> dict:
    """--mode drones (module docstring)."""
    from geometry_msgs.msg import PoseStamped
    from sensor_msgs.msg import Image
    from vp_interfaces.msg import CaptureTrigger, FleetAssignment, SceneDescription

    from vp_scene.camera import cameras_to_poses
    from vp_scene.messages import fleet_assignment_msg, pose_msg

    tmp = Path(tempfile.mkdtemp(prefix='bench_fleet_'))
    h = Harness(env, tmp)
    try:
        drones = [f'd{i}' for i in range(args.drones)]
        cams = ring(args.drones)
        t_start = time.monotonic()
        scene = h.start('vp_scene', 'scene', SCENE)
        sims = [h.start('vp_scene', 'sim_drone', {'drone': d, 'x': float(c[0]), 'y': float(c[1]),
                                                    'z': float(c[2]), 'camera': True, 'capture': 'ideal',
                                                    'width': args.width, 'height': args.height},
                        name=f'sim_{d}') for d, c in zip(drones, cams)]
        node = h.node
        got: dict = {}  # (drone, stamp ns) -> time received
        lock = threading.Lock()

        def on(d: str, msg) -> None:
            with lock:
                got.setdefault(d, []).append(time.monotonic())

        for d in drones:
            node.create_subscription(Image, f'/{d}/camera/image_raw', lambda m, d=d: on(d, m), _qos())
        descriptions: list = []
        node.create_subscription(SceneDescription, '/scene/description', descriptions.append, _qos())
        fleet_pub = node.create_publisher(FleetAssignment, '/fleet/assignment', _qos())
        trig_pub = node.create_publisher(CaptureTrigger, '/fleet/capture', _qos())
        goal_pubs = {d: node.create_publisher(PoseStamped, f'/{d}/goal_pose', _qos()) for d in drones}
        h.wait(lambda: all('sim drone' in s.output() for s in sims), 600, 'the drones', *sims)
        started = time.monotonic() - t_start
        fleet_pub.publish(fleet_assignment_msg(7, drones, cams))
        for d, c in zip(drones, cams):
            g = PoseStamped(pose=pose_msg(cameras_to_poses(c)))
            g.header.frame_id = 'map'
            goal_pubs[d].publish(g)
        h.wait(lambda: all('goal (' in s.output() for s in sims), 120, 'the goals', *sims)
        h.wait(lambda: trig_pub.get_subscription_count() >= args.drones, 60, 'the drones\' trigger subscriptions')
        # a trigger before the drones have the scene fails their capture ("no /scene/description yet",
        # counted below): wait for the description here, then as long again for the drones to have it
        t0 = time.monotonic()
        h.wait(lambda: descriptions, 300, 'the scene description', scene)
        time.sleep(min(30.0, time.monotonic() - t0) + 2.0)
        sets = []
        for r in range(args.repeats):
            with lock:
                before = {d: len(got.get(d, [])) for d in drones}
            trigger = CaptureTrigger(realization=r % SCENE['realizations'])
            trigger.plan_stamp.sec = 7
            trigger.header.frame_id = 'map'
            t0 = time.monotonic()
            trig_pub.publish(trigger)

            def arrived():
                with lock:
                    return {d: got[d][before[d]] for d in drones if len(got.get(d, [])) > before[d]}
            deadline = time.monotonic() + args.set_timeout
            while time.monotonic() < deadline and len(arrived()) < args.drones:
                time.sleep(0.05)
            a = arrived()
            missing = [d for d in drones if d not in a]
            sets.append({'realization': int(trigger.realization),
                         'seconds_trigger_to_last_image': round(max(a.values()) - t0, 3) if a else None,
                         'seconds_trigger_to_first_image': round(min(a.values()) - t0, 3) if a else None,
                         'images': len(a), 'missing_drones': missing})
        failed_lines = sum(s.output().count('capture failed') for s in sims)
        rss = []
        import psutil

        for s in sims:
            try:
                rss.append(psutil.Process(s.pid).memory_info().rss / 2 ** 20)
            except psutil.Error:
                pass
        return {
            'drones': args.drones, 'width': args.width, 'height': args.height,
            'processes': f'{args.drones} sim_drone processes (camera:=true, capture ideal) + 1 scene node; '
                         'this process triggers and receives image_raw',
            'seconds_to_start_all_drones': round(started, 1), 'sets': sets,
            'failures': {'images_missing': sum(len(s['missing_drones']) for s in sets),
                         'capture_failed_log_lines': failed_lines,
                         'drone_processes_exited': sum(1 for s in sims if not s.alive())},
            'drone_rss_mb_mean': round(float(np.mean(rss)), 1) if rss else None,
            'note': 'per set: trigger published -> last image received here; includes each drone\'s render '
                    '(llvmpipe, 1 thread; the first set also builds the scene meshes in every drone) and PNG '
                    'encoding of image_raw/compressed; the 16 processes share 2 cores',
        }
    finally:
        h.close()


def main() -> int:
    from vp_scene.camera import IMAGE_SIZE

    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--mode', choices=('transport', 'recon', 'drones'), default='transport')
    ap.add_argument('--drones', type=int, default=16)
    ap.add_argument('--width', type=int, default=IMAGE_SIZE[0])
    ap.add_argument('--height', type=int, default=IMAGE_SIZE[1])
    ap.add_argument('--repeats', type=int, default=3)
    ap.add_argument('--sparse-seconds', type=float, default=20.0, help='recon: seconds of the sparse step measured')
    ap.add_argument('--set-timeout', type=float, default=300.0, help='drones: s a capture set may take')
    ap.add_argument('--child', action='store_true', help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        subscriber(args.drones, args.repeats)
        return 0
    import os

    env = dict(os.environ, PYTHONUNBUFFERED='1')
    if args.mode == 'transport':
        new = {**transport(args), **provenance()}
    else:
        key = {'recon': 'recon_node_memory', 'drones': 'drone_processes'}[args.mode]
        fn = recon_memory if args.mode == 'recon' else drone_processes
        new = {key: {**fn(args, env), 'machine_load': MACHINE_LOAD,
                     'date': time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime()), **provenance()}}
    out = json.loads(RESULTS.read_text()) if RESULTS.is_file() else {}
    if args.mode == 'drones':  # one record per image size
        new = {'drone_processes': {**out.get('drone_processes', {}),
                                   f'{args.width}x{args.height}': new['drone_processes']}}
    out.update(new)
    write_json(RESULTS, out, indent=1)  # a record per mode, each with its command and commit
    print(json.dumps(new, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
