"""Start parameters of the planner, recon and dispatcher nodes: a wrong type or a bad value is
one log line and exit 2 (one case a node as a real process, every case through the node's
constructor in this process), an integer where a float is expected is simply a float. Every
node's parameter descriptors, asked over DDS through DescribeParameters: descriptions, ranges,
read_only, enforced."""
from __future__ import annotations

import math

import pytest

READY = {"planner": "planner ready", "recon": "recon ready", "dispatcher": "dispatcher ready"}
PKG = {"planner": "vp_planner", "recon": "vp_recon", "dispatcher": "vp_planner"}


#: (node, bad start parameters, the text of the one line the node exits with)
BAD = [
    ("planner", {"num_cameras": 4.0}, "'num_cameras' must be an integer"),
    ("planner", {"fov": "wide"}, "'fov' must be a number"),
    ("planner", {"min_standoff": float("nan")}, "'min_standoff' must be a finite number"),
    ("planner", {"num_cameras": 500}, "num_cameras must be from 2 to 100"),
    ("planner", {"parts": -1}, "parts must be >= 0"),
    ("planner", {"lawnmower_overlap": 1.0}, "lawnmower overlap must be in [0, 0.95]"),
    ("planner", {"lawnmower_tilt": 1.5}, "lawnmower tilt must be in [0, 60 degrees]"),
    ("planner", {"report_position_sigma": 0.0}, "report_position_sigma must be finite and in (0, 10), got 0.0"),
    ("planner", {"sim_flights": 201}, "sim_flights must be from -1 to 200 (an integer), got 201"),
    ("planner", {"flight_dense_scale": 0.05}, "flight_dense_scale must be finite and in [0.1, 1], got 0.05"),
    ("recon", {"width": 640.0}, "'width' must be an integer"),
    ("recon", {"dense": 1}, "'dense' must be a boolean"),
    ("recon", {"max_realizations": -1}, "max_realizations must be >= 0"),
    ("recon", {"fov": 4}, "fov must be in (0, pi)"),
    ("recon", {"matching": "magic"}, "matching must be one of auto, exhaustive, poses"),
    ("recon", {"image_transport": "theora"}, "image_transport must be raw or compressed, got 'theora'"),
    ("recon", {"dense_scale": 0.0}, "dense_scale must be in (0, 1], got 0.0"),
    ("recon", {"sift_first_octave": 2}, "sift_first_octave"),
    ("recon", {"scheduler": "tls://127.0.0.1:8786"}, "scheduler tls://127.0.0.1:8786 is tls://: give the CA file"),
    ("recon", {"max_cameras": 1}, "max_cameras must be an integer >= 2, got 1"),
    ("dispatcher", {}, 'drones must name at least one drone, e.g. -p "drones:=[d0, d1, d2, d3]"'),
    ("dispatcher", {"drones": "d0"}, "'drones' must be a list of strings"),
    ("dispatcher", {"drones": ["d0", "d1", "d0"]}, "drones names a drone twice: ['d0']"),
    ("dispatcher", {"drones": ["d0", "drone-1"]}, "drone names must start with a letter"),
    ("dispatcher", {"drones": ["d0"], "assignment": "fastest"}, "assignment must be one of min_max, min_total"),
    ("dispatcher", {"drones": ["d0"], "origin": "91,8,400"},
     "[INVALID_ORIGIN] origin latitude must be in [-90, 90] deg, got 91.0"),
    ("dispatcher", {"drones": ["d0"], "cruise_speed": 0.0},
     "[INVALID_FLIGHT_MODEL] cruise_speed must be in (0, 30] m/s, got 0.0"),
    ("dispatcher", {"drones": ["d0"], "goal_topic": "/goal"}, "goal_topic must contain {drone}"),
    ("dispatcher", {"drones": ["d0"], "pose_timeout": 0}, "pose_timeout must be > 0"),
    ("dispatcher", {"drones": ["d0"], "fleet_yaw": 0.5}, "fleet_frame is frame_id ('map')"),
]
#: one case a node checked as a real process: the one line, exit 2, no traceback (the rest in process)
AS_PROCESS = [next(case for case in BAD if case[0] == exe) for exe in READY]
NODE_CLASS = {"planner": ("vp_planner.planner_node", "PlannerNode"), "recon": ("vp_recon.recon_node", "ReconNode"),
              "dispatcher": ("vp_planner.dispatcher_node", "DispatcherNode")}


