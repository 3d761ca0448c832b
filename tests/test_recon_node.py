"""The real ``vp_recon recon`` node in its own process, fed by the real scene node, over DDS.

The test publishes plans on /camera_plan and /camera_plan/info (as the planner does) and listens
to /reconstruction/score and /reconstruction/points.
"""
from __future__ import annotations

import math
import re
import signal
import time

import cv2
import numpy as np
import pytest

from geometry_msgs.msg import Pose, PoseArray
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2
from vp_interfaces.msg import CameraPlan, SceneDescription
from vp_interfaces.msg import ReconstructionScore as Score

from vp_recon.recon_node import SCORES  # transient local: a score sent before the match is not lost
from vp_scene.camera import cameras_to_poses
from vp_scene.cloud import pointcloud2_to_numpy

LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
SCENE = dict(scenario="one_plant", points_per_plant=3000, realizations=2, levels=5, seed=2)
RECON = dict(width=640, height=480, capture="ideal")  # plumbing on small images (exact poses)
TIMEOUT = 240.0


def ring(n: int = 6, radius: float = 1.7, height: float = 1.3, arc: float = math.radians(150),
         target=(0.0, 0.0, 0.9)) -> np.ndarray:
    """n cameras on an arc around the plant, facing a point on its stalk."""
    az = np.linspace(0.0, arc, n)
    c = np.stack([radius * np.cos(az), radius * np.sin(az), np.full(n, height)], axis=1)
    return np.concatenate([c, np.asarray(target) - c], axis=1)


def pose_array(cameras: np.ndarray, frame: str = "map", stamp: int = 0) -> PoseArray:
    msg = PoseArray()
    msg.header.frame_id = frame
    msg.header.stamp.sec = stamp
    for x, y, z, qx, qy, qz, qw in cameras_to_poses(cameras) if len(cameras) else []:
        p = Pose()
        p.position.x, p.position.y, p.position.z = float(x), float(y), float(z)
        p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w = float(qx), float(qy), float(qz), float(qw)
        msg.poses.append(p)
    return msg


@pytest.fixture
def recon_system(ros_env, start_node, ros_node, tmp_path):
    def make(**params):
        start_node("vp_scene", "scene", SCENE, ros_env)
        recon = start_node("vp_recon", "recon", {**RECON, "output_folder": str(tmp_path / "out"), **params}, ros_env)
        client = ros_node(ros_env)
        scores = client.subscribe(Score, "/reconstruction/score", SCORES)
        clouds = client.subscribe(PointCloud2, "/reconstruction/points", 10)
        pub = client.node.create_publisher(PoseArray, "/camera_plan", LATCHED)
        assert client.spin_until(lambda: client.node.count_subscribers("/camera_plan") >= 1, 60), recon.output()
        return client, pub, scores, clouds, recon
    return make


def aggregate(scores: list):
    return [s for s in scores if s.realization == Score.AGGREGATE]


