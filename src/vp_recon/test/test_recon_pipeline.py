"""reconstruct_realization / reconstruct_plan: quality of a good plan, error codes of bad ones."""
from __future__ import annotations

import numpy as np
import pytest

from vp_scene.capture import IDEAL

from vp_recon.config import ReconConfig
from vp_scene.meshing import scene_meshes
from vp_recon.errors import (EMPTY_PLAN, NO_SCENE, NOTHING_VISIBLE, OUTPUT_NOT_WRITABLE, RECONSTRUCTION_FAILED,
                             ReconError)
from vp_recon.pipeline import reconstruct_plan, reconstruct_realization
from vp_recon.progress import ReconCancelled

# These tests check the plumbing on small images under the ideal capture (exact poses, as before
# issue 18); the realistic capture is tested at the paper's resolution in test_recon_capture.py.
CFG = ReconConfig(width=640, height=480, capture=IDEAL)
TARGET = np.array([0.0, 0.0, 0.9])


def ring(n: int, step_deg: float, radius: float = 1.4, height: float = 1.2) -> np.ndarray:
    """n cameras on a horizontal circle around the plant, ``step_deg`` apart, looking at TARGET."""
    a = np.deg2rad(step_deg * np.arange(n))
    c = np.stack([radius * np.cos(a), radius * np.sin(a), np.full(n, height)], axis=1)
    return np.concatenate([c, TARGET - c], axis=1)


@pytest.fixture(scope="module")
def good(noisy_scene):
    """6 cameras 30 degrees apart on a ring around the plant (realization 1)."""
    stages = []
    res = reconstruct_realization(noisy_scene, 1, ring(6, 30.0), CFG, progress=lambda s, k: stages.append((s, k)))
    return res, stages


def test_ring_reconstructs_the_plant(noisy_scene, good) -> None:
    res, stages = good
    assert stages == [("render", 1), ("sparse", 1), ("dense", 1), ("score", 1)]
    assert res.source == "dense" and len(res.points) > 2000 and res.sparse_points > 10
    assert res.images >= 4 and res.num_images == 6 and res.visible_images == 6
    assert res.accuracy < 0.015 and res.chamfer < 0.03 and res.fscore > 0.8
    assert res.chamfer == pytest.approx(res.accuracy + res.completeness)
    assert len(res.rendered) == 6 and res.rendered[0].shape == (480, 640, 3)
    assert set(res.seconds) == {"mesh", "render", "sparse", "dense", "score"}
    # scored against realization 1's own points: realization 0's truth fits worse
    from vp_recon.metrics import chamfer
    assert chamfer(res.points, noisy_scene.points[0]).accuracy > res.accuracy


def test_degenerate_plan_is_worse_or_fails(noisy_scene, good) -> None:
    """Six cameras within 2 cm of each other, all looking the same way: no usable baseline."""
    base = ring(1, 0.0)[0]
    cams = np.tile(base, (6, 1))
    cams[:, :3] += np.random.default_rng(0).normal(0, 0.01, (6, 3))
    try:
        res = reconstruct_realization(noisy_scene, 1, cams, CFG)
    except ReconError as exc:
        assert exc.code in (RECONSTRUCTION_FAILED, NOTHING_VISIBLE)
    else:
        assert res.chamfer > 2 * good[0].chamfer


def test_sparse_only(noisy_scene) -> None:
    cfg = ReconConfig(width=640, height=480, dense=False, keep_images=False, capture=IDEAL)
    res = reconstruct_realization(noisy_scene, 0, ring(4, 30.0), cfg)
    # the scored sparse cloud is the cleaned one (cropped, silhouette-filtered), as the dense cloud
    assert res.source == "sparse" and 10 < len(res.points) <= res.sparse_points
    assert res.sparse_score is not None and res.sparse_score.chamfer == pytest.approx(res.chamfer)
    assert res.accuracy < 0.05 and res.rendered == []
    # 'auto' below MATCH_POSES_FROM cameras: all 6 pairs, as before pose-based pairs existed
    assert res.matching == "exhaustive" and res.matched_pairs == 6


