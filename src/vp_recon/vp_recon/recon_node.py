"""The recon node: a thin ROS 2 adapter around :func:`vp_recon.pipeline.reconstruct_sets`.

Subscribes (all reliable, TRANSIENT_LOCAL, as the scene and planner nodes publish them)

* ``/scene/description`` (vp_interfaces/SceneDescription): how the scene was built; the node
  rebuilds the identical scene, with its plant meshes, to render it, from the plants' placements
  (model, yaw, scale, position), the models folder, seed and points per plant (a scene from a
  layout file needs no copy of the file here);
* ``/scene/noisy_points`` (sensor_msgs/PointCloud2): the K wind realizations, the ground truth
  the reconstructions are scored against (checked against the rebuilt scene);
* ``/camera_plan`` (geometry_msgs/PoseArray): the plan, one pose per camera, +x = optical axis,
  in the node's ``frame_id`` (a plan in another frame is refused with ``WRONG_FRAME``: no
  transform is applied);
* ``/camera_plan/info`` (vp_interfaces/CameraPlan): what the planner knows about its plan (the
  same header and poses): the reward and reward model copied into the scores (NaN and '' for a
  plan that came without it). The node has no reward code of its own. A second sortie's plan
  carries the cameras already flown (``fixed_poses``): the node reconstructs from their images
  and the new ones together (README "A second sortie"). ``source: render`` renders both;
  ``source: fleet`` reads the flown cameras' images of each realization back from the capture
  sets of the earlier fleet plan that flew them (``record_captures``; the newest of the last
  ``_FLOWN_MEMORY`` plans), or fails with ``CAPTURE_MISSING`` naming the cameras it cannot find.

For every plan it reconstructs and scores each wind realization's capture set, rendered here or
sent by the fleet (one loop, one failure rule: :func:`vp_recon.pipeline.reconstruct_sets`, the
first failing realization stops the plan) and publishes

* ``/reconstruction/score`` (vp_interfaces/ReconstructionScore): one per realization as it is
  done, then the aggregate (``realization = AGGREGATE``); on a failure, the failing
  realization's error and an aggregate with the same error code; transient local with depth
  ``SCORE_HISTORY`` (64): a subscriber that asks for transient local durability gets the last 64
  scores when it joins, a volatile one (``ros2 topic echo`` by default) those sent after;
* ``/reconstruction/points`` (PointCloud2, field ``realization``, latched with depth 1): after
  each realization, the reconstructed clouds of *all* realizations of the plan done so far, so
  that a late subscriber gets every finished realization in the one message it receives.

Images and PLY files go to a new folder ``<output_folder>/plan-<time>[-n]`` per plan (never one
that exists); with ``record_captures`` each realization's capture set (the images, the poses
the drones reported, the camera) goes to its ``captures/realization_<k>`` as a flight folder
(:func:`vp_recon.flight.write_flight`; README "From a real flight"). The rendering and scoring parameters are read anew for every plan; a change to a
bad value is refused with the reason.

It serves ``vp_interfaces/action/SimulateFlights`` on ``/simulate_flights``, the planner's simulated
flights (:mod:`vp_recon.sim_flights`): the goal's plans flown over the scene rebuilt from
``/scene/description`` (as for rendering), each under its own draw, photographed at the goal's
setting and capture figures, reconstructed and scored; one flight a Dask task on the node's
cluster (the user's ``scheduler``, else the kept local cluster of ``workers``, opened at the first
batch when ``scheduler`` is '': a cancel is answered within :data:`vp_recon.sim_flights.POLL_S`
whatever a flight is doing; a flight already running ends on its worker and is dropped). Feedback
as each flight comes back; a flight that fails is a scored failure in the result, never a failed
goal. A goal with no plans readies the local cluster's workers for flights of its setting and is
answered at once (the planner sends one as its cheap stage starts). One batch flies at a time
(another goal meanwhile is rejected); a batch and a plan's
reconstruction run side by side, sharing the machine (on one cluster, the scheduler interleaves
their tasks): neither waits for the other.

The work runs on a worker thread, so the node's callbacks keep running. Queueing policy: the
plan in progress is finished; of the plans that arrive meanwhile only the newest is kept
(it replaces an older queued one, which is logged), because a newer plan supersedes older ones.
Bad input (an empty plan, cameras that see no plant, nothing reconstructed, an unwritable output
folder, no scene yet, a wrong frame, more than ``max_cameras`` cameras: refused as it arrives)
gives a score message with an error code and message and a log line; the node keeps running. A
realization whose files cannot all be written (a full disk) fails the plan with
``OUTPUT_NOT_WRITABLE``, its score and the aggregate naming the file.
Signals, exit codes and parameter types follow :mod:`vp_scene.node_runtime`.
"""
from __future__ import annotations

import contextlib
import math
import os
import threading
import time
from collections import OrderedDict
from pathlib import Path
from typing import Optional

import numpy as np
from geometry_msgs.msg import PoseArray
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2