def test_plan_becomes_scores_and_clouds(recon_system, tmp_path) -> None:
    """A plan with its /camera_plan/info: scores carry the planner's reward; the rendering
    parameters are read per plan (issue 10, item 12: they were read once); a late subscriber to
    /reconstruction/points gets every realization in one latched message (it got the last)."""
    client, pub, scores, clouds, recon = recon_system(method="ring")
    params = AsyncParameterClient(client.node, "recon")
    assert params.wait_for_services(timeout_sec=60)
    refused = client.call(lambda: params.set_parameters([Parameter("width", value=4)]), 60).results[0]
    assert not refused.successful and "width" in refused.reason
    refused = client.call(lambda: params.set_parameters([Parameter("max_realizations", value=-1)]), 60).results[0]
    assert not refused.successful and "max_realizations" in refused.reason
    smaller = [Parameter("width", value=400), Parameter("height", value=300)]
    assert all(r.successful for r in client.call(lambda: params.set_parameters(smaller), 60).results)

    info_pub = client.node.create_publisher(CameraPlan, "/camera_plan/info", LATCHED)
    plan = pose_array(ring(), stamp=7)
    info = CameraPlan(header=plan.header, poses=plan.poses, reward=0.4321, reward_model="coverage", method="egp")
    info_pub.publish(info)
    pub.publish(plan)
    assert client.spin_until(lambda: aggregate(scores), TIMEOUT), recon.output()[-4000:]
    per = [s for s in scores if s.realization != Score.AGGREGATE]
    agg = aggregate(scores)[0]
    assert agg.error_code == Score.NONE, agg.error_msg
    assert sorted(s.realization for s in per) == [0, 1] and all(s.error_code == Score.NONE for s in per)
    assert agg.realizations == 2 and agg.num_images == 6 and agg.method == "ring"
    assert math.isfinite(agg.chamfer) and 0 < agg.chamfer < 10  # x100: under 10 cm
    assert agg.chamfer == pytest.approx(np.mean([s.chamfer for s in per]))
    assert agg.chamfer == pytest.approx(agg.accuracy + agg.completeness, rel=1e-6)
    assert all(s.reward == pytest.approx(0.4321) and s.reward_model == "coverage" for s in scores)
    assert 0 <= agg.fscore <= 1
    # the metrics without a ground truth (issue 20, part 4) travel in the score, appended fields
    assert agg.mean_reprojection_error > 0 and agg.mean_track_length >= 2 and agg.coverage_tau > 0
    assert math.isnan(agg.centre_residual)  # the ideal capture: known poses, no SfM to check
    assert 0 < agg.coverage_of_prior <= 1 and len(agg.coverage_of_prior_per_plant) == 1

    late = client.add_node("late_subscriber")
    late_clouds = client.subscribe(PointCloud2, "/reconstruction/points", LATCHED, node=late)
    late_scores = client.subscribe(Score, "/reconstruction/score", SCORES, node=late)
    assert client.spin_until(lambda: late_clouds and len(late_scores) == 3, 30), len(late_scores)
    assert [s.realization for s in late_scores] == [0, 1, Score.AGGREGATE]  # the plan's scores, kept
    pts, _, real = pointcloud2_to_numpy(late_clouds[0])
    assert len(late_clouds) == 1 and sorted(np.unique(real)) == [0, 1]
    assert [int((real == k).sum()) for k in (0, 1)] == [next(s.num_points for s in per if s.realization == k)
                                                        for k in (0, 1)]
    out = list((tmp_path / "out").glob("plan-*"))
    assert len(out) == 1 and re.fullmatch(r"plan-\d{8}-\d{6}", out[0].name)
    assert sorted(p.name for p in out[0].glob("recon_*.ply")) == ["recon_0.ply", "recon_1.ply"]
    assert sorted(p.name for p in out[0].glob("views_*.png")) == ["views_0.png", "views_1.png"]
    sheet = cv2.imread(str(out[0] / "views_0.png"))
    assert sheet.shape[:2] == (2 * 300, 3 * 400)  # 6 views of the new size, not 640 x 480
    assert not list(out[0].glob("realization_*"))  # COLMAP workspaces are cleaned up
    # issue 20: every realization's capture set is a flight folder that `make recon IMAGES=...` reads
    from vp_recon.flight import read_flight

    for k in (0, 1):
        views = read_flight(out[0] / "captures" / f"realization_{k}")
        assert len(views.images) == 6 and views.size == (400, 300) and views.realization == k
        np.testing.assert_allclose(views.reported[:, :3], ring()[:, :3], atol=1e-9)  # ideal: the planned poses


def test_realizations_on_a_local_dask_cluster(recon_system) -> None:
    """Issue 22, item 6: parameter scheduler 'local' reconstructs the K realizations of a plan on a
    local Dask cluster of ``workers`` processes; the node publishes every score as without it."""
    client, pub, scores, clouds, recon = recon_system(scheduler="local", workers=2, width=400, height=300)
    pub.publish(pose_array(ring()))
    assert client.spin_until(lambda: aggregate(scores), TIMEOUT), recon.output()[-4000:]
    agg = aggregate(scores)[0]
    assert agg.error_code == Score.NONE, agg.error_msg
    per = [s for s in scores if s.realization != Score.AGGREGATE]
    assert sorted(s.realization for s in per) == [0, 1] and agg.realizations == 2
    assert recon.wait_for_output("realizations in parallel on Dask (local", 20), recon.output()[-3000:]
    # the local cluster is the node's for its life (started with the node, while a planner plans):
    # a second plan runs on the same scheduler instead of starting a cluster of its own
    pub.publish(pose_array(ring(), stamp=2))
    assert client.spin_until(lambda: len(aggregate(scores)) >= 2, TIMEOUT), recon.output()[-4000:]
    assert aggregate(scores)[1].error_code == Score.NONE, aggregate(scores)[1].error_msg
    used = re.findall(r"realizations in parallel on Dask \(local: (\S+),", recon.output())
    assert len(used) == 2 and used[0] == used[1], used
    assert recon.poll() is None, recon.output()[-2000:]


