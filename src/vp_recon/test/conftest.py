"""Shared fixture of the vp_recon tests: one small procedural plant, two wind realizations."""
from __future__ import annotations

import os

import pytest

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


@pytest.fixture(scope="session")
def noisy_scene():
    from vp_scene.build import build_noisy_scene

    ns, _ = build_noisy_scene("one_plant", seed=0, points_per_plant=3000, realizations=2)
    return ns
