"""Start parameters of the planner and recon nodes (real processes): a wrong type or a bad value
is one log line and exit 2, an integer where a float is expected is simply a float (issue 10,
items 7 and 12)."""
from __future__ import annotations

import pytest

READY = {"planner": "planner ready", "recon": "recon ready"}
PKG = {"planner": "vp_planner", "recon": "vp_recon"}


@pytest.mark.parametrize("exe, params, text", [
    ("planner", {"num_cameras": 4.0}, "'num_cameras' must be an integer"),
    ("planner", {"fov": "wide"}, "'fov' must be a number"),
    ("planner", {"min_standoff": float("nan")}, "'min_standoff' must be a finite number"),
    ("planner", {"num_cameras": 500}, "num_cameras must be from 2 to 100"),
    ("recon", {"width": 640.0}, "'width' must be an integer"),
    ("recon", {"dense": 1}, "'dense' must be a boolean"),
    ("recon", {"max_realizations": -1}, "max_realizations must be >= 0"),
    ("recon", {"fov": 4}, "fov must be in (0, pi)"),
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
])
def test_integers_where_floats_are_expected_are_accepted(exe, params, ros_env, start_node) -> None:
    node = start_node(PKG[exe], exe, params, ros_env)
    assert node.wait_for_output(READY[exe], 30.0), node.output()
    assert node.alive() and "Traceback" not in node.output()