def test_a_lost_scheduler_is_an_error_score_and_the_node_serves_on(recon_system, tmp_path) -> None:
    """Hardening III, item 10: parameter scheduler, a running scheduler's address, SIGKILLed while
    the node reconstructs on its worker: the plan's aggregate score has error UNKNOWN and names the
    scheduler (it said FutureCancelledError, without the address), no traceback in the log, and
    the node serves on."""
    import os

    from test_cluster import dask_scheduler, worker_busy  # tests/: a dask scheduler and worker as processes

    env = dict(os.environ, OMP_NUM_THREADS="1", PYOPENGL_PLATFORM="egl")
    env.pop("DASK_SCHEDULER_ADDRESS", None)
    sched, worker, address = dask_scheduler(tmp_path, env)
    try:
        assert sched.wait_for_output("Register worker", 60), sched.output()
        client, pub, scores, _clouds, recon = recon_system(scheduler=address, width=1280, height=960)
        pub.publish(pose_array(ring()))
        assert recon.wait_for_output(f"realizations in parallel on Dask ({address}", TIMEOUT), recon.output()[-3000:]
        assert worker_busy(address, TIMEOUT), recon.output()[-3000:]  # a realization on the worker
        sched.signal(signal.SIGKILL)
        assert client.spin_until(lambda: aggregate(scores), 60), recon.output()[-3000:]
    finally:
        worker.stop()
        sched.stop()
    agg = aggregate(scores)[0]
    assert agg.error_code == Score.UNKNOWN and f"lost the Dask scheduler {address}" in agg.error_msg, agg.error_msg
    # it serves on: the next plan is answered (an empty one, at once), and the lost scheduler left
    # no traceback in the log meanwhile
    pub.publish(pose_array(np.zeros((0, 6)), stamp=2))
    assert client.spin_until(lambda: len(aggregate(scores)) >= 2, 60), recon.output()[-3000:]
    assert aggregate(scores)[1].error_code == Score.EMPTY_PLAN, aggregate(scores)[1].error_msg
    assert recon.alive() and "Traceback" not in recon.output(), recon.output()[-3000:]


def test_bad_plans_give_error_scores_and_node_keeps_running(recon_system) -> None:
    client, pub, scores, _clouds, recon = recon_system()
    pub.publish(pose_array(np.zeros((0, 6))))
    assert client.spin_until(lambda: aggregate(scores), 60), recon.output()[-3000:]
    assert aggregate(scores)[0].error_code == Score.EMPTY_PLAN and aggregate(scores)[0].error_msg

    # issue 10, item 12: the frame of the PoseArray was ignored
    pub.publish(pose_array(ring(), frame="odom"))
    assert client.spin_until(lambda: len(aggregate(scores)) >= 2, 60), recon.output()[-3000:]
    agg = aggregate(scores)[1]
    assert agg.error_code == Score.WRONG_FRAME and "'odom'" in agg.error_msg

    away = ring()
    away[:, 3:] *= -1.0  # every camera looks away from the plant
    pub.publish(pose_array(away))
    assert client.spin_until(lambda: len(aggregate(scores)) >= 3, TIMEOUT), recon.output()[-3000:]
    agg = aggregate(scores)[2]
    assert agg.error_code == Score.NOTHING_VISIBLE, agg.error_msg
    # one rule (vp_recon.pipeline): the first failing realization stops the plan
    assert [(s.realization, s.error_code) for s in scores if s.realization >= 0] == [(0, Score.NOTHING_VISIBLE)]
    assert math.isnan(agg.chamfer) and math.isnan(agg.reward) and agg.reward_model == ""  # no info: unknown
    assert recon.alive()


