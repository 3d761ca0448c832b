"""The planner and the dispatcher as ROS 2 lifecycle nodes (real processes over DDS): a plain start
is active at once; with ``managed:=true`` the test drives configure, activate, deactivate, cleanup
and shutdown through lifecycle_msgs' services, as nav2's lifecycle manager does, and checks what
each state serves. Every wait has a deadline."""
from __future__ import annotations

import math

import numpy as np
from geometry_msgs.msg import Pose, PoseArray
from lifecycle_msgs.msg import State, Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rclpy.action import ActionClient
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from vp_interfaces.action import PlanViews
from vp_interfaces.msg import FleetAssignment

from vp_scene.camera import cameras_to_poses, look_at

LATCHED = QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
SCENE = dict(scenario="one_plant", points_per_plant=600, realizations=2, levels=5, seed=3)
TIMEOUT = 60.0


class Managed:
    """lifecycle_msgs' client of one node: its state, and a transition that must succeed."""

    def __init__(self, client, node: str) -> None:
        self.client = client
        self.get = client.node.create_client(GetState, f"/{node}/get_state")
        self.change = client.node.create_client(ChangeState, f"/{node}/change_state")
        assert self.get.wait_for_service(timeout_sec=TIMEOUT) and self.change.wait_for_service(timeout_sec=TIMEOUT)

    def state(self) -> int:
        return self.client.call(lambda: self.get.call_async(GetState.Request()), TIMEOUT).current_state.id

    def __call__(self, transition: int, then: int) -> None:
        answer = self.client.call(lambda: self.change.call_async(
            ChangeState.Request(transition=Transition(id=transition))), TIMEOUT)
        assert answer.success, transition
        assert self.state() == then


def ring(n: int) -> np.ndarray:
    az = np.linspace(0, 2 * math.pi, n, endpoint=False)
    c = np.stack([2.2 * np.cos(az), 2.2 * np.sin(az), np.full(n, 1.2)], axis=1)
    return look_at(c, np.tile([0.0, 0.0, 0.9], (n, 1)))


def plan_msg(cameras: np.ndarray, stamp: int) -> PoseArray:
    msg = PoseArray()
    msg.header.frame_id, msg.header.stamp.sec = "map", stamp
    for row in cameras_to_poses(cameras):
        p = Pose()
        p.position.x, p.position.y, p.position.z = (float(x) for x in row[:3])
        p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w = (float(x) for x in row[3:])
        msg.poses.append(p)
    return msg


def test_a_plain_start_is_active(ros_env, start_node, ros_node) -> None:
    start_node("vp_planner", "planner", {}, ros_env)
    start_node("vp_planner", "dispatcher", {"drones": ["d0"]}, ros_env)
    client = ros_node(ros_env)
    for node in ("planner", "dispatcher"):
        assert Managed(client, node).state() == State.PRIMARY_STATE_ACTIVE


