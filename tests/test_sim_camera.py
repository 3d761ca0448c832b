"""Simulated drones take pictures (issue 20, part 1): the real scene node and a real
``vp_scene sim_drone`` with ``camera:=true`` over DDS; the test plays the dispatcher
(/fleet/assignment, the goal) and the capture trigger (/fleet/capture). Every wait has a deadline.
"""
from __future__ import annotations

import math

import numpy as np

from geometry_msgs.msg import PoseStamped
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, CompressedImage, Image
from vp_interfaces.msg import CaptureTrigger, DroneAssignment, FleetAssignment, SceneDescription

from vp_recon.config import ReconConfig
from vp_recon.pipeline import render_flight
from vp_scene.camera import cameras_to_poses, look_at
from vp_scene.capture import CaptureModel
from vp_scene.messages import (camera_info_intrinsics, compressed_image_array, image_array, pose_array, pose_msg,
                               scene_of_description)

LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
SCENE = dict(scenario="one_plant", points_per_plant=600, realizations=2, levels=5, seed=3)
TIMEOUT = 90.0


def test_a_settled_drone_publishes_the_image_its_camera_of_the_plan_gets(ros_env, start_node, ros_node) -> None:
    """Drone d0 holds pose 2 of a plan, sits at its goal; a trigger for another plan is ignored
    once that plan's assignment comes, a trigger before its plan's assignment waits for it; the plan's
    trigger (realization 1) gives one image (raw and PNG), camera_info and reported
    pose with one stamp: exactly the render source's camera 2 (realistic capture, same seeds). A
    route of two poses gives one picture at each, in the route's order."""
    cams = look_at(np.array([[1.6, 0.0, 1.2], [0.0, 1.6, 1.2], [-1.2, 1.0, 1.3]]), np.tile([0.0, 0.0, 0.9], (3, 1)))
    goal = cameras_to_poses(cams[2])
    start_node("vp_scene", "scene", SCENE, ros_env)
    drone = start_node("vp_scene", "sim_drone", {"drone": "d0", "x": float(goal[0]), "y": float(goal[1]),
                                                    "z": float(goal[2]), "camera": True, "width": 320,
                                                    "height": 240}, ros_env)
    client = ros_node(ros_env)
    received = {name: client.subscribe(t, f"/d0/camera/{name}", LATCHED) for name, t in (
        ("image_raw", Image), ("image_raw/compressed", CompressedImage), ("camera_info", CameraInfo),
        ("pose", PoseStamped))}
    descriptions = client.subscribe(SceneDescription, "/scene/description", LATCHED)
    assignment_pub = client.node.create_publisher(FleetAssignment, "/fleet/assignment", LATCHED)
    goal_pub = client.node.create_publisher(PoseStamped, "/d0/goal_pose", LATCHED)
    trigger_pub = client.node.create_publisher(CaptureTrigger, "/fleet/capture", LATCHED)
    assert client.spin_until(lambda: descriptions, TIMEOUT)

    fleet = FleetAssignment(num_poses=3, assignment="min_total", orientation="body")
    fleet.header.frame_id = "map"
    fleet.plan_stamp.sec = 7
    fleet.entries = [DroneAssignment(drone="d0", pose_index=2, goal=pose_msg(goal))]
    g = PoseStamped(pose=pose_msg(goal))
    g.header.frame_id = "map"
    goal_pub.publish(g)
    other = CaptureTrigger(realization=1)
    other.plan_stamp.sec = 6  # a plan that gave d0 no pose: its trigger waits for its assignment, then is ignored
    trigger_pub.publish(other)
    assert client.spin_until(lambda: "capture of plan (6, 0) waits for the plan's assignment" in drone.output(),
                             TIMEOUT), drone.output()
    elsewhere = FleetAssignment(num_poses=3, assignment="min_total", orientation="body")
    elsewhere.header.frame_id = "map"
    elsewhere.plan_stamp.sec = 6
    elsewhere.entries = [DroneAssignment(drone="d1", pose_index=0, goal=pose_msg(goal))]
    assignment_pub.publish(elsewhere)
    assert client.spin_until(lambda: "ignored: no pose of it is mine" in drone.output(), TIMEOUT), drone.output()
    assert not received["image_raw"]
    trigger = CaptureTrigger(realization=1)
    trigger.plan_stamp.sec = 7
    trigger_pub.publish(trigger)  # before plan 7's assignment (a fleet test's drone once dropped such a trigger)
    assert client.spin_until(lambda: "capture of plan (7, 0) waits for the plan's assignment" in drone.output(),
                             TIMEOUT), drone.output()
    assignment_pub.publish(fleet)
    assert client.spin_until(lambda: all(received.values()), TIMEOUT), drone.output()[-3000:]

    (raw,), (png,), (info,), (pose,) = (received[n] for n in ("image_raw", "image_raw/compressed", "camera_info",
                                                              "pose"))
    assert raw.header.stamp == png.header.stamp == info.header.stamp == pose.header.stamp
    assert raw.header.frame_id == "d0/camera_optical" and pose.header.frame_id == "map"
    image = image_array(raw)
    np.testing.assert_array_equal(compressed_image_array(png), image)  # PNG: lossless
    scene = scene_of_description(descriptions[-1])
    cfg = ReconConfig(width=320, height=240, fov=math.pi / 2, num_threads=1, capture=CaptureModel.named("realistic"))
    expected = render_flight(scene, 1, cams, cfg)
    K, w, h = camera_info_intrinsics(info)
    np.testing.assert_allclose(K, expected.K)
    assert (w, h) == (320, 240)
    np.testing.assert_allclose(pose_array(pose.pose), cameras_to_poses(expected.reported[2]), atol=1e-9)
    # the same flight as the render source, rendered in another process: the same pixels
    np.testing.assert_array_equal(image, expected.images[2])

    # plan 8 gives d0 pose 0, and its trigger comes before the new goal: the drone, still settled at
    # plan 7's goal, waits; once at the new goal it photographs camera 0 of plan 8
    for r in received.values():
        r.clear()
    fleet.plan_stamp.sec = 8
    fleet.entries = [DroneAssignment(drone="d0", pose_index=0, goal=pose_msg(cameras_to_poses(cams[0])))]
    assignment_pub.publish(fleet)
    trigger.plan_stamp.sec = 8
    trigger_pub.publish(trigger)
    assert client.spin_until(lambda: "capture of plan (8, 0), pose(s) [0]" in drone.output(), TIMEOUT), drone.output()
    client.spin_until(lambda: received["image_raw"], 3.0)  # at plan 7's goal: no picture
    assert not received["image_raw"], "photographed plan 8 from plan 7's pose"
    g = PoseStamped(pose=pose_msg(cameras_to_poses(cams[0])))
    g.header.frame_id = "map"
    goal_pub.publish(g)
    assert client.spin_until(lambda: received["image_raw"] and received["pose"], TIMEOUT), drone.output()[-3000:]
    np.testing.assert_allclose(pose_array(received["pose"][0].pose), cameras_to_poses(expected.reported[0]),
                               atol=1e-9)
    np.testing.assert_array_equal(image_array(received["image_raw"][0]), expected.images[0])

    # plan 9 gives d0 a route of two poses, 2 then 1: one picture at each, as it settles there, in that order
    for r in received.values():
        r.clear()
    fleet.plan_stamp.sec = 9
    fleet.entries = [DroneAssignment(drone="d0", pose_index=j, order=k, goal=pose_msg(cameras_to_poses(cams[j])))
                     for k, j in enumerate((2, 1))]
    assignment_pub.publish(fleet)
    trigger.plan_stamp.sec = 9
    trigger_pub.publish(trigger)
    assert client.spin_until(lambda: "capture of plan (9, 0), pose(s) [2, 1]" in drone.output(), TIMEOUT), \
        drone.output()
    for n, j in enumerate((2, 1), 1):
        g = PoseStamped(pose=pose_msg(cameras_to_poses(cams[j])))
        g.header.frame_id = "map"
        goal_pub.publish(g)
        assert client.spin_until(lambda: len(received["image_raw"]) >= n and len(received["pose"]) >= n, TIMEOUT), \
            drone.output()[-3000:]
        np.testing.assert_array_equal(image_array(received["image_raw"][n - 1]), expected.images[j])
        np.testing.assert_allclose(pose_array(received["pose"][n - 1].pose), cameras_to_poses(expected.reported[j]),
                                   atol=1e-9)
