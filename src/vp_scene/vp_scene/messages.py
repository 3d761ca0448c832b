"""The suite's ROS message conversions: one home, called by every node and tool (the science
modules never see a message).

* clouds: numpy <-> ``sensor_msgs/PointCloud2`` live in their own module, :mod:`vp_scene.cloud`;
* poses: (N, 7) ``[x, y, z, qx, qy, qz, qw]`` <-> ``geometry_msgs/Pose`` lists, one pose
  <-> ``Pose``, a position (3,) <-> ``geometry_msgs/Point``;
* plans: cameras (N, 6) ``[c, v]`` <-> ``geometry_msgs/PoseArray`` (the body convention of
  :mod:`vp_scene.camera`: +x of each pose = optical axis), a plan and its figures ->
  ``vp_interfaces/CameraPlan``, a plan's identity across the two topics (:func:`plan_key`);
* frustums: cameras -> ``visualization_msgs/MarkerArray`` (RViz);
* scenes: a noisy scene -> ``vp_interfaces/SceneDescription``, and its plant placements back;
* scores: a reconstruction's figures (one realization, the aggregate, or an error) ->
  ``vp_interfaces/ReconstructionScore`` (distances x 100, as the message says), and back to a
  plain record (:func:`score_record`);
* simulated flights: a batch of plans and their draws -> a ``vp_interfaces/SimulateFlights`` goal,
  a :class:`vp_scene.flights.FlightScore` <-> ``vp_interfaces/SimulatedFlight`` (metres), a
  flight's record (plan.json's ``flights`` entries) -> the message;
* routes: timed poses (m, 7) <-> ``nav_msgs/Path`` (each pose stamped with its time);
* drones: a pose report (``PoseStamped`` or ``nav_msgs/Odometry``, :data:`POSE_TYPES`) <-> a
  position (3,) and a pose (7,); per-drone topics from a template (:func:`drone_topic`); a
  geodetic position (latitude, longitude in degrees, ellipsoidal height; :mod:`vp_scene.geo`)
  <-> ``sensor_msgs/NavSatFix`` (whose altitude is above the WGS84 ellipsoid);
* images: an RGB image (H, W, 3) uint8 <-> ``sensor_msgs/Image`` (``rgb8``; ``bgr8`` and
  ``mono8`` read too) and ``sensor_msgs/CompressedImage`` (PNG or JPEG, the image_transport
  convention), intrinsics K (3x3, OpenCV pixel convention) and the image size <->
  ``sensor_msgs/CameraInfo`` (``plumb_bob``, zero distortion, REP-104).

Degenerate cases: an empty pose list gives a (0, 7) array and back; non-finite numbers pass
through unchanged (the callers decide: the dispatcher refuses them, the recon reports them).
"""
from __future__ import annotations

import math
from typing import Any, Optional, Sequence

import numpy as np
from geometry_msgs.msg import Point, Pose, PoseArray, PoseStamped
from nav_msgs.msg import Odometry, Path
from sensor_msgs.msg import CameraInfo, CompressedImage, Image, NavSatFix, NavSatStatus
from numpy.typing import ArrayLike, NDArray
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from vp_interfaces.action import SimulateFlights
from vp_interfaces.msg import CameraPlan, PlantPlacement, ReconstructionScore, SceneDescription, SimulatedFlight

from .camera import cameras_to_poses, check_coordinates, poses_to_cameras, rotation_matrix, tan_half_fov

__all__ = [
    "point_msg", "point_array", "pose_msg", "pose_array", "poses_to_msgs", "msgs_to_poses", "position_of",
    "cameras_to_pose_array", "pose_array_to_cameras", "camera_plan_msg", "plan_key", "frustum_markers",
    "scene_description_msg", "placements_of", "scene_of_description", "POSE_TYPES", "drone_topic", "pose_report",
    "score_msg", "realization_score", "aggregate_score", "error_score", "score_record",
    "simulate_flights_goal", "flight_msg", "flight_score_of", "flight_record_msg", "flight_record",
    "image_msg", "image_array", "compressed_image_msg", "compressed_image_array", "camera_info_msg",
    "camera_info_intrinsics", "navsatfix_msg", "navsatfix_geodetic", "stamp_after", "path_msg", "path_poses",
    "fleet_assignment_msg",
]