def test_auto_matching_uses_the_poses_from_eight_cameras(noisy_scene) -> None:
    """8 cameras 20 degrees apart: 'auto' matches only the pairs select_pairs picks from the
    poses and realization 0's true points, not all 28."""
    from vp_recon.config import MATCH_POSES_FROM, matching_method
    from vp_recon.pairs import select_pairs
    from vp_scene.camera import CameraModel

    assert MATCH_POSES_FROM == 8 and matching_method("auto", 7) == "exhaustive"
    cams = ring(8, 20.0)
    cfg = ReconConfig(width=640, height=480, dense=False, keep_images=False, capture=IDEAL)
    res = reconstruct_realization(noisy_scene, 0, cams, cfg)
    expected = select_pairs(cams, noisy_scene.points[0], CameraModel(640, 480))
    assert res.matching == "poses" and res.matched_pairs == len(expected) < 28
    assert res.pair_inliers and set(res.pair_inliers) <= set(expected)
    assert set(res.sparse_seconds) == {"pairs", "extract", "match", "triangulate"}
    assert set(res.seconds) == {"mesh", "render", "sparse", "dense", "score"}


def test_meshes_follow_the_wind(noisy_scene) -> None:
    from scipy.spatial import cKDTree

    d = {}
    for k in (0, 1):
        v = np.concatenate([np.asarray(m.vertices) for m in scene_meshes(noisy_scene, k)])
        for j in (0, 1):
            d[k, j] = cKDTree(v).query(noisy_scene.points[j])[0].mean()
    assert d[0, 0] < 0.01 and d[1, 1] < 0.01
    assert d[0, 1] > d[1, 1] and d[1, 0] > d[0, 0]


@pytest.mark.parametrize("cams,match", [
    (np.zeros((0, 6)), "no cameras"),
    (np.zeros((3, 5)), "shape"),
    ([[1.0, 0.0, 1.0, -1.0, 0.0, 0.0]], "at least 2"),
    ([[1.0, 0.0, 1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 1.0, 0.0, -1.0, 0.0]], "zero viewing"),
    ([[np.nan, 0.0, 1.0, -1.0, 0.0, 0.0]] * 2, "NaN"),
    ("abc", "numeric"),
])
def test_bad_plans(noisy_scene, cams, match) -> None:
    with pytest.raises(ReconError, match=match) as ei:
        reconstruct_realization(noisy_scene, 0, cams, CFG)
    assert ei.value.code == EMPTY_PLAN and ei.value.name == "EMPTY_PLAN"


def test_cameras_looking_away(noisy_scene) -> None:
    cams = ring(4, 30.0)
    cams[:, 3:] *= -1.0
    with pytest.raises(ReconError, match="none of the 4 cameras") as ei:
        reconstruct_realization(noisy_scene, 0, cams, CFG)
    assert ei.value.code == NOTHING_VISIBLE


def test_only_one_camera_sees(noisy_scene) -> None:
    cams = ring(3, 30.0)
    cams[1:, 3:] *= -1.0
    with pytest.raises(ReconError, match="only camera 0") as ei:
        reconstruct_realization(noisy_scene, 0, cams, CFG)
    assert ei.value.code == NOTHING_VISIBLE


def test_no_scene_and_bad_realization(noisy_scene) -> None:
    with pytest.raises(ReconError) as ei:
        reconstruct_realization(None, 0, ring(2, 30.0), CFG)
    assert ei.value.code == NO_SCENE
    with pytest.raises(ReconError, match="realization 5") as ei:
        reconstruct_realization(noisy_scene, 5, ring(2, 30.0), CFG)
    assert ei.value.code == NO_SCENE
    with pytest.raises(ReconError, match=r"\[7\]") as ei:
        reconstruct_plan(noisy_scene, ring(2, 30.0), CFG, realizations=[0, 7])
    assert ei.value.code == NO_SCENE


def test_unwritable_output(noisy_scene, tmp_path) -> None:
    f = tmp_path / "a_file"
    f.write_text("x")
    with pytest.raises(ReconError, match="not writable") as ei:
        reconstruct_plan(noisy_scene, ring(4, 30.0), CFG, out_dir=f / "sub")
    assert ei.value.code == OUTPUT_NOT_WRITABLE
    with pytest.raises(ReconError) as ei:
        reconstruct_realization(noisy_scene, 0, ring(4, 30.0), CFG, workdir=f)
    assert ei.value.code == OUTPUT_NOT_WRITABLE


