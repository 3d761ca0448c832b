"""The dispatcher node: each plan on ``/camera_plan`` becomes one goal per drone (thin adapter
around :mod:`vp_planner.fleet`).

Subscribes (reliable, TRANSIENT_LOCAL, as the planner and scene publish them)

* ``/camera_plan`` (geometry_msgs/PoseArray, in ``frame_id``, +x of each pose = optical axis);
* ``/scene/noisy_points`` (sensor_msgs/PointCloud2, in ``frame_id``): the stand-off check;

and each drone's pose, ``pose_topic`` with ``{drone}`` replaced by its name
(geometry_msgs/PoseStamped, or nav_msgs/Odometry with ``pose_type:=odometry``; in
``fleet_frame``), best effort (it matches reliable and best-effort publishers alike, as
autopilot bridges publish poses best effort).

For every plan it checks the plan (frame, poses, as many drones as poses, the planner's
feasibility rules), reads the drones' latest positions (a drone that has not reported within
``pose_timeout`` seconds makes the dispatch fail, naming it: no guessing where it is), assigns
the poses to the drones (``assignment``: ``min_total`` or ``min_max`` travel distance), and
publishes, reliable and TRANSIENT_LOCAL,

* each assigned drone's goal on ``goal_topic`` (geometry_msgs/PoseStamped, in ``fleet_frame``,
  orientation ``body`` or ``optical``); spare drones get nothing;
* ``/fleet/assignment`` (vp_interfaces/FleetAssignment): who goes where, the distances, or the
  error (``error_code`` + ``error_msg``; then no goal of this plan is published).

A plan that arrives before the scene waits ``scene_timeout`` seconds for it; without a scene the
stand-off rule cannot be checked: the plan is refused (``NO_SCENE``), or, with
``require_scene:=false``, dispatched with a warning (``standoff_checked`` false). Plans are
dispatched on a worker thread, one at a time; of the plans that arrive meanwhile only the newest
is kept. Signals, exit codes and parameter types follow :mod:`vp_scene.node_runtime`.
"""
from __future__ import annotations

import math
import re
import time
from functools import partial
from typing import Optional

import numpy as np
from geometry_msgs.msg import PoseArray, PoseStamped
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import PointCloud2

from vp_interfaces.msg import DroneAssignment, FleetAssignment
from vp_planner.feasibility import Feasibility
from vp_planner.fleet import (ASSIGNMENTS, ORIENTATIONS, AssignmentError, FleetTransform, assign, goal_orientations,
                              plan_problems)
from vp_scene.camera import poses_to_cameras
from vp_scene.cloud import realizations_from_cloud
from vp_scene.messages import POSE_TYPES, drone_topic, msgs_to_poses, point_msg, pose_msg, position_of
from vp_scene.node_runtime import LATCHED, NewestWins, Param, declare_typed, refuse_bad_changes, run_node, typed_values

Msg = FleetAssignment

#: The node's parameters (:class:`vp_scene.node_runtime.Param`); those that make topics are
#: read_only (fixed at start: restart the node to change them).
_M = (0.0, math.inf)
PARAMS = {
    'drones': Param([], 'names of the drones, e.g. "drones:=[d0, d1, d2, d3]" (the {drone} of the topic templates)',
                    None, True, 'at least one; letters, digits and _, starting with a letter; no name twice'),
    'goal_topic': Param('/{drone}/goal_pose', "each drone's goal topic (geometry_msgs/PoseStamped), {drone} = its name",
                        None, True, 'contains {drone}'),
    'pose_topic': Param('/{drone}/pose', "each drone's pose topic, {drone} = its name", None, True,
                        'contains {drone}; not the goal_topic'),
    'pose_type': Param('pose', 'pose: geometry_msgs/PoseStamped | odometry: nav_msgs/Odometry', None, True,
                       'one of ' + ', '.join(POSE_TYPES)),
    'assignment': Param('min_total', 'travel distance minimized: the total or the longest flight', None, False,
                        'one of ' + ', '.join(ASSIGNMENTS)),
    'orientation': Param('body', 'goal orientation, body: +x = optical axis (as /camera_plan) | optical: REP-103 '
                                 'camera optical frame (z forward, x right, y down)', None, False,
                         'one of ' + ', '.join(ORIENTATIONS)),
    'frame_id': Param('map', 'frame of the plans and of the scene (the planner\'s frame_id)', None, False, 'not empty'),
    'fleet_frame': Param('map', "frame of the drones' poses and goals", None, False,
                         'not empty; fleet_x/y/z/yaw are 0 when it is frame_id'),
    'fleet_x': Param(0.0, 'm, origin of fleet_frame in frame_id'),
    'fleet_y': Param(0.0, 'm, origin of fleet_frame in frame_id'),
    'fleet_z': Param(0.0, 'm, origin of fleet_frame in frame_id'),
    'fleet_yaw': Param(0.0, 'rad, rotation of fleet_frame about the z axis of frame_id'),
    'pose_timeout': Param(2.0, 's: a drone whose last pose is older is silent and the dispatch fails', _M, False,
                          '> 0'),
    'min_standoff': Param(Feasibility.min_standoff, 'm from every scene point (the planner\'s rule)', _M),
    'min_altitude': Param(Feasibility.min_altitude, 'm above the ground (the planner\'s rule)', _M),
    'min_separation': Param(Feasibility.min_separation, 'm between cameras (the planner\'s rule)', _M),
    'require_scene': Param(True, 'refuse a plan when no scene arrived to check the stand-off (false: dispatch '
                                 'with a warning)'),
    'scene_timeout': Param(10.0, 's a plan that arrives before the scene waits for it', _M),
}
_NAME = re.compile(r'^[A-Za-z][A-Za-z0-9_]*$')


