"""The real ``vp_planner dispatcher`` node with simulated drones (``vp_scene sim_drone``, one
process per drone) and the real scene node, over DDS.

The test publishes plans on /camera_plan (as the planner does, latched, frame ``map``) and
listens to /fleet/assignment, the goals and the drones' poses. Every wait has a deadline.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from geometry_msgs.msg import Pose, PoseArray, PoseStamped
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from vp_interfaces.msg import FleetAssignment

from vp_planner.fleet import FleetTransform, goal_orientations
from vp_planner.dispatcher_node import PARAMS
from vp_planner.routes import FlightModel, plan_routes
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


#: a quick flight model for the tests: the simulated drones fly at the same speeds
FAST = {"cruise_speed": 8.0, "climb_rate": 4.0, "hover_s": 0.3}


def route_of(ans: FleetAssignment, drone: str):
    return next(r for r in ans.routes if r.drone == drone)


def check_dispatch(fleet: Fleet, ans: FleetAssignment, cameras: np.ndarray, transform: FleetTransform,
                   orientation: str, model: FlightModel = FlightModel(**FAST), separation: float = 0.5,
                   objective: str = "min_max", scene=None) -> dict:
    """The answer holds every pose once, each drone's route is the library's (vp_planner.routes)
    from the starts it reports, the goals are the plan's poses in the fleet frame; returns
    {drone: route path poses (m, 7)}."""
    m = len(cameras)
    assert ans.error_code == FleetAssignment.NONE, ans.error_msg
    assert [e.pose_index for e in ans.entries] == list(range(m))
    expected = transform.poses_to_fleet(cameras_to_poses(cameras))
    expected[:, 3:] = goal_orientations(expected[:, 3:], orientation)
    for e in ans.entries:
        np.testing.assert_allclose(pose7(e.goal), expected[e.pose_index], atol=1e-9)
    starts = {e.drone: [e.start.x, e.start.y, e.start.z] for e in ans.entries}
    for d in fleet.drones:  # the spare drones' starts are their reported positions
        starts.setdefault(d, fleet.position(d)[:3])
    homes = transform.points_to_map(np.array([starts[d] for d in fleet.drones]))
    want = plan_routes(cameras, homes, model, separation, obstacles=scene, objective=objective)
    assert ans.time_on_site == pytest.approx(want.time_on_site, abs=1e-9)
    assert ans.min_separation == pytest.approx(want.min_separation, abs=1e-9) and ans.min_separation >= separation
    assert ans.budget == pytest.approx(model.budget_s)
    paths = {}
    for r in want.routes:
        name = fleet.drones[r.drone]
        if not len(r.views):
            assert name in ans.spare_drones
            continue
        got = route_of(ans, name)
        assert list(got.pose_indices) == r.views.tolist()
        np.testing.assert_allclose(got.arrival, r.arrival, atol=1e-9)
        np.testing.assert_allclose(got.departure, r.departure, atol=1e-9)
        assert got.flight_time == pytest.approx(r.flight_time) and got.path.header.frame_id == transform_frame(ans)
        path = np.array([pose7(p.pose) for p in got.path.poses])
        np.testing.assert_allclose(path[:, :3], transform.points_to_fleet(r.points), atol=1e-9)
        for order, j in enumerate(r.views):
            e = ans.entries[int(j)]
            assert (e.drone, e.order) == (name, order)
            assert e.eta == pytest.approx(r.eta()[order])
        paths[name] = path
    return paths


def transform_frame(ans: FleetAssignment) -> str:
    return ans.header.frame_id


def wait_for_sortie(fleet: Fleet, paths: dict, timeout: float = TIMEOUT) -> None:
    """Each drone gets its route's waypoints one at a time, in order, and lands where it started."""
    def done() -> bool:
        return all(len(fleet.goals[d]) >= len(p) - 1 for d, p in paths.items()) and \
            all(np.allclose(fleet.position(d)[:3], p[-1, :3], atol=1e-9) for d, p in paths.items())
    assert fleet.client.spin_until(done, timeout), {d: (len(fleet.goals[d]), fleet.position(d)) for d in paths}
    for d, path in paths.items():
        sent = np.array([pose7(g.pose) for g in fleet.goals[d][-(len(path) - 1):]])
        np.testing.assert_allclose(sent, path[1:], atol=1e-12)


