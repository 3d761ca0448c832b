"""The dispatcher node: each plan on ``/camera_plan`` becomes one timed route per drone, flown one
goal at a time (thin adapter around :mod:`vp_planner.routes`, :mod:`vp_planner.fleet` and
:mod:`vp_planner.missions`).

Subscribes (reliable, TRANSIENT_LOCAL, as the planner and scene publish them)

* ``/camera_plan`` (geometry_msgs/PoseArray, in ``frame_id``, +x of each pose = optical axis);
* ``/scene/noisy_points`` (sensor_msgs/PointCloud2, in ``frame_id``): the stand-off check, and the
  points the routes' legs keep ``min_standoff`` from;
* ``/fleet/capture`` (vp_interfaces/CaptureTrigger): with ``fly_on:=capture``, each trigger of the
  dispatched plan flies its routes once (the simulated fleet's wind realizations, one sortie each);

and each drone's pose, ``pose_topic`` with ``{drone}`` replaced by its name
(geometry_msgs/PoseStamped, or nav_msgs/Odometry with ``pose_type:=odometry``; in
``fleet_frame``), best effort (it matches reliable and best-effort publishers alike, as
autopilot bridges publish poses best effort).

For every plan it checks the plan (frame, poses, the planner's feasibility rules), reads the
drones' latest positions (a drone that has not reported within ``pose_timeout`` seconds makes
the dispatch fail, naming it: no guessing where it is), routes any number of drones through any
number of poses from there (:func:`vp_planner.routes.plan_routes`: the longest flight or the total
minimized within the flight model's budget, the drones ``separation`` apart at every moment), and
publishes, reliable and TRANSIENT_LOCAL,

* ``/fleet/assignment`` (vp_interfaces/FleetAssignment): each pose's drone, order and ETA, each
  drone's route (vp_interfaces/DroneRoute), the fleet's time on site, or the error (``error_code``
  + ``error_msg``; then nothing of this plan is published);
* each drone's route on ``route_topic`` (nav_msgs/Path in ``fleet_frame``, each pose stamped with
  its arrival; published again as each sortie starts);
* while a sortie is flown, each drone's next waypoint on ``goal_topic`` (geometry_msgs/PoseStamped,
  in ``fleet_frame``, orientation ``body`` or ``optical``) once it has arrived at the last one
  (within ``arrival_radius``) and its scheduled departure has come (the hover, and any wait of the
  separation, counted from its arrival); with an ``origin``, also as sensor_msgs/NavSatFix on
  ``goal_fix_topic``. A drone that falls silent mid-sortie ends the sortie (logged).

``~/write_missions`` (vp_interfaces/WriteMissions) writes the latest dispatched plan's missions
(QGroundControl plans, fleet.kml, fleet.json: :mod:`vp_planner.missions`) into a folder, given an
``origin``.

A plan that arrives before the scene waits ``scene_timeout`` seconds for it; without a scene the
stand-off rule cannot be checked: the plan is refused (``NO_SCENE``), or, with
``require_scene:=false``, dispatched with a warning (``standoff_checked`` false). Plans are
dispatched on a worker thread, one at a time (a sortie in flight is finished first); of the plans
that arrive meanwhile only the newest is kept. Signals, exit codes and parameter types follow
:mod:`vp_scene.node_runtime`.

A lifecycle node (rclpy.lifecycle; ``managed:=true`` waits unconfigured for a manager, the
default configures and activates itself at start): configure makes the topics, subscriptions and
the service, activate dispatches, deactivate ignores new plans and ends a sortie in flight,
cleanup destroys what configure made.
"""
from __future__ import annotations

import math
import re
import time
from dataclasses import dataclass, fields
from functools import partial
from pathlib import Path
from typing import Optional

import numpy as np
from geometry_msgs.msg import PoseArray, PoseStamped
from nav_msgs.msg import Path as PathMsg
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import NavSatFix, PointCloud2

