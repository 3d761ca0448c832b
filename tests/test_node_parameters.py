"""Start parameters of the planner, recon and dispatcher nodes (real processes): a wrong type or a
bad value is one log line and exit 2, an integer where a float is expected is simply a float
(issue 10, items 7 and 12; issue 11 for the dispatcher)."""
from __future__ import annotations

import pytest

READY = {"planner": "planner ready", "recon": "recon ready", "dispatcher": "dispatcher ready"}
PKG = {"planner": "vp_planner", "recon": "vp_recon", "dispatcher": "vp_planner"}


@pytest.mark.parametrize("exe, params, text", [
    ("planner", {"num_cameras": 4.0}, "'num_cameras' must be an integer"),
    ("planner", {"fov": "wide"}, "'fov' must be a number"),
    ("planner", {"min_standoff": float("nan")}, "'min_standoff' must be a finite number"),
    ("planner", {"num_cameras": 500}, "num_cameras must be from 2 to 100"),
    ("planner", {"parts": -1}, "parts must be >= 0"),
    ("planner", {"lawnmower_overlap": 1.0}, "lawnmower overlap must be in [0, 0.95]"),
    ("planner", {"lawnmower_tilt": 1.5}, "lawnmower tilt must be in [0, 60 degrees]"),
    ("recon", {"width": 640.0}, "'width' must be an integer"),
    ("recon", {"dense": 1}, "'dense' must be a boolean"),
    ("recon", {"max_realizations": -1}, "max_realizations must be >= 0"),
    ("recon", {"fov": 4}, "fov must be in (0, pi)"),
    ("recon", {"matching": "magic"}, "matching must be one of auto, exhaustive, poses"),
    ("dispatcher", {}, 'drones must name at least one drone, e.g. -p "drones:=[d0, d1, d2, d3]"'),
    ("dispatcher", {"drones": "d0"}, "'drones' must be a list of strings"),
    ("dispatcher", {"drones": ["d0", "d1", "d0"]}, "drones names a drone twice: ['d0']"),
    ("dispatcher", {"drones": ["d0", "drone-1"]}, "drone names must start with a letter"),
    ("dispatcher", {"drones": ["d0"], "assignment": "fastest"}, "assignment must be one of min_total, min_max"),
    ("dispatcher", {"drones": ["d0"], "goal_topic": "/goal"}, "goal_topic must contain {drone}"),
    ("dispatcher", {"drones": ["d0"], "pose_timeout": 0}, "pose_timeout must be > 0"),
    ("dispatcher", {"drones": ["d0"], "fleet_yaw": 0.5}, "fleet_frame is frame_id ('map')"),
])
def test_bad_parameter_is_one_line_and_exit_2(exe, params, text, ros_env, start_node) -> None:
    node = start_node(PKG[exe], exe, params, ros_env)
    assert node.wait(30.0) == 2, node.output()
    out = node.output()
    assert text in out and "Traceback" not in out, out
    assert len([ln for ln in out.splitlines() if ln.strip()]) == 1, out


@pytest.mark.parametrize("exe, params", [
    ("planner", {"fov": 2, "theta_match": 1, "min_separation": 0}),
    ("recon", {"fov": 2, "fscore_threshold": 1}),
    ("dispatcher", {"drones": ["d0"], "pose_timeout": 1, "fleet_frame": "plot", "fleet_x": 3}),
])
def test_integers_where_floats_are_expected_are_accepted(exe, params, ros_env, start_node) -> None:
    node = start_node(PKG[exe], exe, params, ros_env)
    assert node.wait_for_output(READY[exe], 30.0), node.output()
    assert node.alive() and "Traceback" not in node.output()