def test_two_drones_fly_routes_through_eight_poses(ros_env, start_node, ros_node) -> None:
    """Two drones for eight poses, in a fleet frame turned and shifted from map: each drone's route
    is the library's from where it stands, its waypoints come one at a time as it arrives, it
    lands where it started. A new plan (after switching to min_total and optical goals at run
    time) is routed again from there; the drones' names are read-only."""
    drones = ["d0", "d1"]
    transform = FleetTransform(x=1.0, y=-2.0, z=0.0, yaw=0.4)
    start_node("vp_scene", "scene", SCENE, ros_env)
    dispatcher = start_node("vp_planner", "dispatcher", {
        "drones": drones, "fleet_frame": "plot", "fleet_x": transform.x, "fleet_y": transform.y,
        "fleet_z": transform.z, "fleet_yaw": transform.yaw, **FAST}, ros_env)
    starts = {"d0": [0.0, -4.0, 0.0], "d1": [1.5, -4.5, 0.0]}
    start_drones(start_node, ros_env, starts, frame_id="plot", speed=FAST["cruise_speed"],
                 climb_rate=FAST["climb_rate"])
    fleet = Fleet(ros_node(ros_env), drones)
    routes = {d: fleet.client.subscribe(PathMsg, f"/{d}/route", ANSWERS) for d in drones}
    assert fleet.wait_for_poses(dispatcher), dispatcher.output()

    first = ring(8)
    ans = fleet.send(first, stamp=101)
    assert ans.header.frame_id == "plot" and ans.plan_frame_id == "map" and ans.num_poses == 8
    assert ans.standoff_checked and ans.assignment == "min_max" and ans.orientation == "body"
    assert len(ans.routes) == 2 and not ans.spare_drones  # both drones fly: the longest flight is shorter
    for e in ans.entries:  # the drones were still at their starts
        np.testing.assert_allclose([e.start.x, e.start.y, e.start.z], starts[e.drone], atol=1e-9)
    paths = check_dispatch(fleet, ans, first, transform, "body", scene=scene_points())
    for d in drones:  # the route on /<drone>/route: stamped with the arrivals
        assert fleet.client.spin_until(lambda: routes[d], TIMEOUT)
        path = routes[d][-1]
        t0 = path.header.stamp.sec * 10 ** 9 + path.header.stamp.nanosec
        arrivals = [1e-9 * (p.header.stamp.sec * 10 ** 9 + p.header.stamp.nanosec - t0) for p in path.poses]
        np.testing.assert_allclose(arrivals, route_of(ans, d).arrival, atol=1e-9)
    wait_for_sortie(fleet, paths)
    assert "plan 101.000000000 dispatched (min_max" in dispatcher.output()
    assert fleet.client.spin_until(lambda: all(f"{d} landed" in dispatcher.output() for d in drones), 10)

    params = AsyncParameterClient(fleet.client.node, "dispatcher")
    assert params.wait_for_services(timeout_sec=TIMEOUT)
    set_ = fleet.client.call(lambda: params.set_parameters([Parameter("assignment", value="min_total"),
                                                          Parameter("orientation", value="optical")]), TIMEOUT)
    assert all(r.successful for r in set_.results), [r.reason for r in set_.results]
    refused = fleet.client.call(lambda: params.set_parameters([Parameter("drones", value=["d0"])]), TIMEOUT)
    assert not refused.results[0].successful and "read-only parameter: drones" in refused.results[0].reason

    second = ring(3, radius=3.0, height=1.6, phase=0.9)
    for d in drones:
        fleet.goals[d].clear()
    ans2 = fleet.send(second, stamp=102)
    assert ans2.assignment == "min_total" and ans2.orientation == "optical"
    for e in ans2.entries:  # routed again from where the first sortie left the drones: their starts
        np.testing.assert_allclose([e.start.x, e.start.y, e.start.z], starts[e.drone], atol=1e-9)
    wait_for_sortie(fleet, check_dispatch(fleet, ans2, second, transform, "optical", objective="min_total",
                                          scene=scene_points()))


def scene_points() -> np.ndarray:
    """The scene node's realizations (the same build as the node's, in the cloud's float32)."""
    from vp_scene.build import build_noisy_scene

    return np.asarray(build_noisy_scene(**SCENE)[0].points, dtype=np.float32).astype(np.float64)


