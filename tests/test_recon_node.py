"""The real ``vp_recon recon`` node in its own process, fed by the real scene node, over DDS.

The test publishes plans on /camera_plan (as the planner does) and listens to
/reconstruction/score and /reconstruction/points.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("rclpy", reason="rclpy is not importable: source install/setup.bash in the venv")
pytest.importorskip("vp_recon.pipeline", reason="vp_recon is not built: run tools/setup.sh")

from geometry_msgs.msg import Pose, PoseArray  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from sensor_msgs.msg import PointCloud2  # noqa: E402
from vp_interfaces.msg import ReconstructionScore as Score  # noqa: E402

from vp_scene.camera import cameras_to_poses  # noqa: E402
from vp_scene.cloud import pointcloud2_to_numpy  # noqa: E402

LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
SCENE = dict(scenario="one_plant", points_per_plant=3000, realizations=2, levels=5, seed=2)
RECON = dict(width=640, height=480)
TIMEOUT = 240.0


def ring(n: int = 6, radius: float = 1.7, height: float = 1.3, arc: float = math.radians(150),
         target=(0.0, 0.0, 0.9)) -> np.ndarray:
    """n cameras on an arc around the plant, facing a point on its stalk."""
    az = np.linspace(0.0, arc, n)
    c = np.stack([radius * np.cos(az), radius * np.sin(az), np.full(n, height)], axis=1)
    return np.concatenate([c, np.asarray(target) - c], axis=1)


def pose_array(cameras: np.ndarray) -> PoseArray:
    msg = PoseArray()
    msg.header.frame_id = "map"
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
        scores = client.subscribe(Score, "/reconstruction/score", 10)
        clouds = client.subscribe(PointCloud2, "/reconstruction/points", 10)
        pub = client.node.create_publisher(PoseArray, "/camera_plan", LATCHED)
        assert client.spin_until(lambda: client.node.count_subscribers("/camera_plan") >= 1, 60), recon.output()
        return client, pub, scores, clouds, recon
    return make


def aggregate(scores: list):
    return [s for s in scores if s.realization == Score.AGGREGATE]


def test_plan_becomes_scores_and_clouds(recon_system, tmp_path) -> None:
    client, pub, scores, clouds, recon = recon_system(method="ring")
    pub.publish(pose_array(ring()))
    assert client.spin_until(lambda: aggregate(scores), TIMEOUT), recon.output()[-4000:]
    per = [s for s in scores if s.realization != Score.AGGREGATE]
    agg = aggregate(scores)[0]
    assert agg.error_code == Score.NONE, agg.error_msg
    assert sorted(s.realization for s in per) == [0, 1] and all(s.error_code == Score.NONE for s in per)
    assert agg.realizations == 2 and agg.num_images == 6 and agg.method == "ring"
    assert math.isfinite(agg.chamfer) and 0 < agg.chamfer < 10  # x100: under 10 cm
    assert agg.chamfer == pytest.approx(np.mean([s.chamfer for s in per]))
    assert agg.chamfer == pytest.approx(agg.accuracy + agg.completeness, rel=1e-6)
    assert 0 < agg.reward <= 1 and 0 <= agg.fscore <= 1
    assert client.spin_until(lambda: len(clouds) >= 2, 30)
    pts, _, real = pointcloud2_to_numpy(clouds[0])
    assert len(pts) == per[0].num_points and set(np.unique(real)) == {0}
    out = list((tmp_path / "out").glob("plan-*"))
    assert out and sorted(p.name for p in out[0].glob("recon_*.ply")) == ["recon_0.ply", "recon_1.ply"]
    assert sorted(p.name for p in out[0].glob("views_*.png")) == ["views_0.png", "views_1.png"]
    assert not list(out[0].glob("realization_*"))  # COLMAP workspaces are cleaned up


def test_bad_plans_give_error_scores_and_node_keeps_running(recon_system) -> None:
    client, pub, scores, _clouds, recon = recon_system()
    pub.publish(pose_array(np.zeros((0, 6))))
    assert client.spin_until(lambda: aggregate(scores), 60), recon.output()[-3000:]
    assert aggregate(scores)[0].error_code == Score.EMPTY_PLAN and aggregate(scores)[0].error_msg

    away = ring()
    away[:, 3:] *= -1.0  # every camera looks away from the plant
    pub.publish(pose_array(away))
    assert client.spin_until(lambda: len(aggregate(scores)) >= 2, TIMEOUT), recon.output()[-3000:]
    agg = aggregate(scores)[1]
    assert agg.error_code == Score.NOTHING_VISIBLE, agg.error_msg
    assert [s.error_code for s in scores if s.realization >= 0] == [Score.NOTHING_VISIBLE] * 2
    assert math.isnan(agg.chamfer) and recon.alive()


def test_unwritable_output_folder(recon_system, tmp_path) -> None:
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    client, pub, scores, _clouds, recon = recon_system(output_folder=str(blocker / "sub"))
    pub.publish(pose_array(ring()))
    assert client.spin_until(lambda: aggregate(scores), 60), recon.output()[-3000:]
    agg = aggregate(scores)[0]
    assert agg.error_code == Score.OUTPUT_NOT_WRITABLE and str(blocker) in agg.error_msg
    assert recon.alive() and "not writable" in recon.output()


def test_bad_parameter_exits_non_zero(ros_env, start_node) -> None:
    recon = start_node("vp_recon", "recon", {"width": 4}, ros_env)
    assert recon.wait(30.0) not in (None, 0), recon.output()
    assert "width" in recon.output()


def test_plan_without_scene_is_reported(ros_env, start_node, ros_node, tmp_path) -> None:
    recon = start_node("vp_recon", "recon", {**RECON, "output_folder": str(tmp_path), "scene_timeout": 1.0}, ros_env)
    client = ros_node(ros_env)
    scores = client.subscribe(Score, "/reconstruction/score", 10)
    pub = client.node.create_publisher(PoseArray, "/camera_plan", LATCHED)
    pub.publish(pose_array(ring()))
    assert client.spin_until(lambda: aggregate(scores), 60), recon.output()[-3000:]
    agg = aggregate(scores)[0]
    assert agg.error_code == Score.NO_SCENE and "/scene/noisy_points" in agg.error_msg
    assert recon.alive()
