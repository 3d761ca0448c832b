"""The capture model in the reconstruction (issue 18, parts 1-2): ``ideal`` is the pipeline before
the capture model bit for bit; the realistic default reconstructs as a flight can and no longer
flatters a plan without baseline."""
from __future__ import annotations

import hashlib
import math

import numpy as np
import pytest

from vp_scene.capture import IDEAL, REALISTIC

from vp_recon.config import ReconConfig
from vp_recon.errors import RECONSTRUCTION_FAILED, ReconError
from vp_recon.pipeline import reconstruct_realization


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
def test_ideal_capture_reproduces_the_pipeline_before_it_bit_for_bit(scene, name, monkeypatch) -> None:
    # the dense step's pair budget (later than f11de5b) matches some pairs of these rings smaller
    # (ring6 Chamfer 0.015687 -> 0.015545, ring9 0.014475 -> 0.014578): off, as it was then
    import functools

    from vp_recon import dense

    monkeypatch.setattr(dense, "dense_reconstruct", functools.partial(dense.dense_reconstruct, pair_budget=False))
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
    default = ReconConfig(width=2000, height=1500, num_threads=1)
    assert default.capture == REALISTIC and default.sparse_mode_used == "anchored" and default.ground_used
    # make run's reconstruction settings (SIFT on the image as it is, dense at 0.7): what is checked is
    # the capture model; the recon node's doubled first octave scores the same here, at several times the cost
    cfg = ReconConfig(width=2000, height=1500, num_threads=1, sift_first_octave=0, dense_scale=0.7)
    assert not ReconConfig(capture=IDEAL).ground_used  # the ideal capture keeps its blue screen
    good = reconstruct_realization(scene, 1, ring(6), cfg)
    assert good.images >= 4 and good.capture["kind"] == "realistic" and good.sparse_mode == "anchored"
    assert good.chamfer < 0.06 and good.chamfer_shape <= good.chamfer + 1e-3  # measured 0.016 / 0.014
    # the self-check's figure: registered centres within a few sigma (0.02 m) of the reported ones
    assert 0.0 < good.centre_residual < 0.1, good.centre_residual
    base = ring(1, arc=0.0)[0]
    degenerate = np.array([base + [dx, dy, 0, 0, 0, 0] for dx, dy in ((0, 0), (0.03, 0), (0, 0.03), (0.03, 0.03))])
    try:
        bad = reconstruct_realization(scene, 1, degenerate, cfg)
    except ReconError as exc:
        assert exc.code == RECONSTRUCTION_FAILED and "registered" in str(exc)
    else:
        assert bad.chamfer >= 2 * good.chamfer, (bad.chamfer, good.chamfer)  # measured 0.12 vs 0.016


def test_a_plan_that_does_not_register_names_the_images_registered(scene) -> None:
    """RECONSTRUCTION_FAILED names how many images registered (small images: too few features)."""
    cfg = ReconConfig(width=320, height=240, num_threads=1, dense=False)
    with pytest.raises(ReconError) as err:
        reconstruct_realization(scene, 1, ring(4), cfg)
    assert err.value.code == RECONSTRUCTION_FAILED
    assert "registered" in str(err.value) and "of 4 images" in str(err.value)


def test_parts_that_share_no_matches_are_each_registered_to_map(scene, tmp_path) -> None:
    """A plan in two parts that share no image content (a field planned by parts: each part's
    drones see their own plants), here 4 cameras on each side of the plant matched within their part
    only: COLMAP's mapper makes one model per part, and each is placed in map on its own reported
    poses. Before, only the largest model was kept: 4 of 8 images registered and one side lost."""
    from vp_recon.pipeline import render_flight
    from vp_recon.segment import image_mask
    from vp_recon.config import SparseOptions
    from vp_recon.sparse import sparse_reconstruct

    cfg = ReconConfig(width=1600, height=1200, num_threads=1)  # 1000 x 750: too few points a side
    near = ring(4, arc=math.radians(45))
    far = near.copy()
    far[:, [0, 1, 3, 4]] *= -1  # the same arc turned 180 degrees about the plant's axis
    views = render_flight(scene, 1, np.vstack([near, far]), cfg)
    masks = [image_mask(im, cfg.ground_used) for im in views.images]
    within = [(i, j) for part in (range(4), range(4, 8)) for i in part for j in part if i < j]
    sp = sparse_reconstruct(views.images, views.reported, views.K, tmp_path,
                            SparseOptions(mode="incremental", num_threads=1), masks=masks, pairs=within,
                            prior_centres=views.reported[:, :3])
    assert sp.models == 2 and sp.registered == 8, (sp.models, sp.registered)
    # every image placed where its drone reported it, to the hover and localization errors
    assert np.all(np.linalg.norm(sp.cameras[:, :3] - views.reported[:, :3], axis=1) < 0.1)
    # the points of both parts on the plant: each side's plant points have sparse points nearby
    from scipy.spatial import cKDTree

    from vp_recon.dense import silhouette_filter

    truth = scene.points[1]
    lo, hi = truth.min(axis=0) - 0.05, truth.max(axis=0) + 0.05
    on = sp.points[np.all((sp.points >= lo) & (sp.points <= hi), axis=1)]
    on = on[silhouette_filter(on, sp.cameras, views.K, masks)]  # as the pipeline cleans them
    d, _ = cKDTree(truth).query(on)
    assert len(on) > 100 and np.median(d) < 0.02, (len(on), np.median(d))  # measured 217, 0.011
    recall = []
    for side in (near, far):
        facing = truth[(truth[:, :2] @ side[0, :2]) > 0.05]  # plant points on that part's side
        recall.append(float(np.mean(cKDTree(on).query(facing)[0] < 0.05)))
    assert min(recall) > 0.1, recall  # measured 0.28 and 0.45
