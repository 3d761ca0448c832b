"""The real ``vp_planner dispatcher`` node with simulated drones (``vp_scene sim_drone``, one
process per drone) and the real scene node, over DDS.

The test publishes plans on /camera_plan (as the planner does, latched, frame ``map``) and
listens to /fleet/assignment, the goals and the drones' poses. Every wait has a deadline.
"""
from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from geometry_msgs.msg import Pose, PoseArray, PoseStamped
from nav_msgs.msg import Odometry
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from vp_interfaces.msg import FleetAssignment

from vp_planner.fleet import FleetTransform, goal_orientations
from vp_scene.camera import cameras_to_poses, look_at

LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
ANSWERS = QoSProfile(depth=20, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
SCENE = dict(scenario="one_plant", points_per_plant=600, realizations=2, levels=5, seed=3)
TIMEOUT = 60.0


def ring(n: int, radius: float = 2.2, height: float = 1.2, phase: float = 0.0) -> np.ndarray:
    """n cameras on a horizontal circle around the plant, facing its stalk: a feasible plan."""
    az = phase + np.linspace(0, 2 * math.pi, n, endpoint=False)
    c = np.stack([radius * np.cos(az), radius * np.sin(az), np.full(n, height)], axis=1)
    return look_at(c, np.tile([0.0, 0.0, 0.9], (n, 1)))


def plan_msg(cameras: np.ndarray, stamp: int, frame: str = "map") -> PoseArray:
    msg = PoseArray()
    msg.header.frame_id, msg.header.stamp.sec = frame, stamp
    for x, y, z, qx, qy, qz, qw in (cameras_to_poses(cameras) if len(cameras) else []):
        p = Pose()
        p.position.x, p.position.y, p.position.z = float(x), float(y), float(z)
        p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w = float(qx), float(qy), float(qz), float(qw)
        msg.poses.append(p)
    return msg


def pose7(p: Pose) -> np.ndarray:
    return np.array([p.position.x, p.position.y, p.position.z,
                     p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w])


def brute_force(starts: np.ndarray, goals: np.ndarray) -> tuple[float, float]:
    """(min total distance, min longest distance) over every injective map poses -> drones."""
    cost = np.linalg.norm(starts[:, None] - goals[None], axis=-1)
    m = goals.shape[0]
    flights = [cost[list(perm), np.arange(m)] for perm in itertools.permutations(range(len(starts)), m)]
    return min(f.sum() for f in flights), min(f.max() for f in flights)


class Fleet:
    """A test client: publishes plans, collects /fleet/assignment, goals and drone poses."""

    def __init__(self, client, drones: list, odometry: bool = False) -> None:
        self.client, self.drones = client, drones
        self.plans = client.node.create_publisher(PoseArray, "/camera_plan", LATCHED)
        self.answers = client.subscribe(FleetAssignment, "/fleet/assignment", ANSWERS)
        self.goals = {d: client.subscribe(PoseStamped, f"/{d}/goal_pose", ANSWERS) for d in drones}
        self.poses = {d: client.subscribe(Odometry if odometry else PoseStamped, f"/{d}/pose", 10) for d in drones}

    def answer(self, stamp: int, timeout: float = TIMEOUT) -> FleetAssignment:
        def got():
            return [a for a in self.answers if a.plan_stamp.sec == stamp]
        assert self.client.spin_until(got, timeout), f"no /fleet/assignment for plan {stamp}"
        return got()[-1]

    def send(self, cameras: np.ndarray, stamp: int, frame: str = "map", timeout: float = TIMEOUT) -> FleetAssignment:
        self.plans.publish(plan_msg(cameras, stamp, frame))
        return self.answer(stamp, timeout)

    def position(self, drone: str) -> np.ndarray:
        msg = self.poses[drone][-1]
        p = msg.pose.pose if isinstance(msg, Odometry) else msg.pose
        return pose7(p)

    def wait_for_poses(self, dispatcher=None, timeout: float = TIMEOUT) -> bool:
        """Until this client has every drone's pose and, given the dispatcher's process, until the
        dispatcher logged each drone's first pose (it discovers a late drone on its own, 0.5-3 s)."""
        def ready() -> bool:
            seen = dispatcher.output() if dispatcher is not None else ""
            return all(self.poses[d] for d in self.drones) and \
                (dispatcher is None or all(f"drone {d} reporting" in seen for d in self.drones))
        return self.client.spin_until(ready, timeout)


def start_drones(start_node, env, starts: dict, **params) -> dict:
    return {d: start_node("vp_scene", "sim_drone", {"drone": d, "x": float(p[0]), "y": float(p[1]),
                                                      "z": float(p[2]), **params}, env,
                          args=("--ros-args", "-r", f"__node:=sim_{d}"))
            for d, p in starts.items()}


def check_dispatch(fleet: Fleet, ans: FleetAssignment, cameras: np.ndarray, transform: FleetTransform,
                   orientation: str) -> np.ndarray:
    """The answer is a complete, optimal, one-pose-per-drone assignment whose goals are the plan's
    poses in the fleet frame; returns the goals (M, 7) in pose order."""
    m = len(cameras)
    assert ans.error_code == FleetAssignment.NONE, ans.error_msg
    assert [e.pose_index for e in ans.entries] == list(range(m))
    assert len({e.drone for e in ans.entries}) == m  # no two drones get the same pose
    expected = transform.poses_to_fleet(cameras_to_poses(cameras))
    expected[:, 3:] = goal_orientations(expected[:, 3:], orientation)
    for e in ans.entries:
        np.testing.assert_allclose(pose7(e.goal), expected[e.pose_index], atol=1e-9)
        assert e.distance == pytest.approx(np.linalg.norm(pose7(e.goal)[:3] - [e.start.x, e.start.y, e.start.z]))
    starts = {e.drone: [e.start.x, e.start.y, e.start.z] for e in ans.entries}
    for d in fleet.drones:  # the spare drones' starts are their reported positions
        starts.setdefault(d, fleet.position(d)[:3])
    best_total, best_max = brute_force(np.array([starts[d] for d in fleet.drones]), expected[:, :3])
    if ans.assignment == "min_total":
        assert ans.total_distance == pytest.approx(best_total, rel=1e-9)
    else:
        assert ans.max_distance == pytest.approx(best_max, rel=1e-9)
    assert ans.total_distance == pytest.approx(sum(e.distance for e in ans.entries))
    assert sorted(ans.spare_drones) == sorted(set(fleet.drones) - {e.drone for e in ans.entries})
    return expected


def wait_at_goals(fleet: Fleet, ans: FleetAssignment, timeout: float = TIMEOUT) -> None:
    """Each drone's goal topic holds its entry's goal, and the drone ends there."""
    for e in ans.entries:
        assert fleet.client.spin_until(lambda: fleet.goals[e.drone] and
                                       pose7(fleet.goals[e.drone][-1].pose)[0] == e.goal.position.x, timeout)
        np.testing.assert_allclose(pose7(fleet.goals[e.drone][-1].pose), pose7(e.goal), atol=1e-12)

    def arrived() -> bool:
        return all(np.allclose(fleet.position(e.drone), pose7(e.goal), atol=1e-9) for e in ans.entries)
    assert fleet.client.spin_until(arrived, timeout), {e.drone: fleet.position(e.drone) for e in ans.entries}


def test_drones_fly_to_their_poses_and_a_new_plan_redispatches(ros_env, start_node, ros_node) -> None:
    """Four drones in a fleet frame turned and shifted from map: the goals are the plan's poses in
    that frame, the assignment is the brute-force optimum, every drone ends at its pose. A new
    plan (after switching to min_max and optical goals at run time) re-dispatches from where the
    drones are now."""
    drones = ["d0", "d1", "d2", "d3"]
    transform = FleetTransform(x=1.0, y=-2.0, z=0.0, yaw=0.4)
    start_node("vp_scene", "scene", SCENE, ros_env)
    dispatcher = start_node("vp_planner", "dispatcher", {
        "drones": drones, "fleet_frame": "plot", "fleet_x": transform.x, "fleet_y": transform.y,
        "fleet_z": transform.z, "fleet_yaw": transform.yaw}, ros_env)
    starts = {d: [float(k), -6.0 + 0.3 * k * k, 0.0] for k, d in enumerate(drones)}  # a launch row
    start_drones(start_node, ros_env, starts, frame_id="plot", speed=4.0)
    fleet = Fleet(ros_node(ros_env), drones)
    assert fleet.wait_for_poses(dispatcher), dispatcher.output()

    first = ring(4)
    ans = fleet.send(first, stamp=101)
    assert ans.header.frame_id == "plot" and ans.plan_frame_id == "map" and ans.num_poses == 4
    assert ans.standoff_checked and ans.assignment == "min_total" and ans.orientation == "body"
    for e in ans.entries:  # the drones were still at their starts
        np.testing.assert_allclose([e.start.x, e.start.y, e.start.z], starts[e.drone], atol=1e-9)
    check_dispatch(fleet, ans, first, transform, "body")
    wait_at_goals(fleet, ans)
    assert "plan 101.000000000 dispatched (min_total" in dispatcher.output()

    params = AsyncParameterClient(fleet.client.node, "dispatcher")
    assert params.wait_for_services(timeout_sec=TIMEOUT)
    set_ = fleet.client.call(lambda: params.set_parameters([Parameter("assignment", value="min_max"),
                                                          Parameter("orientation", value="optical")]), TIMEOUT)
    assert all(r.successful for r in set_.results), [r.reason for r in set_.results]
    refused = fleet.client.call(lambda: params.set_parameters([Parameter("drones", value=["d0"])]), TIMEOUT)
    assert not refused.results[0].successful and "read-only parameter: drones" in refused.results[0].reason

    second = ring(4, radius=3.0, height=1.6, phase=0.9)
    ans2 = fleet.send(second, stamp=102)
    assert ans2.assignment == "min_max" and ans2.orientation == "optical"
    goals_first = {e.drone: pose7(e.goal)[:3] for e in ans.entries}
    for e in ans2.entries:  # re-dispatched from where the first plan left the drones
        np.testing.assert_allclose([e.start.x, e.start.y, e.start.z], goals_first[e.drone], atol=1e-9)
    check_dispatch(fleet, ans2, second, transform, "optical")
    wait_at_goals(fleet, ans2)


def test_a_silent_drone_is_named_and_nothing_is_dispatched(ros_env, start_node, ros_node) -> None:
    """Three drones configured (nav_msgs/Odometry poses), one never reports: the dispatch fails
    naming it and no goal is published. Once it reports, the next plan is dispatched (one drone
    spare). A drone that stops reporting is named with the age of its last pose."""
    drones = ["d0", "d1", "d2"]
    start_node("vp_scene", "scene", SCENE, ros_env)
    dispatcher = start_node("vp_planner", "dispatcher", {"drones": drones, "pose_timeout": 1.0,
                                                          "pose_type": "odometry"}, ros_env)
    starts = {"d0": [0.0, -4.0, 0.0], "d1": [1.0, -4.0, 0.0], "d2": [2.0, -4.0, 0.0]}
    sims = start_drones(start_node, ros_env, {d: starts[d] for d in ("d0", "d1")}, pose_type="odometry")
    fleet = Fleet(ros_node(ros_env), drones, odometry=True)
    assert fleet.client.spin_until(lambda: fleet.poses["d0"] and fleet.poses["d1"] and all(
        f"drone {d} reporting" in dispatcher.output() for d in ("d0", "d1")), TIMEOUT), dispatcher.output()

    ans = fleet.send(ring(2), stamp=201)
    assert ans.error_code == FleetAssignment.DRONE_SILENT, ans.error_msg
    assert list(ans.silent_drones) == ["d2"] and "d2 (no pose yet)" in ans.error_msg
    assert "pose_timeout 1 s" in ans.error_msg and not ans.entries
    assert fleet.client.spin_until(lambda: "plan 201.000000000 not dispatched" in dispatcher.output(), 10)
    fleet.client.spin_until(lambda: False, 1.0)  # time for a goal that should not come
    assert not any(fleet.goals[d] for d in drones)

    # issue 19, item 4: a drone reporting NaN was named as having "no pose yet"
    nan_pub = fleet.client.node.create_publisher(Odometry, "/d2/pose", 10)
    nan = Odometry()
    nan.header.frame_id = "map"
    nan.pose.pose.position.x = float("nan")
    nan.pose.pose.orientation.w = 1.0
    for _ in range(5):
        nan_pub.publish(nan)
        fleet.client.spin_until(lambda: False, 0.2)
    assert fleet.client.spin_until(lambda: "drone d2: ignoring a pose with non-finite" in dispatcher.output(),
                                   10), dispatcher.output()
    ans = fleet.send(ring(2), stamp=2011)
    assert ans.error_code == FleetAssignment.DRONE_SILENT and list(ans.silent_drones) == ["d2"], ans.error_msg
    assert "d2 (reports a non-finite pose: (nan, 0, 0))" in ans.error_msg, ans.error_msg

    sims.update(start_drones(start_node, ros_env, {"d2": starts["d2"]}, pose_type="odometry"))
    assert fleet.wait_for_poses(dispatcher), dispatcher.output()
    ans = fleet.send(ring(2), stamp=202)
    check_dispatch(fleet, ans, ring(2), FleetTransform(), "body")
    assert len(ans.spare_drones) == 1
    wait_at_goals(fleet, ans)

    assert sims["d1"].stop() == 0, sims["d1"].output()[-2000:]  # SIGTERM: a quiet exit 0
    fleet.client.spin_until(lambda: False, 1.5)
    ans = fleet.send(ring(2, phase=1.0), stamp=203)
    assert ans.error_code == FleetAssignment.DRONE_SILENT and list(ans.silent_drones) == ["d1"], ans.error_msg
    assert "d1 (last pose" in ans.error_msg and "s ago)" in ans.error_msg
    assert dispatcher.alive()


def test_refused_plans_and_the_missing_scene(ros_env, start_node, ros_node) -> None:
    """No scene: refused (stand-off could not be checked), or dispatched with a warning once
    require_scene is false. With the scene: too many poses, a pose inside the plant, too low,
    too close to another, in another frame, no poses: each refused with its error code and
    nothing sent; then a good plan goes out. SIGTERM ends the node with exit 0."""
    drones = ["d0", "d1"]
    dispatcher = start_node("vp_planner", "dispatcher", {"drones": drones, "scene_timeout": 0.5}, ros_env)
    start_drones(start_node, ros_env, {"d0": [0.0, -4.0, 0.0], "d1": [1.0, -4.0, 0.0]})
    fleet = Fleet(ros_node(ros_env), drones)
    assert fleet.wait_for_poses(dispatcher), dispatcher.output()

    ans = fleet.send(ring(2), stamp=301)
    assert ans.error_code == FleetAssignment.NO_SCENE and "stand-off could not be checked" in ans.error_msg
    params = AsyncParameterClient(fleet.client.node, "dispatcher")
    assert params.wait_for_services(timeout_sec=TIMEOUT)
    fleet.client.call(lambda: params.set_parameters([Parameter("require_scene", value=False)]), TIMEOUT)
    ans = fleet.send(ring(2), stamp=302)
    assert ans.error_code == FleetAssignment.NONE and not ans.standoff_checked, ans.error_msg
    assert "stand-off not checked" in dispatcher.output()
    fleet.client.call(lambda: params.set_parameters([Parameter("require_scene", value=True)]), TIMEOUT)
    start_node("vp_scene", "scene", SCENE, ros_env)
    assert fleet.client.spin_until(lambda: "scene received" in dispatcher.output(), TIMEOUT), dispatcher.output()
    for d in drones:
        fleet.goals[d].clear()

    inside = ring(2)
    inside[1, :3] = [0.05, 0.0, 1.0]
    low = ring(2)
    low[0, 2] = 0.1
    close = ring(2)
    close[1, :3] = close[0, :3] + [0.0, 0.3, 0.0]
    cases = [
        (ring(3), "map", FleetAssignment.TOO_FEW_DRONES, "3 poses but there are only 2 drones"),
        (inside, "map", FleetAssignment.INFEASIBLE_PLAN, "camera 1 at"),
        (inside, "map", FleetAssignment.INFEASIBLE_PLAN, "min_standoff 0.5 m"),
        (low, "map", FleetAssignment.INFEASIBLE_PLAN, "camera 0 at (+2.20, +0.00, +0.10) is 0.100 m above the ground"),
        (close, "map", FleetAssignment.INFEASIBLE_PLAN, "cameras 0 and 1 are 0.300 m apart (min_separation 0.5 m)"),
        (ring(2), "odom", FleetAssignment.WRONG_FRAME, "'odom'"),
        (np.zeros((0, 6)), "map", FleetAssignment.EMPTY_PLAN, "no poses"),
    ]
    for k, (cams, frame, code, text) in enumerate(cases):
        ans = fleet.send(cams, stamp=310 + k, frame=frame)
        assert ans.error_code == code and text in ans.error_msg, (k, ans.error_code, ans.error_msg)
        assert not ans.entries and math.isnan(ans.total_distance)
    fleet.client.spin_until(lambda: False, 0.5)
    assert not any(fleet.goals[d] for d in drones)  # nothing was sent for a refused plan
    ans = fleet.send(ring(2, phase=0.5), stamp=330)
    check_dispatch(fleet, ans, ring(2, phase=0.5), FleetTransform(), "body")
    assert ans.standoff_checked
    assert dispatcher.alive()
    assert dispatcher.stop() == 0 and "Traceback" not in dispatcher.output(), dispatcher.output()[-3000:]