def check_parameters(values: dict) -> dict:
    """The parameter values ({name: value}, any subset of :data:`PARAMS`, complete at start)
    typed and checked; ValueError naming the first bad one."""
    v = typed_values(PARAMS, values)
    if 'drones' in v:
        drones = v['drones']
        if not drones:
            raise ValueError('drones must name at least one drone, e.g. -p "drones:=[d0, d1, d2, d3]"')
        bad = [d for d in drones if not _NAME.match(d)]
        if bad:
            raise ValueError(f'drone names must start with a letter and hold letters, digits and _ only: {bad}')
        twice = sorted({d for d in drones if drones.count(d) > 1})
        if twice:
            raise ValueError(f'drones names a drone twice: {twice}')
    for name in ('goal_topic', 'pose_topic'):
        if name in v and '{drone}' not in v[name]:
            raise ValueError(f"{name} must contain {{drone}} (each drone has its own topic), got {v[name]!r}")
    if 'goal_topic' in v and v['goal_topic'] == v.get('pose_topic'):
        raise ValueError('goal_topic and pose_topic must differ')
    if v.get('pose_type', 'pose') not in POSE_TYPES:
        raise ValueError(f"pose_type must be one of {', '.join(POSE_TYPES)}, got {v['pose_type']!r}")
    if v.get('assignment', 'min_total') not in ASSIGNMENTS:
        raise ValueError(f"assignment must be one of {', '.join(ASSIGNMENTS)}, got {v['assignment']!r}")
    if v.get('orientation', 'body') not in ORIENTATIONS:
        raise ValueError(f"orientation must be one of {', '.join(ORIENTATIONS)}, got {v['orientation']!r}")
    for name in ('frame_id', 'fleet_frame'):
        if v.get(name, 'x') == '':
            raise ValueError(f'{name} must not be empty')
    if v.get('pose_timeout', 1.0) <= 0.0:
        raise ValueError(f'pose_timeout must be > 0 s, got {v["pose_timeout"]}')
    Feasibility(**{n: v[n] for n in ('min_standoff', 'min_altitude', 'min_separation') if n in v})  # its checks
    if v.get('scene_timeout', 0.0) < 0.0:
        raise ValueError(f'scene_timeout must be >= 0, got {v["scene_timeout"]}')
    if all(k in v for k in ('frame_id', 'fleet_frame', 'fleet_x', 'fleet_y', 'fleet_z', 'fleet_yaw')):
        if v['frame_id'] == v['fleet_frame'] and not _transform(v).is_identity:
            raise ValueError(f"fleet_frame is frame_id ({v['frame_id']!r}): fleet_x, fleet_y, fleet_z and "
                             'fleet_yaw must be 0 (name the fleet frame to give it a transform)')
    return v


def _transform(v: dict) -> FleetTransform:
    return FleetTransform(v['fleet_x'], v['fleet_y'], v['fleet_z'], v['fleet_yaw'])


