"""The recon node: a thin ROS 2 adapter around :mod:`vp_recon.pipeline`.

Subscribes (all reliable, TRANSIENT_LOCAL, as the scene and planner nodes publish them)

* ``/scene/description`` (vp_interfaces/SceneDescription): how the scene was built; the node
  rebuilds the identical scene, with its plant meshes, to render it;
* ``/scene/noisy_points`` (sensor_msgs/PointCloud2): the K wind realizations, the ground truth
  the reconstructions are scored against (checked against the rebuilt scene);
* ``/camera_plan`` (geometry_msgs/PoseArray): the plan, one pose per camera, +x = optical axis.

For every plan it renders, reconstructs and scores each wind realization and publishes
``/reconstruction/score`` (vp_interfaces/ReconstructionScore, one per realization, then the
aggregate with ``realization = AGGREGATE``) and ``/reconstruction/points`` (PointCloud2, the
reconstructed cloud of each realization, field ``realization``). Images and PLY files go to the
``output_folder`` parameter.

The work runs on a worker thread, so the node's callbacks keep running. Queueing policy: the
plan in progress is finished; of the plans that arrive meanwhile only the newest is kept
(it replaces an older queued one, which is logged), because a newer plan supersedes older ones.
Bad input (an empty plan, cameras that see no plant, nothing reconstructed, an unwritable output
folder, no scene yet) gives a score message with an error code and message and a log line; the
node keeps running.
"""
from __future__ import annotations

import math
import os
import threading
import time
from pathlib import Path
from typing import Optional

import numpy as np
import rclpy
from geometry_msgs.msg import PoseArray
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2

from vp_interfaces.msg import ReconstructionScore, SceneDescription
from vp_scene.camera import poses_to_cameras
from vp_planner.reward import noisy_reward
from vp_recon.metrics import DEFAULT_FSCORE_THRESHOLD
from vp_recon.outputs import contact_sheet, write_image, write_ply
from vp_recon.pipeline import ReconCancelled, ReconConfig, ReconError, ensure_writable_dir, reconstruct_realization
from vp_scene.build import build_noisy_scene
from vp_scene.cloud import numpy_to_pointcloud2, realizations_from_cloud

LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
Score = ReconstructionScore