from vp_interfaces.action import SimulateFlights
from vp_interfaces.msg import CameraPlan, ReconstructionScore, SceneDescription
from vp_recon.config import MAX_CAMERAS, ReconConfig
from vp_recon.errors import ReconError, check_plan_size, ensure_writable_dir
from vp_recon.fleet_captures import IMAGE_TRANSPORTS, FleetCaptures
from vp_scene.flight_poses import FlightError
from vp_recon.flight import locate_flown, write_flight
from vp_recon.gcp import describe
from vp_recon.metrics import DEFAULT_FSCORE_THRESHOLD
from vp_recon.outputs import contact_sheet, write_image, write_ply
from vp_recon.pipeline import reconstruct_plan, reconstruct_sets
from vp_recon.progress import ReconCancelled
from vp_recon.results import RealizationResult
from vp_recon.sim_flights import SceneFlights, flight_batch, flight_config
from vp_scene.camera import IMAGE_SIDE_RANGE, IMAGE_SIZE
from vp_scene.capture import IDEAL, REALISTIC, CaptureModel
from vp_scene.cloud import numpy_to_pointcloud2, realizations_from_cloud
from vp_scene.cluster import KeptLocalCluster
from vp_scene.flights import FlightSettings, flight_capture
from vp_scene.folders import new_run_folder, remove_if_empty
from vp_scene.limits import MAX_SEED
from vp_scene.messages import (aggregate_score, error_score, flight_msg, plan_key, pose_array_to_cameras,
                               realization_score, scene_of_description, score_msg)
from vp_scene.node_runtime import (INT_MAX, LATCHED, NewestWins, Param, declare_typed, parameter_value,
                                   refuse_bad_changes, run_node, typed_values)

Score = ReconstructionScore
#: /reconstruction/score keeps the last SCORE_HISTORY scores for a late subscriber that asks for
#: them (transient local): a plan's scores outlast the moment they were sent, and an immediate
#: error score is not lost to a subscriber whose match with this publisher is not complete yet.
SCORE_HISTORY = 64
SCORES = QoSProfile(depth=SCORE_HISTORY, reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.TRANSIENT_LOCAL)

#: The node's parameters (:class:`vp_scene.node_runtime.Param`): default (its type is enforced),
#: description, the range the node enforces; all are read for every plan.
_M = (0.0, math.inf)
PARAMS = {
    'output_folder': Param(str(Path.home() / '.ros' / 'vp_recon'), 'a plan-<time> folder per plan goes here', None,
                           False, 'not empty'),
    'width': Param(IMAGE_SIZE[0], 'rendered image width, pixels', IMAGE_SIDE_RANGE),
    'height': Param(IMAGE_SIZE[1], 'rendered image height, pixels', IMAGE_SIDE_RANGE),
    'fov': Param(math.pi / 2, 'horizontal field of view, rad (the planner\'s)', (0.0, math.pi), False,
                 'the ends are excluded'),
    'sparse_mode': Param('auto', 'auto (anchored for a realistic capture, known_poses for the ideal one) | '
                                 'known_poses | incremental | anchored'),
    'capture': Param('realistic', 'realistic (hover and localization errors, sensor noise) | ideal (none)'),
    'hover_position_sigma': Param(REALISTIC.hover_position_sigma, 'capture: hover error, m per axis', _M),
    'hover_attitude_sigma': Param(REALISTIC.hover_attitude_sigma, 'capture: hover error of the optical axis, deg',
                                  (0.0, 10.0)),
    'report_position_sigma': Param(REALISTIC.report_position_sigma, 'capture: localization error, m per axis', _M),
    'report_attitude_sigma': Param(REALISTIC.report_attitude_sigma, 'capture: localization error, deg', (0.0, 10.0)),
    'sensor_noise': Param(REALISTIC.sensor_noise, 'capture: image noise std, fraction of full scale', (0.0, 0.5)),
    'gcp_markers': Param(REALISTIC.gcp_markers, 'capture: ground markers laid around the plants and surveyed (0: '
                                                'none, the reported poses alone place the model)', (0, 50)),
    'gcp_sigma': Param(REALISTIC.gcp_sigma, "capture: the markers' survey error, m per axis", (0.0, 1.0), False,
                       'above 0'),
    'capture_seed': Param(0, 'capture: seed of the draws', (0, MAX_SEED)),
    'ground_control': Param('', 'source fleet: the field\'s ground control, a markers.csv or gcp_list.txt (README "From a '
                                'real flight"); \'\': the capture model\'s markers (the simulated drones render them)'),
    'dense': Param(True, 'CPU dense stereo (else the sparse cloud is scored)'),
    'matching': Param('auto', 'image pairs SIFT matches: auto (from the poses from 8 cameras up) | exhaustive | poses'),
    'fscore_threshold': Param(DEFAULT_FSCORE_THRESHOLD, 'F-score distance threshold, m', _M, False, '> 0'),
    'sift_first_octave': Param(-1, "SIFT's first octave: -1 (COLMAP's default) doubles the image first, 0 does not",
                               (-1, 1)),
    'dense_scale': Param(1.0, 'dense stereo on the images resized by this factor (SGM cost about its cube)',
                         (0.0, 1.0), False, 'above 0'),
    'method': Param('', 'label of the scores (default: the method from /camera_plan/info)'),
    'source': Param('render', 'render: the node renders each plan under the capture model | fleet: the drones\' '
                              'images (/fleet/capture, README "From a real flight")'),
    'capture_timeout': Param(60.0, 's source fleet: how long a capture set may take to arrive', _M),
    'camera_topic': Param('/{drone}/camera', 'source fleet: the drones\' camera topics (image_raw, camera_info, '
                                             'pose)'),
    'image_transport': Param('raw', 'source fleet: the images from image_raw (sensor_msgs/Image) | compressed: '
                                    'from image_raw/compressed (CompressedImage, PNG or JPEG; PNG is lossless)'),
    'record_captures': Param(True, 'write each realization\'s capture set (images, poses.csv, COLMAP text model) '
                                   'to <plan folder>/captures/realization_<k>: `make recon IMAGES=...` re-runs it, '
                                   'and a second fleet sortie reads the flown cameras\' images from it'),
    'max_realizations': Param(0, 'reconstruct only the first n realizations (0: all)', (0, INT_MAX)),
    'max_cameras': Param(MAX_CAMERAS, 'a plan of more cameras (a second sortie\'s flown ones included) is refused '
                                      'at once with PLAN_TOO_LARGE (every image of a realization is held at once: '
                                      'about 23 MB a camera at 2000 x 1500)', (2, INT_MAX)),
    'scene_timeout': Param(10.0, 's a plan that arrives before the scene waits for it', _M),
    'frame_id': Param('map', 'frame of the plans and of the published clouds', None, False, 'not empty'),
    # beside the planner (1 thread by default) the reconstruction takes the other cores
    'num_threads': Param(max(1, (os.cpu_count() or 2) - 1), 'threads of COLMAP, OpenCV and the renderer', (1, INT_MAX)),
    'scheduler': Param('', "Dask cluster the realizations reconstruct on in parallel: 'local' (workers processes "
                           "here; 127.0.0.1, TLS with this run's credentials) or a scheduler address "
                           "tls://host:8786 (with tls_ca_file, tls_cert) or tcp://host:8786; '' (default): in this "
                           "process"),
    'tls_ca_file': Param('', 'scheduler tls://: the CA certificate (PEM) that signed the cluster\'s certificates'),
    'tls_cert': Param('', 'scheduler tls://: this client\'s certificate (PEM)'),
    'tls_key': Param('', 'scheduler tls://: this client\'s private key (PEM; default: in tls_cert\'s file)'),
    'workers': Param(max(1, (os.cpu_count() or 2) - 1), "worker processes of scheduler 'local', one thread each",
                     (1, INT_MAX)),
}

