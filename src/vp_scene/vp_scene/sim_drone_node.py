"""A simulated drone for the dispatcher: flies straight toward its goal at a fixed speed and
publishes its pose (the tests, ``make run`` and the cross-host test run one process per drone).

Subscribes ``goal_topic`` (geometry_msgs/PoseStamped, reliable, TRANSIENT_LOCAL: a goal
published before the drone started still reaches it) and publishes ``pose_topic``
(geometry_msgs/PoseStamped, or nav_msgs/Odometry with ``pose_type:=odometry``) ``rate`` times a
second, in ``frame_id``: its position (:func:`vp_scene.sim_drone.fly_toward` at ``speed``
horizontally and ``climb_rate`` vertically, as the dispatcher's flight model times its legs;
exactly the goal on arrival) and the goal's orientation (identity before the first goal). A goal in another frame
is ignored with a log line. Signals, exit codes and parameter types follow
:mod:`vp_scene.node_runtime`.

With ``camera:=true`` the drone also takes pictures: on a
``vp_interfaces/CaptureTrigger`` on ``/fleet/capture`` for a plan in which ``/fleet/assignment``
gives it poses (its route's, in their ``order``), each time it settles at the next of those
poses' goals (not at an earlier plan's: a trigger can arrive before the new goal), it flies
that camera i of the plan under the
capture model (``capture``: realistic | ideal, seeded by ``capture_seed``, realization and i:
:func:`vp_scene.sim_drone.photograph` with ``indices=[i]``, so its image and reported pose are
exactly those the recon node's render source gives camera i), renders the scene of
``/scene/description`` at the trigger's wind realization from its actual pose and publishes,
all with one stamp,

* ``{camera_topic}/image_raw`` (sensor_msgs/Image, rgb8) and ``{camera_topic}/image_raw/compressed``
  (sensor_msgs/CompressedImage, PNG), frame ``{drone}/camera_optical``;
* ``{camera_topic}/camera_info`` (sensor_msgs/CameraInfo: K from ``fov`` and the size, plumb_bob
  with zero distortion);
* ``{camera_topic}/pose`` (geometry_msgs/PoseStamped, ``frame_id``): the pose it reports.

A trigger for a plan that gives it no pose is ignored with a log line, one that comes before its plan's
assignment waits for it (the latest such); one trigger, one capture of each of its poses.
The camera works in its own thread (one, which owns the OpenGL context), so the drone keeps
reporting its pose while it renders, as a real drone's autopilot does beside its camera; it
builds the scene and renders once as soon as ``/scene/description`` arrives (while the planner
plans), so that its first picture costs what the others do.
"""
from __future__ import annotations

import math
import threading
import time
from concurrent.futures import ThreadPoolExecutor, wait

import numpy as np
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node

from .camera import IMAGE_SIDE_RANGE, IMAGE_SIZE
from .limits import MAX_SEED
from .messages import (POSE_TYPES, camera_info_msg, compressed_image_msg, drone_topic, image_msg, pose_array, pose_report,
                       scene_of_description)
from .node_runtime import LATCHED, Param, declare_typed, run_node, typed_values
from .sim_drone import fly_toward, photograph, warm_up


#: how far (m, per axis) from its assigned goal a drone may hover and still take that plan's picture
#: (it arrives exactly: :func:`vp_scene.sim_drone.fly_toward`)
GOAL_TOLERANCE_M = 1e-6

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
    'speed': Param(2.0, 'm/s, horizontal', (0.0, math.inf), True, '> 0'),
    'climb_rate': Param(2.0, 'm/s, vertical, up and down', (0.0, math.inf), True, '> 0'),
    'rate': Param(20.0, 'Hz, pose reports', (0.0, math.inf), True, '> 0'),
    'camera': Param(False, 'take pictures on /fleet/capture (README "From a real flight")', None, True),
    'camera_topic': Param('/{drone}/camera', 'camera topics template: image_raw, image_raw/compressed, '
                                             'camera_info, pose', None, True),
    'width': Param(IMAGE_SIZE[0], 'camera image width, pixels', IMAGE_SIDE_RANGE, True),
    'height': Param(IMAGE_SIZE[1], 'camera image height, pixels', IMAGE_SIDE_RANGE, True),
    'fov': Param(math.pi / 2, 'camera horizontal field of view, rad', (0.0, math.pi), True, 'the ends are excluded'),
    'capture': Param('realistic', 'capture model: realistic (RTK multirotor defaults) | ideal', None, True),
    'capture_seed': Param(0, 'seed of the capture draws (as the recon node\'s)', (0, MAX_SEED), True),
}