# ---------------------------------------------------------------- points and poses
def point_msg(xyz: ArrayLike) -> Point:
    """``geometry_msgs/Point`` of a position (3,)."""
    x, y, z = (float(c) for c in np.asarray(xyz, dtype=np.float64).reshape(3))
    return Point(x=x, y=y, z=z)


def point_array(p: Point) -> NDArray[np.float64]:
    """(3,) of a ``geometry_msgs/Point``."""
    return np.array([p.x, p.y, p.z], dtype=np.float64)


def pose_msg(pose: ArrayLike) -> Pose:
    """``geometry_msgs/Pose`` of ``[x, y, z, qx, qy, qz, qw]``."""
    x, y, z, qx, qy, qz, qw = (float(c) for c in np.asarray(pose, dtype=np.float64).reshape(7))
    msg = Pose()
    msg.position.x, msg.position.y, msg.position.z = x, y, z
    msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w = qx, qy, qz, qw
    return msg


def pose_array(pose: Pose) -> NDArray[np.float64]:
    """(7,) ``[x, y, z, qx, qy, qz, qw]`` of a ``geometry_msgs/Pose``."""
    p, q = pose.position, pose.orientation
    return np.array([p.x, p.y, p.z, q.x, q.y, q.z, q.w], dtype=np.float64)


def poses_to_msgs(poses: ArrayLike) -> list:
    """``geometry_msgs/Pose`` list of poses (N, 7)."""
    return [pose_msg(p) for p in np.asarray(poses, dtype=np.float64).reshape(-1, 7)]


def msgs_to_poses(poses: Sequence[Pose]) -> NDArray[np.float64]:
    """Poses (N, 7) of a ``geometry_msgs/Pose`` sequence ((0, 7) when empty)."""
    return np.array([pose_array(p) for p in poses], dtype=np.float64).reshape(-1, 7)


# ---------------------------------------------------------------- drones
#: A drone's pose reports (the dispatcher's and sim_drone's ``pose_type``) -> message class.
POSE_TYPES = {"pose": PoseStamped, "odometry": Odometry}


def drone_topic(template: str, drone: str) -> str:
    """The topic of one drone: ``template`` with ``{drone}`` replaced by its name."""
    return template.replace('{drone}', drone)


def position_of(msg: Any) -> NDArray[np.float64]:
    """Position (3,) of a drone's report: ``geometry_msgs/PoseStamped`` or ``nav_msgs/Odometry``."""
    pose = msg.pose.pose if isinstance(msg, Odometry) else msg.pose
    return point_array(pose.position)


def pose_report(pose_type: str, pose: ArrayLike, frame_id: str, stamp: Any, child_frame_id: str = "") -> Any:
    """A drone's report of its pose (7,): ``PoseStamped`` or ``Odometry`` (with ``child_frame_id``)."""
    msg = POSE_TYPES[pose_type]()
    msg.header.stamp, msg.header.frame_id = stamp, frame_id
    if isinstance(msg, Odometry):
        msg.child_frame_id = child_frame_id
        msg.pose.pose = pose_msg(pose)
    else:
        msg.pose = pose_msg(pose)
    return msg