def test_a_silent_drone_is_named_and_nothing_is_dispatched(ros_env, start_node, ros_node) -> None:
    """Three drones configured (nav_msgs/Odometry poses), one never reports: the dispatch fails
    naming it and no goal is published. Once it reports, the next plan is dispatched (one drone
    spare). A drone that stops reporting is named with the age of its last pose."""
    drones = ["d0", "d1", "d2"]
    start_node("vp_scene", "scene", SCENE, ros_env)
    dispatcher = start_node("vp_planner", "dispatcher", {"drones": drones, "pose_timeout": 1.0,
                                                          "pose_type": "odometry", **FAST}, ros_env)
    starts = {"d0": [0.0, -4.0, 0.0], "d1": [1.0, -4.0, 0.0], "d2": [2.0, -4.0, 0.0]}
    fast = dict(pose_type="odometry", speed=FAST["cruise_speed"], climb_rate=FAST["climb_rate"])
    sims = start_drones(start_node, ros_env, {d: starts[d] for d in ("d0", "d1")}, **fast)
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

    sims.update(start_drones(start_node, ros_env, {"d2": starts["d2"]}, **fast))
    assert fleet.wait_for_poses(dispatcher), dispatcher.output()
    ans = fleet.send(ring(2), stamp=202)
    for d in drones:
        fleet.goals[d].clear()
    paths = check_dispatch(fleet, ans, ring(2), FleetTransform(), "body", scene=scene_points())
    assert len(ans.routes) + len(ans.spare_drones) == 3
    wait_for_sortie(fleet, paths)

    assert sims["d1"].stop() == 0, sims["d1"].output()[-2000:]  # SIGTERM: a quiet exit 0
    fleet.client.spin_until(lambda: False, 1.5)
    ans = fleet.send(ring(2, phase=1.0), stamp=203)
    assert ans.error_code == FleetAssignment.DRONE_SILENT and list(ans.silent_drones) == ["d1"], ans.error_msg
    assert "d1 (last pose" in ans.error_msg and "s ago)" in ans.error_msg
    assert dispatcher.alive()


def test_refused_plans_and_the_missing_scene(ros_env, start_node, ros_node) -> None:
    """No scene: refused (stand-off could not be checked), or dispatched with a warning once
    require_scene is false. With the scene: a pose inside the plant, too low, too close to another,
    in another frame, no poses, routes over the battery's budget, drones nearer than the
    separation: each refused with its error code and nothing sent; then three poses go out to the
    two drones. SIGTERM ends the node with exit 0."""
    drones = ["d0", "d1"]
    dispatcher = start_node("vp_planner", "dispatcher", {"drones": drones, "scene_timeout": 0.5, **FAST}, ros_env)
    start_drones(start_node, ros_env, {"d0": [0.0, -4.0, 0.0], "d1": [1.0, -4.0, 0.0]},
                 speed=FAST["cruise_speed"], climb_rate=FAST["climb_rate"])
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
    assert fleet.client.spin_until(lambda: all(f"{r.drone} landed" in dispatcher.output() for r in ans.routes), TIMEOUT)
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
        assert not ans.entries and not ans.routes and math.isnan(ans.total_distance)
    for k, (name, value, code, text) in enumerate([
            ("flight_time_s", 1.0, FleetAssignment.DOES_NOT_FIT, "s short"),
            ("separation", 1.5, FleetAssignment.DRONES_TOO_CLOSE, "are 1.00 m apart, less than the separation")]):
        fleet.client.call(lambda: params.set_parameters([Parameter(name, value=value)]), TIMEOUT)
        ans = fleet.send(ring(2), stamp=320 + k)
        assert ans.error_code == code and text in ans.error_msg and "\n" not in ans.error_msg, ans.error_msg
        assert not ans.entries and not ans.routes
        fleet.client.call(lambda: params.set_parameters([Parameter(name, value=PARAMS[name].default)]), TIMEOUT)
    fleet.client.spin_until(lambda: False, 0.5)
    assert not any(fleet.goals[d] for d in drones)  # nothing was sent for a refused plan
    ans = fleet.send(ring(3, phase=0.5), stamp=330)  # more poses than drones
    check_dispatch(fleet, ans, ring(3, phase=0.5), FleetTransform(), "body", scene=scene_points())
    assert ans.standoff_checked and len(ans.entries) == 3
    assert dispatcher.alive()
    assert dispatcher.stop() == 0 and "Traceback" not in dispatcher.output(), dispatcher.output()[-3000:]


