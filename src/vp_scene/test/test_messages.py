"""vp_scene.messages, the one home of the suite's ROS message conversions:
round trips, the drones' reports, scores, and no conversion code left in the node files."""
from __future__ import annotations

import math
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry

from vp_scene import messages as m
from vp_scene.camera import cameras_to_poses

SRC = Path(__file__).resolve().parents[2]

CAMERAS = np.array([[3.0, 0.0, 1.5, -1.0, 0.0, -0.3], [0.0, 3.0, 1.0, 0.0, -1.0, 0.0],
                    [-2.0, -2.0, 2.5, 1.0, 1.0, -0.8]])


def test_poses_round_trip_exactly() -> None:
    poses = cameras_to_poses(CAMERAS)
    msgs = m.poses_to_msgs(poses)
    assert len(msgs) == 3
    np.testing.assert_array_equal(m.msgs_to_poses(msgs), poses)
    np.testing.assert_array_equal(m.pose_array(m.pose_msg(poses[1])), poses[1])
    np.testing.assert_array_equal(m.point_array(m.point_msg([1.5, -2.0, 3.25])), [1.5, -2.0, 3.25])
    assert m.msgs_to_poses([]).shape == (0, 7) and m.poses_to_msgs(np.zeros((0, 7))) == []


def test_cameras_through_a_pose_array() -> None:
    msg = m.cameras_to_pose_array(CAMERAS, "map")
    assert msg.header.frame_id == "map" and len(msg.poses) == 3
    back = m.pose_array_to_cameras(msg.poses)
    np.testing.assert_allclose(back[:, :3], CAMERAS[:, :3], atol=0)
    v = CAMERAS[:, 3:] / np.linalg.norm(CAMERAS[:, 3:], axis=1, keepdims=True)
    np.testing.assert_allclose(back[:, 3:] / np.linalg.norm(back[:, 3:], axis=1, keepdims=True), v, atol=1e-12)
    with pytest.raises(ValueError):
        bad = m.cameras_to_pose_array(CAMERAS, "map")
        bad.poses[0].orientation.w = bad.poses[0].orientation.x = 0.0
        bad.poses[0].orientation.y = bad.poses[0].orientation.z = 0.0
        m.pose_array_to_cameras(bad.poses)
    far = m.cameras_to_pose_array(CAMERAS, "map")  # a plan's message is bounded as its file is
    far.poses[1].position.y = 1e300
    with pytest.raises(ValueError, match=r"the poses holds 1e\+300, outside \[-10000, 10000\]"):
        m.pose_array_to_cameras(far.poses)


def test_camera_plan_and_plan_key() -> None:
    plan = m.cameras_to_pose_array(CAMERAS, "map")
    plan.header.stamp.sec = 7
    info = m.camera_plan_msg(plan, 0.25, "coverage", "egp", 100, 12.5)
    assert (info.reward, info.reward_model, info.method, info.evaluations, info.planning_time) == \
        (0.25, "coverage", "egp", 100, 12.5)
    assert m.plan_key(info.header, info.poses) == m.plan_key(plan.header, plan.poses)
    other = m.cameras_to_pose_array(CAMERAS + [0.0, 0.0, 0.01, 0.0, 0.0, 0.0], "map")
    other.header.stamp.sec = 7
    assert m.plan_key(other.header, other.poses) != m.plan_key(plan.header, plan.poses)


def test_frustum_markers() -> None:
    markers = m.frustum_markers(CAMERAS, "map", PoseStamped().header.stamp, 1.2)
    assert len(markers.markers) == 1 + 2 * len(CAMERAS)
    frustum = markers.markers[1]
    assert len(frustum.points) == 16 and m.point_array(frustum.points[0]).tolist() == CAMERAS[0, :3].tolist()


@pytest.mark.parametrize("pose_type", ["pose", "odometry"])
def test_drone_reports(pose_type: str) -> None:
    pose = np.array([1.0, -2.0, 3.0, 0.0, 0.0, math.sin(0.3), math.cos(0.3)])
    msg = m.pose_report(pose_type, pose, "map", PoseStamped().header.stamp, "d0/base_link")
    assert isinstance(msg, {"pose": PoseStamped, "odometry": Odometry}[pose_type])
    assert msg.header.frame_id == "map"
    np.testing.assert_array_equal(m.position_of(msg), pose[:3])
    if pose_type == "odometry":
        assert msg.child_frame_id == "d0/base_link"
    assert m.drone_topic("/{drone}/pose", "d3") == "/d3/pose"


def test_navsatfix_round_trip() -> None:
    from sensor_msgs.msg import NavSatFix, NavSatStatus

    fix = m.navsatfix_msg([47.3977421, 8.5455941, 488.25], "map", PoseStamped().header.stamp)
    assert isinstance(fix, NavSatFix) and fix.header.frame_id == "map" and fix.status.status == NavSatStatus.STATUS_FIX
    assert fix.position_covariance_type == NavSatFix.COVARIANCE_TYPE_UNKNOWN
    assert m.navsatfix_geodetic(fix).tolist() == [47.3977421, 8.5455941, 488.25]