@pytest.mark.parametrize("exe, params, text", AS_PROCESS)
def test_bad_parameter_is_one_line_and_exit_2(exe, params, text, ros_env, start_node) -> None:
    node = start_node(PKG[exe], exe, params, ros_env)
    assert node.wait(30.0) == 2, node.output()
    out = node.output()
    assert text in out and "Traceback" not in out, out
    assert len([ln for ln in out.splitlines() if ln.strip()]) == 1, out


@pytest.mark.parametrize("exe, params, text", BAD)
def test_bad_parameter_is_refused_by_the_node_constructor(exe, params, text, ros_env) -> None:
    """Every bad start parameter, given on the command line's ``--ros-args`` as a start gives it:
    the node's constructor raises the ValueError whose one line :func:`vp_scene.node_runtime.run_node`
    logs before exit 2 (that path, as a process: the test above). In this process, one import a node."""
    import importlib

    import rclpy

    from node_process import node_command

    module, cls = NODE_CLASS[exe]
    make_node = getattr(importlib.import_module(module), cls)
    cmd = node_command(PKG[exe], exe, params)
    args = cmd[cmd.index("--ros-args"):]
    rclpy.init(args=args, domain_id=int(ros_env["ROS_DOMAIN_ID"]))
    try:
        with pytest.raises(ValueError) as err:
            node = make_node()
            node.destroy_node()
    finally:
        rclpy.shutdown()
    line = " ".join(str(err.value).split())
    assert text in line, line


@pytest.mark.parametrize("exe, params", [
    ("planner", {"fov": 2, "theta_match": 1, "min_separation": 0}),
    ("recon", {"fov": 2, "fscore_threshold": 1, "dense_scale": 1}),
    ("dispatcher", {"drones": ["d0"], "pose_timeout": 1, "fleet_frame": "plot", "fleet_x": 3}),
])
def test_integers_where_floats_are_expected_are_accepted(exe, params, ros_env, start_node) -> None:
    node = start_node(PKG[exe], exe, params, ros_env)
    assert node.wait_for_output(READY[exe], 30.0), node.output()
    assert node.alive() and "Traceback" not in node.output()


# ---------------------------------------------------------------- descriptors (issue 19, the house)
INT, DOUBLE = "integer", "floating"
INT64_MAX = 2 ** 63 - 1

#: node -> (package, executable, start parameters, {parameter: expected limits}, a value outside a
#: range or None, a read-only parameter with a new value or None). Limits: (kind, from, to, read_only); None: no range.
DESCRIBED = {
    "planner": ("vp_planner", "planner", {}, {
        "num_cameras": (INT, 2, 100, False), "evaluations": (INT, 1, 100000, False),
        "fov": (DOUBLE, 0.0, math.pi, False), "lawnmower_overlap": (DOUBLE, 0.0, 0.95, False),
        "lawnmower_tilt": (DOUBLE, 0.0, math.radians(60.0), False), "num_threads": (INT, 1, INT64_MAX, True),
        "min_standoff": (DOUBLE, 0.0, math.inf, False), "method": None, "seed": (INT, 0, 2 ** 32 - 1, False),
        "tau": (DOUBLE, 0.0, math.inf, False), "reconstructed_weight": (DOUBLE, 0.0, 1.0, False),
        "sim_flights": (INT, -1, 200, False), "flight_sift_octave": (INT, -1, 0, False),
        "flight_dense_scale": (DOUBLE, 0.1, 1.0, False), "flight_workers": (INT, 1, INT64_MAX, False)},
        ("num_cameras", 101), ("num_threads", 2)),
    "dispatcher": ("vp_planner", "dispatcher", {"drones": ["d0", "d1"]}, {
        "pose_timeout": (DOUBLE, 0.0, math.inf, False), "min_separation": (DOUBLE, 0.0, math.inf, False),
        "drones": (None, None, None, True), "assignment": None, "cruise_speed": (DOUBLE, 0.0, 30.0, False),
        "reserve": (DOUBLE, 0.0, 0.9, False), "route_topic": (None, None, None, True)},
        ("min_altitude", -0.5), ("drones", ["d0"])),
    "scene": ("vp_scene", "scene", {"points_per_plant": 200, "realizations": 2}, {
        "realizations": (INT, 1, 100, False), "points_per_plant": (INT, 1, 1_000_000, False),
        "seed": (INT, 0, 2 ** 32 - 1, False), "levels": (INT, 1, INT64_MAX, False),
        "wind_variance": (DOUBLE, 0.0, math.inf, False), "scenario": None},
        ("levels", 0), None),
    "recon": ("vp_recon", "recon", {}, {
        "width": (INT, 16, 16384, False), "sensor_noise": (DOUBLE, 0.0, 0.5, False),
        "hover_attitude_sigma": (DOUBLE, 0.0, 10.0, False), "max_realizations": (INT, 0, INT64_MAX, False),
        "max_cameras": (INT, 2, INT64_MAX, False)},
        ("sensor_noise", 0.9), None),
    "sim_drone": ("vp_scene", "sim_drone", {"drone": "d0"}, {
        "speed": (DOUBLE, 0.0, math.inf, True), "drone": (None, None, None, True)},
        None, ("speed", 3.0)),
}