def test_a_plan_of_more_than_max_cameras_is_refused_at_once_and_the_node_serves_on(recon_system) -> None:
    """Hardening III, item 4: a 10,000-pose PoseArray on /camera_plan grew the recon from 0.75 to
    5.4 GB in 100 s (a MemoryError under 8 GB; every image of a realization is held at once).
    A plan of more than max_cameras (default 256) is refused as it arrives, with PLAN_TOO_LARGE
    and one log line; a second sortie whose flown cameras (/camera_plan/info) take it over the cap
    is refused too; the next plan is reconstructed."""
    client, pub, scores, _clouds, recon = recon_system(width=400, height=300, max_realizations=1, dense=False)
    pub.publish(pose_array(np.tile(ring(), (1667, 1))[:10_000], stamp=1))
    assert client.spin_until(lambda: aggregate(scores), 60), recon.output()[-3000:]
    agg = aggregate(scores)[0]
    assert (agg.error_code, agg.num_images) == (Score.PLAN_TOO_LARGE, 10_000), agg.error_msg
    assert agg.error_msg.startswith("the plan has 10000 cameras; at most 256 are reconstructed (max_cameras")
    # the node's log reaches the test through a pipe and a reader thread: wait for it, then count
    assert client.spin_until(lambda: "plan: the plan has 10000 cameras" in recon.output(), 20), recon.output()[-3000:]
    assert [line for line in recon.output().splitlines() if "10000" in line] == \
        [line for line in recon.output().splitlines() if "plan: the plan has 10000 cameras" in line] != []

    params = AsyncParameterClient(client.node, "recon")
    assert params.wait_for_services(timeout_sec=60)
    refused = client.call(lambda: params.set_parameters([Parameter("max_cameras", value=1)]), 60).results[0]
    assert not refused.successful and "max_cameras" in refused.reason
    assert client.call(lambda: params.set_parameters([Parameter("max_cameras", value=8)]), 60).results[0].successful
    info_pub = client.node.create_publisher(CameraPlan, "/camera_plan/info", LATCHED)
    second = pose_array(ring(), stamp=2)  # 6 new cameras after the 6 flown: 12
    info_pub.publish(CameraPlan(header=second.header, poses=second.poses, fixed_poses=pose_array(ring(), stamp=2).poses,
                                reward=0.5, reward_model="coverage", method="egp"))
    pub.publish(second)
    assert client.spin_until(lambda: len(aggregate(scores)) >= 2, 60), recon.output()[-3000:]
    agg = aggregate(scores)[1]
    assert agg.error_code == Score.PLAN_TOO_LARGE and "12 cameras; at most 8" in agg.error_msg, agg.error_msg

    pub.publish(pose_array(ring(), stamp=3))
    assert client.spin_until(lambda: len(aggregate(scores)) >= 3, TIMEOUT), recon.output()[-3000:]
    agg = aggregate(scores)[2]
    assert agg.error_code == Score.NONE and agg.num_images == 6, agg.error_msg
    assert recon.alive()
    from vp_recon.config import MAX_CAMERAS
    from vp_recon.recon_node import PARAMS

    assert PARAMS["max_cameras"][0] == MAX_CAMERAS == 256  # one default: the node's, the CLI's, the library's


def test_unwritable_output_folder(recon_system, tmp_path) -> None:
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    client, pub, scores, _clouds, recon = recon_system(output_folder=str(blocker / "sub"))
    pub.publish(pose_array(ring()))
    assert client.spin_until(lambda: aggregate(scores), 60), recon.output()[-3000:]
    agg = aggregate(scores)[0]
    assert agg.error_code == Score.OUTPUT_NOT_WRITABLE and str(blocker) in agg.error_msg
    # the log line reaches the test through a pipe and a reader thread: it may trail the score
    assert recon.wait_for_output("not writable", 20) and recon.alive(), recon.output()[-3000:]