#: /camera_plan/info messages remembered to find the one of a plan.
_INFO_MEMORY = 16
#: earlier fleet plans whose capture sets a second sortie may read back (locate_flown)
_FLOWN_MEMORY = 16
#: s a plan waits for its /camera_plan/info (its reward, a second sortie's cameras already flown);
#: a plan without one (another planner) is reconstructed as it is after that.
INFO_WAIT_S = 2.0


#: The parameters of the capture model (a realistic capture's figures; ignored by the ideal one).
CAPTURE_KEYS = ('capture', 'hover_position_sigma', 'hover_attitude_sigma', 'report_position_sigma',
                'report_attitude_sigma', 'sensor_noise', 'gcp_markers', 'gcp_sigma', 'capture_seed')


def capture_model(values: dict) -> CaptureModel:
    """The capture model of the parameter values (defaults for those not given); ValueError."""
    full = {k: values.get(k, PARAMS[k][0]) for k in CAPTURE_KEYS}
    if full['capture'] == 'ideal':
        return IDEAL
    figures = {k: full[k] for k in CAPTURE_KEYS[1:-1]}
    return CaptureModel.named(full['capture'], seed=full['capture_seed'], **figures)


#: The parameters that are the :class:`vp_recon.config.ReconConfig` fields of the same name.
CONFIG_KEYS = ('width', 'height', 'fov', 'sparse_mode', 'dense', 'matching', 'fscore_threshold', 'sift_first_octave',
               'dense_scale', 'max_cameras', 'num_threads')


def recon_config(values: dict) -> ReconConfig:
    """The reconstruction settings of the parameter values (defaults for those not given), the
    images kept for the plan folder; ValueError naming a bad one."""
    return ReconConfig(**{k: values.get(k, PARAMS[k][0]) for k in CONFIG_KEYS}, keep_images=True,
                       capture=capture_model(values)).validate()


#: The parameters of a tls:// scheduler's certificate files, in vp_scene.cluster.TlsFiles' order.
TLS_KEYS = ('tls_ca_file', 'tls_cert', 'tls_key')


def cluster_tls(values: dict):
    """The TLS files (vp_scene.cluster.TlsFiles) of the parameter values."""
    from vp_scene.cluster import TlsFiles

    return TlsFiles(*(values.get(k, '') for k in TLS_KEYS))


