"""vp_planner.feasibility: the feasibility rules live in a torch-free module,
so the dispatcher (and the simulated drone beside it) start and check plans without torch; the
search space's verdict is the rules' verdict."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from vp_planner.feasibility import FeasibilityRules
from vp_planner.space import ViewSpace

#: Run in a fresh interpreter: the dispatcher's modules, its node built, a plan checked with a scene.
DISPATCHER_WITHOUT_TORCH = textwrap.dedent("""
    import sys
    import numpy as np
    import rclpy
    import vp_planner.dispatcher_node as dn
    import vp_scene.sim_drone_node  # noqa: F401
    from vp_planner.fleet import plan_problems
    rclpy.init(args=['--ros-args', '-p', 'drones:=[d1, d2]'])
    node = dn.DispatcherNode()
    scene = np.random.default_rng(0).uniform(-0.3, 0.3, (2, 200, 3)) + [0.0, 0.0, 1.0]
    cams = np.array([[3.0, 0.0, 1.0, -1.0, 0.0, 0.0], [0.0, 3.0, 1.0, 0.0, -1.0, 0.0]])
    assert plan_problems(cams, scene) == [], plan_problems(cams, scene)
    near = cams.copy(); near[0, :3] = [0.1, 0.0, 1.0]
    assert 'min_standoff' in plan_problems(near, scene)[0], plan_problems(near, scene)
    node.destroy_node()
    rclpy.shutdown()
    heavy = sorted(m for m in ('torch', 'botorch', 'gpytorch', 'vp_planner.space') if m in sys.modules)
    print('HEAVY', heavy)
    assert not heavy, heavy
""")


def test_dispatcher_starts_and_checks_plans_without_torch(tmp_path) -> None:
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               ROS_DOMAIN_ID=str(201 + os.getpid() % 32))  # no traffic: the node is built, never spun
    out = subprocess.run([sys.executable, "-c", DISPATCHER_WITHOUT_TORCH], env=env, cwd=tmp_path,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "HEAVY []" in out.stdout


@pytest.mark.parametrize("fixed", [False, True])
def test_view_space_verdict_is_the_rules_verdict(fixed: bool, small_realizations: np.ndarray) -> None:
    R = small_realizations
    fixed_positions = np.array([[2.0, 0.0, 1.0], [0.0, 2.5, 1.5]]) if fixed else None
    space = ViewSpace(R, 4, fixed_positions=fixed_positions)
    U = np.random.default_rng(1).random((400, space.dim))
    cams = space.decode(U)
    rules = FeasibilityRules(R, 4, fixed_positions=fixed_positions)
    verdict = rules(cams)
    assert np.array_equal(space.feasible(U), verdict)
    assert 0 < verdict.sum() < len(verdict)  # both kinds occur: the comparison can fail


def test_rules_refuse_bad_minima_and_need_obstacles_for_standoff() -> None:
    with pytest.raises(ValueError, match="min_standoff must be finite"):
        FeasibilityRules(np.zeros((1, 3)), 2, min_standoff=float("nan"))
    with pytest.raises(ValueError, match="obstacle points"):
        FeasibilityRules(None, 2, min_standoff=0.5)
    free = FeasibilityRules(None, 2, min_standoff=0.0, min_separation=1.0)
    cams = np.array([[[0, 0, 1, 1, 0, 0], [0.5, 0, 1, 1, 0, 0]], [[0, 0, 1, 1, 0, 0], [2, 0, 1, 1, 0, 0]]], float)
    assert free(cams).tolist() == [False, True]