from vp_interfaces.msg import CaptureTrigger, DroneAssignment, DroneRoute, FleetAssignment
from vp_interfaces.srv import WriteMissions
from vp_planner.feasibility import Feasibility
from vp_planner.fleet import ORIENTATIONS, FleetTransform, goal_orientations, plan_problems
from vp_planner.missions import MISSION_FILES, write_missions
from vp_planner.routes import OBJECTIVES, FleetRoutes, FlightModel, RouteError, plan_routes
from vp_scene.camera import poses_to_cameras
from vp_scene.cloud import realizations_from_cloud
from vp_scene.folders import OutputExists, ResultFolder
from vp_scene.geo import GeoError, GeoOrigin
from vp_scene.messages import (POSE_TYPES, drone_topic, msgs_to_poses, navsatfix_msg, path_msg, point_msg, pose_msg,
                               position_of)
from vp_scene.node_runtime import (LATCHED, MANAGED, NewestWins, Param, declare_typed, refuse_bad_changes, run_node,
                                   start_lifecycle, typed_values)

Msg = FleetAssignment
#: routes' refusals -> the assignment's codes
_ROUTE_ERRORS = {'DOES_NOT_FIT': Msg.DOES_NOT_FIT, 'SEPARATION_CONFLICT': Msg.SEPARATION_CONFLICT,
                 'NO_CLEAR_LEG': Msg.NO_CLEAR_LEG, 'INVALID_INPUT': Msg.DRONES_TOO_CLOSE}
FLY_ON = ('plan', 'capture')
#: plans whose capture triggers are remembered
_TRIGGERS_KEPT = 16


def _model_param(f) -> Param:
    low, high = f.metadata['range']
    unit = f' ({f.metadata["unit"]})' if f.metadata['unit'] else ''
    return Param(f.default, f'flight model: {f.metadata["help"]}{unit}', (low, high), False,
                 f'> {low:g}' if f.metadata['low_open'] else '')


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
    'route_topic': Param('/{drone}/route', "each drone's route (nav_msgs/Path), {drone} = its name", None, True,
                         'contains {drone}'),
    'goal_fix_topic': Param('/{drone}/goal_fix', "each drone's goal as sensor_msgs/NavSatFix (with an origin)", None,
                            True, 'contains {drone}'),
    'pose_type': Param('pose', 'pose: geometry_msgs/PoseStamped | odometry: nav_msgs/Odometry', None, True,
                       'one of ' + ', '.join(POSE_TYPES)),
    'assignment': Param('min_max', "the routes' objective: the longest flight (the fleet's time on site) | the total "
                                   'flight time', None, False, 'one of ' + ', '.join(OBJECTIVES)),
    'orientation': Param('body', 'goal orientation, body: +x = optical axis (as /camera_plan) | optical: REP-103 '
                                 'camera optical frame (z forward, x right, y down)', None, False,
                         'one of ' + ', '.join(ORIENTATIONS)),
    **{f.name: _model_param(f) for f in fields(FlightModel)},
    'separation': Param(Feasibility.min_separation, 'm between two drones at every moment of their routes', _M),
    'arrival_radius': Param(0.1, 'm: a drone this near its waypoint has arrived there', _M, False, '> 0'),
    'fly_on': Param('plan', 'plan: each plan is flown once, as it is dispatched | capture: once per /fleet/capture '
                            'trigger of it (one sortie a wind realization of the simulated fleet)', None, False,
                    'one of ' + ', '.join(FLY_ON)),
    'origin': Param('', "the map's origin LAT,LON,HEIGHT (WGS84 degrees, ellipsoidal m); '': none (no NavSatFix "
                        'goals, no missions)', None, False, "'' or three numbers, latitude in [-90, 90]"),
    'map_yaw': Param(0.0, "rad: the map's x axis from east, counter-clockwise", (-2 * math.pi, 2 * math.pi)),
    'frame_id': Param('map', 'frame of the plans and of the scene (the planner\'s frame_id)', None, False, 'not empty'),
    'fleet_frame': Param('map', "frame of the drones' poses and goals", None, False,
                         'not empty; fleet_x/y/z/yaw are 0 when it is frame_id'),
    'fleet_x': Param(0.0, 'm, origin of fleet_frame in frame_id'),
    'fleet_y': Param(0.0, 'm, origin of fleet_frame in frame_id'),
    'fleet_z': Param(0.0, 'm, origin of fleet_frame in frame_id'),
    'fleet_yaw': Param(0.0, 'rad, rotation of fleet_frame about the z axis of frame_id'),
    'pose_timeout': Param(2.0, 's: a drone whose last pose is older is silent and the dispatch fails', _M, False,
                          '> 0'),
    'min_standoff': Param(Feasibility.min_standoff, 'm from every scene point (the planner\'s rule; the legs keep it '
                                                    'too)', _M),
    'min_altitude': Param(Feasibility.min_altitude, 'm above the ground (the planner\'s rule)', _M),
    'min_separation': Param(Feasibility.min_separation, 'm between cameras (the planner\'s rule)', _M),
    'require_scene': Param(True, 'refuse a plan when no scene arrived to check the stand-off (false: dispatch '
                                 'with a warning)'),
    'scene_timeout': Param(10.0, 's a plan that arrives before the scene waits for it', _M),
    'managed': MANAGED,
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
    for name in ('goal_topic', 'pose_topic', 'route_topic', 'goal_fix_topic'):
        if name in v and '{drone}' not in v[name]:
            raise ValueError(f"{name} must contain {{drone}} (each drone has its own topic), got {v[name]!r}")
    if 'goal_topic' in v and v['goal_topic'] == v.get('pose_topic'):
        raise ValueError('goal_topic and pose_topic must differ')
    if v.get('pose_type', 'pose') not in POSE_TYPES:
        raise ValueError(f"pose_type must be one of {', '.join(POSE_TYPES)}, got {v['pose_type']!r}")
    if v.get('assignment', 'min_max') not in OBJECTIVES:
        raise ValueError(f"assignment must be one of {', '.join(OBJECTIVES)}, got {v['assignment']!r}")
    if v.get('fly_on', 'plan') not in FLY_ON:
        raise ValueError(f"fly_on must be one of {', '.join(FLY_ON)}, got {v['fly_on']!r}")
    if v.get('arrival_radius', 1.0) <= 0.0:
        raise ValueError(f'arrival_radius must be > 0 m, got {v["arrival_radius"]}')
    model = [f.name for f in fields(FlightModel)]
    FlightModel(**{n: v[n] for n in model if n in v})  # its checks (RouteError is a ValueError)
    if v.get('origin'):
        GeoOrigin.parse(v['origin'], yaw=v.get('map_yaw', 0.0))  # its checks (GeoError is a ValueError)
    if v.get('separation', 0.0) < 0.0:
        raise ValueError(f'separation must be >= 0 m, got {v["separation"]}')
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


