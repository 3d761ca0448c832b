"""vp_planner.fleet: the map -> fleet transform, goal orientations, the feasibility check
(ViewSpace's rules, explained) and the simulated flight."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vp_planner.fleet import FleetTransform, goal_orientations, plan_problems
from vp_planner.space import ViewSpace
from vp_scene.camera import OPTICAL_IN_BODY, cameras_to_poses, look_at, rotation_matrix


def test_fleet_transform() -> None:
    t = FleetTransform(x=2.0, y=-1.0, z=0.5, yaw=math.pi / 2)
    # the fleet frame's origin is (2, -1, 0.5) in map, its x axis along map's +y
    np.testing.assert_allclose(t.points_to_fleet([2.0, -1.0, 0.5]), [0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(t.points_to_fleet([2.0, 0.0, 0.5]), [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(t.points_to_map([0.0, 1.0, 0.0]), [1.0, -1.0, 0.5], atol=1e-12)
    rng = np.random.default_rng(0)
    p = rng.normal(size=(20, 3))
    np.testing.assert_allclose(t.points_to_map(t.points_to_fleet(p)), p, atol=1e-12)
    # a camera looking along map +y looks along fleet +x after the 90 degree yaw
    cams = look_at([[3.0, 0.0, 1.0]], [[3.0, 5.0, 1.0]])
    fleet = t.poses_to_fleet(cameras_to_poses(cams))
    x_axis = Rotation.from_quat(fleet[0, 3:]).as_matrix()[:, 0]
    np.testing.assert_allclose(x_axis, [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(fleet[0, :3], t.points_to_fleet(cams[0, :3]), atol=1e-12)
    assert fleet[0, 6] >= 0
    assert FleetTransform().is_identity and FleetTransform(yaw=2 * math.pi).is_identity
    assert not t.is_identity
    np.testing.assert_allclose(FleetTransform().poses_to_fleet(cameras_to_poses(cams)), cameras_to_poses(cams))
    with pytest.raises(ValueError, match="finite"):
        FleetTransform(x=math.nan)


def test_goal_orientations() -> None:
    cams = look_at([[1.0, 2.0, 3.0], [0.0, -2.0, 1.0]], [[0.0, 0.0, 0.5], [0.0, 0.0, 1.0]])
    q = cameras_to_poses(cams)[:, 3:]
    np.testing.assert_allclose(goal_orientations(q, "body"), q)
    opt = goal_orientations(q, "optical")
    for k in range(2):
        R = Rotation.from_quat(opt[k]).as_matrix()
        body = rotation_matrix(cams[k, 3:])
        np.testing.assert_allclose(R[:, 2], body[:, 0], atol=1e-12)   # optical z = viewing direction
        np.testing.assert_allclose(R[:, 0], -body[:, 1], atol=1e-12)  # x right
        np.testing.assert_allclose(R[:, 1], -body[:, 2], atol=1e-12)  # y down
    np.testing.assert_allclose(goal_orientations([[0, 0, 0, 1.0]], "optical")[0], OPTICAL_IN_BODY)
    with pytest.raises(ValueError, match="unknown orientation"):
        goal_orientations(q, "gimbal")


def ring(n: int, radius: float, height: float) -> np.ndarray:
    az = np.linspace(0, 2 * math.pi, n, endpoint=False)
    c = np.stack([radius * np.cos(az), radius * np.sin(az), np.full(n, height)], axis=1)
    return look_at(c, np.tile([0.0, 0.0, 1.0], (n, 1)))


def test_plan_problems_agree_with_the_view_space(realizations) -> None:
    """The verdict is ViewSpace.feasible's; the explanation names the broken rule."""
    ok = ring(4, 2.5, 1.2)
    assert plan_problems(ok, realizations) == []
    low = ok.copy()
    low[1, 2] = 0.1
    (text,) = plan_problems(low, realizations)
    assert "camera 1" in text and "min_altitude" in text
    close = ok.copy()
    close[2, :3] = [0.05, 0.0, 1.0]  # inside the plant
    (text,) = plan_problems(close, realizations)
    assert "camera 2" in text and "min_standoff" in text
    pair = ok.copy()
    pair[3, :3] = pair[0, :3] + [0.0, 0.2, 0.0]
    (text,) = plan_problems(pair, realizations)
    assert "cameras 0 and 3" in text and "0.200 m apart" in text and "min_separation" in text
    # without a scene the stand-off rule is left out, the others stay
    assert plan_problems(close, None) == []
    assert "min_altitude" in plan_problems(low, None)[0]
    # a single camera: altitude and stand-off only
    assert plan_problems(ok[:1], realizations) == [] and "min_altitude" in plan_problems(low[1:2], realizations)[0]
    # the same verdict as the planner's view space on random plans
    rng = np.random.default_rng(1)
    space = ViewSpace(realizations, 3)
    for _ in range(40):
        cams = look_at(rng.uniform([-1.5, -1.5, 0.0], [1.5, 1.5, 2.5], (3, 3)), np.tile([0.0, 0.0, 1.0], (3, 1)))
        assert (plan_problems(cams, realizations) == []) == bool(space.feasible(cams))
