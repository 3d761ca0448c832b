"""vp_scene.sim_drone: the simulated drones' step and their photographs."""
from __future__ import annotations

import numpy as np

from vp_scene.sim_drone import fly_toward


def test_fly_toward() -> None:
    p = fly_toward([0.0, 0.0, 0.0], [3.0, 4.0, 0.0], speed=2.0, dt=0.5)
    np.testing.assert_allclose(p, [0.6, 0.8, 0.0])
    np.testing.assert_array_equal(fly_toward([2.9, 3.9, 0.0], [3.0, 4.0, 0.0], 2.0, 0.5), [3.0, 4.0, 0.0])