def stamp_after(stamp: Any, seconds: float) -> Any:
    """The ``builtin_interfaces/Time`` ``seconds`` after ``stamp``."""
    from builtin_interfaces.msg import Time

    ns = int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec) + int(round(float(seconds) * 1e9))
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def path_msg(poses: ArrayLike, seconds: ArrayLike, frame_id: str, stamp: Any) -> Path:
    """``nav_msgs/Path`` of poses (m, 7), pose k stamped ``seconds[k]`` after ``stamp`` (the header's)."""
    msg = Path()
    msg.header.stamp, msg.header.frame_id = stamp, frame_id
    for pose, t in zip(np.asarray(poses, dtype=np.float64).reshape(-1, 7), np.asarray(seconds, dtype=np.float64)):
        ps = PoseStamped(pose=pose_msg(pose))
        ps.header.stamp, ps.header.frame_id = stamp_after(stamp, t), frame_id
        msg.poses.append(ps)
    return msg


def path_poses(msg: Path) -> NDArray[np.float64]:
    """(m, 7) poses of a ``nav_msgs/Path``."""
    return msgs_to_poses([p.pose for p in msg.poses])


def navsatfix_msg(geodetic: ArrayLike, frame_id: str, stamp: Any) -> NavSatFix:
    """``sensor_msgs/NavSatFix`` of a geodetic position (3,) = latitude, longitude (deg),
    ellipsoidal height (m): status fix, service GPS, covariance unknown."""
    g = np.asarray(geodetic, dtype=np.float64).reshape(3)
    msg = NavSatFix()
    msg.header.stamp, msg.header.frame_id = stamp, frame_id
    msg.status.status, msg.status.service = NavSatStatus.STATUS_FIX, NavSatStatus.SERVICE_GPS
    msg.latitude, msg.longitude, msg.altitude = (float(x) for x in g)
    msg.position_covariance_type = NavSatFix.COVARIANCE_TYPE_UNKNOWN
    return msg


def navsatfix_geodetic(msg: NavSatFix) -> NDArray[np.float64]:
    """(3,) latitude, longitude (deg), ellipsoidal height (m) of a ``NavSatFix``."""
    return np.array([msg.latitude, msg.longitude, msg.altitude], dtype=np.float64)


# ---------------------------------------------------------------- plans
def cameras_to_pose_array(cameras: ArrayLike, frame_id: str, stamp: Any = None) -> PoseArray:
    """``geometry_msgs/PoseArray`` of cameras (N, 6) = [c, v] (+x of each pose = optical axis)."""
    msg = PoseArray()
    msg.header.frame_id = frame_id
    if stamp is not None:
        msg.header.stamp = stamp
    msg.poses = poses_to_msgs(cameras_to_poses(cameras))
    return msg


def fleet_assignment_msg(plan_stamp_sec: int, drones: Sequence[str], cameras: ArrayLike,
                         frame_id: str = 'map') -> Any:
    """``vp_interfaces/FleetAssignment`` giving drone i pose i of a plan of cameras (N, 6) stamped
    ``plan_stamp_sec`` (as the dispatcher answers it; for tests and benchmarks that play it)."""
    from vp_interfaces.msg import DroneAssignment, FleetAssignment

    cams = np.asarray(cameras, dtype=np.float64).reshape(-1, 6)
    msg = FleetAssignment(num_poses=len(cams), assignment='min_total', orientation='body')
    msg.header.frame_id = frame_id
    msg.plan_stamp.sec = int(plan_stamp_sec)
    msg.entries = [DroneAssignment(drone=d, pose_index=i, goal=pose_msg(cameras_to_poses(c)))
                   for i, (d, c) in enumerate(zip(drones, cams))]
    return msg


def pose_array_to_cameras(poses: Sequence[Pose]) -> NDArray[np.float64]:
    """Cameras (N, 6) = [c, v] of a PoseArray's poses (ValueError for unusable quaternions or a
    number beyond :data:`vp_scene.camera.MAX_COORDINATE`)."""
    return poses_to_cameras(check_coordinates(msgs_to_poses(poses), "the poses"))


