"""The capture model in the reconstruction (issue 18, parts 1-2): ``ideal`` is the pipeline before
the capture model bit for bit; the realistic default reconstructs as a flight can and no longer
flatters a plan without baseline."""
from __future__ import annotations

import hashlib
import math

import numpy as np
import pytest

from vp_scene.capture import IDEAL, REALISTIC

from vp_recon.pipeline import RECONSTRUCTION_FAILED, ReconConfig, ReconError, reconstruct_realization


@pytest.fixture(scope="module")
def scene():
    from vp_scene.build import build_noisy_scene

    ns, _ = build_noisy_scene(scenario="one_plant", points_per_plant=3000, realizations=2, levels=5, seed=2)
    return ns


def ring(n: int = 6, radius: float = 1.7, height: float = 1.3, arc: float = math.radians(150),
         target=(0.0, 0.0, 0.9)) -> np.ndarray:
    az = np.linspace(0.0, arc, n)
    c = np.stack([radius * np.cos(az), radius * np.sin(az), np.full(n, height)], axis=1)
    return np.concatenate([c, np.asarray(target) - c], axis=1)


#: Measured with the pipeline of f11de5b (before the capture model), 640 x 480, one thread:
#: (Chamfer repr, F-score repr, points, sha256 of the points' bytes, first 16 hex digits).
BEFORE = {
    "ring6": ("0.01568667434947112", "0.9568624081602843", 65001, "7a0a183f85598451", "exhaustive"),
    "ring9": ("0.014475378770857613", "0.9664853421936578", 80705, "f3eb4da0137c76b0", "poses"),
}


@pytest.mark.parametrize("name", sorted(BEFORE))
def test_ideal_capture_reproduces_the_pipeline_before_it_bit_for_bit(scene, name) -> None:
    cams = ring(6) if name == "ring6" else ring(9, arc=math.radians(240))
    r = reconstruct_realization(scene, 1, cams, ReconConfig(width=640, height=480, num_threads=1, capture=IDEAL))
    digest = hashlib.sha256(np.ascontiguousarray(r.points).tobytes()).hexdigest()[:16]
    assert (repr(r.chamfer), repr(r.fscore), len(r.points), digest, r.matching) == BEFORE[name]
    assert r.capture["kind"] == "ideal" and r.sparse_mode == "known_poses"


def test_realistic_capture_reconstructs_and_a_plan_without_baseline_does_not_pass(scene) -> None:
    """The issue's degenerate plan: four cameras within a few centimetres, all looking the same
    way. With exact poses on noise-free renders (ideal) it scored 2.37 against the ring's 1.27
    (Chamfer x100, measured); flown (hover and localization errors, sensor noise, SfM with the
    reported poses as priors, registered to the reported centres) it fails or scores far worse."""
    cfg = ReconConfig(width=2000, height=1500, num_threads=1)
    assert cfg.capture == REALISTIC and cfg.sparse_mode_used == "incremental" and cfg.ground_used
    assert not ReconConfig(capture=IDEAL).ground_used  # the ideal capture keeps its blue screen
    good = reconstruct_realization(scene, 1, ring(6), cfg)
    assert good.images >= 4 and good.capture["kind"] == "realistic" and good.sparse_mode == "incremental"
    assert good.chamfer < 0.06 and good.chamfer_shape <= good.chamfer + 1e-3  # measured 0.034 / 0.026
    base = ring(1, arc=0.0)[0]
    degenerate = np.array([base + [dx, dy, 0, 0, 0, 0] for dx, dy in ((0, 0), (0.03, 0), (0, 0.03), (0.03, 0.03))])
    try:
        bad = reconstruct_realization(scene, 1, degenerate, cfg)
    except ReconError as exc:
        assert exc.code == RECONSTRUCTION_FAILED and "registered" in str(exc)
    else:
        assert bad.chamfer >= 2 * good.chamfer, (bad.chamfer, good.chamfer)  # measured 0.378 vs 0.034


def test_a_plan_that_does_not_register_names_the_images_registered(scene) -> None:
    """RECONSTRUCTION_FAILED names how many images registered (small images: too few features)."""
    cfg = ReconConfig(width=320, height=240, num_threads=1, dense=False)
    with pytest.raises(ReconError) as err:
        reconstruct_realization(scene, 1, ring(4), cfg)
    assert err.value.code == RECONSTRUCTION_FAILED
    assert "registered" in str(err.value) and "of 4 images" in str(err.value)
