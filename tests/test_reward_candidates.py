"""bench/reward_candidates.py: the registration DOP's closed form (issue 42, direction 1)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from bench.reward_candidates import registration_dop


def square(half: float, height: float = 2.0) -> np.ndarray:
    c = np.array([[half, 0, height], [0, half, height], [-half, 0, height], [0, -half, height]], dtype=float)
    return np.concatenate([c, -c], axis=1)


def test_at_the_cameras_centroid_only_the_translation_counts():
    """Centres symmetric about their mean decouple t from omega and s: a point at the mean moves by
    the translation's error alone, sigma_p sqrt(3 / N) RMS."""
    cams = square(1.5)
    assert registration_dop(cams, np.array([[0.0, 0.0, 2.0]])) == pytest.approx(0.02 * math.sqrt(3 / 4), rel=1e-9)


def test_bunched_cameras_place_a_distant_plant_worse_and_one_camera_not_at_all():
    plant = np.random.default_rng(0).normal(scale=0.3, size=(200, 3))
    wide, bunched = registration_dop(square(2.0), plant), registration_dop(square(0.2), plant)
    assert wide < bunched and bunched > 2 * 0.02            # the scale from 0.4 m of baseline carried 2 m
    assert registration_dop(square(2.0)[:1], plant) == math.inf   # no baseline: no scale
    # attitudes known exactly pin the rotation: only scale and translation are left
    assert registration_dop(square(0.2), plant, sigma_attitude=1e-6) < bunched