def camera_plan_msg(plan: PoseArray, reward: float, reward_model: str, method: str, evaluations: int,
                    planning_time: float, fixed_cameras: Optional[ArrayLike] = None) -> CameraPlan:
    """``vp_interfaces/CameraPlan``: the plan's header and poses with the planner's figures, and
    the cameras (M, 6) already flown that it completes (a second sortie) as ``fixed_poses``."""
    info = CameraPlan()
    info.header, info.poses = plan.header, plan.poses
    info.reward, info.reward_model, info.method = float(reward), reward_model, method
    info.evaluations, info.planning_time = int(evaluations), float(planning_time)
    if fixed_cameras is not None and len(fixed_cameras):
        info.fixed_poses = poses_to_msgs(cameras_to_poses(fixed_cameras))
    return info


def plan_key(header: Any, poses: Sequence[Pose]) -> tuple:
    """What identifies a plan across ``/camera_plan`` and ``/camera_plan/info``: stamp, frame, poses
    (rounded to 1e-9)."""
    return (header.stamp.sec, header.stamp.nanosec, header.frame_id,
            tuple(round(float(x), 9) for x in msgs_to_poses(poses).ravel()))


def frustum_markers(cameras: ArrayLike, frame_id: str, stamp: Any, fov: float,
                    depth: float = 0.4, aspect: float = 4.0 / 3.0) -> MarkerArray:
    """One LINE_LIST frustum (apex at c, far plane at ``depth`` along v) and a label a camera,
    after a DELETEALL that clears the previous plan's."""
    out = MarkerArray()
    clear = Marker()
    clear.action = Marker.DELETEALL
    out.markers.append(clear)
    half_w = depth * tan_half_fov(fov)
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
        m.points = [point_msg(p) for p in segments]
        out.markers.append(m)
        label = Marker()
        label.header = m.header
        label.ns = 'labels'
        label.id = i
        label.type = Marker.TEXT_VIEW_FACING
        label.action = Marker.ADD
        label.pose.position = point_msg(c + np.array([0.0, 0.0, 0.1]))
        label.pose.orientation.w = 1.0
        label.scale.z = 0.1
        label.color = ColorRGBA(r=1.0, g=1.0, b=1.0, a=1.0)
        label.text = f'cam {i}'
        out.markers.append(label)
    return out


# ---------------------------------------------------------------- scenes
def scene_description_msg(noisy: Any, values: dict, frame_id: str, stamp: Any) -> SceneDescription:
    """``vp_interfaces/SceneDescription`` of a :class:`vp_scene.wind.NoisyScene` built from the
    scene node's parameter ``values`` (scenario as given, models_folder, seed, sampling)."""
    scene, cfg = noisy.scene, noisy.config
    desc = SceneDescription()
    desc.header.stamp, desc.header.frame_id = stamp, frame_id
    desc.scenario = values["scenario"]  # the name or the layout file as given; the plants say where they stand
    desc.models_folder = values["models_folder"]
    desc.seed = values["seed"]
    desc.points_per_plant = values["points_per_plant"]
    desc.plant_spacing, desc.row_spacing = values["plant_spacing"], values["row_spacing"]
    desc.levels, desc.realizations = cfg.levels, cfg.realizations
    desc.wind_variance, desc.wind_direction = cfg.variance, cfg.direction
    desc.n_wind = [float(w) for w in noisy.n_wind]
    desc.plants = [PlantPlacement(model=pl.model_name, yaw=float(pl.yaw), scale=float(pl.scale),
                                  position=point_msg(pl.position))
                   for pl in scene.plants]
    return desc


def placements_of(desc: SceneDescription) -> list:
    """The plants of a SceneDescription as (model, yaw, scale, x, y) tuples
    (:meth:`vp_scene.layout.Layout.from_placements`)."""
    return [(p.model, p.yaw, p.scale, p.position.x, p.position.y) for p in desc.plants]