def check_parameters(values: dict) -> dict:
    """Typed and checked parameter values; ValueError naming the first bad one."""
    v = typed_values(PARAMS, values)
    if v.get('pose_type', 'pose') not in POSE_TYPES:
        raise ValueError(f"pose_type must be one of {', '.join(POSE_TYPES)}, got {v['pose_type']!r}")
    if v.get('speed', 1.0) <= 0 or v.get('rate', 1.0) <= 0 or v.get('climb_rate', 1.0) <= 0:
        raise ValueError('speed, climb_rate and rate must be > 0')
    if not v.get('drone', 'd') or not v.get('frame_id', 'map'):
        raise ValueError('drone and frame_id must not be empty')
    if v.get('capture', 'realistic') not in ('realistic', 'ideal'):
        raise ValueError(f"capture must be realistic or ideal, got {v['capture']!r}")
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
        self._camera = _Camera(self, v) if v['camera'] else None
        self.create_timer(1.0 / v['rate'], self._tick)
        self.get_logger().info(f'sim drone {v["drone"]} at ({v["x"]:.2f}, {v["y"]:.2f}, {v["z"]:.2f}) '
                               f'in {v["frame_id"]!r}, {v["speed"]:g} m/s, climbing {v["climb_rate"]:g} m/s')

    def on_shutdown(self, timeout: float) -> bool:
        """SIGINT/SIGTERM (:func:`vp_scene.node_runtime.run_node`): pictures not begun are dropped;
        True once the one being taken, if any, is done within ``timeout`` seconds."""
        return self._camera is None or self._camera.stop(timeout)

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
            self._position = fly_toward(self._position, self._goal[0], self._v['speed'], dt, self._v['climb_rate'])
            quat = self._goal[1]
        msg = pose_report(self._v['pose_type'], np.concatenate([self._position, quat]), self._v['frame_id'],
                          self.get_clock().now().to_msg(), f'{self._v["drone"]}/base_link')
        self._pub.publish(msg)
        if self._camera is not None and self._goal is not None and np.array_equal(self._position, self._goal[0]):
            self._camera.settled(np.concatenate([self._position, self._goal[1]]))


