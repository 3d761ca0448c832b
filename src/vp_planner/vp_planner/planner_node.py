"""The planner node: a thin ROS 2 adapter around :func:`vp_planner.optimizers.plan_views`.

Subscribes ``/scene/noisy_points`` (all K wind realizations in one PointCloud2, in the node's
``frame_id``: a cloud in another frame is refused, no transform is applied), serves the
``vp_interfaces/action/PlanViews`` action on ``/plan_views`` and publishes the best plan,
latched, on ``/camera_plan`` (``geometry_msgs/PoseArray``, +x of each pose = optical axis), on
``/camera_plan/info`` (``vp_interfaces/CameraPlan``: the same header and poses with the plan's
reward, reward model and method, for the recon node) and camera frustums on
``/camera_plan/markers`` for RViz. With ``autostart`` it plans with its parameters as soon as a
scene arrives.

A goal may carry ``candidates``, poses in ``frame_id`` to choose the N cameras among
(:mod:`vp_planner.candidates`; the result's ``selected`` names them; another frame, NaN, fewer
than N or lawnmower: INVALID_CANDIDATES). A goal may carry a second sortie's context (README "A second sortie"): ``fixed_cameras``, the
cameras already flown, which every reward model counts with the plan, and ``reconstruction``,
what they reconstructed (its points mark the scene points within ``tau`` as reconstructed,
weighed ``reconstructed_weight``); both in ``frame_id`` (else INVALID_FIXED_CAMERAS /
INVALID_RECONSTRUCTION, as for NaN or more than the memory holds; more than
:data:`vp_planner.request.MAX_FIXED_CAMERAS` cameras already flown: INVALID_FIXED_CAMERAS).

Goals are validated in the execute callback and aborted with a named ``error_code`` and an
``error_msg`` (as nav2's planner servers do); one goal runs at a time, a second one while
planning is rejected. The plan is made in a process of its own (:mod:`vp_planner.plan_process`,
whose fork server starts when the first scene arrives), so a cancel is answered within
:data:`vp_planner.plan_process.POLL_S` of the execute callback seeing it, at any stage of the
plan (an evaluation of a hundred cameras, a GP fit, a KD-tree), and the next goal is served at
once. On SIGINT/SIGTERM a running goal is aborted once (``CANCELED``, "shutting down") and its
client answered before the node exits (:mod:`vp_scene.node_runtime`).

Simulated flights (:mod:`vp_planner.flight_planning`): a plan that makes them (``sim_flights``,
the goal's or the parameter's; -1: the method's default, egp's) flies them through the recon
node's ``/simulate_flights`` action (:class:`vp_planner.flight_client.ActionFlights`, handed to
:func:`vp_planner.plan_process.run_plan`: the planning process asks, the node flies), the first
flights as one goal and the confirmation's in goals of ``flight_workers``, each flight's wind
drawn with the variance of ``/scene/description`` (the wind model's default before one arrives);
feedback and a log line after every flight; the result says how the plan was chosen
(``chosen_by``), its flights' score and every flight. When
``/simulate_flights`` is not served within ``flight_server_timeout`` seconds (no recon node), the
plan is made without flights and ``flights_note`` says why. A cancel during the flights kills the
planning process and cancels the flights' goal, answered as any cancel.

A lifecycle node (rclpy.lifecycle; ``managed:=true`` waits unconfigured for a manager, the
default configures and activates itself at start): configure makes the topics and the action
server, activate accepts goals, deactivate rejects them (a running goal finishes), cleanup
destroys what configure made.
"""
from __future__ import annotations

import math
import os
import threading
import time
from typing import Optional

import numpy as np
import torch
from geometry_msgs.msg import PoseArray
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from sensor_msgs.msg import PointCloud2
from visualization_msgs.msg import MarkerArray

from vp_interfaces.action import PlanViews, SimulateFlights
from vp_interfaces.msg import CameraPlan, SceneDescription
from vp_planner.flight_client import ActionFlights
from vp_planner.gp import MODEL_NAMES
from vp_planner.optimizers import InvalidSceneError, PlanResult
from vp_planner.plan_process import PlanProcessDied, run_plan, warm
from vp_planner.request import (SETTINGS, BudgetTooLargeError, InvalidBudgetError, InvalidCandidatesError,
                                InvalidFixedCamerasError, InvalidNumCamerasError, InvalidReconstructionError,
                                PlanRequest, Setting, UnknownMethodError, UnknownRewardModelError, check_fields,
                                values_of_settings)