def test_scores() -> None:
    res = [SimpleNamespace(chamfer=0.01, accuracy=0.004, completeness=0.006, chamfer_shape=0.008, images=4,
                           fscore=0.7, points=np.zeros((100, 3)), mean_reprojection_error=0.5, mean_track_length=3.0,
                           centre_residual=0.02,
                           coverage=SimpleNamespace(fraction=0.8, per_plant=(0.7, 0.9), tau=0.02)),
           SimpleNamespace(chamfer=0.03, accuracy=0.01, completeness=0.02, chamfer_shape=0.02, images=3,
                           fscore=0.5, points=np.zeros((300, 3)), mean_reprojection_error=0.7, mean_track_length=2.0,
                           centre_residual=0.04,
                           coverage=SimpleNamespace(fraction=0.6, per_plant=(0.5, 0.7), tau=0.02))]
    info = SimpleNamespace(method="egp", reward=0.4, reward_model="paper")
    head = m.score_msg("map", PoseStamped().header.stamp, 0, 1, 4, 0.005, "ideal", "", info)
    one = m.realization_score(head, res[0])
    assert (one.method, one.reward, one.reward_model, one.capture) == ("egp", 0.4, "paper", "ideal")
    assert one.chamfer == pytest.approx(1.0) and one.num_points == 100 and one.registered_images == 4
    agg = m.aggregate_score(m.score_msg("map", PoseStamped().header.stamp, -1, 2, 4, 0.005, "ideal", "ring"),
                            SimpleNamespace(realizations=res, chamfer_mean=0.02, chamfer_std=0.01,
                                            chamfer_shape_mean=0.014))
    assert agg.method == "ring" and math.isnan(agg.reward) and agg.reward_model == ""
    assert agg.chamfer == pytest.approx(2.0) and agg.registered_images == 3 and agg.num_points == 200
    assert agg.accuracy == pytest.approx(0.7) and agg.fscore == pytest.approx(0.6)
    # the metrics without a ground truth: the realization's, the aggregate's means
    assert (one.mean_reprojection_error, one.mean_track_length, one.coverage_of_prior, one.coverage_tau) == \
        (0.5, 3.0, 0.8, 0.02) and list(one.coverage_of_prior_per_plant) == [0.7, 0.9]
    assert agg.mean_reprojection_error == pytest.approx(0.6) and agg.mean_track_length == pytest.approx(2.5)
    assert agg.coverage_of_prior == pytest.approx(0.7)
    assert one.centre_residual == 0.02 and agg.centre_residual == pytest.approx(0.03)
    np.testing.assert_allclose(agg.coverage_of_prior_per_plant, [0.6, 0.8])
    err = m.error_score(m.score_msg("map", PoseStamped().header.stamp, -1, 1, 0, 0.005, "ideal"), 3, "no scene")
    assert (err.error_code, err.error_msg) == (3, "no scene") and math.isnan(err.chamfer)
    assert math.isnan(err.centre_residual)
    rec = m.score_record(one)
    assert rec["chamfer"] == one.chamfer and rec["points"] == 100 and rec["error_code"] == 0
    assert rec["coverage_of_prior"] == 0.8 and rec["coverage_of_prior_per_plant"] == [0.7, 0.9]
    assert rec["centre_residual"] == 0.02


def test_simulated_flights_round_trip() -> None:
    """A batch to the SimulateFlights goal (flat, as vp_recon.sim_flights.flight_batch reads it), a
    FlightScore <-> SimulatedFlight (metres, NaN for what a failure has not), a planning run's flight
    record -> message -> the summary's record."""
    from vp_scene.flights import FlightScore, FlightSettings, flight_draws

    draws = flight_draws(3, 2, 0.002)
    goal = m.simulate_flights_goal([CAMERAS, CAMERAS[:2]], draws, FlightSettings(640, 480, -1, 0.5), 0.02, 0.5,
                                   False, 1.5)
    assert list(goal.cameras_per_plan) == [3, 2] and list(goal.cameras) == CAMERAS.ravel().tolist() + \
        CAMERAS[:2].ravel().tolist()
    assert list(goal.capture_seeds) == [d.capture_seed for d in draws] and list(goal.n_wind) == [d.n_wind for d in draws]
    assert (goal.width, goal.height, goal.sift_first_octave, goal.dense_scale) == (640, 480, -1, 0.5)
    assert (goal.report_position_sigma, goal.report_attitude_sigma, goal.ground_control, goal.fov) == (0.02, 0.5, False, 1.5)
    ok = FlightScore(draw=draws[0], chamfer=0.03, chamfer_shape=0.02, coverage=0.7, images=3, seconds=4.0)
    bad = FlightScore(draw=draws[1], failed=True, error_code=4, reason="nothing visible", seconds=1.0)
    for score in (ok, bad):
        assert m.flight_score_of(m.flight_msg(score, 1)) == score
    msg = m.flight_msg(bad, 1, "arc")
    assert msg.plan == 1 and msg.source == "arc" and math.isnan(msg.chamfer) and msg.error_msg == "nothing visible"
    record = {"plan": 2, "source": "cheap", **ok.to_dict()}
    assert m.flight_record(m.flight_record_msg(record)) == {
        "plan": 2, "source": "cheap", "draw": draws[0].to_dict(), "seconds": 4.0,
        "score": {"chamfer": 0.03, "chamfer_shape": 0.02, "coverage": 0.7, "images": 3, "failed": False,
                  "error_code": 0, "reason": ""}}