def scene_of_description(desc: SceneDescription) -> Any:
    """The :class:`vp_scene.wind.NoisyScene` a SceneDescription describes, rebuilt from the
    plants' placements (model, yaw, scale, position: no layout file needed), the models folder,
    seed, points per plant and wind. ValueError / OSError when it cannot be rebuilt."""
    from .build import build_noisy_scene
    from .layout import Layout

    layout = Layout.from_placements(desc.scenario or 'scene', placements_of(desc), source='/scene/description')
    scene, _ = build_noisy_scene(
        scenario=layout, models=desc.models_folder or None, seed=desc.seed,
        points_per_plant=desc.points_per_plant, plant_spacing=desc.plant_spacing,
        row_spacing=desc.row_spacing, levels=desc.levels, realizations=desc.realizations,
        wind_variance=desc.wind_variance, wind_direction=desc.wind_direction)
    return scene


# ---------------------------------------------------------------- scores
def score_msg(frame_id: str, stamp: Any, realization: int, realizations: int, num_images: int,
              fscore_threshold: float, capture: str, method: str = '',
              info: Optional[CameraPlan] = None, source: str = 'render') -> ReconstructionScore:
    """The head of a ``vp_interfaces/ReconstructionScore``: which plan and realization, the
    settings; the plan's reward and reward model from its ``/camera_plan/info`` (NaN and '' when
    unknown), the method from ``method`` or else from the info."""
    msg = ReconstructionScore()
    msg.header.frame_id, msg.header.stamp = frame_id, stamp
    msg.method = method or (info.method if info is not None else '')
    msg.realization, msg.realizations = int(realization), int(realizations)
    msg.num_images = int(num_images)
    msg.reward = float(info.reward) if info is not None else math.nan
    msg.reward_model = info.reward_model if info is not None else ''
    msg.fscore_threshold = float(fscore_threshold)
    msg.capture, msg.source = capture, source
    return msg


def realization_score(msg: ReconstructionScore, res: Any) -> ReconstructionScore:
    """``msg`` with the figures of one realization's result (``chamfer``, ``accuracy``,
    ``completeness``, ``chamfer_shape`` in metres, ``images``, ``fscore``, ``points``)."""
    msg.chamfer, msg.accuracy, msg.completeness = 100 * res.chamfer, 100 * res.accuracy, 100 * res.completeness
    msg.chamfer_shape, msg.registered_images = 100 * res.chamfer_shape, int(res.images)
    msg.fscore, msg.num_points = float(res.fscore), int(len(res.points))
    return _no_truth(msg, [res])


def _no_truth(msg: ReconstructionScore, per: Any) -> ReconstructionScore:
    """``msg`` with the metrics without a ground truth of the realizations ``per`` (means;
    NaN and no per-plant entries where a realization has no coverage of the prior)."""
    msg.mean_reprojection_error = float(np.mean([r.mean_reprojection_error for r in per]))
    msg.mean_track_length = float(np.mean([r.mean_track_length for r in per]))
    msg.centre_residual = float(np.mean([r.centre_residual for r in per]))  # NaN where any had no SfM
    cov = [r.coverage for r in per]
    if all(c is not None for c in cov):
        msg.coverage_of_prior = float(np.mean([c.fraction for c in cov]))
        msg.coverage_of_prior_per_plant = [float(x) for x in np.mean([c.per_plant for c in cov], axis=0)]
        msg.coverage_tau = float(cov[0].tau)
    else:
        msg.coverage_of_prior = msg.coverage_tau = math.nan
    return msg


def aggregate_score(msg: ReconstructionScore, result: Any) -> ReconstructionScore:
    """``msg`` with the aggregate figures of a plan's result (``chamfer_mean``, ``chamfer_std``,
    ``chamfer_shape_mean`` and its ``realizations``): means over the realizations, the fewest
    registered images."""
    per = result.realizations
    msg.chamfer, msg.chamfer_std = 100 * result.chamfer_mean, 100 * result.chamfer_std
    msg.chamfer_shape = 100 * result.chamfer_shape_mean
    msg.registered_images = int(min(r.images for r in per))
    msg.accuracy = float(np.mean([100 * r.accuracy for r in per]))
    msg.completeness = float(np.mean([100 * r.completeness for r in per]))
    msg.fscore = float(np.mean([r.fscore for r in per]))
    msg.num_points = int(np.mean([len(r.points) for r in per]))
    return _no_truth(msg, per)