def check_parameters(values: dict) -> dict:
    """The parameter values ({name: value}, any subset of :data:`PARAMS`) typed and checked;
    ValueError naming the first bad one."""
    v = typed_values(PARAMS, values)
    if v.get('max_realizations', 0) < 0:
        raise ValueError(f'max_realizations must be >= 0 (0: all), got {v["max_realizations"]}')
    if v.get('scene_timeout', 0.0) < 0.0:
        raise ValueError(f'scene_timeout must be >= 0 s, got {v["scene_timeout"]}')
    if v.get('num_threads', 1) < 1 or v.get('workers', 1) < 1:
        raise ValueError(f'num_threads and workers must be >= 1, got {v.get("num_threads", 1)}, '
                         f'{v.get("workers", 1)}')
    if v.get('source', 'render') not in ('render', 'fleet'):
        raise ValueError(f"source must be render or fleet, got {v['source']!r}")
    if v.get('image_transport', 'raw') not in IMAGE_TRANSPORTS:
        raise ValueError(f"image_transport must be raw or compressed, got {v['image_transport']!r}")
    if v.get('capture_timeout', 1.0) <= 0.0:
        raise ValueError(f'capture_timeout must be > 0 s, got {v["capture_timeout"]}')
    if v.get('output_folder', 'x') == '' or v.get('frame_id', 'x') == '':
        raise ValueError('output_folder and frame_id must not be empty')
    tls = cluster_tls(v)
    if any(v.get(k) for k in TLS_KEYS) and not v.get('scheduler', ''):
        raise ValueError('tls_ca_file, tls_cert and tls_key go with a scheduler tls://host:port')
    if v.get('scheduler', ''):
        from vp_scene.cluster import check_cluster_args

        check_cluster_args(v['scheduler'], v.get('workers', PARAMS['workers'][0]), tls)
    if any(k in v for k in CONFIG_KEYS + CAPTURE_KEYS):  # the reconstruction's settings: ReconConfig's own checks
        recon_config(v)
    return v