from vp_planner.space import NoFeasiblePlanError
from vp_scene.cloud import pointcloud2_to_numpy, realizations_from_cloud
from vp_scene.messages import (cameras_to_pose_array, camera_plan_msg, flight_record_msg, frustum_markers,
                               pose_array_to_cameras)
from vp_scene.wind import WindConfig
from vp_scene.node_runtime import (INT_MAX, LATCHED, MANAGED, Param, declare_typed, parameter_value,
                                   refuse_bad_changes, run_node, start_lifecycle, typed_values)


#: The library's refusals and the action's error codes (the first class a refusal is an instance of).
ERROR_CODES = (
    (InvalidNumCamerasError, PlanViews.Result.INVALID_NUM_CAMERAS),  # also more than the memory holds
    (UnknownMethodError, PlanViews.Result.UNKNOWN_METHOD),
    (BudgetTooLargeError, PlanViews.Result.BUDGET_TOO_LARGE),  # also a run the memory cannot hold
    (InvalidBudgetError, PlanViews.Result.INVALID_BUDGET),
    (UnknownRewardModelError, PlanViews.Result.UNKNOWN_REWARD_MODEL),
    (InvalidFixedCamerasError, PlanViews.Result.INVALID_FIXED_CAMERAS),  # NaN, above the bound, beyond the memory
    (InvalidReconstructionError, PlanViews.Result.INVALID_RECONSTRUCTION),
    (InvalidCandidatesError, PlanViews.Result.INVALID_CANDIDATES),  # NaN, fewer than N, lawnmower
    (NoFeasiblePlanError, PlanViews.Result.NO_FEASIBLE_PLAN),
)


def error_code(exc: Exception) -> int:
    """The PlanViews error code of a refusal of the library (PLANNER_FAILED for anything else)."""
    return next((code for cls, code in ERROR_CODES if isinstance(exc, cls)), PlanViews.Result.PLANNER_FAILED)


#: What a goal does to the parameters it may override (the rest of a parameter's description is
#: its request field's help).
GOAL_NOTES = {'num_cameras': 'autostart, and goals that leave it 0', 'method': 'autostart, and goals that leave it empty',
              'evaluations': 'goals that leave it 0', 'initial_evaluations': 'goals that leave it 0',
              'seed': 'goals with seed -1', 'reward': 'goals that leave it empty'}


def setting_param(setting: Setting) -> Param:
    """The node parameter of a request's setting (:data:`vp_planner.request.SETTINGS`): its
    default, help, inclusive range (no upper end: INT_MAX or inf) and what the range cannot say
    (excluded ends, choices, limits)."""
    rng = None
    if setting.range is not None:
        lo, hi = setting.range
        top = INT_MAX if isinstance(setting.default, int) else math.inf
        rng = (lo, top if hi is None else hi)
    said = [text for text in (setting.limits, _OPEN if setting.open else '',
                              'one of ' + ', '.join(setting.choices) if setting.choices else '') if text]
    note = GOAL_NOTES.get(setting.name)
    return Param(setting.default, setting.help + (f' ({note})' if note else ''), rng, False, '; '.join(said))


_OPEN = 'the ends are excluded'
#: The node's parameters (:class:`vp_scene.node_runtime.Param`): default (its type is enforced),
#: description, the range the node enforces, read_only where a change is not honoured. Those of a
#: plan request are its settings (:data:`vp_planner.request.SETTINGS`: name, default, help and
#: range from the request's field metadata), so that a new request field is a parameter too.
PARAMS = {
    **{s.name: setting_param(s) for s in SETTINGS},
    'num_threads': Param(1, 'torch threads (set at start)', (1, INT_MAX), True),
    'autostart': Param(False, 'plan with the parameters as soon as a scene arrives'),
    'managed': MANAGED,
    'frame_id': Param('map', 'frame of the plans; the scene cloud must be in it', None, False, 'not empty'),
    'scene_timeout': Param(10.0, 's a goal that arrives before the scene waits for it', (0.0, math.inf)),
    'flight_workers': Param(os.cpu_count() or 1, 'the recon node\'s flights at once: the confirmation\'s batch '
                            '(the first flights go as one batch; the recon node\'s cluster flies them)', (1, INT_MAX)),
    'flight_server_timeout': Param(5.0, 's a plan with simulated flights waits for /simulate_flights (then it is '
                                   'made without them)', (0.0, math.inf)),
}