def _stamp(t) -> str:
    return f'{t.sec}.{t.nanosec:09d}'


class _Superseded(Exception):
    """A newer plan arrived while this one waited for the scene or the drones."""


class DispatcherNode(Node):
    """ROS 2 adapter: plans, scene and drone poses in, :mod:`vp_planner.fleet` calls, goals out."""

    def __init__(self) -> None:
        super().__init__('dispatcher')
        v = declare_typed(self, PARAMS, check_parameters)  # ValueError: exit 2
        refuse_bad_changes(self, PARAMS, check_parameters)

        self._drones: list[str] = list(v['drones'])
        # of the plans that arrive while one is dispatched, the newest waits
        self._plans = NewestWins('dispatcher-worker', self._dispatch_newest,
                                 lambda plan, exc: self._fail(plan, Msg.UNKNOWN, f'{type(exc).__name__}: {exc}',
                                                              self._values()),
                                 self.get_logger(), 'a newer plan arrived: it replaces the one waiting to be dispatched')
        self._lock = self._plans.lock
        self._scene: Optional[np.ndarray] = None
        self._scene_problem = ''
        # drone -> (monotonic time of the report, frame_id, position (3,))
        self._reports: dict[str, tuple[float, str, np.ndarray]] = {}
        self._nonfinite: dict[str, tuple] = {}  # drone -> its latest position, when that was not finite
        self._goal_pubs = {}
        pose_type = POSE_TYPES[v['pose_type']]
        for d in self._drones:
            self._goal_pubs[d] = self.create_publisher(PoseStamped, drone_topic(v['goal_topic'], d), LATCHED)
            self.create_subscription(pose_type, drone_topic(v['pose_topic'], d), partial(self._on_pose, d),
                                     qos_profile_sensor_data)
        self.assignment_pub = self.create_publisher(FleetAssignment, '/fleet/assignment', LATCHED)
        self.create_subscription(PointCloud2, '/scene/noisy_points', self._on_scene, LATCHED)
        self.create_subscription(PoseArray, '/camera_plan', self._on_plan, LATCHED)
        self._plans.start()
        self.get_logger().info(
            f'dispatcher ready: {len(self._drones)} drones ({", ".join(self._drones)}), {v["assignment"]}, '
            f'goals on {drone_topic(v["goal_topic"], "<drone>")} in {v["fleet_frame"]!r}; waiting for /camera_plan')

    # ---------------------------------------------------------------- parameters
    def _values(self) -> dict:
        return check_parameters({n: self.get_parameter(n).value for n in PARAMS})

    def on_shutdown(self, timeout: float) -> bool:
        """SIGINT/SIGTERM: the worker stops waiting; nothing else to wind down."""
        self._plans.stop()
        return True

    # ---------------------------------------------------------------- inputs
    def _on_pose(self, drone: str, msg) -> None:
        p = position_of(msg)
        if not np.all(np.isfinite(p)):
            self.get_logger().warn(f'drone {drone}: ignoring a pose with non-finite coordinates',
                                   throttle_duration_sec=5.0)
            with self._lock:  # named as such when the drone is missed (issue 19: it read "no pose yet")
                self._nonfinite[drone] = (float(p[0]), float(p[1]), float(p[2]))
            return
        with self._lock:
            self._nonfinite.pop(drone, None)
            first = drone not in self._reports
            self._reports[drone] = (time.monotonic(), msg.header.frame_id, p)
        if first:
            self.get_logger().info(f'drone {drone} reporting: first pose at ({p[0]:+.2f}, {p[1]:+.2f}, {p[2]:+.2f}) '
                                   f'in {msg.header.frame_id!r}')

    def _on_scene(self, msg: PointCloud2) -> None:
        frame = self._values()['frame_id']
        if msg.header.frame_id != frame:
            problem = (f'the cloud on /scene/noisy_points is in frame {msg.header.frame_id!r}, the plans in '
                       f'{frame!r} (frame_id); no transform is applied')
            self.get_logger().error(f'ignoring /scene/noisy_points: {problem}')
            with self._lock:
                self._scene_problem = problem
            return
        try:
            realizations = realizations_from_cloud(msg)
        except Exception as exc:  # a bad cloud must not take the node down
            self.get_logger().error(f'ignoring /scene/noisy_points: {exc}')
            with self._lock:
                self._scene_problem = f'the cloud on /scene/noisy_points is unusable: {exc}'
            return
        with self._lock:
            self._scene, self._scene_problem = realizations, ''
            self._lock.notify_all()
        self.get_logger().info(f'scene received: {realizations.shape[0]} realizations x '
                               f'{realizations.shape[1]} points (for the stand-off check)')

    def _on_plan(self, msg: PoseArray) -> None:
        self._plans.offer(msg)
        self.get_logger().info(f'plan received: {len(msg.poses)} poses (frame {msg.header.frame_id!r}, '
                               f'stamp {_stamp(msg.header.stamp)})')

    # ---------------------------------------------------------------- work
    def _dispatch_newest(self, plan: PoseArray) -> None:
        """The worker's work (:class:`NewestWins`): dispatch the plan unless a newer one arrives
        while it waits for the scene or the drones."""
        try:
            self._dispatch(plan)
        except _Superseded:
            if not self._plans.stopped:
                self.get_logger().info(f'plan {_stamp(plan.header.stamp)} superseded by a newer one before it '
                                       'was dispatched')

    def _wait(self, ready, timeout: float) -> None:
        """Wait (lock held) until ``ready()``, ``timeout`` s, a newer plan (_Superseded) or shutdown."""
        deadline = time.monotonic() + timeout
        while not ready():
            if self._plans.pending is not None or self._plans.stopped:
                raise _Superseded()
            left = deadline - time.monotonic()
            if left <= 0:
                return
            self._lock.wait(min(0.05, left))

    def _scene_now(self, timeout: float) -> Optional[np.ndarray]:
        with self._lock:
            self._wait(lambda: self._scene is not None, timeout)
            return self._scene

    def _positions(self, v: dict) -> tuple[dict, list, list]:
        """({drone: position}, silent drones as (name, description), drones reporting in another
        frame), after waiting up
        to pose_timeout for every drone to have reported within the last pose_timeout seconds."""
        timeout = v['pose_timeout']

        def fresh() -> dict:
            now = time.monotonic()
            return {d: r for d, r in self._reports.items() if now - r[0] <= timeout}

        with self._lock:
            self._wait(lambda: len(fresh()) == len(self._drones), timeout)
            reports = fresh()
            ages = {d: time.monotonic() - r[0] for d, r in self._reports.items()}
            nonfinite = dict(self._nonfinite)

        def why(d: str) -> str:
            if d in nonfinite:
                return f'{d} (reports a non-finite pose: ({", ".join(f"{x:g}" for x in nonfinite[d])}))'
            return f'{d} (last pose {ages[d]:.1f} s ago)' if d in ages else f'{d} (no pose yet)'
        silent = [(d, why(d)) for d in self._drones if d not in reports]
        wrong = [f'{d} reports in {r[1]!r}' for d, r in reports.items() if r[1] != v['fleet_frame']]
        return {d: r[2] for d, r in reports.items()}, silent, wrong

    def _base(self, plan: PoseArray, v: dict) -> FleetAssignment:
        out = FleetAssignment()
        out.header.stamp = self.get_clock().now().to_msg()
        out.header.frame_id = v['fleet_frame']
        out.plan_stamp, out.plan_frame_id = plan.header.stamp, plan.header.frame_id
        out.num_poses = len(plan.poses)
        out.assignment, out.orientation = v['assignment'], v['orientation']
        return out

    def _fail(self, plan: PoseArray, code: int, text: str, v: dict, silent: tuple = (),
              standoff_checked: bool = False) -> None:
        out = self._base(plan, v)
        out.error_code, out.error_msg = int(code), text
        out.silent_drones = [name for name, _ in silent]
        out.total_distance = out.max_distance = math.nan
        out.standoff_checked = standoff_checked
        self.get_logger().error(f'plan {_stamp(plan.header.stamp)} not dispatched: {text}')
        self.assignment_pub.publish(out)

    def _dispatch(self, plan: PoseArray) -> None:
        v = self._values()
        n, drones = len(plan.poses), self._drones
        if plan.header.frame_id != v['frame_id']:
            return self._fail(plan, Msg.WRONG_FRAME, f'the plan is in frame {plan.header.frame_id!r}, the '
                              f'dispatcher expects {v["frame_id"]!r} (frame_id); no transform is applied', v)
        if n == 0:
            return self._fail(plan, Msg.EMPTY_PLAN, 'the plan on /camera_plan has no poses', v)
        poses = msgs_to_poses(plan.poses)
        try:
            if not np.all(np.isfinite(poses)):
                raise ValueError('non-finite coordinates')
            cameras = poses_to_cameras(poses)
        except ValueError as exc:
            return self._fail(plan, Msg.EMPTY_PLAN, f'the plan has unusable poses: {exc}', v)
        if n > len(drones):
            return self._fail(plan, Msg.TOO_FEW_DRONES, f'the plan has {n} poses but there are only {len(drones)} '
                              f'drones ({", ".join(drones)}): every pose needs its own drone', v)
        scene = self._scene_now(v['scene_timeout'])
        if scene is None:
            why = self._scene_problem or f'nothing received on /scene/noisy_points within {v["scene_timeout"]:g} s'
            if v['require_scene']:
                return self._fail(plan, Msg.NO_SCENE, f'stand-off could not be checked: {why} (require_scene is '
                                  'true; set it false to dispatch without the stand-off check)', v)
            self.get_logger().warn(f'stand-off not checked ({why}): dispatching anyway (require_scene false)')
        problems = plan_problems(cameras, scene, v['min_standoff'], v['min_altitude'], v['min_separation'])
        if problems:
            more = f'; and {len(problems) - 5} more' if len(problems) > 5 else ''
            return self._fail(plan, Msg.INFEASIBLE_PLAN, 'the plan breaks the feasibility rules: '
                              + '; '.join(problems[:5]) + more, v, standoff_checked=scene is not None)
        positions, silent, wrong = self._positions(v)
        if silent:
            return self._fail(plan, Msg.DRONE_SILENT, f'no pose within pose_timeout {v["pose_timeout"]:g} s from '
                              f'{", ".join(text for _, text in silent)} on {drone_topic(v["pose_topic"], "<drone>")}: not guessing '
                              'where they are', v, silent=tuple(silent), standoff_checked=scene is not None)
        if wrong:
            return self._fail(plan, Msg.WRONG_FRAME, f'drone poses must be in fleet_frame {v["fleet_frame"]!r}: '
                              f'{", ".join(wrong)}; no transform is applied', v, standoff_checked=scene is not None)
        goals = _transform(v).poses_to_fleet(poses)
        goals[:, 3:] = goal_orientations(goals[:, 3:], v['orientation'])
        start = np.array([positions[d] for d in drones])
        try:
            result = assign(start, goals[:, :3], v['assignment'])
        except AssignmentError as exc:
            return self._fail(plan, Msg.UNKNOWN, str(exc), v, standoff_checked=scene is not None)
        self._publish(plan, v, goals, start, result, scene is not None)

    def _publish(self, plan: PoseArray, v: dict, goals: np.ndarray, start: np.ndarray, result,
                 standoff_checked: bool) -> None:
        out = self._base(plan, v)
        drones = self._drones
        lines = []
        for j, i in enumerate(result.drone_of_pose):
            drone = drones[int(i)]
            pose = pose_msg(goals[j])
            goal = PoseStamped()
            goal.header.stamp, goal.header.frame_id = out.header.stamp, v['fleet_frame']
            goal.pose = pose
            self._goal_pubs[drone].publish(goal)
            entry = DroneAssignment()
            entry.drone, entry.pose_index, entry.goal = drone, j, pose
            entry.start = point_msg(start[i])
            entry.distance = float(result.distances[j])
            out.entries.append(entry)
            lines.append(f'{drone} -> pose {j} ({entry.distance:.2f} m)')
        out.spare_drones = [drones[i] for i in result.spare(len(drones))]
        out.total_distance, out.max_distance = result.total, result.max_distance
        out.standoff_checked = standoff_checked
        self.assignment_pub.publish(out)
        spare = f'; spare: {", ".join(out.spare_drones)}' if out.spare_drones else ''
        self.get_logger().info(
            f'plan {_stamp(plan.header.stamp)} dispatched ({v["assignment"]}, total {result.total:.2f} m, '
            f'longest {result.max_distance:.2f} m): {", ".join(lines)}{spare}')

    def destroy_node(self) -> None:
        self._plans.stop()
        super().destroy_node()


def main(args=None) -> int:
    """Entry point ``dispatcher``: exit 2 with one line for a bad parameter, 0 after SIGINT/SIGTERM."""
    return run_node('dispatcher', DispatcherNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