class ReconNode(Node):
    """ROS 2 adapter: plans and scenes in, :func:`reconstruct_realization` calls, scores out."""

    def __init__(self) -> None:
        super().__init__('recon')
        self.declare_parameter('output_folder', str(Path.home() / '.ros' / 'vp_recon'))
        self.declare_parameter('width', 2000)
        self.declare_parameter('height', 1500)
        self.declare_parameter('fov', math.pi / 2)
        self.declare_parameter('theta_match', math.pi / 4)
        self.declare_parameter('sparse_mode', 'known_poses')
        self.declare_parameter('dense', True)
        self.declare_parameter('fscore_threshold', DEFAULT_FSCORE_THRESHOLD)
        self.declare_parameter('method', '')
        self.declare_parameter('max_realizations', 0)
        self.declare_parameter('scene_timeout', 10.0)
        # beside the planner (1 thread by default) the reconstruction takes the other cores
        self.declare_parameter('num_threads', max(1, (os.cpu_count() or 2) - 1))
        self.config = self._config()  # raises ValueError naming a bad parameter
        # Mesa's llvmpipe renderer reads its thread count when the first context is created
        os.environ.setdefault('LP_NUM_THREADS', str(self.config.num_threads))

        self._lock = threading.Condition()
        self._pending: Optional[PoseArray] = None
        self._description: Optional[SceneDescription] = None
        self._truth: Optional[np.ndarray] = None
        self._scene = None  # rebuilt NoisyScene matching _description
        self._stop = False
        self.score_pub = self.create_publisher(Score, '/reconstruction/score', 10)
        self.points_pub = self.create_publisher(PointCloud2, '/reconstruction/points', LATCHED)
        self.create_subscription(SceneDescription, '/scene/description', self._on_description, LATCHED)
        self.create_subscription(PointCloud2, '/scene/noisy_points', self._on_truth, LATCHED)
        self.create_subscription(PoseArray, '/camera_plan', self._on_plan, LATCHED)
        self._worker = threading.Thread(target=self._work, name='recon-worker', daemon=True)
        self._worker.start()
        self.get_logger().info(
            f'recon ready ({self.config.width}x{self.config.height}, output {self._param("output_folder")}): '
            'waiting for /scene/description, /scene/noisy_points and /camera_plan')

    # ---------------------------------------------------------------- parameters
    def _param(self, name: str):
        return self.get_parameter(name).value

    def _config(self) -> ReconConfig:
        fov = float(self._param('fov'))
        return ReconConfig(width=int(self._param('width')), height=int(self._param('height')), fov=fov,
                           sparse_mode=self._param('sparse_mode'), dense=bool(self._param('dense')),
                           fscore_threshold=float(self._param('fscore_threshold')), keep_images=True,
                           num_threads=int(self._param('num_threads'))).validate()

    # ---------------------------------------------------------------- inputs
    def _on_description(self, msg: SceneDescription) -> None:
        with self._lock:
            self._description, self._scene = msg, None  # rebuilt lazily on the worker thread
            self._lock.notify_all()
        self.get_logger().info(f'scene description: {msg.scenario}, {len(msg.plants)} plants, '
                               f'K = {msg.realizations}')

    def _on_truth(self, msg: PointCloud2) -> None:
        try:
            truth = realizations_from_cloud(msg)
        except Exception as exc:  # a bad cloud must not take the node down
            self.get_logger().error(f'ignoring /scene/noisy_points: {exc}')
            return
        with self._lock:
            self._truth, self._scene = truth, None
            self._lock.notify_all()
        self.get_logger().info(f'ground truth: {truth.shape[0]} realizations x {truth.shape[1]} points')

    def _on_plan(self, msg: PoseArray) -> None:
        with self._lock:
            if self._pending is not None:
                self.get_logger().warn('a newer plan arrived: it replaces the queued one')
            self._pending = msg
            self._lock.notify()
        self.get_logger().info(f'plan received: {len(msg.poses)} cameras (frame {msg.header.frame_id!r})')

    # ---------------------------------------------------------------- work
    def _work(self) -> None:
        while True:
            with self._lock:
                while self._pending is None and not self._stop:
                    self._lock.wait(0.5)
                if self._stop:
                    return
                plan, self._pending = self._pending, None
            try:
                self._reconstruct(plan)
            except Exception as exc:  # never let one plan kill the worker
                self.get_logger().error(f'reconstruction crashed: {type(exc).__name__}: {exc}')
                self._publish_error(Score.UNKNOWN, f'{type(exc).__name__}: {exc}', Score.AGGREGATE, 0)

    def _scene_now(self):
        """The rebuilt NoisyScene (cached), checked against the received ground truth.

        A plan that arrives before the scene waits up to ``scene_timeout`` seconds for it (latched
        topics from several nodes arrive in any order at start-up)."""
        with self._lock:
            self._lock.wait_for(lambda: (self._description is not None and self._truth is not None) or self._stop,
                                timeout=max(0.0, float(self._param('scene_timeout'))))
            desc, truth, scene = self._description, self._truth, self._scene
        if desc is None or truth is None:
            missing = [n for n, v in (('/scene/description', desc), ('/scene/noisy_points', truth)) if v is None]
            raise ReconError(Score.NO_SCENE, f'no scene yet: nothing received on {" and ".join(missing)}')
        if scene is None:
            folder = desc.models_folder
            try:
                scene, _ = build_noisy_scene(
                    scenario=desc.scenario, models=folder or None, seed=desc.seed,
                    points_per_plant=desc.points_per_plant, plant_spacing=desc.plant_spacing,
                    row_spacing=desc.row_spacing, levels=desc.levels, realizations=desc.realizations,
                    wind_variance=desc.wind_variance, wind_direction=desc.wind_direction)
            except (ValueError, OSError) as exc:
                raise ReconError(Score.NO_SCENE, f'cannot rebuild the scene from /scene/description: {exc}')
            if scene.points.shape != truth.shape or np.abs(scene.points - truth).max() > 1e-4:
                raise ReconError(Score.NO_SCENE, 'the scene rebuilt from /scene/description does not match '
                                 '/scene/noisy_points (different scene node versions or models?)')
            with self._lock:
                if self._description is desc:
                    self._scene = scene
        return scene

    def _reconstruct(self, plan: PoseArray) -> None:
        method = self._param('method')
        out_root = Path(self._param('output_folder')).expanduser()
        if not plan.poses:
            self._publish_error(Score.EMPTY_PLAN, 'the plan on /camera_plan has no poses', Score.AGGREGATE, 0)
            return
        try:
            scene = self._scene_now()
            cameras = poses_to_cameras([[p.position.x, p.position.y, p.position.z, p.orientation.x,
                                         p.orientation.y, p.orientation.z, p.orientation.w] for p in plan.poses])
            if not np.all(np.isfinite(cameras)):
                raise ReconError(Score.EMPTY_PLAN, 'the plan has non-finite poses')
            run_dir = out_root / time.strftime('plan-%Y%m%d-%H%M%S')
            ensure_writable_dir(run_dir)
        except ReconError as exc:
            self._publish_error(exc.code, str(exc), Score.AGGREGATE, len(plan.poses))
            return
        K = scene.points.shape[0]
        if self._param('max_realizations') > 0:
            K = min(K, int(self._param('max_realizations')))
        reward = float(noisy_reward(cameras, scene.points[:K], self.config.fov, self._param('theta_match'))) \
            if len(cameras) >= 2 else 0.0
        self.get_logger().info(f'reconstructing {K} realizations of a {len(cameras)}-camera plan '
                               f'(reward {reward:.4f}) into {run_dir}')
        results, errors = [], []
        for k in range(K):
            start = time.monotonic()

            def progress(stage: str, *_args) -> bool:
                self.get_logger().info(f'realization {k + 1}/{K}: {stage} done')
                return rclpy.ok()
            try:
                res = reconstruct_realization(scene, k, cameras, self.config, run_dir,
                                              progress=progress)
            except ReconCancelled:
                self.get_logger().info('shutting down: reconstruction abandoned')
                return
            except ReconError as exc:
                errors.append(exc)
                self._publish_error(exc.code, str(exc), k, len(cameras), reward)
                continue
            results.append(res)
            try:
                write_ply(run_dir / f'recon_{k}.ply', res.points, res.colors)
                if res.rendered:
                    write_image(run_dir / f'views_{k}.png', contact_sheet(res.rendered))
            except OSError as exc:
                self.get_logger().error(f'could not write the outputs of realization {k}: {exc}')
            res.rendered = []
            msg = self._score(k, K, len(cameras), reward, method)
            msg.chamfer, msg.accuracy, msg.completeness = (100 * res.chamfer, 100 * res.accuracy,
                                                           100 * res.completeness)
            msg.fscore, msg.num_points = float(res.fscore), int(len(res.points))
            self.score_pub.publish(msg)
            self.points_pub.publish(numpy_to_pointcloud2(
                res.points, res.colors, realization=np.full(len(res.points), k, dtype=np.uint16),
                frame_id='map', stamp=self.get_clock().now().to_msg()))
            self.get_logger().info(f'realization {k}: Chamfer x100 {msg.chamfer:.3f}, {msg.num_points} points '
                                   f'({time.monotonic() - start:.1f} s)')
        agg = self._score(Score.AGGREGATE, K, len(cameras), reward, method)
        if results:
            ch = np.array([100 * r.chamfer for r in results])
            agg.chamfer, agg.chamfer_std = float(ch.mean()), float(ch.std())
            agg.accuracy = float(np.mean([100 * r.accuracy for r in results]))
            agg.completeness = float(np.mean([100 * r.completeness for r in results]))
            agg.fscore = float(np.mean([r.fscore for r in results]))
            agg.num_points = int(np.mean([len(r.points) for r in results]))
            agg.realizations = len(results)
            if errors:
                agg.error_msg = f'{len(errors)} of {K} realizations failed: {errors[0]}'
            self.get_logger().info(f'aggregate: Chamfer x100 {agg.chamfer:.3f} +- {agg.chamfer_std:.3f} '
                                   f'over {len(results)} realizations')
        else:
            agg.error_code, agg.error_msg = errors[0].code, f'every realization failed: {errors[0]}'
            agg.chamfer = agg.chamfer_std = float('nan')
            self.get_logger().error(agg.error_msg)
        self.score_pub.publish(agg)

    # ---------------------------------------------------------------- outputs
    def _score(self, realization: int, K: int, images: int, reward: float, method: str) -> Score:
        msg = Score()
        msg.header.frame_id = 'map'
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.method, msg.realization, msg.realizations = method, int(realization), int(K)
        msg.num_images, msg.reward = int(images), float(reward)
        msg.fscore_threshold = float(self.config.fscore_threshold)
        return msg

    def _publish_error(self, code: int, text: str, realization: int, images: int, reward: float = 0.0) -> None:
        msg = self._score(realization, 0 if realization == Score.AGGREGATE else 1, images, reward,
                          self._param('method'))
        msg.error_code, msg.error_msg = int(code), text
        msg.chamfer = msg.accuracy = msg.completeness = float('nan')
        where = 'plan' if realization == Score.AGGREGATE else f'realization {realization}'
        self.get_logger().error(f'{where}: {text}')
        self.score_pub.publish(msg)

    def destroy_node(self) -> None:
        with self._lock:
            self._stop = True
            self._lock.notify()
        super().destroy_node()


def main(args=None) -> int:
    rclpy.init(args=args)
    node = None
    rc = 0
    try:
        try:
            node = ReconNode()
        except ValueError as exc:
            rclpy.logging.get_logger('recon').error(f'bad parameters: {exc}')
            rc = 2
        else:
            executor = MultiThreadedExecutor(num_threads=2)
            executor.add_node(node)
            executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return rc


if __name__ == '__main__':
    raise SystemExit(main())