def test_capture_triggers_fly_sorties_and_the_missions_are_written(ros_env, start_node, ros_node, tmp_path) -> None:
    """``fly_on:=capture``: nothing flies until a /fleet/capture trigger of the plan, then one sortie a
    trigger; with an origin each goal also comes as a NavSatFix (pymap3d's), and ~/write_missions
    writes the plan's missions (NO_ROUTES before a plan, OUTPUT_EXISTS the second time)."""
    from rclpy.qos import QoSProfile as Qos
    from sensor_msgs.msg import NavSatFix
    from vp_interfaces.msg import CaptureTrigger
    from vp_interfaces.srv import WriteMissions

    from vp_scene.geo import GeoOrigin

    origin = "47.397742,8.545594,488.0"
    start_node("vp_scene", "scene", SCENE, ros_env)
    dispatcher = start_node("vp_planner", "dispatcher", {"drones": ["d0"], "fly_on": "capture", "origin": origin,
                                                          "map_yaw": 0.3, **FAST}, ros_env)
    start_drones(start_node, ros_env, {"d0": [0.0, -4.0, 0.0]}, speed=FAST["cruise_speed"],
                 climb_rate=FAST["climb_rate"])
    fleet = Fleet(ros_node(ros_env), ["d0"])
    fixes = fleet.client.subscribe(NavSatFix, "/d0/goal_fix", Qos(depth=50, reliability=ReliabilityPolicy.RELIABLE,
                                                                  durability=DurabilityPolicy.TRANSIENT_LOCAL))
    missions = fleet.client.node.create_client(WriteMissions, "/dispatcher/write_missions")
    assert missions.wait_for_service(timeout_sec=TIMEOUT) and fleet.wait_for_poses(dispatcher), dispatcher.output()

    def write(folder):
        return fleet.client.call(lambda: missions.call_async(WriteMissions.Request(folder=str(folder))), TIMEOUT)
    assert write(tmp_path / "early").error_code == WriteMissions.Response.NO_ROUTES
    assert not (tmp_path / "early").exists()

    ans = fleet.send(ring(3), stamp=401)
    paths = check_dispatch(fleet, ans, ring(3), FleetTransform(), "body", scene=scene_points())
    fleet.client.spin_until(lambda: False, 1.0)
    assert not fleet.goals["d0"]  # no trigger yet: nothing flies
    triggers = fleet.client.node.create_publisher(CaptureTrigger, "/fleet/capture", LATCHED)
    geo = GeoOrigin.parse(origin, yaw=0.3)
    for k in range(2):  # one sortie a trigger
        fleet.goals["d0"].clear()
        fixes.clear()
        trigger = CaptureTrigger(realization=k)
        trigger.plan_stamp.sec = 401
        trigger.header.stamp = fleet.client.node.get_clock().now().to_msg()
        triggers.publish(trigger)
        wait_for_sortie(fleet, paths)
        assert fleet.client.spin_until(lambda: len(fixes) >= len(paths["d0"]) - 1, 10)
        got = np.array([[f.latitude, f.longitude, f.altitude] for f in fixes[-(len(paths["d0"]) - 1):]])
        np.testing.assert_allclose(got, geo.to_geodetic(paths["d0"][1:, :3]), rtol=0, atol=1e-9)
        assert f"sortie of plan 401.000000000 for capture {k}" in dispatcher.output()

    out = tmp_path / "missions"
    answer = write(out)
    assert answer.error_code == WriteMissions.Response.NONE, answer.error_msg
    assert sorted(p.name for p in out.iterdir()) == ["d0.plan", "fleet.json", "fleet.kml"]
    assert sorted(answer.files) == sorted(str(out / n) for n in ("d0.plan", "fleet.kml", "fleet.json"))
    again = write(out)
    assert again.error_code == WriteMissions.Response.OUTPUT_EXISTS and "already holds" in again.error_msg