def test_scene_of_a_layout_file_is_rebuilt_from_the_description(ros_env, start_node, ros_node, tmp_path) -> None:
    """The recon rebuilds a layout file's scene (jitter, an explicit yaw, scale and procedural
    model) from the placements in /scene/description: the file is deleted before the plan comes.
    The unwritable output folder is checked right after the scene, so OUTPUT_NOT_WRITABLE (not
    NO_SCENE) says the rebuilt scene matched /scene/noisy_points; no rendering is needed."""
    field = tmp_path / "recon_field.json"
    field.write_text('{"name": "recon_field", "jitter": 0.05, "plants": [{"x": -0.4, "y": 0.0}, '
                     '{"x": 0.4, "y": 0.1, "yaw": 1.0, "scale": 1.2, "model": "procedural-3"}]}')
    client = ros_node(ros_env)
    desc = client.subscribe(SceneDescription, "/scene/description", LATCHED)
    start_node("vp_scene", "scene", {**SCENE, "scenario": str(field), "points_per_plant": 500}, ros_env)
    assert client.spin_until(lambda: desc, 60), "no /scene/description"
    assert desc[0].scenario == str(field) and [p.model for p in desc[0].plants][1] == "procedural-3"
    field.unlink()

    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    recon = start_node("vp_recon", "recon", {**RECON, "output_folder": str(blocker / "sub")}, ros_env)
    scores = client.subscribe(Score, "/reconstruction/score", SCORES)
    pub = client.node.create_publisher(PoseArray, "/camera_plan", LATCHED)
    assert client.spin_until(lambda: client.node.count_subscribers("/camera_plan") >= 1, 60), recon.output()
    pub.publish(pose_array(ring()))
    assert client.spin_until(lambda: aggregate(scores), 60), recon.output()[-3000:]
    agg = aggregate(scores)[0]
    assert agg.error_code == Score.OUTPUT_NOT_WRITABLE, (agg.error_code, agg.error_msg)
    assert recon.wait_for_output(f"scene description: {field}, 2 plants", 30), recon.output()[-3000:]


def test_bad_parameter_exits_non_zero(ros_env, start_node) -> None:
    recon = start_node("vp_recon", "recon", {"width": 4}, ros_env)
    assert recon.wait(30.0) == 2, recon.output()
    assert "width" in recon.output()


def test_plan_without_scene_is_reported(ros_env, start_node, ros_node, tmp_path) -> None:
    recon = start_node("vp_recon", "recon", {**RECON, "output_folder": str(tmp_path), "scene_timeout": 1.0}, ros_env)
    client = ros_node(ros_env)
    scores = client.subscribe(Score, "/reconstruction/score", SCORES)
    pub = client.node.create_publisher(PoseArray, "/camera_plan", LATCHED)
    pub.publish(pose_array(ring()))
    assert client.spin_until(lambda: aggregate(scores), 60), recon.output()[-3000:]
    agg = aggregate(scores)[0]
    assert agg.error_code == Score.NO_SCENE and "/scene/noisy_points" in agg.error_msg
    assert recon.alive()


@pytest.mark.parametrize("stage", ["recon ready", "sparse done"])
def test_sigterm_exits_promptly_whatever_the_node_does(stage, recon_system, tmp_path) -> None:
    """Issue 10, item 4: the recon ignored SIGTERM in 2 of 72 trials (its main thread stuck in
    the multithreaded executor), and once COLMAP had run, glog's SIGTERM handler (installed by
    importing pycolmap) killed it with a stack trace. Idle or in the middle of a
    reconstruction: exit 0 within a few seconds, quietly. Issue 19, item 4: a plan interrupted
    before anything was written left an empty ``plan-<time>/`` folder behind."""
    client, pub, scores, _clouds, recon = recon_system()
    if stage != "recon ready":
        pub.publish(pose_array(ring()))
    assert recon.wait_for_output(stage, TIMEOUT), recon.output()[-3000:]
    recon.signal(signal.SIGTERM)
    t0 = time.monotonic()
    code = recon.wait(15.0)
    took = time.monotonic() - t0
    out = recon.output()
    assert code == 0, out[-3000:]
    assert took < 5.0, f"exited {took:.1f} s after SIGTERM"
    assert "Traceback" not in out, out[-3000:]
    if stage != "recon ready":
        assert "reconstructing" in out, out[-3000:]
        folders = sorted((tmp_path / "out").glob("plan-*"))
        empty = [f.name for f in folders if not any(p.is_file() for p in f.rglob("*"))]
        assert not empty, f"empty plan folders left behind: {empty}"