#: The wind variance of the flights before a /scene/description arrives: the wind model's default.
DEFAULT_WIND_VARIANCE = WindConfig().variance


def request_values(params: dict, goal: Optional[PlanViews.Goal] = None) -> dict:
    """The flat request values (:data:`vp_planner.request.FLAT`) of the node's parameters
    ({name: typed value}, all of :data:`PARAMS`: :func:`vp_planner.request.values_of_settings`)
    and a goal's fields, which override their parameter unless left 0, empty or (seed, sim_flights) -1."""
    values = values_of_settings(params)
    if goal is not None:
        given = {'num_cameras': int(goal.num_cameras), 'method': goal.method, 'evaluations': int(goal.evaluations),
                 'initial_evaluations': int(goal.initial_evaluations), 'reward': goal.reward}
        values.update({name: value for name, value in given.items() if value})
        if goal.seed >= 0:
            values['seed'] = int(goal.seed)
        if goal.sim_flights >= 0:
            values['sim_flights'] = int(goal.sim_flights)
    return values


def request_of(params: dict, goal: Optional[PlanViews.Goal] = None) -> PlanRequest:
    """The one builder of the node's requests: the PlanRequest of its parameters and a goal
    (:func:`request_values`), validated by the request (its ValueError for a bad one)."""
    return PlanRequest.from_dict(request_values(params, goal))


def check_parameters(values: dict) -> dict:
    """The parameter values ({name: value}, any subset of :data:`PARAMS`: the others are their
    defaults) typed and checked; ValueError naming the first bad one. The request's fields are
    checked by the request (:func:`vp_planner.request.check_fields`: each alone, since a goal may
    override method, budget and initial design), the node's own here."""
    v = typed_values(PARAMS, values)
    check_fields(request_values({**{n: p.default for n, p in PARAMS.items()}, **v}))
    if v.get('num_threads', 1) < 1:
        raise ValueError('num_threads must be >= 1')
    if v.get('scene_timeout', 0.0) < 0.0:
        raise ValueError('scene_timeout must be >= 0')
    if v.get('frame_id', 'map') == '':
        raise ValueError('frame_id must not be empty')
    if v.get('flight_workers', 1) < 1 or v.get('flight_server_timeout', 0.0) < 0.0:
        raise ValueError(f'flight_workers must be >= 1 and flight_server_timeout >= 0 s, got '
                         f'{v.get("flight_workers", 1)}, {v.get("flight_server_timeout", 0.0)}')
    return v