def error_score(msg: ReconstructionScore, code: int, text: str) -> ReconstructionScore:
    """``msg`` as a failure: ``error_code``, ``error_msg`` and NaN distances."""
    msg.error_code, msg.error_msg = int(code), text
    msg.chamfer = msg.accuracy = msg.completeness = msg.chamfer_shape = float('nan')
    msg.mean_reprojection_error = msg.mean_track_length = msg.coverage_of_prior = msg.coverage_tau = float('nan')
    msg.centre_residual = float('nan')
    return msg


def score_record(msg: ReconstructionScore) -> dict:
    """A realization's score as a plain record (the run summary's ``per_realization`` entries)."""
    return {'realization': msg.realization, 'chamfer': msg.chamfer, 'chamfer_shape': msg.chamfer_shape,
            'registered_images': msg.registered_images, 'accuracy': msg.accuracy,
            'completeness': msg.completeness, 'fscore': msg.fscore, 'points': msg.num_points,
            'mean_reprojection_error': msg.mean_reprojection_error, 'mean_track_length': msg.mean_track_length,
            'centre_residual': msg.centre_residual, 'coverage_of_prior': msg.coverage_of_prior,
            'coverage_of_prior_per_plant': [float(x) for x in msg.coverage_of_prior_per_plant],
            'coverage_tau': msg.coverage_tau, 'error_code': msg.error_code, 'error_msg': msg.error_msg}


# ---------------------------------------------------------------- simulated flights
def simulate_flights_goal(plans: Sequence[ArrayLike], draws: Sequence[Any], settings: Any,
                          report_position_sigma: float, report_attitude_sigma: float, ground_control: bool,
                          fov: float) -> SimulateFlights.Goal:
    """The ``SimulateFlights`` goal that flies ``plans`` ((N_i, 6) each) under ``draws``
    (:class:`vp_scene.flights.FlightDraw`, one a plan) at ``settings``
    (:class:`vp_scene.flights.FlightSettings`), photographed with these reported-pose errors and
    ground control, with this field of view (rad)."""
    goal = SimulateFlights.Goal()
    cams = [np.asarray(p, dtype=np.float64).reshape(-1, 6) for p in plans]
    goal.cameras = [float(x) for c in cams for x in c.ravel()]
    goal.cameras_per_plan = [len(c) for c in cams]
    goal.flight_indices = [int(d.index) for d in draws]
    goal.n_wind = [float(d.n_wind) for d in draws]
    goal.capture_seeds = [int(d.capture_seed) for d in draws]
    goal.width, goal.height = int(settings.width), int(settings.height)
    goal.sift_first_octave, goal.dense_scale = int(settings.sift_first_octave), float(settings.dense_scale)
    goal.report_position_sigma, goal.report_attitude_sigma = float(report_position_sigma), float(report_attitude_sigma)
    goal.ground_control, goal.fov = bool(ground_control), float(fov)
    return goal


def _nan(x: Optional[float]) -> float:
    return math.nan if x is None else float(x)


def _none(x: float) -> Optional[float]:
    return None if not math.isfinite(x) else float(x)


def flight_msg(score: Any, plan: int = 0, source: str = '') -> SimulatedFlight:
    """``vp_interfaces/SimulatedFlight`` of a :class:`vp_scene.flights.FlightScore` (metres; NaN
    for the distances a failed flight has not) of the plan ``plan`` (from ``source``)."""
    d = score.draw
    return SimulatedFlight(plan=int(plan), source=source, index=int(d.index), n_wind=float(d.n_wind),
                           capture_seed=int(d.capture_seed), failed=bool(score.failed), chamfer=_nan(score.chamfer),
                           chamfer_shape=_nan(score.chamfer_shape), coverage=_nan(score.coverage),
                           images=int(score.images), error_code=int(score.error_code), error_msg=score.reason,
                           seconds=float(score.seconds))