def test_scene_description_round_trip() -> None:
    from vp_scene.build import build_noisy_scene
    from vp_scene.layout import Layout

    noisy, _ = build_noisy_scene(scenario="three_row", points_per_plant=200, realizations=2)
    values = {"scenario": "three_row", "models_folder": "", "seed": 0, "points_per_plant": 200,
              "plant_spacing": 0.6, "row_spacing": 0.76}
    desc = m.scene_description_msg(noisy, values, "map", PoseStamped().header.stamp)
    assert desc.realizations == 2 and len(desc.plants) == 3 and len(desc.n_wind) == 2
    layout = Layout.from_placements("three_row", m.placements_of(desc), source="test")
    again, _ = build_noisy_scene(scenario=layout, points_per_plant=200, realizations=2)
    np.testing.assert_allclose(again.points, noisy.points, atol=1e-6)


#: What converting a message by hand looks like: field by field, or building one from numbers.
HAND_CONVERSION = re.compile(r"\.position\.[xyz]\b|\.orientation\.[xyzw]\b|\b(Pose|PoseArray|CameraPlan|Marker|"
                             r"SceneDescription|ReconstructionScore|Score|PointCloud2)\(\)|\b(Point|PlantPlacement|"
                             r"PointField|SimulatedFlight)\(")


def test_no_conversion_code_left_in_the_node_files() -> None:
    nodes = sorted(SRC.glob("vp_*/vp_*/*_node.py"))
    assert len(nodes) >= 7, nodes
    found = [f"{p.relative_to(SRC)}:{k}: {line.strip()}" for p in nodes
             for k, line in enumerate(p.read_text().splitlines(), 1) if HAND_CONVERSION.search(line)]
    assert not found, "\n".join(found)


def test_images_and_camera_info_round_trip() -> None:
    """Image (rgb8, and bgr8 / mono8 / padded rows read), CompressedImage (PNG lossless, JPEG
    close), CameraInfo (K, zero plumb_bob) -> numpy and back."""
    from sensor_msgs.msg import Image

    from vp_scene.camera import intrinsics

    stamp = PoseStamped().header.stamp
    rgb = np.random.default_rng(0).integers(0, 256, (5, 7, 3), dtype=np.uint8)
    msg = m.image_msg(rgb, "d0/camera_optical", stamp)
    assert (msg.encoding, msg.width, msg.height, msg.step, msg.header.frame_id) == \
        ("rgb8", 7, 5, 21, "d0/camera_optical")
    np.testing.assert_array_equal(m.image_array(msg), rgb)
    padded = Image(height=5, width=7, encoding="bgr8", step=24,
                   data=np.pad(rgb[..., ::-1].reshape(5, 21), ((0, 0), (0, 3))).tobytes())
    np.testing.assert_array_equal(m.image_array(padded), rgb)
    mono = Image(height=5, width=7, encoding="mono8", step=7, data=rgb[..., 0].tobytes())
    np.testing.assert_array_equal(m.image_array(mono), np.repeat(rgb[..., :1], 3, axis=2))
    with pytest.raises(ValueError, match="16UC1"):
        m.image_array(Image(height=1, width=1, encoding="16UC1", step=2, data=b"ab"))
    with pytest.raises(ValueError, match="bytes"):
        m.image_array(Image(height=5, width=7, encoding="rgb8", step=21, data=b"short"))
    with pytest.raises(ValueError, match="RGB uint8"):
        m.image_msg(rgb[..., 0], "f", stamp)

    png = m.compressed_image_msg(rgb, "d0/camera_optical", stamp)
    assert png.format == "rgb8; png compressed bgr8"
    np.testing.assert_array_equal(m.compressed_image_array(png), rgb)
    smooth = np.tile(np.linspace(0, 255, 64, dtype=np.uint8)[None, :, None], (48, 1, 3))
    jpeg = m.compressed_image_msg(smooth, "f", stamp, fmt="jpeg")
    assert "jpeg" in jpeg.format and np.abs(m.compressed_image_array(jpeg).astype(int) - smooth).max() < 8
    png.data = b"not an image"
    with pytest.raises(ValueError, match="does not decode"):
        m.compressed_image_array(png)

    K = intrinsics(2000, 1500)
    info = m.camera_info_msg(K, 2000, 1500, "d0/camera_optical", stamp)
    assert info.distortion_model == "plumb_bob" and list(info.d) == [0.0] * 5 and info.p[3] == 0.0
    K2, w, h = m.camera_info_intrinsics(info)
    np.testing.assert_array_equal(K2, K)
    assert (w, h) == (2000, 1500)
    info.d = [0.1, 0, 0, 0, 0]
    with pytest.raises(ValueError, match="undistort"):
        m.camera_info_intrinsics(info)
