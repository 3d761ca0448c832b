"""The planner node: a thin ROS 2 adapter around :func:`vp_planner.optimizers.plan_views`.

Subscribes ``/scene/noisy_points`` (all K wind realizations in one PointCloud2), serves the
``vp_interfaces/action/PlanViews`` action on ``/plan_views`` and publishes the best plan on
``/camera_plan`` (``geometry_msgs/PoseArray``, frame ``map``, +x of each pose = optical axis)
and camera frustums on ``/camera_plan/markers`` for RViz. With ``autostart`` it plans with its
parameters as soon as a scene arrives.

Goals are validated in the execute callback and aborted with a named ``error_code`` and an
``error_msg`` (as nav2's planner servers do); one goal runs at a time, a second one while
planning is rejected. Cancel is honoured within one reward evaluation.
"""
from __future__ import annotations

import math
import threading
import time
from typing import Optional

import numpy as np
import rclpy
import torch
from geometry_msgs.msg import Point, Pose, PoseArray
from rcl_interfaces.msg import SetParametersResult
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from vp_interfaces.action import PlanViews
from vp_planner.gp import MODEL_NAMES
from vp_planner.optimizers import (METHODS, InvalidBudgetError, InvalidNumCamerasError, InvalidSceneError,
                                   NoFeasiblePlanError, PlanResult, UnknownMethodError, plan_views,
                                   validate_request)
from vp_planner.reward_models import DEFAULT_REWARD_MODEL, REWARD_MODELS, check_reward_model
from vp_scene.camera import cameras_to_poses, rotation_matrix
from vp_scene.cloud import realizations_from_cloud

LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


class Cancelled(Exception):
    """Raised inside the progress callback when the goal was cancelled."""