class PlannerNode(LifecycleNode):
    """ROS 2 adapter: parameters and messages in, plans made in a process of their own
    (:func:`vp_planner.plan_process.run_plan`), plans out. A lifecycle node (``managed``): its
    topics and the action exist once configured; it accepts goals (and autostarts) only while
    active; a goal running at a deactivation finishes."""

    def __init__(self) -> None:
        super().__init__('planner')
        declare_typed(self, PARAMS, check_parameters)  # ValueError: exit 2
        refuse_bad_changes(self, PARAMS, check_parameters)
        torch.set_num_threads(self._param('num_threads'))  # leave the other cores to the recon

        self._realizations: Optional[np.ndarray] = None
        self._scene_problem = ''  # why the last cloud was refused
        self._scene_arrived = threading.Event()
        self._wind_variance = DEFAULT_WIND_VARIANCE  # the flights' winds: /scene/description's
        self._busy = threading.Lock()
        self._shutting_down = threading.Event()
        self._running = 0  # goals inside the execute callback (+ an autostart plan)
        self._running_lock = threading.Lock()
        self._cb = ReentrantCallbackGroup()
        self._active = False
        self._made: list = []  # what on_configure made, to destroy on cleanup
        start_lifecycle(self, self._param('managed'))

    # ---------------------------------------------------------------- lifecycle
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.plan_pub = self.create_lifecycle_publisher(PoseArray, '/camera_plan', LATCHED)
        self.info_pub = self.create_lifecycle_publisher(CameraPlan, '/camera_plan/info', LATCHED)
        self.marker_pub = self.create_lifecycle_publisher(MarkerArray, '/camera_plan/markers', LATCHED)
        scene = self.create_subscription(PointCloud2, '/scene/noisy_points', self._on_scene, LATCHED,
                                         callback_group=MutuallyExclusiveCallbackGroup())
        self._server = ActionServer(
            self, PlanViews, '/plan_views', execute_callback=self._execute,
            goal_callback=self._on_goal, cancel_callback=lambda _g: CancelResponse.ACCEPT,
            callback_group=self._cb)
        description = self.create_subscription(SceneDescription, '/scene/description', self._on_description,
                                                LATCHED, callback_group=MutuallyExclusiveCallbackGroup())
        self._flights = ActionClient(self, SimulateFlights, '/simulate_flights', callback_group=self._cb)
        self._made = [(self.destroy_lifecycle_publisher, p) for p in (self.plan_pub, self.info_pub, self.marker_pub)]
        self._made += [(self.destroy_subscription, scene), (lambda server: server.destroy(), self._server),
                       (self.destroy_subscription, description), (lambda client: client.destroy(), self._flights)]
        self.get_logger().info('planner configured')
        return super().on_configure(state)

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._active = True
        self.get_logger().info('planner ready: waiting for /scene/noisy_points, serving /plan_views')
        if self._param('autostart') and self._realizations is not None:
            threading.Thread(target=self._autostart, daemon=True).start()
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._active = False
        self.get_logger().info('planner inactive: goals are rejected')
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        for destroy, entity in reversed(self._made):
            destroy(entity)
        self._made = []
        self.get_logger().info('planner cleaned up: no topics and no /plan_views until configured again')
        return super().on_cleanup(state)

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._shutting_down.set()
        return super().on_shutdown(state)

    # ---------------------------------------------------------------- parameters
    def _param(self, name: str):
        return parameter_value(self, PARAMS, name)

    def _params(self) -> dict:
        """Every parameter now, typed."""
        return typed_values(PARAMS, {name: self.get_parameter(name).value for name in PARAMS})

    def _enter(self) -> None:
        with self._running_lock:
            self._running += 1

    def _leave(self) -> None:
        with self._running_lock:
            self._running -= 1

    def wind_down(self, timeout: float) -> bool:
        """SIGINT/SIGTERM: stop planning, let a running goal be aborted and its client answered;
        True when that happened within ``timeout`` seconds (node_runtime then tears down)."""
        self._shutting_down.set()
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self._running_lock:
                if self._running == 0:
                    break
            time.sleep(0.02)
        else:
            return False
        time.sleep(0.3)  # the executor sends the result response to the waiting client
        return True

    def _stopping(self) -> bool:
        return self._shutting_down.is_set()

    # ---------------------------------------------------------------- scene
    def _on_scene(self, msg: PointCloud2) -> None:
        frame = self._param('frame_id')
        if msg.header.frame_id != frame:
            self._scene_problem = (f'the cloud on /scene/noisy_points is in frame {msg.header.frame_id!r}, '
                                   f'the planner plans in {frame!r} (frame_id); no transform is applied')
            self.get_logger().error(f'ignoring /scene/noisy_points: {self._scene_problem}')
            return
        try:
            realizations = realizations_from_cloud(msg)
        except Exception as exc:  # a bad cloud must not take the node down
            self._scene_problem = f'the cloud on /scene/noisy_points is unusable: {exc}'
            self.get_logger().error(f'ignoring /scene/noisy_points: {exc}')
            return
        self._realizations, self._scene_problem = realizations, ''
        self._scene_arrived.set()
        warm()  # the planning processes' fork server imports the planner while goals may come
        k, p, _ = realizations.shape
        self.get_logger().info(f'scene received: {k} realizations x {p} points')
        if self._param('autostart') and self._active:
            threading.Thread(target=self._autostart, daemon=True).start()

    def _on_description(self, msg: SceneDescription) -> None:
        self._wind_variance = float(msg.wind_variance)

    def _autostart(self) -> None:
        if not self._busy.acquire(blocking=False):
            self.get_logger().warn('autostart skipped: a plan is already being computed')
            return
        self._enter()
        try:
            request = request_of(self._params())
            result = self._plan(request, progress=self._log_progress, should_stop=self._stopping,
                                on_flight=self._log_flight)
            if result is None:
                self.get_logger().info('autostart planning stopped: shutting down')
            else:
                self._publish_plan(result)
        except Exception as exc:
            self.get_logger().error(f'autostart planning failed: {exc}')
        finally:
            self._leave()
            self._busy.release()

    def _log_progress(self, done: int, total: int, best: float, weights) -> None:
        if done == total or done % max(1, total // 10) == 0:
            extra = '' if not weights else ' weights ' + ' '.join(f'{w:.2f}' for w in weights)
            self.get_logger().info(f'planning {done}/{total} best reward {best:.4f}{extra}')

    def _log_flight(self, done: int, total: int, score) -> None:
        d = score.draw
        what = (f'failed ({score.reason})' if score.failed else
                f'map Chamfer {score.chamfer:.4f} m, shape {score.chamfer_shape:.4f} m, {score.images} images')
        self.get_logger().info(f'simulated flight {done}/{total}: {what} (n_wind {d.n_wind:+.4f}, capture seed '
                               f'{d.capture_seed}, {score.seconds:.1f} s)')

    # ---------------------------------------------------------------- planning
    def _simulator(self, request: PlanRequest, should_stop):
        """(the flights' simulator, '') for a plan that makes simulated flights, once
        /simulate_flights is served (waiting up to ``flight_server_timeout`` s); (None, why) when it
        is not; (None, '') for a plan without flights (the library's note stands)."""
        if not request.flights.flights_of(request.method) or request.candidates.poses is not None:
            return None, ''
        deadline = time.monotonic() + self._param('flight_server_timeout')
        while not self._flights.server_is_ready():
            if should_stop() or time.monotonic() > deadline:
                why = (f'/simulate_flights is not served (no recon node within '
                       f'{self._param("flight_server_timeout"):g} s): the cheap reward chose, without simulated flights')
                self.get_logger().warn(why)
                return None, why
            time.sleep(0.05)
        rs = request.reward
        return ActionFlights(self._flights, request.flights.settings(), rs.position_sigma, rs.attitude_sigma,
                             rs.ground_control, request.cameras.fov, self._param('flight_workers'),
                             self._wind_variance, log=self.get_logger().info), ''

    def _plan(self, request: PlanRequest, progress, should_stop, on_flight=None) -> Optional[PlanResult]:
        """The plan of ``request`` on the scene, made in a process of its own
        (:func:`vp_planner.plan_process.run_plan`), its simulated flights flown through
        /simulate_flights; None when ``should_stop()`` ended it."""
        realizations = self._realizations
        assert realizations is not None
        flights = request.flights.flights_of(request.method)
        self.get_logger().info(f'planning {request.cameras.num_cameras} cameras with {request.method} '
                               f'({request.reward.name} reward): {request.evaluations} evaluations'
                               + (f', {flights} simulated flights' if flights else '') + f', seed {request.seed}')
        simulator, why = self._simulator(request, should_stop)
        result = run_plan(request, realizations, progress, should_stop, threads=self._param('num_threads'),
                          simulator=simulator, on_flight=on_flight)
        if result is not None and why and result.flights_note:
            result.flights_note = why
        return result

    def _publish_plan(self, result: PlanResult, fixed: Optional[np.ndarray] = None,
                      candidates: Optional[PoseArray] = None) -> PoseArray:
        """/camera_plan/info first (so that a recon has the reward, and the cameras already flown
        of a second sortie, when the plan arrives), then /camera_plan and the markers: one header,
        one set of poses (among ``candidates``: the chosen candidates' own poses, roll and all)."""
        msg = cameras_to_pose_array(result.cameras, self._param('frame_id'), self.get_clock().now().to_msg())
        if candidates is not None and result.selected is not None:
            msg.poses = [candidates.poses[i] for i in result.selected]
        self.info_pub.publish(camera_plan_msg(msg, result.reward, result.reward_model, result.method,
                                              result.evaluations, result.seconds, fixed))
        self.plan_pub.publish(msg)
        self.marker_pub.publish(frustum_markers(result.cameras, msg.header.frame_id,
                                                msg.header.stamp, self._param('fov')))
        self.get_logger().info(
            f'published /camera_plan: {len(msg.poses)} cameras, {result.reward_model} reward {result.reward:.4f}'
            + (f' with {result.fixed_cameras} cameras already flown' if result.fixed_cameras else '')
            + (f' among {len(candidates.poses)} candidates' if candidates is not None else '')
            + f' ({result.method}, {result.evaluations} evaluations'
            + (f', by {len(result.parts)} parts of ' + '+'.join(str(p['cameras']) for p in result.parts) + ' cameras'
               if result.parts else '')
            + (f', chosen by {len(result.flights)} simulated flights: map Chamfer {result.flight_score:.4f} m'
               if result.chosen_by == 'flights' else '')
            + f', {result.seconds:.1f} s)' + (f'; {result.flights_note}' if result.flights_note else ''))
        return msg

    # ---------------------------------------------------------------- action
    def _on_goal(self, goal: PlanViews.Goal) -> GoalResponse:
        if not self._active:
            self.get_logger().warn('rejecting goal: the planner is inactive (lifecycle)')
            return GoalResponse.REJECT
        if self._stopping():
            self.get_logger().warn('rejecting goal: shutting down')
            return GoalResponse.REJECT
        if self._busy.locked():
            self.get_logger().warn('rejecting goal: a plan is already being computed')
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _wait_for_scene(self) -> bool:
        """Latched topics from several nodes arrive in any order at start-up: give the scene
        ``scene_timeout`` seconds (less when the node shuts down)."""
        deadline = time.monotonic() + self._param('scene_timeout')
        while self._realizations is None and not self._stopping():
            left = deadline - time.monotonic()
            if left <= 0:
                break
            self._scene_arrived.wait(min(0.1, left))
        return self._realizations is not None

    def _goal_poses(self, msg: PoseArray, what: str) -> Optional[np.ndarray]:
        """A goal's PoseArray ``what`` (fixed_cameras, candidates) as cameras (M, 6), None when it
        is empty; ValueError for another frame or unusable poses (the library refuses NaN)."""
        if not msg.poses:
            return None
        frame = self._param('frame_id')
        if msg.header.frame_id != frame:
            raise ValueError(f'{what} are in frame {msg.header.frame_id!r}, the planner plans in {frame!r} '
                             f'(frame_id); no transform is applied')
        return pose_array_to_cameras(msg.poses)

    def _goal_reconstruction(self, msg: PointCloud2) -> Optional[np.ndarray]:
        """A goal's reconstruction (Q, 3), None when empty; ValueError for another frame or an
        unreadable cloud (the library refuses NaN and too many points)."""
        if int(msg.width) * int(msg.height) == 0:
            return None
        frame = self._param('frame_id')
        if msg.header.frame_id != frame:
            raise ValueError(f'the reconstruction is in frame {msg.header.frame_id!r}, the planner plans in {frame!r} '
                             f'(frame_id); no transform is applied')
        return pointcloud2_to_numpy(msg)[0]

    def _execute(self, goal_handle) -> PlanViews.Result:
        self._enter()
        try:
            return self._execute_goal(goal_handle)
        finally:
            self._leave()

    def _execute_goal(self, goal_handle) -> PlanViews.Result:
        goal = goal_handle.request
        result = PlanViews.Result()

        def finish(code: int, text: str, succeed: bool = False) -> PlanViews.Result:
            """The one terminal transition of this goal (never a second one)."""
            result.error_code, result.error_msg = code, text
            if goal_handle.is_active:
                if succeed:
                    goal_handle.succeed()
                elif goal_handle.is_cancel_requested:
                    goal_handle.canceled()
                else:
                    goal_handle.abort()
            return result

        def abort(code: int, text: str) -> PlanViews.Result:
            self.get_logger().error(f'goal aborted: {text}')
            return finish(code, text)

        try:  # the request's own checks (vp_planner.request), mapped to the action's error codes
            request = request_of(self._params(), goal)
        except ValueError as exc:
            return abort(error_code(exc), str(exc))
        try:
            fixed = self._goal_poses(goal.fixed_cameras, 'fixed_cameras')
        except ValueError as exc:
            return abort(PlanViews.Result.INVALID_FIXED_CAMERAS, str(exc))
        try:
            candidates = self._goal_poses(goal.candidates, 'candidates')
        except ValueError as exc:
            return abort(PlanViews.Result.INVALID_CANDIDATES, str(exc))
        try:
            reconstruction = self._goal_reconstruction(goal.reconstruction)
        except ValueError as exc:
            return abort(PlanViews.Result.INVALID_RECONSTRUCTION, str(exc))
        try:  # NaN poses, a non-finite reconstruction, candidates fewer than N or for lawnmower
            request = request.replace(fixed_cameras=fixed, reconstruction=reconstruction, candidates=candidates)
        except ValueError as exc:
            return abort(error_code(exc), str(exc))
        if not self._wait_for_scene():
            if self._stopping():
                return abort(PlanViews.Result.CANCELED, 'the planner is shutting down')
            return abort(PlanViews.Result.NO_SCENE, self._scene_problem
                         or 'no scene yet: nothing received on /scene/noisy_points')
        if not self._busy.acquire(blocking=False):
            return abort(PlanViews.Result.UNKNOWN, 'a plan is already being computed')

        def should_stop() -> bool:
            return goal_handle.is_cancel_requested or self._stopping()

        made = [0, 0]  # evaluations and simulated flights the plan has made
        fb = PlanViews.Feedback()  # the last feedback: a flight's keeps the evaluations' figures
        fb.last_flight_chamfer = math.nan

        def progress(done: int, total: int, best: float, weights) -> None:
            made[0] = done
            if should_stop():
                return
            fb.evaluations_done, fb.evaluations_total, fb.best_reward = done, total, float(best)
            if weights:
                fb.ensemble_weights = [float(w) for w in weights]
                fb.ensemble_models = list(MODEL_NAMES)
            goal_handle.publish_feedback(fb)

        def flown(done: int, total: int, score) -> None:
            made[1] = done
            self._log_flight(done, total, score)
            if should_stop():
                return
            fb.flights_done, fb.flights_total = done, total
            fb.last_flight_chamfer = math.nan if score.failed or score.chamfer is None else float(score.chamfer)
            goal_handle.publish_feedback(fb)

        try:
            start = time.monotonic()
            plan = self._plan(request, progress, should_stop, on_flight=flown)
            if plan is None:
                why = 'cancelled' if goal_handle.is_cancel_requested else 'the planner is shutting down'
                text = f'{why} after {made[0]} evaluations' + (f' and {made[1]} simulated flights' if made[1] else '')
                result.evaluations = int(made[0])
                self.get_logger().info(text)
                return finish(PlanViews.Result.CANCELED, text)
            msg = self._publish_plan(plan, fixed, goal.candidates if candidates is not None else None)
            result.plan = msg
            result.cameras = [float(x) for x in np.asarray(plan.cameras).ravel()]
            result.reward = float(plan.reward)
            result.reward_model = plan.reward_model
            result.trace = [float(x) for x in plan.trace]
            result.planning_time = time.monotonic() - start
            result.evaluations = int(plan.evaluations)
            result.selected = [int(i) for i in plan.selected or []]
            result.chosen_by, result.flights_note = plan.chosen_by, plan.flights_note
            result.flight_score = math.nan if plan.flight_score is None else float(plan.flight_score)
            result.flights = [flight_record_msg(r) for r in plan.flights or []]
            return finish(PlanViews.Result.NONE, '', succeed=True)
        except InvalidSceneError as exc:
            return abort(PlanViews.Result.NO_SCENE, f'unusable scene: {exc}')
        except ValueError as exc:  # the library's refusals that need the scene or the memory
            code = error_code(exc)
            return abort(code, str(exc) if code != PlanViews.Result.PLANNER_FAILED else f'{type(exc).__name__}: {exc}')
        except PlanProcessDied as exc:
            return abort(PlanViews.Result.PLANNER_FAILED, str(exc))
        except Exception as exc:  # keep serving whatever happened inside the optimizer
            return abort(PlanViews.Result.PLANNER_FAILED, f'{type(exc).__name__}: {exc}')
        finally:
            self._busy.release()


def main(args=None) -> int:
    """Entry point ``planner``: exit 2 with one line for a bad parameter, 0 after SIGINT/SIGTERM."""
    return run_node('planner', PlannerNode, args, num_threads=4)


if __name__ == '__main__':
    raise SystemExit(main())