@pytest.mark.parametrize("name", list(DESCRIBED))
def test_descriptors_show_the_limits_and_rclpy_enforces_them(name, ros_env, start_node, ros_node) -> None:
    """``ros2 param describe`` on a stock install: a real node answers rcl_interfaces'
    DescribeParameters with a description for every parameter, the ranges the node enforces
    (IntegerRange / FloatingPointRange) and read_only where a change is not honoured; a
    set_parameters outside a range, or of a read-only parameter, is refused and leaves the value."""
    from rcl_interfaces.srv import DescribeParameters, ListParameters
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient

    pkg, exe, params, expected, outside, fixed = DESCRIBED[name]
    node = start_node(pkg, exe, params, ros_env)
    client = ros_node(ros_env)
    node_name = exe
    lister = client.node.create_client(ListParameters, f"/{node_name}/list_parameters")
    describer = client.node.create_client(DescribeParameters, f"/{node_name}/describe_parameters")
    assert client.spin_until(lambda: lister.service_is_ready() and describer.service_is_ready(), 60.0), node.output()
    names = [n for n in client.call(lambda: lister.call_async(ListParameters.Request()), 60.0).result.names
             if n not in ("use_sim_time", "start_type_description_service")]
    assert set(expected) <= set(names), names
    descs = {d.name: d for d in client.call(
        lambda: describer.call_async(DescribeParameters.Request(names=names)), 60.0).descriptors}
    assert set(descs) == set(names)
    for n, d in descs.items():
        assert d.description.strip(), f"{name}: parameter {n} has no description"
    for n, limits in expected.items():
        d = descs[n]
        if limits is None:
            assert not d.integer_range and not d.floating_point_range and not d.read_only, (n, d)
            continue
        kind, lo, hi, read_only = limits
        assert d.read_only == read_only, (n, d)
        if kind == INT:
            assert len(d.integer_range) == 1 and not d.floating_point_range, (n, d)
            r = d.integer_range[0]
            assert (r.from_value, r.to_value) == (lo, hi), (n, r)
        elif kind == DOUBLE:
            assert len(d.floating_point_range) == 1 and not d.integer_range, (n, d)
            r = d.floating_point_range[0]
            assert r.from_value == pytest.approx(lo) and r.to_value == pytest.approx(hi), (n, r)

    setter = AsyncParameterClient(client.node, node_name)
    assert setter.wait_for_services(timeout_sec=60.0)
    for prm_name, value in ([outside] if outside else []):
        before = client.call(lambda: setter.get_parameters([prm_name]), 60.0).values[0]
        res = client.call(lambda: setter.set_parameters([Parameter(prm_name, value=value)]), 60.0).results[0]
        assert not res.successful and "out of range" in res.reason and prm_name in res.reason, res.reason
        after = client.call(lambda: setter.get_parameters([prm_name]), 60.0).values[0]
        assert after == before, (before, after)
    if fixed:
        prm_name, value = fixed
        before = client.call(lambda: setter.get_parameters([prm_name]), 60.0).values[0]
        res = client.call(lambda: setter.set_parameters([Parameter(prm_name, value=value)]), 60.0).results[0]
        assert not res.successful and f"read-only parameter: {prm_name}" in res.reason, res.reason
        assert client.call(lambda: setter.get_parameters([prm_name]), 60.0).values[0] == before
    assert node.alive(), node.output()
