"""vp_scene.sim_drone: the simulated drones' step and their photographs."""
from __future__ import annotations

import numpy as np

from vp_scene.sim_drone import fly_toward


def test_fly_toward() -> None:
    p = fly_toward([0.0, 0.0, 0.0], [3.0, 4.0, 0.0], speed=2.0, dt=0.5)
    np.testing.assert_allclose(p, [0.6, 0.8, 0.0])
    np.testing.assert_array_equal(fly_toward([2.9, 3.9, 0.0], [3.0, 4.0, 0.0], 2.0, 0.5), [3.0, 4.0, 0.0])


def test_fly_toward_with_a_climb_rate_takes_the_routes_leg_time() -> None:
    """Horizontal at most `speed`, vertical at most `climb_rate`, on the straight line: 8 m across
    and 3 m up at 4 and 1 m/s take max(2, 3) = 3 s, as vp_planner.routes times the leg."""
    p, goal, t = np.zeros(3), np.array([8.0, 0.0, 3.0]), 0.0
    while not np.array_equal(p, goal):
        q = fly_toward(p, goal, speed=4.0, dt=0.1, climb_rate=1.0)
        assert abs(q[2] - p[2]) <= 0.1 + 1e-12 and np.linalg.norm(q[:2] - p[:2]) <= 0.4 + 1e-12
        np.testing.assert_allclose(np.cross(q, goal), 0.0, atol=1e-12)  # on the line
        p, t = q, t + 0.1
    assert abs(t - 3.0) < 1e-9