def test_one_loop_stops_at_the_first_failing_realization(noisy_scene) -> None:
    """The failure rule of reconstruct_plan (CLI, node and Table I alike): a realization that
    fails stops the plan, and the error says which realization it was."""
    away = ring(4, 30.0)
    away[:, 3:] *= -1.0  # every camera looks away from the plant
    seen = []
    with pytest.raises(ReconError) as ei:
        reconstruct_plan(noisy_scene, away, CFG, realizations=[1, 0], on_realization=seen.append)
    assert ei.value.code == NOTHING_VISIBLE and ei.value.realization == 1 and seen == []


def test_on_realization_sees_each_result_with_its_images(noisy_scene) -> None:
    cfg = ReconConfig(width=640, height=480, dense=False, capture=IDEAL)
    seen = []
    res = reconstruct_plan(noisy_scene, ring(6, 30.0), cfg, realizations=[1, 0],
                           on_realization=lambda r: seen.append((r.realization, len(r.rendered))))
    assert seen == [(1, 6), (0, 6)]  # in order, images attached while the callback runs
    assert [r.realization for r in res.realizations] == [1, 0]
    assert len(res.realizations[0].rendered) == 6 and res.realizations[1].rendered == []  # memory


def test_cancel(noisy_scene) -> None:
    with pytest.raises(ReconCancelled):
        reconstruct_plan(noisy_scene, ring(4, 30.0), CFG, progress=lambda s, k: s != "render")


def test_bad_config() -> None:
    with pytest.raises(ValueError, match="sparse_mode"):
        ReconConfig(sparse_mode="magic").validate()
    with pytest.raises(ValueError, match="width"):
        ReconConfig(width=0).validate()
    with pytest.raises(ValueError, match="matching must be one of auto, exhaustive, poses"):
        ReconConfig(matching="magic").validate()
    for scale in (0, -0.5, 1.5, float("nan")):
        with pytest.raises(ValueError, match="dense_scale must be in"):
            ReconConfig(dense_scale=scale).validate()
    with pytest.raises(ValueError, match="sift_first_octave must be -1, 0 or 1"):
        ReconConfig(sift_first_octave=2).validate()


def test_faster_settings_still_reconstruct(noisy_scene, good) -> None:
    """SIFT from the image's own resolution and stereo on half-size views (bench_recon_speed):
    the plant still reconstructs, from fewer SIFT points and about a quarter of the raw stereo
    points (640 x 480 here: SIFT from octave 0 then keeps only about half the sparse points)."""
    cfg = ReconConfig(width=640, height=480, capture=IDEAL, sift_first_octave=0, dense_scale=0.5)
    res = reconstruct_realization(noisy_scene, 1, ring(6, 30.0), cfg)
    full = good[0]
    assert res.source == "dense" and 0 < res.sparse_points < full.sparse_points
    assert res.accuracy < 0.015 and res.chamfer < 0.03 and res.fscore > 0.8
    raw, raw_full = sum(res.dense_pair_points), sum(full.dense_pair_points)
    assert 0.1 * raw_full < raw < 0.5 * raw_full


def test_target_is_inside_the_plant(noisy_scene) -> None:
    """The rings above aim at the plant: TARGET lies within the plant's bounding box."""
    p = noisy_scene.points[0]
    assert np.all(TARGET >= p.min(axis=0)) and np.all(TARGET <= p.max(axis=0))


def test_incremental_mode_is_aligned_to_the_world(noisy_scene) -> None:
    """Unknown poses: COLMAP's own frame, similarity-aligned to the camera centres."""
    cfg = ReconConfig(width=1000, height=750, sparse_mode="incremental", dense=False, keep_images=False,
                      capture=IDEAL)
    res = reconstruct_realization(noisy_scene, 0, ring(8, 20.0), cfg)
    assert res.images >= 3 and res.sparse_points > 20
    assert res.accuracy < 0.03