def flight_score_of(msg: SimulatedFlight) -> Any:
    """The :class:`vp_scene.flights.FlightScore` of a ``SimulatedFlight`` (NaN distances: None)."""
    from .flights import FlightDraw, FlightScore

    return FlightScore(draw=FlightDraw(index=int(msg.index), n_wind=float(msg.n_wind), capture_seed=int(msg.capture_seed)),
                       chamfer=_none(msg.chamfer), chamfer_shape=_none(msg.chamfer_shape),
                       coverage=_none(msg.coverage), images=int(msg.images), failed=bool(msg.failed),
                       error_code=int(msg.error_code), reason=msg.error_msg, seconds=float(msg.seconds))


def flight_record_msg(record: dict) -> SimulatedFlight:
    """The ``SimulatedFlight`` of a planning run's flight record
    (:attr:`vp_planner.optimizers.PlanResult.flights`: ``plan``, ``source`` and a FlightScore's fields)."""
    from .flights import FlightScore

    score = FlightScore.from_dict({k: v for k, v in record.items() if k not in ('plan', 'source')})
    return flight_msg(score, record['plan'], record['source'])


def flight_record(msg: SimulatedFlight) -> dict:
    """A ``SimulatedFlight`` as a plain record (a run summary's ``flights`` entries): the plan and its
    source, the draw, the score (metres; None where NaN) and the seconds."""
    score = flight_score_of(msg)
    return {'plan': int(msg.plan), 'source': msg.source, 'draw': score.draw.to_dict(),
            'score': {k: v for k, v in score.to_dict().items() if k not in ('draw', 'seconds')},
            'seconds': score.seconds}


# ---------------------------------------------------------------- images
def _rgb(image: ArrayLike) -> NDArray[np.uint8]:
    a = np.asarray(image)
    if a.dtype != np.uint8 or a.ndim != 3 or a.shape[2] != 3 or a.shape[0] < 1 or a.shape[1] < 1:
        raise ValueError(f"an image must be RGB uint8 (H, W, 3), got {a.dtype} {a.shape}")
    return np.ascontiguousarray(a)


def image_msg(image: ArrayLike, frame_id: str, stamp: Any) -> Image:
    """``sensor_msgs/Image`` (``rgb8``, rows packed) of an RGB image (H, W, 3) uint8."""
    a = _rgb(image)
    msg = Image(height=a.shape[0], width=a.shape[1], encoding='rgb8', is_bigendian=0, step=3 * a.shape[1])
    msg.header.frame_id, msg.header.stamp = frame_id, stamp
    msg.data = a.tobytes()
    return msg


def image_array(msg: Image) -> NDArray[np.uint8]:
    """RGB (H, W, 3) uint8 of a ``sensor_msgs/Image`` in ``rgb8``, ``bgr8`` or ``mono8`` (rows
    may be padded: ``step``); ValueError naming the problem for another encoding or a short buffer.
    An ``rgb8`` image without padding is a view of ``msg.data`` (no copy; it keeps the buffer alive)."""
    channels = {'rgb8': 3, 'bgr8': 3, 'mono8': 1}
    if msg.encoding not in channels:
        raise ValueError(f"image encoding {msg.encoding!r} is not read (rgb8, bgr8, mono8)")
    c, h, w, step = channels[msg.encoding], int(msg.height), int(msg.width), int(msg.step)
    try:  # a view of the message's buffer (rclpy: array.array), not a copy: a set of 16 images is 144 MB
        data = np.frombuffer(msg.data, dtype=np.uint8)
    except (TypeError, ValueError):
        data = np.frombuffer(bytes(msg.data), dtype=np.uint8)
    if step < c * w or len(data) < step * h or h < 1 or w < 1:
        raise ValueError(f"image of {w}x{h} {msg.encoding} with step {step} has {len(data)} bytes")
    a = data[:step * h].reshape(h, step)[:, :c * w].reshape(h, w, c)
    if msg.encoding == 'bgr8':
        a = a[..., ::-1]
    elif c == 1:
        a = np.repeat(a, 3, axis=2)
    return np.ascontiguousarray(a)