class ReconNode(Node):
    """ROS 2 adapter: plans and scenes in, :func:`reconstruct_sets` calls, scores out."""

    def __init__(self) -> None:
        super().__init__('recon')
        declare_typed(self, PARAMS, check_parameters)  # ValueError: exit 2
        refuse_bad_changes(self, PARAMS, check_parameters)
        # Mesa's llvmpipe renderer reads its thread count when the first context is created
        os.environ.setdefault('LP_NUM_THREADS', str(self._param('num_threads')))
        # Importing pycolmap installs glog's SIGTERM handler (a stack trace, then death by the
        # signal); imported here, in the constructor, node_runtime puts its own handler back.
        import pycolmap  # noqa: F401

        # of the plans that arrive during a reconstruction, the newest waits
        self._plans = NewestWins('recon-worker', self._reconstruct_newest, self._crashed, self.get_logger(),
                                 'a newer plan arrived: it replaces the queued one')
        self._lock = self._plans.lock
        self._infos: OrderedDict = OrderedDict()  # plan key -> CameraPlan
        self._description: Optional[SceneDescription] = None
        self._truth: Optional[np.ndarray] = None
        self._scene = None  # rebuilt NoisyScene matching _description
        self._run_dir: Optional[Path] = None  # the plan folder being filled (see on_shutdown)
        self._flown: list = []  # fleet plans reconstructed and recorded: (cameras (N, 6), plan folder)
        self.score_pub = self.create_publisher(Score, '/reconstruction/score', SCORES)
        self.points_pub = self.create_publisher(PointCloud2, '/reconstruction/points', LATCHED)
        self.create_subscription(SceneDescription, '/scene/description', self._on_description, LATCHED)
        self.create_subscription(PointCloud2, '/scene/noisy_points', self._on_truth, LATCHED)
        self.create_subscription(CameraPlan, '/camera_plan/info', self._on_info, LATCHED)
        self.create_subscription(PoseArray, '/camera_plan', self._on_plan, LATCHED)
        self._fleet = FleetCaptures(self, self._lock)
        self._local = KeptLocalCluster()  # scheduler 'local': one cluster for the node's life
        if self._param('scheduler') == 'local':
            self._local.warm(self._param('workers'))  # started while the planner plans
        self._flying = threading.Lock()  # one batch of simulated flights at a time
        self._warming: list = []  # the last warm-up's tasks (a goal with no plans)
        self._flights_server = ActionServer(self, SimulateFlights, '/simulate_flights', execute_callback=self._fly,
                                            goal_callback=self._on_flights_goal,
                                            cancel_callback=lambda _g: CancelResponse.ACCEPT,
                                            callback_group=ReentrantCallbackGroup())
        self._plans.start()
        self.get_logger().info(
            f'recon ready ({self._param("width")}x{self._param("height")}, output {self._param("output_folder")}): '
            'waiting for /scene/description, /scene/noisy_points and /camera_plan; serving /simulate_flights')

    # ---------------------------------------------------------------- parameters
    def _param(self, name: str):
        return parameter_value(self, PARAMS, name)

    def _config(self) -> ReconConfig:
        """The reconstruction settings of the parameters now (read for every plan)."""
        return recon_config({k: self._param(k) for k in CONFIG_KEYS + CAPTURE_KEYS})

    def _ground_control(self, scene: object, config: ReconConfig) -> object:
        """The fleet's ground control: the ``ground_control`` file (a real field's), else the markers
        the capture model lays around the scene's plants (what the simulated drones render), None
        without either. ReconError CAPTURE_MISSING for a file that cannot be read."""
        from vp_scene.ground_control import GroundControlError, read_gcp_list, read_markers_csv

        path = self._param('ground_control')
        if not path:
            return None if config.capture.ideal else config.capture.lay_markers(scene.points)[1]
        try:
            return read_gcp_list(path) if Path(path).name.endswith('.txt') else read_markers_csv(path)
        except GroundControlError as exc:
            raise ReconError(Score.CAPTURE_MISSING, f'ground_control: {exc}') from None

    def on_shutdown(self, timeout: float) -> bool:
        """SIGINT/SIGTERM: the worker abandons its plan at the next stage; nothing to wait for.
        The plan's folder goes with it when nothing was written into it yet (no empty
        ``plan-<time>/`` is left behind); what was written stays."""
        with self._lock:  # (the queue's lock: stopped and the folder read together)
            self._plans.stop()
            run_dir = self._run_dir
        remove_if_empty(run_dir)
        import threading  # the kept local cluster: closed in the background, its workers end with the node anyway

        threading.Thread(target=self._local.close, name='dask-close', daemon=True).start()
        return True

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

    def _on_info(self, msg: CameraPlan) -> None:
        with self._lock:
            self._infos[plan_key(msg.header, msg.poses)] = msg
            while len(self._infos) > _INFO_MEMORY:
                self._infos.popitem(last=False)
            self._lock.notify_all()

    def _info_of(self, plan: PoseArray, wait: float = 0.0) -> Optional[CameraPlan]:
        """The plan's /camera_plan/info, waiting up to ``wait`` seconds for it (the planner sends
        it first, but two topics keep no order between them)."""
        key = plan_key(plan.header, plan.poses)
        with self._lock:
            self._lock.wait_for(lambda: key in self._infos or self._plans.stopped, timeout=wait)
            return self._infos.get(key)

    def _on_plan(self, msg: PoseArray) -> None:
        try:  # refused at once, not queued: it replaces no plan waiting to be reconstructed
            check_plan_size(len(msg.poses), self._param('max_cameras'))
        except ReconError as exc:
            self._publish_error(exc.code, str(exc), Score.AGGREGATE, len(msg.poses), msg)
            return
        self._plans.offer(msg)
        self.get_logger().info(f'plan received: {len(msg.poses)} cameras (frame {msg.header.frame_id!r})')

    # ---------------------------------------------------------------- work
    def _reconstruct_newest(self, plan: PoseArray) -> None:
        """The worker's work (:class:`NewestWins`): reconstruct the plan to its end, or until
        SIGINT/SIGTERM abandons it."""
        try:
            self._reconstruct(plan)
        except ReconCancelled:
            self.get_logger().info('shutting down: reconstruction abandoned')

    def _crashed(self, plan: PoseArray, exc: Exception) -> None:
        self.get_logger().error(f'reconstruction crashed: {type(exc).__name__}: {exc}')
        self._publish_error(Score.UNKNOWN, f'{type(exc).__name__}: {exc}', Score.AGGREGATE, 0, plan)

    def _scene_now(self):
        """The rebuilt NoisyScene (cached), checked against the received ground truth.

        A plan that arrives before the scene waits up to ``scene_timeout`` seconds for it (latched
        topics from several nodes arrive in any order at start-up)."""
        with self._lock:
            self._lock.wait_for(lambda: (self._description is not None and self._truth is not None) or self._plans.stopped,
                                timeout=self._param('scene_timeout'))
            desc, truth, scene = self._description, self._truth, self._scene
        if desc is None or truth is None:
            missing = [n for n, v in (('/scene/description', desc), ('/scene/noisy_points', truth)) if v is None]
            raise ReconError(Score.NO_SCENE, f'no scene yet: nothing received on {" and ".join(missing)}')
        if scene is None:
            try:  # from the plants' placements, not the scenario: no layout file needed here
                scene = scene_of_description(desc)
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
        n_cams = len(plan.poses)
        frame = self._param('frame_id')
        if not plan.poses:
            self._publish_error(Score.EMPTY_PLAN, 'the plan on /camera_plan has no poses', Score.AGGREGATE, 0, plan)
            return
        if plan.header.frame_id != frame:
            self._publish_error(Score.WRONG_FRAME, f'the plan is in frame {plan.header.frame_id!r}, the recon '
                                f'works in {frame!r} (frame_id); no transform is applied', Score.AGGREGATE,
                                n_cams, plan)
            return
        try:
            config = self._config()  # the parameters as they are now
            try:
                cameras = pose_array_to_cameras(plan.poses)
            except ValueError as exc:
                raise ReconError(Score.EMPTY_PLAN, f'the plan has unusable poses: {exc}')
            info = self._info_of(plan, INFO_WAIT_S)
            if info is not None and info.fixed_poses:  # a second sortie: the images of both
                try:
                    cameras = np.concatenate([pose_array_to_cameras(info.fixed_poses), cameras])
                except ValueError as exc:
                    raise ReconError(Score.EMPTY_PLAN, f'the plan\'s cameras already flown are unusable: {exc}')
                self.get_logger().info(f'a second sortie: {len(info.fixed_poses)} cameras already flown and '
                                       f'{n_cams} new ones')
                n_cams = len(cameras)
            check_plan_size(n_cams, config.max_cameras)  # the flown cameras count, and max_cameras may have changed
            if not np.all(np.isfinite(cameras)):
                raise ReconError(Score.EMPTY_PLAN, 'the plan has non-finite poses')
            located = None
            if self._param('source') == 'fleet' and info is not None and info.fixed_poses:
                try:  # the images of the cameras already flown: an earlier fleet plan's capture sets
                    located = locate_flown(self._flown, cameras[:len(info.fixed_poses)])
                except FlightError as exc:
                    raise ReconError(Score.CAPTURE_MISSING, f'source fleet, a second sortie: {exc}; their images '
                                     'are read back from that plan\'s captures (record_captures)')
            scene = self._scene_now()
            root = ensure_writable_dir(Path(self._param('output_folder')).expanduser())
            try:
                run_dir = new_run_folder(root)
                with self._lock:
                    self._run_dir = run_dir
            except OSError as exc:
                raise ReconError(Score.OUTPUT_NOT_WRITABLE, f'cannot create a plan folder in {root}: {exc}')
        except (ReconError, ValueError) as exc:
            code = exc.code if isinstance(exc, ReconError) else Score.UNKNOWN
            self._publish_error(code, str(exc), Score.AGGREGATE, n_cams, plan)
            return
        K = scene.points.shape[0]
        if self._param('max_realizations') > 0:
            K = min(K, self._param('max_realizations'))
        self.get_logger().info(f'reconstructing {K} realizations of a {n_cams}-camera plan into {run_dir}')
        done: list[RealizationResult] = []
        started = [time.monotonic()]

        def stop() -> bool:
            return self._plans.stopped

        def progress(stage: str, k: int) -> bool:
            self.get_logger().info(f'realization {k + 1}/{K}: {stage} done')
            return not stop()

        record = self._param('record_captures')

        def on_realization(res: RealizationResult) -> None:
            k = res.realization
            try:  # a realization whose outputs are not all written failed: its score says so
                write_ply(run_dir / f'recon_{k}.ply', res.points, res.colors)
                if res.rendered:
                    write_image(run_dir / f'views_{k}.png', contact_sheet(res.rendered))
                if record and res.captured_views() is not None:
                    write_flight(res.captured_views(), run_dir / 'captures' / f'realization_{k}',
                                 meta={'capture': res.capture})
            except (OSError, ValueError) as exc:
                raise ReconError(Score.OUTPUT_NOT_WRITABLE, f'its outputs are not all written: {exc}', k) from None
            done.append(res)
            msg = realization_score(self._score(k, K, n_cams, plan), res)
            self.score_pub.publish(msg)
            self._publish_clouds(done, frame)
            self.get_logger().info(f'realization {k}: Chamfer x100 {msg.chamfer:.3f}, {msg.num_points} points '
                                   f'({time.monotonic() - started[0]:.1f} s)')
            if res.control is not None:  # what the ground control did; a warning when some was refused
                log = self.get_logger().info if res.control['applied'] and not res.control['rejected'] \
                    else self.get_logger().warning
                log(f'realization {k}: {describe(res.control)}')
            started[0] = time.monotonic()

        try:
            with contextlib.ExitStack() as stack:
                client = None
                if self._param('scheduler'):
                    from vp_scene.cluster import dashboard, open_client

                    if self._param('scheduler') == 'local':  # kept for the node's life
                        client = self._local.get(self._param('workers'))
                    else:
                        tls = cluster_tls({k: self._param(k) for k in TLS_KEYS})
                        client = stack.enter_context(open_client(self._param('scheduler'), self._param('workers'),
                                                                 quiet=True, tls=tls))
                    self.get_logger().info(f'realizations in parallel on Dask ({self._param("scheduler")}: '
                                           f'{client.scheduler.address}, dashboard {dashboard(client)})')
                if self._param('source') == 'fleet':  # the capture sets as the drones send them
                    captures = self._fleet.capture_sets(
                        plan.header.stamp, len(plan.poses), K, self._param('capture_timeout'),
                        self._param('camera_topic'), stop, transport=self._param('image_transport'),
                        control=self._ground_control(scene, config), flown=located)
                    result = reconstruct_sets(scene, captures, config, out_dir=run_dir, progress=progress,
                                              on_realization=on_realization, client=client, should_stop=stop)
                    if record:  # a later sortie may name these cameras as flown (locate_flown)
                        self._flown = (self._flown + [(cameras, run_dir)])[-_FLOWN_MEMORY:]
                else:
                    result = reconstruct_plan(scene, cameras, config, out_dir=run_dir, realizations=range(K),
                                              progress=progress, on_realization=on_realization, client=client,
                                              should_stop=stop)
        except OSError as exc:  # the cluster: no scheduler at that address, workers that cannot start
            remove_if_empty(run_dir)
            self._publish_error(Score.UNKNOWN, f'the Dask cluster {self._param("scheduler")!r} failed: {exc}',
                                Score.AGGREGATE, n_cams, plan, realizations=len(done))
            return
        except ReconError as exc:
            remove_if_empty(run_dir)  # a plan that wrote nothing leaves no folder
            if exc.realization is not None:
                self._publish_error(exc.code, str(exc), exc.realization, n_cams, plan)
            text = (f'realization {exc.realization} of {K} failed: {exc}' if exc.realization is not None
                    else str(exc))
            self._publish_error(exc.code, text, Score.AGGREGATE, n_cams, plan, realizations=len(done))
            return
        agg = aggregate_score(self._score(Score.AGGREGATE, K, n_cams, plan), result)
        self.get_logger().info(f'aggregate: Chamfer x100 {agg.chamfer:.3f} +- {agg.chamfer_std:.3f} '
                               f'over {len(result.realizations)} realizations')
        self.score_pub.publish(agg)

    # ---------------------------------------------------------------- simulated flights
    def _on_flights_goal(self, _goal: SimulateFlights.Goal) -> GoalResponse:
        if self._plans.stopped:
            self.get_logger().warn('rejecting simulated flights: shutting down')
            return GoalResponse.REJECT
        if self._flying.locked():
            self.get_logger().warn('rejecting simulated flights: another batch is flying')
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _fly(self, goal_handle) -> SimulateFlights.Result:
        """A SimulateFlights goal to its one terminal transition (succeed, canceled or abort)."""
        R = SimulateFlights.Result
        result = R()

        def finish(code: int, text: str = '') -> SimulateFlights.Result:
            result.error_code, result.error_msg = code, text
            if code not in (R.NONE, R.CANCELED):
                self.get_logger().error(f'simulated flights: {text}')
            if goal_handle.is_active:
                if code == R.NONE:
                    goal_handle.succeed()
                elif goal_handle.is_cancel_requested:
                    goal_handle.canceled()
                else:
                    goal_handle.abort()
            return result

        goal = goal_handle.request
        if not goal.cameras_per_plan and not goal.cameras:  # no plans: ready the workers, fly nothing
            return self._warm_flights(goal, finish)
        if not self._flying.acquire(blocking=False):
            return finish(R.UNKNOWN, 'another batch of simulated flights is flying')
        try:
            return self._fly_batch(goal_handle, result, finish)
        finally:
            self._flying.release()

    @staticmethod
    def _flight_setting(goal: SimulateFlights.Goal) -> tuple:
        """(FlightSettings, CaptureModel, fov) of a goal; ValueError naming a bad field."""
        settings = FlightSettings(width=int(goal.width), height=int(goal.height),
                                  sift_first_octave=int(goal.sift_first_octave), dense_scale=float(goal.dense_scale))
        capture = flight_capture(float(goal.report_position_sigma), float(goal.report_attitude_sigma),
                                 bool(goal.ground_control))
        if not (math.isfinite(goal.fov) and 0.0 < goal.fov < math.pi):
            raise ValueError(f'fov must be in (0, pi) rad, got {goal.fov}')
        return settings, capture, float(goal.fov)

    def _warm_flights(self, goal: SimulateFlights.Goal, finish) -> SimulateFlights.Result:
        """A goal with no plans: every worker of the kept local cluster readied for flights of the
        goal's setting over the scene (:meth:`vp_recon.sim_flights.SceneFlights.warm_up`: the
        imports, the renderer's context at the flight's size, the soil), started and answered at
        once, so that the planner's cheap stage and the warm-up overlap; the first flights queue
        behind it. On a user's scheduler (a client per batch) nothing is done. Not a batch: it
        holds no batch's turn."""
        R = SimulateFlights.Result
        try:
            settings, capture, fov = self._flight_setting(goal)
        except ValueError as exc:
            return finish(R.INVALID_GOAL, str(exc))
        if self._param('scheduler') not in ('', 'local'):
            return finish(R.NONE)
        try:
            noisy = self._scene_now()
        except ReconError as exc:
            return finish(R.NO_SCENE if exc.code == Score.NO_SCENE else R.UNKNOWN, str(exc))
        try:
            client = self._local.get(self._param('workers'))
            tasks = SceneFlights(noisy.scene, noisy.config, settings, capture, client, fov).warm_up()
        except Exception as exc:  # noqa: BLE001 - the flights meet, and report, whatever failed here
            return finish(R.CLUSTER_FAILED, f'readying the flight workers failed: {type(exc).__name__}: {exc}')
        self._warming = tasks  # held until the next warm-up: a released future's task may be dropped
        self.get_logger().info(f'readying {len(tasks)} flight worker(s) for {settings.width}x{settings.height} flights')
        return finish(R.NONE)

    def _fly_batch(self, goal_handle, result: SimulateFlights.Result, finish) -> SimulateFlights.Result:
        R, goal = SimulateFlights.Result, goal_handle.request
        try:  # the goal as a whole, before anything flies
            plans, draws = flight_batch(goal.cameras, goal.cameras_per_plan, goal.flight_indices, goal.n_wind,
                                        goal.capture_seeds, self._param('max_cameras'))
            settings, capture, fov = self._flight_setting(goal)
            flight_config(settings, capture, draws[0], fov)  # the reconstruction's own checks
        except ValueError as exc:
            return finish(R.INVALID_GOAL, str(exc))
        try:
            noisy = self._scene_now()
        except ReconError as exc:
            return finish(R.NO_SCENE if exc.code == Score.NO_SCENE else R.UNKNOWN, str(exc))
        total, done = len(plans), [0]

        def stopped() -> bool:
            return goal_handle.is_cancel_requested or self._plans.stopped

        def on_flight(i: int, score) -> None:
            done[0] += 1
            goal_handle.publish_feedback(SimulateFlights.Feedback(flights_done=done[0], flights_total=total,
                                                                  last=flight_msg(score, i)))
            what = (f'failed ({score.reason})' if score.failed else
                    f'map Chamfer {score.chamfer:.4f} m, shape {score.chamfer_shape:.4f} m')
            self.get_logger().info(f'simulated flight {done[0]}/{total} (plan {i}): {what}, {score.seconds:.1f} s')

        self.get_logger().info(f'flying {total} plans ({settings.width}x{settings.height}, SIFT octave '
                               f'{settings.sift_first_octave}, dense scale {settings.dense_scale:g})')
        # the batch has started: its client knows the goal accepted even when the answer was lost
        goal_handle.publish_feedback(SimulateFlights.Feedback(flights_done=0, flights_total=total))
        try:
            with contextlib.ExitStack() as stack:
                client = self._flights_client(stack)
                sim = SceneFlights(noisy.scene, noisy.config, settings, capture, client, fov)
                scores = sim.fly(plans, draws, on_flight=on_flight, should_stop=stopped)
        except OSError as exc:  # the cluster: no scheduler at that address, workers that cannot start
            return finish(R.CLUSTER_FAILED, f'the Dask cluster {self._param("scheduler") or "local"!r} failed: {exc}')
        except Exception as exc:  # noqa: BLE001 - e.g. a cluster lost while the scene is sent: the goal's failure
            return finish(R.UNKNOWN, f'{type(exc).__name__}: {exc}')
        result.flights = [flight_msg(score, i) for i, score in enumerate(scores)]
        if stopped():
            why = 'cancelled' if goal_handle.is_cancel_requested else 'the recon node is shutting down'
            self.get_logger().info(f'simulated flights {why} after {done[0]} of {total}')
            return finish(R.CANCELED, f'{why} after {done[0]} of {total} flights')
        return finish(R.NONE)

    def _flights_client(self, stack: contextlib.ExitStack) -> object:
        """The Dask client the flights fly on: the user's scheduler (open for the batch), else the
        node's kept local cluster of ``workers`` (``scheduler`` '' too: a flight a task, so that a
        cancel is answered at once). OSError when it cannot be opened."""
        from vp_scene.cluster import open_client

        scheduler = self._param('scheduler')
        if scheduler and scheduler != 'local':
            tls = cluster_tls({k: self._param(k) for k in TLS_KEYS})
            return stack.enter_context(open_client(scheduler, self._param('workers'), quiet=True, tls=tls))
        return self._local.get(self._param('workers'))

    # ---------------------------------------------------------------- outputs
    def _publish_clouds(self, done: list, frame: str) -> None:
        """The clouds of every realization of the plan done so far, in one latched message."""
        pts = np.concatenate([r.points for r in done])
        cols = np.concatenate([r.colors for r in done])
        real = np.concatenate([np.full(len(r.points), r.realization, dtype=np.uint16) for r in done])
        self.points_pub.publish(numpy_to_pointcloud2(pts, cols, realization=real, frame_id=frame,
                                                     stamp=self.get_clock().now().to_msg()))

    def _score(self, realization: int, K: int, images: int, plan: Optional[PoseArray]) -> Score:
        return score_msg(self._param('frame_id'), self.get_clock().now().to_msg(), realization, K, images,
                         self._param('fscore_threshold'), self._param('capture'), self._param('method'),
                         self._info_of(plan) if plan is not None else None, source=self._param('source'))

    def _publish_error(self, code: int, text: str, realization: int, images: int, plan: Optional[PoseArray],
                       realizations: int = 0) -> None:
        K = realizations if realization == Score.AGGREGATE else 1
        msg = error_score(self._score(realization, K, images, plan), code, text)
        where = 'plan' if realization == Score.AGGREGATE else f'realization {realization}'
        self.get_logger().error(f'{where}: {text}')
        self.score_pub.publish(msg)

    def destroy_node(self) -> None:
        self._plans.stop()
        super().destroy_node()


def main(args=None) -> int:
    """Entry point ``recon``: exit 2 with one line for a bad parameter, 0 after SIGINT/SIGTERM."""
    # a SimulateFlights goal holds a thread while it flies: the others serve its cancel and the topics
    return run_node('recon', ReconNode, args, num_threads=3)


if __name__ == '__main__':
    raise SystemExit(main())