class _Camera:
    """The drone's camera (module docstring): triggers wait here until the drone has settled."""

    def __init__(self, node: Node, v: dict) -> None:
        from sensor_msgs.msg import CameraInfo, CompressedImage, Image
        from vp_interfaces.msg import CaptureTrigger, FleetAssignment, SceneDescription

        self._node, self._v = node, v
        self._description = None
        self._scene = None            # the camera thread's only: (description, NoisyScene)
        self._warm = False            # the camera thread's only
        # one thread: it owns the OpenGL context (current to the thread that made it)
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix=f'{v["drone"]}-camera')
        self._jobs: list = []
        self._jobs_lock = threading.Lock()
        self._assignments: dict = {}  # plan stamp -> [(pose index, goal (3,))] of this drone in route order
        self._pending = None          # (trigger, [(pose index, goal)] not photographed yet)
        self._early = None            # the latest trigger whose plan's assignment has not arrived yet
        base = drone_topic(v['camera_topic'], v['drone'])
        self._image = node.create_publisher(Image, f'{base}/image_raw', LATCHED)
        self._compressed = node.create_publisher(CompressedImage, f'{base}/image_raw/compressed', LATCHED)
        self._info = node.create_publisher(CameraInfo, f'{base}/camera_info', LATCHED)
        self._pose = node.create_publisher(PoseStamped, f'{base}/pose', LATCHED)
        node.create_subscription(SceneDescription, '/scene/description', self._on_description, LATCHED)
        node.create_subscription(FleetAssignment, '/fleet/assignment', self._on_assignment, LATCHED)
        node.create_subscription(CaptureTrigger, '/fleet/capture', self._on_trigger, LATCHED)

    @staticmethod
    def _key(stamp) -> tuple:
        return (int(stamp.sec), int(stamp.nanosec))

    def _on_description(self, msg) -> None:
        self._description = msg
        self._submit('the camera\'s warm-up', self._prepare, msg)

    def _submit(self, what: str, job, *args) -> None:
        """``job(*args)`` in the camera thread, after the jobs before it; its error is logged."""
        def logged():
            try:
                job(*args)
            except Exception as exc:  # noqa: BLE001 - a failed capture is logged, the drone flies on
                self._node.get_logger().error(f'{what} failed: {type(exc).__name__}: {exc}')

        with self._jobs_lock:
            self._jobs = [j for j in self._jobs if not j.done()]
            try:
                self._jobs.append(self._worker.submit(logged))
            except RuntimeError:  # shutting down: no new picture
                pass

    def stop(self, timeout: float) -> bool:
        """Drop the jobs not begun; True once the running one, if any, ends within ``timeout`` s."""
        self._worker.shutdown(wait=False, cancel_futures=True)
        with self._jobs_lock:
            jobs = list(self._jobs)
        return not wait(jobs, timeout=timeout).not_done

    def _scene_of(self, description):
        """The NoisyScene of ``description``, built once (camera thread)."""
        if self._scene is None or self._scene[0] is not description:
            self._scene = (description, scene_of_description(description))
        return self._scene[1]

    def _prepare(self, description) -> None:
        """Camera thread: the scene built, and the renderer warmed up once (:func:`warm_up`)."""
        from .capture import CaptureModel

        scene = self._scene_of(description)
        if not self._warm:
            v = self._v
            seconds = warm_up(scene, CaptureModel.named(v['capture'], seed=v['capture_seed']), v['width'],
                              v['height'], v['fov'])
            self._warm = True
            self._node.get_logger().info(f'camera ready ({v["width"]}x{v["height"]}, warmed up in {seconds:.1f} s)')

    def _on_assignment(self, msg) -> None:
        mine = sorted((int(e.order), int(e.pose_index), pose_array(e.goal)[:3]) for e in msg.entries
                      if e.drone == self._v['drone'])
        key = self._key(msg.plan_stamp)
        self._assignments[key] = [(i, goal) for _, i, goal in mine]
        if self._early is not None and self._key(self._early.plan_stamp) == key:
            early, self._early = self._early, None
            self._on_trigger(early)

    def _on_trigger(self, msg) -> None:
        key = self._key(msg.plan_stamp)
        if key not in self._assignments:  # two latched topics: the trigger may come before its assignment
            self._early = msg
            self._node.get_logger().info(f'capture of plan {key} waits for the plan\'s assignment')
            return
        if not self._assignments[key]:
            self._node.get_logger().info(f'capture of plan {key} ignored: no pose of it is mine')
            return
        self._pending = (msg, list(self._assignments[key]))
        self._node.get_logger().info(f'capture of plan {key}, pose(s) {[i for i, _ in self._pending[1]]}, '
                                     f'realization {msg.realization}: each to be taken at its goal')

    def settled(self, pose: np.ndarray) -> None:
        """The drone is at its goal ``pose`` (7,): take the next pending picture, if any, once that
        goal is the next pose its plan assigned (a trigger may arrive before the new goal: the drone
        then still hovers at the last plan's pose, and waits)."""
        if self._pending is None:
            return
        trigger, todo = self._pending
        i, goal = todo[0]
        if np.max(np.abs(np.asarray(pose[:3], dtype=np.float64) - goal)) > GOAL_TOLERANCE_M:
            return
        if self._description is None:  # latched, it may come after the trigger: wait for it
            return
        todo.pop(0)
        if not todo:
            self._pending = None
        self._submit('capture', self._capture, trigger, i, pose, self._description)

    def _capture(self, trigger, i: int, pose: np.ndarray, description) -> None:
        """Camera thread: pose i of the trigger's plan photographed from ``pose`` and published."""
        from .camera import cameras_to_poses, poses_to_cameras
        from .capture import CaptureModel

        v = self._v
        capture = CaptureModel.named(v['capture'], seed=v['capture_seed'])
        views = photograph(self._scene_of(description), int(trigger.realization), poses_to_cameras(pose)[None],
                           capture, v['width'], v['height'], v['fov'], indices=[i], masks=False)
        stamp = self._node.get_clock().now().to_msg()
        optical = f'{v["drone"]}/camera_optical'
        image = views.images[0]
        self._image.publish(image_msg(image, optical, stamp))
        self._compressed.publish(compressed_image_msg(image, optical, stamp))
        self._info.publish(camera_info_msg(views.K, v['width'], v['height'], optical, stamp))
        self._pose.publish(pose_report('pose', cameras_to_poses(views.reported[0]), v['frame_id'], stamp,
                                       f'{v["drone"]}/base_link'))
        self._node.get_logger().info(f'captured pose {i} of plan ({trigger.plan_stamp.sec}, '
                                     f'{trigger.plan_stamp.nanosec}), realization {trigger.realization}')


def main(args=None) -> int:
    """Entry point ``sim_drone``."""
    return run_node('sim_drone', SimDroneNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