def compressed_image_msg(image: ArrayLike, frame_id: str, stamp: Any, fmt: str = 'png') -> CompressedImage:
    """``sensor_msgs/CompressedImage`` of an RGB image, ``fmt`` ``png`` (lossless) or ``jpeg``;
    ``format`` as image_transport's compressed plugin writes it (``rgb8; png compressed bgr8``)."""
    import cv2

    if fmt not in ('png', 'jpeg'):
        raise ValueError(f"compressed image format must be png or jpeg, got {fmt!r}")
    ok, buf = cv2.imencode('.' + fmt, cv2.cvtColor(_rgb(image), cv2.COLOR_RGB2BGR))
    if not ok:
        raise ValueError(f"cannot encode the image as {fmt}")
    msg = CompressedImage(format=f'rgb8; {fmt} compressed bgr8')
    msg.header.frame_id, msg.header.stamp = frame_id, stamp
    msg.data = buf.tobytes()
    return msg


def compressed_image_array(msg: CompressedImage) -> NDArray[np.uint8]:
    """RGB (H, W, 3) uint8 of a ``sensor_msgs/CompressedImage`` (PNG or JPEG); ValueError
    (:class:`vp_scene.images.ImageError`) for one of more than
    :data:`vp_scene.images.MAX_IMAGE_PIXELS` pixels (refused from its header, before decoding),
    or one that is truncated or does not decode."""
    from .images import decode_image

    return decode_image(bytes(msg.data), f"compressed image ({msg.format or 'no format'}, {len(msg.data)} bytes)")


def camera_info_msg(K: ArrayLike, width: int, height: int, frame_id: str, stamp: Any) -> CameraInfo:
    """``sensor_msgs/CameraInfo`` of a pinhole camera: ``k`` = K (OpenCV pixel convention, as
    REP-104), ``plumb_bob`` with zero distortion, ``r`` identity, ``p`` = [K | 0]."""
    k = np.asarray(K, dtype=np.float64).reshape(3, 3)
    msg = CameraInfo(width=int(width), height=int(height), distortion_model='plumb_bob', d=[0.0] * 5)
    msg.header.frame_id, msg.header.stamp = frame_id, stamp
    msg.k = [float(x) for x in k.reshape(-1)]
    msg.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    msg.p = [float(x) for x in np.hstack([k, np.zeros((3, 1))]).reshape(-1)]
    return msg


def camera_info_intrinsics(msg: CameraInfo) -> tuple[NDArray[np.float64], int, int]:
    """(K 3x3, width, height) of a ``sensor_msgs/CameraInfo``; ValueError for a distortion other
    than zero (undistort first), a K that is not a pinhole's, or no size."""
    if any(float(x) != 0.0 for x in msg.d):
        raise ValueError(f"camera_info has a non-zero {msg.distortion_model or 'distortion'} "
                         f"({list(msg.d)}): undistort the images first")
    k = np.asarray(msg.k, dtype=np.float64).reshape(3, 3)
    if not (np.all(np.isfinite(k)) and k[0, 0] > 0 and k[1, 1] > 0 and k[2, 2] == 1.0):
        raise ValueError(f"camera_info K is not a pinhole camera's: {k.reshape(-1).tolist()}")
    if msg.width < 1 or msg.height < 1:
        raise ValueError(f"camera_info has no image size ({msg.width}x{msg.height})")
    return k, int(msg.width), int(msg.height)
