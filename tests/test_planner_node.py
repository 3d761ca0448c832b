"""The real ``vp_planner planner`` node in its own process, fed by the real scene node, over DDS.

A test-side action client sends ``PlanViews`` goals; a separate subscriber (another node, as
``ros2 topic echo /camera_plan`` would be) receives the latched PoseArray.
"""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("rclpy", reason="rclpy is not importable: source install/setup.bash in the venv")
pytest.importorskip("vp_interfaces.action", reason="vp_interfaces is not built: run tools/setup.sh")

from geometry_msgs.msg import PoseArray  # noqa: E402
from rclpy.action import ActionClient  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402
from vp_interfaces.action import PlanViews  # noqa: E402

from vp_scene.camera import poses_to_cameras  # noqa: E402

LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
SCENE = dict(scenario="one_plant", points_per_plant=600, realizations=2, levels=5, seed=3)
TIMEOUT = 60.0


def send(client, action: ActionClient, goal: PlanViews.Goal, feedback: list | None = None):
    """Send a goal; returns (goal_handle, result wrapper or None when rejected)."""
    handle = client.spin_future(action.send_goal_async(
        goal, feedback_callback=(lambda fb: feedback.append(fb.feedback)) if feedback is not None else None),
        TIMEOUT)
    if not handle.accepted:
        return handle, None
    return handle, client.spin_future(handle.get_result_async(), 240.0)


def goal(num_cameras=4, method="circle", evaluations=20, initial=0, seed=1, reward="") -> PlanViews.Goal:
    g = PlanViews.Goal()
    g.num_cameras, g.method, g.evaluations, g.initial_evaluations, g.seed, g.reward = (
        num_cameras, method, evaluations, initial, seed, reward)
    return g


@pytest.fixture
def system(ros_env, start_node, ros_node):
    """Scene + planner processes and a test client with an action client on /plan_views."""
    scene = start_node("vp_scene", "scene", SCENE, ros_env)
    planner = start_node("vp_planner", "planner", {"initial_evaluations": 8}, ros_env)
    client = ros_node(ros_env)
    action = ActionClient(client.node, PlanViews, "/plan_views")
    assert client.spin_until(lambda: action.server_is_ready(), TIMEOUT), planner.output()
    return client, action, scene, planner


def test_no_scene_goal_aborts_then_plans_and_publishes(ros_env, start_node, ros_node) -> None:
    planner = start_node("vp_planner", "planner", {"scene_timeout": 1.0}, ros_env)
    client = ros_node(ros_env)
    action = ActionClient(client.node, PlanViews, "/plan_views")
    assert client.spin_until(lambda: action.server_is_ready(), TIMEOUT), planner.output()
    _, res = send(client, action, goal())
    assert res.result.error_code == PlanViews.Result.NO_SCENE and "scene" in res.result.error_msg

    start_node("vp_scene", "scene", SCENE, ros_env)
    assert client.spin_until(lambda: "scene received" in planner.output(), TIMEOUT), planner.output()
    echo = client.add_node("echo")  # a separate subscriber, as `ros2 topic echo /camera_plan`
    plans = client.subscribe(PoseArray, "/camera_plan", LATCHED, node=echo)
    markers = client.subscribe(MarkerArray, "/camera_plan/markers", LATCHED, node=echo)
    feedback: list = []
    _, res = send(client, action, goal(method="egp", evaluations=14, initial=8), feedback)
    r = res.result
    assert r.error_code == PlanViews.Result.NONE, r.error_msg
    assert len(r.plan.poses) == 4 and r.plan.header.frame_id == "map"
    assert len(r.trace) == 14 and np.all(np.diff(r.trace) >= 0) and r.reward == pytest.approx(r.trace[-1])
    assert 0.0 < r.reward <= 1.0 and r.evaluations == 14
    # feedback after every evaluation, ensemble weights once the GPs are fitted
    assert [f.evaluations_done for f in feedback] == list(range(1, 15))
    fitted = [f for f in feedback if len(f.ensemble_weights)]
    assert fitted and all(abs(sum(f.ensemble_weights) - 1.0) < 1e-6 for f in fitted)
    assert list(fitted[-1].ensemble_models) == ["RBF", "RBF-ARD", "Matern-2.5", "Matern-1.5"]

    assert client.spin_until(lambda: plans and markers, TIMEOUT), "no /camera_plan received"
    msg = plans[-1]
    cams = poses_to_cameras([[p.position.x, p.position.y, p.position.z, p.orientation.x, p.orientation.y,
                              p.orientation.z, p.orientation.w] for p in msg.poses])
    expected = np.asarray(r.cameras).reshape(-1, 6)
    np.testing.assert_allclose(cams[:, :3], expected[:, :3], atol=1e-9)
    v = expected[:, 3:] / np.linalg.norm(expected[:, 3:], axis=1, keepdims=True)
    np.testing.assert_allclose(cams[:, 3:], v, atol=1e-6)  # +x of each pose = optical axis
    assert len([m for m in markers[-1].markers if m.ns == "frustums"]) == 4