def frustum_markers(cameras: np.ndarray, frame_id: str, stamp, fov: float,
                    depth: float = 0.4, aspect: float = 4.0 / 3.0) -> MarkerArray:
    """One LINE_LIST frustum (apex at c, far plane at ``depth`` along v) and a label a camera."""
    out = MarkerArray()
    clear = Marker()
    clear.action = Marker.DELETEALL
    out.markers.append(clear)
    half_w = depth * math.tan(fov / 2.0)
    half_h = half_w / aspect
    for i, cam in enumerate(np.asarray(cameras, dtype=float)):
        c = cam[:3]
        rot = rotation_matrix(cam[3:6])  # columns: body x (optical axis), y (left), z (up)
        x, y, z = rot[:, 0], rot[:, 1], rot[:, 2]
        corners = [c + depth * x + sy * half_w * y + sz * half_h * z
                   for sy, sz in ((1, 1), (-1, 1), (-1, -1), (1, -1))]
        m = Marker()
        m.header.frame_id = frame_id
        m.header.stamp = stamp
        m.ns = 'frustums'
        m.id = i
        m.type = Marker.LINE_LIST
        m.action = Marker.ADD
        m.pose.orientation.w = 1.0
        m.scale.x = 0.01
        m.color = ColorRGBA(r=1.0, g=0.55, b=0.0, a=1.0)
        segments = []
        for k in range(4):
            segments += [c, corners[k], corners[k], corners[(k + 1) % 4]]
        m.points = [Point(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in segments]
        out.markers.append(m)
        label = Marker()
        label.header = m.header
        label.ns = 'labels'
        label.id = i
        label.type = Marker.TEXT_VIEW_FACING
        label.action = Marker.ADD
        label.pose.position = Point(x=float(c[0]), y=float(c[1]), z=float(c[2]) + 0.1)
        label.pose.orientation.w = 1.0
        label.scale.z = 0.1
        label.color = ColorRGBA(r=1.0, g=1.0, b=1.0, a=1.0)
        label.text = f'cam {i}'
        out.markers.append(label)
    return out


class PlannerNode(Node):
    """ROS 2 adapter: parameters and messages in, :func:`plan_views` calls, plans out."""

    def __init__(self) -> None:
        super().__init__('planner')
        self.declare_parameter('num_cameras', 4)
        self.declare_parameter('method', 'egp')
        self.declare_parameter('evaluations', 100)
        self.declare_parameter('initial_evaluations', 50)
        self.declare_parameter('seed', 0)
        self.declare_parameter('reward', DEFAULT_REWARD_MODEL)
        self.declare_parameter('image_width', 2000)
        self.declare_parameter('image_height', 1500)
        self.declare_parameter('bo_mode', 'trust_region')
        self.declare_parameter('structured_init', 20)
        self.declare_parameter('arc_spacing', math.radians(30.0))
        self.declare_parameter('num_threads', 1)
        self.declare_parameter('autostart', False)
        self.declare_parameter('min_standoff', 0.5)
        self.declare_parameter('min_altitude', 0.3)
        self.declare_parameter('min_separation', 0.5)
        self.declare_parameter('fov', math.pi / 2)
        self.declare_parameter('theta_match', math.pi / 4)
        self.declare_parameter('frame_id', 'map')
        self.declare_parameter('scene_timeout', 10.0)
        self.add_on_set_parameters_callback(self._check_parameters)
        bad = self._check_parameters([self.get_parameter(n) for n in (
            'num_cameras', 'method', 'evaluations', 'initial_evaluations', 'fov', 'theta_match',
            'min_standoff', 'min_altitude', 'min_separation', 'reward', 'image_width', 'image_height',
            'bo_mode', 'structured_init', 'arc_spacing', 'num_threads')])
        if not bad.successful:
            raise ValueError(bad.reason)
        torch.set_num_threads(int(self._param('num_threads')))  # leave the other cores to the recon

        self._realizations: Optional[np.ndarray] = None
        self._scene_arrived = threading.Event()
        self._busy = threading.Lock()
        self._cb = ReentrantCallbackGroup()
        self.plan_pub = self.create_publisher(PoseArray, '/camera_plan', LATCHED)
        self.marker_pub = self.create_publisher(MarkerArray, '/camera_plan/markers', LATCHED)
        self.create_subscription(PointCloud2, '/scene/noisy_points', self._on_scene, LATCHED,
                                 callback_group=MutuallyExclusiveCallbackGroup())
        self._server = ActionServer(
            self, PlanViews, '/plan_views', execute_callback=self._execute,
            goal_callback=self._on_goal, cancel_callback=lambda _g: CancelResponse.ACCEPT,
            callback_group=self._cb)
        self.get_logger().info('planner ready: waiting for /scene/noisy_points, serving /plan_views')

    # ---------------------------------------------------------------- parameters
    def _check_parameters(self, params) -> SetParametersResult:
        for p in params:
            v = p.value
            if p.name == 'num_cameras' and v < 2:
                return SetParametersResult(successful=False, reason='num_cameras must be >= 2')
            if p.name == 'method' and v not in METHODS:
                return SetParametersResult(
                    successful=False, reason=f'unknown method {v!r}; one of {", ".join(METHODS)}')
            if p.name == 'reward' and v not in REWARD_MODELS:
                return SetParametersResult(
                    successful=False, reason=f'unknown reward model {v!r}; one of {", ".join(REWARD_MODELS)}')
            if p.name == 'bo_mode' and v not in ('trust_region', 'global'):
                return SetParametersResult(successful=False, reason="bo_mode must be 'trust_region' or 'global'")
            if p.name == 'structured_init' and v < 0:
                return SetParametersResult(successful=False, reason='structured_init must be >= 0')
            if p.name == 'arc_spacing' and not 0.0 < v < 2 * math.pi:
                return SetParametersResult(successful=False, reason='arc_spacing must be in (0, 2 pi) rad')
            if p.name == 'num_threads' and v < 1:
                return SetParametersResult(successful=False, reason='num_threads must be >= 1')
            if p.name in ('image_width', 'image_height') and v < 16:
                return SetParametersResult(successful=False, reason=f'{p.name} must be >= 16 pixels')
            if p.name in ('evaluations', 'initial_evaluations') and v < 1:
                return SetParametersResult(successful=False, reason=f'{p.name} must be >= 1')
            if p.name in ('fov', 'theta_match') and not 0.0 < v < math.pi:
                return SetParametersResult(successful=False, reason=f'{p.name} must be in (0, pi)')
            if p.name in ('min_standoff', 'min_altitude', 'min_separation') and v < 0.0:
                return SetParametersResult(successful=False, reason=f'{p.name} must be >= 0')
        return SetParametersResult(successful=True)

    def _param(self, name: str):
        return self.get_parameter(name).value

    # ---------------------------------------------------------------- scene
    def _on_scene(self, msg: PointCloud2) -> None:
        try:
            realizations = realizations_from_cloud(msg)
        except Exception as exc:  # a bad cloud must not take the node down
            self.get_logger().error(f'ignoring /scene/noisy_points: {exc}')
            return
        self._realizations = realizations
        self._scene_arrived.set()
        k, p, _ = realizations.shape
        self.get_logger().info(f'scene received: {k} realizations x {p} points')
        if self._param('autostart'):
            threading.Thread(target=self._autostart, daemon=True).start()

    def _autostart(self) -> None:
        if not self._busy.acquire(blocking=False):
            self.get_logger().warn('autostart skipped: a plan is already being computed')
            return
        try:
            result = self._plan(self._param('method'), self._param('num_cameras'),
                                self._param('evaluations'), self._param('initial_evaluations'),
                                self._param('seed'), self._param('reward'), progress=self._log_progress)
            self._publish_plan(result)
        except Exception as exc:
            self.get_logger().error(f'autostart planning failed: {exc}')
        finally:
            self._busy.release()

    def _log_progress(self, done: int, total: int, best: float, weights) -> bool:
        if done == total or done % max(1, total // 10) == 0:
            extra = '' if not weights else ' weights ' + ' '.join(f'{w:.2f}' for w in weights)
            self.get_logger().info(f'planning {done}/{total} best reward {best:.4f}{extra}')
        return rclpy.ok()

    # ---------------------------------------------------------------- planning
    def _plan(self, method: str, num_cameras: int, evaluations: int, initial: int, seed: int, reward: str,
              progress) -> PlanResult:
        realizations = self._realizations
        assert realizations is not None
        self.get_logger().info(f'planning {num_cameras} cameras with {method} ({reward} reward): '
                               f'{evaluations} evaluations, seed {seed}')
        return plan_views(
            method, realizations, num_cameras, evaluations=evaluations,
            initial_evaluations=initial, seed=seed, callback=progress,
            min_standoff=self._param('min_standoff'), min_altitude=self._param('min_altitude'),
            min_separation=self._param('min_separation'), fov=self._param('fov'),
            theta_match=self._param('theta_match'), reward=reward,
            image_size=(self._param('image_width'), self._param('image_height')),
            bo_mode=self._param('bo_mode'), structured_init=self._param('structured_init'),
            arc_spacing=self._param('arc_spacing'))

    def _pose_array(self, cameras: np.ndarray) -> PoseArray:
        msg = PoseArray()
        msg.header.frame_id = self._param('frame_id')
        msg.header.stamp = self.get_clock().now().to_msg()
        for x, y, z, qx, qy, qz, qw in cameras_to_poses(cameras):
            pose = Pose()
            pose.position.x, pose.position.y, pose.position.z = float(x), float(y), float(z)
            pose.orientation.x, pose.orientation.y = float(qx), float(qy)
            pose.orientation.z, pose.orientation.w = float(qz), float(qw)
            msg.poses.append(pose)
        return msg

    def _publish_plan(self, result: PlanResult) -> PoseArray:
        msg = self._pose_array(result.cameras)
        self.plan_pub.publish(msg)
        self.marker_pub.publish(frustum_markers(result.cameras, msg.header.frame_id,
                                                msg.header.stamp, self._param('fov')))
        self.get_logger().info(
            f'published /camera_plan: {len(msg.poses)} cameras, {result.reward_model} reward {result.reward:.4f} '
            f'({result.method}, {result.evaluations} evaluations, {result.seconds:.1f} s)')
        return msg

    # ---------------------------------------------------------------- action
    def _on_goal(self, goal: PlanViews.Goal) -> GoalResponse:
        if self._busy.locked():
            self.get_logger().warn('rejecting goal: a plan is already being computed')
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _execute(self, goal_handle) -> PlanViews.Result:
        goal = goal_handle.request
        result = PlanViews.Result()
        method = goal.method or self._param('method')
        evaluations = goal.evaluations or self._param('evaluations')
        initial = goal.initial_evaluations or self._param('initial_evaluations')
        seed = goal.seed if goal.seed >= 0 else self._param('seed')
        reward = goal.reward or self._param('reward')

        def abort(code: int, text: str) -> PlanViews.Result:
            self.get_logger().error(f'goal aborted: {text}')
            result.error_code, result.error_msg = code, text
            goal_handle.abort()
            return result

        try:  # the library's own checks, mapped to the action's error codes
            validate_request(method, int(goal.num_cameras), int(evaluations), int(initial))
        except InvalidNumCamerasError as exc:
            return abort(PlanViews.Result.INVALID_NUM_CAMERAS, str(exc))
        except UnknownMethodError as exc:
            return abort(PlanViews.Result.UNKNOWN_METHOD, str(exc))
        except InvalidBudgetError as exc:
            return abort(PlanViews.Result.INVALID_BUDGET, str(exc))
        try:
            check_reward_model(reward)
        except ValueError as exc:
            return abort(PlanViews.Result.UNKNOWN_REWARD_MODEL, str(exc))
        # latched topics from several nodes arrive in any order at start-up: give the scene a moment
        if self._realizations is None and not self._scene_arrived.wait(max(0.0, self._param('scene_timeout'))):
            return abort(PlanViews.Result.NO_SCENE,
                         'no scene yet: nothing received on /scene/noisy_points')
        if not self._busy.acquire(blocking=False):
            return abort(PlanViews.Result.UNKNOWN, 'a plan is already being computed')

        def progress(done: int, total: int, best: float, weights) -> bool:
            if goal_handle.is_cancel_requested or not rclpy.ok():
                return False
            fb = PlanViews.Feedback()
            fb.evaluations_done, fb.evaluations_total, fb.best_reward = done, total, float(best)
            if weights:
                fb.ensemble_weights = [float(w) for w in weights]
                fb.ensemble_models = list(MODEL_NAMES)
            goal_handle.publish_feedback(fb)
            return True

        try:
            start = time.monotonic()
            plan = self._plan(method, goal.num_cameras, evaluations, initial, seed, reward, progress)
            if plan.stopped:
                text = f'cancelled after {plan.evaluations} evaluations'
                if goal_handle.is_cancel_requested:
                    goal_handle.canceled()
                else:  # the node is shutting down
                    goal_handle.abort()
                result.error_code, result.error_msg = PlanViews.Result.CANCELED, text
                result.evaluations = int(plan.evaluations)
                self.get_logger().info(text)
                return result
            msg = self._publish_plan(plan)
            result.plan = msg
            result.cameras = [float(x) for x in np.asarray(plan.cameras).ravel()]
            result.reward = float(plan.reward)
            result.reward_model = plan.reward_model
            result.trace = [float(x) for x in plan.trace]
            result.planning_time = time.monotonic() - start
            result.evaluations = int(plan.evaluations)
            goal_handle.succeed()
            return result
        except NoFeasiblePlanError as exc:
            return abort(PlanViews.Result.NO_FEASIBLE_PLAN, str(exc))
        except InvalidSceneError as exc:
            return abort(PlanViews.Result.NO_SCENE, f'unusable scene: {exc}')
        except Exception as exc:  # keep serving whatever happened inside the optimizer
            return abort(PlanViews.Result.PLANNER_FAILED, f'{type(exc).__name__}: {exc}')
        finally:
            self._busy.release()


def main(args=None) -> int:
    rclpy.init(args=args)
    node = None
    try:
        node = PlannerNode()
        executor = MultiThreadedExecutor(num_threads=4)
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except ValueError as exc:
        if node is None:
            print(f'[planner] error: {exc}', flush=True)
            return 2
        raise
    finally:
        if node is not None:
            node.destroy_node()
        if rclpy.ok():
            rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