def _model(v: dict) -> FlightModel:
    return FlightModel(**{f.name: v[f.name] for f in fields(FlightModel)})


@dataclass
class _Dispatched:
    """A dispatched plan: its stamp, the routes (in ``frame_id``), the drones' names, each route's
    poses (m, 7) in the fleet frame (the goals) and the plan's cameras (for the missions)."""

    plan: PoseArray
    fleet: FleetRoutes
    names: list
    goals: dict
    cameras: np.ndarray


class DispatcherNode(LifecycleNode):
    """ROS 2 adapter: plans, scene and drone poses in, :mod:`vp_planner.routes` calls, routes and
    goals out. A lifecycle node (``managed``): its topics and service exist once configured; it
    dispatches and flies only while active (a deactivation ends a sortie in flight)."""

    def __init__(self) -> None:
        super().__init__('dispatcher')
        v = declare_typed(self, PARAMS, check_parameters)  # ValueError: exit 2
        refuse_bad_changes(self, PARAMS, check_parameters)

        self._start = v  # the read-only parameters (topics, drones) as they were at start
        self._drones: list[str] = list(v['drones'])
        # of the plans that arrive while one is dispatched, the newest waits
        self._plans = NewestWins('dispatcher-worker', self._dispatch_newest,
                                 lambda plan, exc: self._fail(plan, Msg.UNKNOWN, f'{type(exc).__name__}: {exc}',
                                                              self._values()),
                                 self.get_logger(), 'a newer plan arrived: it replaces the one waiting to be dispatched')
        self._lock = self._plans.lock
        self._worker = False
        self._active = False
        self._entities: list = []  # (destroy, entity) of what on_configure made
        self._scene: Optional[np.ndarray] = None
        self._scene_problem = ''
        # drone -> (monotonic time of the report, frame_id, position (3,))
        self._reports: dict[str, tuple[float, str, np.ndarray]] = {}
        self._nonfinite: dict[str, tuple] = {}  # drone -> its latest position, when that was not finite
        self._triggers: dict[tuple, list] = {}  # plan stamp -> capture triggers not flown yet
        self._latest: Optional[_Dispatched] = None
        start_lifecycle(self, v['managed'])

    # ---------------------------------------------------------------- lifecycle
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """The topics, subscriptions and the missions service; the worker started once."""
        v = self._start

        def publisher(msg_type, topic: str):
            pub = self.create_lifecycle_publisher(msg_type, topic, LATCHED)
            self._entities.append((self.destroy_lifecycle_publisher, pub))
            return pub

        def subscribe(msg_type, topic: str, callback, qos=LATCHED) -> None:
            self._entities.append((self.destroy_subscription, self.create_subscription(msg_type, topic, callback, qos)))

        self._goal_pubs, self._route_pubs, self._fix_pubs = {}, {}, {}
        pose_type = POSE_TYPES[v['pose_type']]
        for d in self._drones:
            self._goal_pubs[d] = publisher(PoseStamped, drone_topic(v['goal_topic'], d))
            self._route_pubs[d] = publisher(PathMsg, drone_topic(v['route_topic'], d))
            self._fix_pubs[d] = publisher(NavSatFix, drone_topic(v['goal_fix_topic'], d))
            subscribe(pose_type, drone_topic(v['pose_topic'], d), partial(self._on_pose, d), qos_profile_sensor_data)
        self.assignment_pub = publisher(FleetAssignment, '/fleet/assignment')
        subscribe(PointCloud2, '/scene/noisy_points', self._on_scene)
        subscribe(PoseArray, '/camera_plan', self._on_plan)
        subscribe(CaptureTrigger, '/fleet/capture', self._on_capture)
        self._entities.append((self.destroy_service,
                               self.create_service(WriteMissions, '~/write_missions', self._on_write_missions)))
        if not self._worker:
            self._plans.start()
            self._worker = True
        self.get_logger().info('dispatcher configured')
        return super().on_configure(state)

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        v = self._values()
        with self._lock:
            self._active = True
        self.get_logger().info(
            f'dispatcher ready: {len(self._drones)} drones ({", ".join(self._drones)}), routes {v["assignment"]}, '
            f'flown on {v["fly_on"]}, goals on {drone_topic(v["goal_topic"], "<drone>")} in {v["fleet_frame"]!r}; '
            'waiting for /camera_plan')
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        with self._lock:
            self._active = False
            self._lock.notify_all()
        self.get_logger().info('dispatcher inactive: plans are not dispatched, a sortie in flight ends')
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        for destroy, entity in reversed(self._entities):
            destroy(entity)
        self._entities.clear()
        self.get_logger().info('dispatcher cleaned up: no topics until configured again')
        return super().on_cleanup(state)

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._plans.stop()
        return super().on_shutdown(state)

    # ---------------------------------------------------------------- parameters
    def _values(self) -> dict:
        return check_parameters({n: self.get_parameter(n).value for n in PARAMS})

    def wind_down(self, timeout: float) -> bool:
        """SIGINT/SIGTERM: the worker stops waiting (a sortie in flight is left); nothing else to wind down."""
        self._plans.stop()
        return True

    # ---------------------------------------------------------------- inputs
    def _on_pose(self, drone: str, msg) -> None:
        p = position_of(msg)
        if not np.all(np.isfinite(p)):
            self.get_logger().warn(f'drone {drone}: ignoring a pose with non-finite coordinates',
                                   throttle_duration_sec=5.0)
            with self._lock:  # named as such when the drone is missed (not as "no pose yet")
                self._nonfinite[drone] = (float(p[0]), float(p[1]), float(p[2]))
            return
        with self._lock:
            self._nonfinite.pop(drone, None)
            first = drone not in self._reports
            self._reports[drone] = (time.monotonic(), msg.header.frame_id, p)
            self._lock.notify_all()
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
        if not self._active:
            self.get_logger().warn(f'plan {_stamp(msg.header.stamp)} ignored: the dispatcher is inactive')
            return
        self._plans.offer(msg)
        self.get_logger().info(f'plan received: {len(msg.poses)} poses (frame {msg.header.frame_id!r}, '
                               f'stamp {_stamp(msg.header.stamp)})')

    def _on_capture(self, msg) -> None:
        key = _key(msg.plan_stamp)
        with self._lock:
            self._triggers.setdefault(key, []).append((_key(msg.header.stamp), int(msg.realization)))
            while len(self._triggers) > _TRIGGERS_KEPT:
                self._triggers.pop(next(iter(self._triggers)))
            self._lock.notify_all()

    # ---------------------------------------------------------------- work
    def _dispatch_newest(self, plan: PoseArray) -> None:
        """The worker's work (:class:`NewestWins`): dispatch the plan unless a newer one arrives
        while it waits for the scene or the drones; then fly it (``fly_on``)."""
        try:
            dispatched = self._dispatch(plan)
        except _Superseded:
            if not self._plans.stopped:
                self.get_logger().info(f'plan {_stamp(plan.header.stamp)} superseded by a newer one before it '
                                       'was dispatched')
            return
        if dispatched is None:
            return
        if self._values()['fly_on'] == 'plan':
            self._fly(dispatched, 'as dispatched')
            return
        key = _key(plan.header.stamp)
        while True:  # one sortie per capture trigger of this plan, until a newer plan or the end
            with self._lock:
                self._lock.wait_for(lambda: self._triggers.get(key) or self._plans.pending is not None
                                    or self._plans.stopped or not self._active)
                if self._plans.stopped or not self._active or not self._triggers.get(key):
                    return
                _, realization = self._triggers[key].pop(0)
            self._fly(dispatched, f'for capture {realization}')

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
        out.separation = v['separation']
        out.budget = _model(v).budget_s
        return out

    def _fail(self, plan: PoseArray, code: int, text: str, v: dict, silent: tuple = (),
              standoff_checked: bool = False) -> None:
        out = self._base(plan, v)
        out.error_code, out.error_msg = int(code), text
        out.silent_drones = [name for name, _ in silent]
        out.total_distance = out.max_distance = out.time_on_site = out.min_separation = math.nan
        out.standoff_checked = standoff_checked
        self.get_logger().error(f'plan {_stamp(plan.header.stamp)} not dispatched: {text}')
        self.assignment_pub.publish(out)

    def _dispatch(self, plan: PoseArray) -> Optional[_Dispatched]:
        """The plan checked, routed and its assignment published (None: refused, the error published)."""
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
        scene = self._scene_now(v['scene_timeout'])
        checked = scene is not None
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
                              + '; '.join(problems[:5]) + more, v, standoff_checked=checked)
        positions, silent, wrong = self._positions(v)
        if silent:
            return self._fail(plan, Msg.DRONE_SILENT, f'no pose within pose_timeout {v["pose_timeout"]:g} s from '
                              f'{", ".join(text for _, text in silent)} on {drone_topic(v["pose_topic"], "<drone>")}: not guessing '
                              'where they are', v, silent=tuple(silent), standoff_checked=checked)
        if wrong:
            return self._fail(plan, Msg.WRONG_FRAME, f'drone poses must be in fleet_frame {v["fleet_frame"]!r}: '
                              f'{", ".join(wrong)}; no transform is applied', v, standoff_checked=checked)
        transform = _transform(v)
        start = np.array([positions[d] for d in drones])
        try:  # routed in frame_id (the plan's and the scene's), flown in the fleet frame
            fleet = plan_routes(cameras, transform.points_to_map(start), _model(v), v['separation'], obstacles=scene,
                                standoff=v['min_standoff'] if checked else 0.0, objective=v['assignment'])
        except RouteError as exc:
            return self._fail(plan, _ROUTE_ERRORS.get(exc.code, Msg.UNKNOWN), str(exc), v, standoff_checked=checked)
        goals = transform.poses_to_fleet(poses)
        goals[:, 3:] = goal_orientations(goals[:, 3:], v['orientation'])
        dispatched = _Dispatched(plan, fleet, list(drones), {}, cameras)
        for r in fleet.routes:
            if len(r.views):
                dispatched.goals[drones[r.drone]] = _route_poses(r, goals, transform)
        self._publish(dispatched, v, start, checked)
        with self._lock:
            self._latest = dispatched
        return dispatched

    def _publish(self, dispatched: _Dispatched, v: dict, start: np.ndarray, standoff_checked: bool) -> None:
        out = self._base(dispatched.plan, v)
        drones, fleet = self._drones, dispatched.fleet
        entries, lines = {}, []
        for r in fleet.routes:
            if not len(r.views):
                continue
            name = drones[r.drone]
            poses = dispatched.goals[name]
            flown = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(r.points, axis=0), axis=1))])
            route = DroneRoute(drone=name, pose_indices=[int(j) for j in r.views], arrival=r.arrival.tolist(),
                               departure=r.departure.tolist(), flight_time=r.flight_time, distance=r.distance)
            route.path = path_msg(poses, r.arrival, v['fleet_frame'], out.header.stamp)
            out.routes.append(route)
            self._route_pubs[name].publish(route.path)
            for order, k in enumerate(np.flatnonzero(r.view_of_point >= 0)):
                j = int(r.view_of_point[k])
                entries[j] = DroneAssignment(drone=name, pose_index=j, order=order, start=point_msg(start[r.drone]),
                                             goal=pose_msg(poses[k]), distance=float(flown[k]), eta=float(r.arrival[k]))
            lines.append(f'{name}: poses {", ".join(str(int(j)) for j in r.views)} ({r.flight_time:.1f} s, '
                         f'{r.distance:.1f} m)')
        out.entries = [entries[j] for j in sorted(entries)]
        out.spare_drones = [drones[r.drone] for r in fleet.routes if not len(r.views)]
        out.total_distance = float(sum(r.distance for r in fleet.routes))
        out.max_distance = float(max(r.distance for r in fleet.routes))
        out.time_on_site, out.min_separation = fleet.time_on_site, fleet.min_separation
        out.standoff_checked = standoff_checked
        self.assignment_pub.publish(out)
        spare = f'; spare: {", ".join(out.spare_drones)}' if out.spare_drones else ''
        self.get_logger().info(
            f'plan {_stamp(dispatched.plan.header.stamp)} dispatched ({v["assignment"]}, time on site '
            f'{fleet.time_on_site:.1f} s, {_apart(fleet.min_separation)}, routed in {fleet.seconds:.2f} s): '
            f'{"; ".join(lines)}{spare}')

    def _fly(self, dispatched: _Dispatched, why: str) -> None:
        """One sortie of the dispatched routes: each drone's next waypoint once it has arrived at
        the last and its departure has come (module docstring); returns when every drone has
        landed, one fell silent, or at shutdown."""
        v = self._values()
        origin = GeoOrigin.parse(v['origin'], yaw=v['map_yaw']) if v['origin'] else None
        transform = _transform(v)
        stamp = self.get_clock().now().to_msg()
        routes = {self._drones[r.drone]: r for r in dispatched.fleet.routes if len(r.views)}
        for name, r in routes.items():
            self._route_pubs[name].publish(path_msg(dispatched.goals[name], r.arrival, v['fleet_frame'], stamp))
        t0 = time.monotonic()
        step = {name: 1 for name in routes}
        arrived: dict = {}

        def send(name: str) -> None:
            pose = dispatched.goals[name][step[name]]
            goal = PoseStamped(pose=pose_msg(pose))
            goal.header.stamp, goal.header.frame_id = self.get_clock().now().to_msg(), v['fleet_frame']
            self._goal_pubs[name].publish(goal)
            if origin is not None:
                where = origin.to_geodetic(transform.points_to_map(pose[:3]))
                self._fix_pubs[name].publish(navsatfix_msg(where, v['frame_id'], goal.header.stamp))

        for name in routes:
            send(name)
        self.get_logger().info(f'sortie of plan {_stamp(dispatched.plan.header.stamp)} {why}: '
                               f'{len(routes)} drones, time on site {dispatched.fleet.time_on_site:.1f} s planned')
        while step and not self._plans.stopped:
            with self._lock:
                self._lock.wait(0.05)
                reports, active = dict(self._reports), self._active
            if not active:
                self.get_logger().warn(f'sortie of plan {_stamp(dispatched.plan.header.stamp)} ended: the dispatcher '
                                       f'was deactivated ({", ".join(step)} in flight)')
                return
            now = time.monotonic()
            for name in list(step):
                r, k = routes[name], step[name]
                report = reports.get(name)
                if report is None or now - report[0] > v['pose_timeout']:
                    self.get_logger().error(f'sortie of plan {_stamp(dispatched.plan.header.stamp)} ended: drone '
                                            f'{name} fell silent on its way to waypoint {k} of its route')
                    return
                if np.linalg.norm(report[2] - dispatched.goals[name][k, :3]) > v['arrival_radius']:
                    continue
                arrived.setdefault(name, now)
                leave = max(t0 + r.departure[k], arrived[name] + r.departure[k] - r.arrival[k])
                if k == len(r.points) - 1:
                    del step[name]
                    self.get_logger().info(f'{name} landed {now - t0:.1f} s into the sortie ({r.landing:.1f} s planned)')
                elif now >= leave:
                    step[name] += 1
                    del arrived[name]
                    send(name)

    # ---------------------------------------------------------------- missions
    def _on_write_missions(self, request, response):
        """``~/write_missions``: the latest dispatched plan's missions into ``request.folder``."""
        Srv = WriteMissions.Response
        v = self._values()
        with self._lock:
            latest = self._latest
        try:
            if latest is None:
                response.error_code, response.error_msg = Srv.NO_ROUTES, 'no plan has been dispatched yet'
            elif not v['origin']:
                response.error_code = Srv.NO_ORIGIN
                response.error_msg = "the origin parameter is empty: give the map's LAT,LON,HEIGHT"
            else:
                origin = GeoOrigin.parse(v['origin'], yaw=v['map_yaw'])
                folder = ResultFolder(request.folder, MISSION_FILES, 'missions', request.overwrite).check()
                with folder:
                    written = write_missions(folder.stage, latest.fleet, latest.cameras, latest.names, origin)
                    folder.commit()
                response.files = [str(Path(request.folder) / p.name) for p in written]
                self.get_logger().info(f'missions of plan {_stamp(latest.plan.header.stamp)} written: '
                                       f'{", ".join(response.files)}')
        except OutputExists as exc:
            response.error_code, response.error_msg = Srv.OUTPUT_EXISTS, ' '.join(str(exc).split())
        except (OSError, GeoError) as exc:
            response.error_code, response.error_msg = Srv.NOT_WRITABLE, f'{request.folder}: {exc}'
        if response.error_code:
            self.get_logger().error(f'missions not written: {response.error_msg}')
        return response

    def destroy_node(self) -> None:
        self._plans.stop()
        super().destroy_node()


def _apart(distance: float) -> str:
    return f'drones at least {distance:.2f} m apart' if math.isfinite(distance) else 'one drone'


def _key(stamp) -> tuple:
    return (int(stamp.sec), int(stamp.nanosec))


def _route_poses(route, goals: np.ndarray, transform: FleetTransform) -> np.ndarray:
    """The route's waypoints (m, 7) in the fleet frame: each view's goal; a corner faces as the
    view it leads to (the return, as the last view)."""
    out = np.zeros((len(route.points), 7))
    out[:, :3] = transform.points_to_fleet(route.points)
    views = np.flatnonzero(route.view_of_point >= 0)
    for k in range(len(route.points)):
        later = views[views >= k]
        at = later[0] if len(later) else views[-1]
        out[k, 3:] = goals[int(route.view_of_point[at]), 3:]
        if k == at:
            out[k] = goals[int(route.view_of_point[at])]
    return out


def main(args=None) -> int:
    """Entry point ``dispatcher``: exit 2 with one line for a bad parameter, 0 after SIGINT/SIGTERM."""
    return run_node('dispatcher', DispatcherNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