def test_the_planner_through_its_transitions(ros_env, start_node, ros_node) -> None:
    """Unconfigured: no /plan_views, no /camera_plan. Configured (inactive): the server is there
    and rejects goals. Active: a goal plans and /camera_plan gets it. Deactivated: rejected again.
    Cleaned up: the server and the topic are gone. Shut down: finalized, the process still exits 0."""
    start_node("vp_scene", "scene", SCENE, ros_env)
    planner = start_node("vp_planner", "planner", {"managed": True}, ros_env)
    client = ros_node(ros_env)
    manage = Managed(client, "planner")
    assert manage.state() == State.PRIMARY_STATE_UNCONFIGURED
    action = ActionClient(client.node, PlanViews, "/plan_views")
    assert not action.wait_for_server(timeout_sec=1.0) and client.node.count_publishers("/camera_plan") == 0

    def goal(accepted: bool):
        g = PlanViews.Goal(num_cameras=2, method="circle", evaluations=4, seed=0)
        handle = client.spin_future(action.send_goal_async(g), TIMEOUT)
        assert handle.accepted == accepted
        return handle

    manage(Transition.TRANSITION_CONFIGURE, State.PRIMARY_STATE_INACTIVE)
    assert action.wait_for_server(timeout_sec=TIMEOUT)
    goal(False)
    assert client.spin_until(lambda: "rejecting goal: the planner is inactive" in planner.output(), TIMEOUT)
    manage(Transition.TRANSITION_ACTIVATE, State.PRIMARY_STATE_ACTIVE)
    plans = client.subscribe(PoseArray, "/camera_plan", LATCHED)
    result = client.spin_future(goal(True).get_result_async(), TIMEOUT).result
    assert result.error_code == PlanViews.Result.NONE, result.error_msg
    assert client.spin_until(lambda: plans, TIMEOUT) and len(plans[-1].poses) == 2
    manage(Transition.TRANSITION_DEACTIVATE, State.PRIMARY_STATE_INACTIVE)
    goal(False)
    manage(Transition.TRANSITION_CLEANUP, State.PRIMARY_STATE_UNCONFIGURED)
    assert client.spin_until(lambda: not action.server_is_ready() and client.node.count_publishers("/camera_plan")
                             == 0, TIMEOUT)
    manage(Transition.TRANSITION_UNCONFIGURED_SHUTDOWN, State.PRIMARY_STATE_FINALIZED)
    assert planner.stop() == 0 and "Traceback" not in planner.output(), planner.output()[-3000:]


def test_the_dispatcher_through_its_transitions(ros_env, start_node, ros_node) -> None:
    """Unconfigured: no /fleet/assignment. Active: a plan is dispatched. Deactivated: a plan is
    ignored (no answer). Activated again: the next plan is dispatched. Shut down from active."""
    start_node("vp_scene", "scene", SCENE, ros_env)
    dispatcher = start_node("vp_planner", "dispatcher", {"drones": ["d0"], "managed": True, "cruise_speed": 8.0,
                                                          "climb_rate": 4.0, "hover_s": 0.2}, ros_env)
    start_node("vp_scene", "sim_drone", {"drone": "d0", "y": -4.0, "speed": 8.0, "climb_rate": 4.0}, ros_env)
    client = ros_node(ros_env)
    manage = Managed(client, "dispatcher")
    assert manage.state() == State.PRIMARY_STATE_UNCONFIGURED
    assert client.node.count_publishers("/fleet/assignment") == 0
    manage(Transition.TRANSITION_CONFIGURE, State.PRIMARY_STATE_INACTIVE)
    manage(Transition.TRANSITION_ACTIVATE, State.PRIMARY_STATE_ACTIVE)
    answers = client.subscribe(FleetAssignment, "/fleet/assignment", LATCHED)
    plans = client.node.create_publisher(PoseArray, "/camera_plan", LATCHED)

    def answered(stamp: int) -> bool:
        return any(a.plan_stamp.sec == stamp for a in answers)
    assert client.spin_until(lambda: "drone d0 reporting" in dispatcher.output(), TIMEOUT), dispatcher.output()
    plans.publish(plan_msg(ring(2), 501))
    assert client.spin_until(lambda: answered(501), TIMEOUT), dispatcher.output()
    assert client.spin_until(lambda: "d0 landed" in dispatcher.output(), TIMEOUT), dispatcher.output()
    manage(Transition.TRANSITION_DEACTIVATE, State.PRIMARY_STATE_INACTIVE)
    plans.publish(plan_msg(ring(3), 502))
    assert client.spin_until(lambda: "plan 502.000000000 ignored: the dispatcher is inactive" in dispatcher.output(),
                             TIMEOUT), dispatcher.output()
    assert not answered(502)
    manage(Transition.TRANSITION_ACTIVATE, State.PRIMARY_STATE_ACTIVE)
    plans.publish(plan_msg(ring(2), 503))
    assert client.spin_until(lambda: answered(503), TIMEOUT), dispatcher.output()
    manage(Transition.TRANSITION_ACTIVE_SHUTDOWN, State.PRIMARY_STATE_FINALIZED)
    assert dispatcher.stop() == 0 and "Traceback" not in dispatcher.output(), dispatcher.output()[-3000:]