@pytest.mark.parametrize("bad, code", [
    (dict(num_cameras=1), "INVALID_NUM_CAMERAS"),
    (dict(method="magic"), "UNKNOWN_METHOD"),
    (dict(method="egp", evaluations=5, initial=10), "INVALID_BUDGET"),
    (dict(reward="magic"), "UNKNOWN_REWARD_MODEL"),
])
def test_bad_goals_are_aborted_and_node_keeps_serving(system, bad, code) -> None:
    client, action, _, planner = system
    assert client.spin_until(lambda: "scene received" in planner.output(), TIMEOUT), planner.output()
    _, res = send(client, action, goal(**bad))
    assert res.result.error_code == getattr(PlanViews.Result, code), res.result.error_msg
    assert res.result.error_msg
    _, ok = send(client, action, goal(method="random", evaluations=10))
    assert ok.result.error_code == PlanViews.Result.NONE and len(ok.result.plan.poses) == 4
    assert planner.alive()


def test_cancel_stops_within_one_evaluation(system) -> None:
    client, action, _, planner = system
    assert client.spin_until(lambda: "scene received" in planner.output(), TIMEOUT), planner.output()
    feedback: list = []
    handle = client.spin_future(action.send_goal_async(
        goal(method="egp", evaluations=400, initial=8), feedback_callback=lambda fb: feedback.append(fb.feedback)),
        TIMEOUT)
    assert handle.accepted
    assert client.spin_until(lambda: len(feedback) >= 10, TIMEOUT)
    client.spin_future(handle.cancel_goal_async(), TIMEOUT)
    res = client.spin_future(handle.get_result_async(), TIMEOUT)
    assert res.result.error_code == PlanViews.Result.CANCELED
    assert res.result.evaluations < 400
    assert planner.alive()


@pytest.mark.parametrize("params, text", [({"method": "magic"}, "unknown method"),
                                          ({"num_cameras": 1}, "num_cameras")])
def test_bad_parameter_exits_non_zero(ros_env, start_node, params, text) -> None:
    planner = start_node("vp_planner", "planner", params, ros_env)
    assert planner.wait(30.0) not in (None, 0), planner.output()
    assert text in planner.output()


def test_autostart_plans_when_the_scene_arrives(ros_env, start_node, ros_node) -> None:
    client = ros_node(ros_env)
    plans = client.subscribe(PoseArray, "/camera_plan", LATCHED)
    planner = start_node("vp_planner", "planner", {"autostart": True, "method": "circle", "num_cameras": 5,
                                                   "evaluations": 12}, ros_env)
    start_node("vp_scene", "scene", SCENE, ros_env)
    assert client.spin_until(lambda: plans, TIMEOUT), planner.output()[-3000:]
    assert len(plans[0].poses) == 5 and plans[0].header.frame_id == "map"
    assert client.spin_until(lambda: "published /camera_plan: 5 cameras" in planner.output(), 10), planner.output()


def test_goal_reward_model(system) -> None:
    """The goal's reward field picks the model; the result says which one the plan maximized."""
    from vp_planner.reward import noisy_reward
    from vp_scene.build import build_noisy_scene

    client, action, _, planner = system
    assert client.spin_until(lambda: "scene received" in planner.output(), TIMEOUT), planner.output()
    _, res = send(client, action, goal(method="random", evaluations=6, reward="paper"))
    r = res.result
    assert r.error_code == PlanViews.Result.NONE and r.reward_model == "paper", r.error_msg
    noisy, _ = build_noisy_scene(**SCENE)
    cams = np.asarray(r.cameras).reshape(-1, 6)
    assert r.reward == pytest.approx(float(noisy_reward(cams, noisy.points)), abs=1e-9)
    _, res = send(client, action, goal(method="random", evaluations=6))  # '' = the node's parameter
    assert res.result.reward_model == "coverage" and res.result.reward != pytest.approx(r.reward)
