"""vp_recon.pairs: image pairs chosen from the known poses (the rule of its module docstring), and
sparse_reconstruct matching only them on real renders."""
from __future__ import annotations

import math
import time
import tracemalloc

import numpy as np
import pytest

from vp_recon.pairs import check_pairs, in_view, pair_geometry, select_pairs
from vp_scene.camera import CameraModel, look_at

MODEL = CameraModel(640, 480)
CENTRE = np.array([0.0, 0.0, 1.0])


def blob(n: int = 400, centre=CENTRE, spread: float = 0.1, seed: int = 0) -> np.ndarray:
    """n points around ``centre``: a small plant-sized cluster."""
    return np.random.default_rng(seed).normal(0.0, spread, (n, 3)) + np.asarray(centre)


def ring_at(degrees, radius: float = 2.0) -> np.ndarray:
    """Cameras on a horizontal circle about CENTRE at the given azimuths, looking at it."""
    a = np.deg2rad(np.asarray(degrees, dtype=np.float64))
    c = np.stack([radius * np.cos(a), radius * np.sin(a), np.full(len(a), CENTRE[2])], axis=1)
    return look_at(c, np.broadcast_to(CENTRE, c.shape))


def partners(pairs: list, n: int) -> np.ndarray:
    count = np.zeros(n, int)
    for i, j in pairs:
        count[i] += 1
        count[j] += 1
    return count


def test_triangulation_angle_is_the_median_over_shared_points() -> None:
    """Two cameras 90 degrees apart seen from the origin; a second and third point shift the rays."""
    cams = look_at([[2.0, 0.0, 0.0], [0.0, 2.0, 0.0]], [[0.0, 0.0, 0.0]] * 2)
    pts = np.array([[0.0, 0.0, 0.0], [0.5, 0.5, 0.0], [-0.3, -0.3, 0.0]])
    vis = in_view(cams, pts, MODEL)
    shared, angle = pair_geometry(cams, pts, vis)
    assert vis.all() and shared[0, 1] == 3 and np.isnan(angle[0, 0])
    per_point = [math.degrees(math.acos(np.dot(a, b) / np.linalg.norm(a) / np.linalg.norm(b)))
                 for a, b in ((cams[0, :3] - p, cams[1, :3] - p) for p in pts)]
    assert math.degrees(angle[0, 1]) == pytest.approx(np.median(per_point)) == pytest.approx(90.0)
    assert angle[1, 0] == angle[0, 1]


def test_neighbours_20_degrees_apart_are_paired() -> None:
    assert select_pairs(ring_at([0, 20]), blob(), MODEL) == [(0, 1)]
    # a ring of 12, 30 degrees apart: each camera with its two neighbours, nothing 60 degrees apart
    assert select_pairs(ring_at(30 * np.arange(12)), blob(), MODEL) == sorted(
        (min(i, (i + 1) % 12), max(i, (i + 1) % 12)) for i in range(12))


def test_far_camera_is_outside_the_window_but_keeps_min_partners() -> None:
    """Camera 3 is 120, 140 and 160 degrees from the others: no qualifying pair, so it keeps its
    best ones (closest to the window: 2 at 120, then 1 at 140), and only as many as min_partners."""
    cams = ring_at([0, 20, 40, 160])
    pts = blob()
    assert select_pairs(cams, pts, MODEL, min_partners=0) == [(0, 1), (0, 2), (1, 2)]
    assert select_pairs(cams, pts, MODEL, min_partners=1) == [(0, 1), (0, 2), (1, 2), (2, 3)]
    assert select_pairs(cams, pts, MODEL, min_partners=2) == [(0, 1), (0, 2), (1, 2), (1, 3), (2, 3)]
    # a wider window admits it by the rule itself
    assert (0, 3) in select_pairs(cams, pts, MODEL, max_angle=math.radians(170), min_partners=0)


def test_cameras_facing_away_share_nothing_and_are_never_paired() -> None:
    """Cameras 0 and 1 stand together back to back, each seeing its own plant: nothing shared, so
    no pair even for min_partners; camera 2 beside camera 0 sees its plant and pairs with it;
    camera 3 looks at the sky and sees nothing."""
    pts = np.concatenate([blob(centre=[2.0, 0.0, 1.0]), blob(centre=[-2.0, 0.0, 1.0], seed=1)])
    cams = np.array([[0.0, 0.0, 1.0, 1.0, 0.0, 0.0],
                     [0.0, 0.0, 1.0, -1.0, 0.0, 0.0],
                     [0.0, 0.6, 1.0, 2.0, -0.6, 0.0],
                     [0.0, 0.0, 1.0, 0.0, 0.0, 1.0]])
    vis = in_view(cams, pts, MODEL)
    assert vis[0, :400].all() and not vis[0, 400:].any() and not vis[1, :400].any() and not vis[3].any()
    assert select_pairs(cams[:2], pts, MODEL, min_partners=3) == []
    assert select_pairs(cams, pts, MODEL, min_partners=3) == [(0, 2)]


def test_pairs_are_sorted_unique_and_no_camera_is_orphaned() -> None:
    """Random cameras around a row of three plants: i < j, sorted, no duplicates; every camera
    that shares a point with another has min(min_partners, cameras it shares with) partners; with
    min_partners = 0 every pair is inside the angle window."""
    rng = np.random.default_rng(3)
    pts = np.concatenate([blob(300, centre=[x, 0.0, 1.0], seed=s) for s, x in enumerate((-0.6, 0.0, 0.6))])
    az = rng.uniform(0, 2 * np.pi, 30)
    c = np.stack([2.0 * np.cos(az), 2.0 * np.sin(az), rng.uniform(0.5, 2.5, 30)], axis=1)
    cams = look_at(c, rng.uniform([-0.8, -0.2, 0.8], [0.8, 0.2, 1.2], (30, 3)))
    pairs = select_pairs(cams, pts, MODEL, min_partners=3)
    assert pairs == sorted(set(pairs)) and all(i < j for i, j in pairs)
    assert all(isinstance(i, int) and isinstance(j, int) for i, j in pairs)
    shared, angle = pair_geometry(cams, pts, in_view(cams, pts, MODEL))
    np.fill_diagonal(shared, 0)
    assert np.all(partners(pairs, 30) >= np.minimum(3, (shared > 0).sum(axis=1)))
    assert len(pairs) < 30 * 29 // 2
    strict = select_pairs(cams, pts, MODEL, min_partners=0)
    assert set(strict) <= set(pairs)
    assert all(angle[i, j] <= math.radians(45.0) and shared[i, j] >= 10 for i, j in strict)


def test_a_hundred_cameras_in_bounded_time_and_memory() -> None:
    """N = 100 cameras and 100k scene points: the points are subsampled, so memory stays O(N S)."""
    pts = blob(100_000, spread=0.3)
    cams = ring_at(3.6 * np.arange(100), radius=3.0)
    tracemalloc.start()
    t0 = time.perf_counter()
    try:
        pairs = select_pairs(cams, pts, MODEL)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 40e6, f"peak {peak / 1e6:.1f} MB"
    assert time.perf_counter() - t0 < 30.0
    assert np.all(partners(pairs, 100) >= 2) and len(pairs) < 100 * 99 // 2 / 3


def test_bad_input() -> None:
    with pytest.raises(ValueError, match="points"):
        select_pairs(ring_at([0, 20]), np.zeros((5, 2)), MODEL)
    with pytest.raises(ValueError, match="NaN"):
        select_pairs(ring_at([0, 20]), np.full((5, 3), np.nan), MODEL)
    with pytest.raises(ValueError, match="min_angle"):
        select_pairs(ring_at([0, 20]), blob(), MODEL, min_angle=1.0, max_angle=0.5)
    with pytest.raises(ValueError, match="shape"):
        select_pairs(np.zeros((2, 5)), blob(), MODEL)


def test_check_pairs() -> None:
    assert check_pairs([(2, 1), (1, 2), (0, 3), (np.int64(0), np.int64(1))], 4) == [(0, 1), (0, 3), (1, 2)]
    for bad in ([(1, 1)], [(0, 4)], [(-1, 0)], [(0.0, 1.5)], [("a", "b")], [(0, 1, 2)]):
        with pytest.raises(ValueError):
            check_pairs(bad, 4)


@pytest.fixture(scope="module")
def renders(noisy_scene):
    """4 real renders (640 x 480) of the plant from a ring 30 degrees apart."""
    from vp_scene.meshing import scene_meshes
    from vp_scene.render import Renderer

    a = np.deg2rad(30.0 * np.arange(4))
    c = np.stack([1.4 * np.cos(a), 1.4 * np.sin(a), np.full(4, 1.2)], axis=1)
    cams = look_at(c, np.broadcast_to([0.0, 0.0, 0.9], c.shape))
    r = Renderer(640, 480)
    images, _, _ = r.render(scene_meshes(noisy_scene, 0), cams)
    return images, cams, r.K


def test_sparse_matches_only_the_given_pairs(renders, tmp_path) -> None:
    from vp_recon.config import SparseOptions
    from vp_recon.sparse import sparse_reconstruct

    images, cams, K = renders
    given = [(2, 1), (0, 1), (2, 3)]                        # any order; (2, 1) is pair (1, 2)
    sp = sparse_reconstruct(images, cams, K, tmp_path / "pairs", SparseOptions(num_threads=1), pairs=given)
    assert sp.matched_pairs == 3 and len(sp.points) > 10
    assert sp.pair_inliers and set(sp.pair_inliers) <= {(0, 1), (1, 2), (2, 3)}
    assert (tmp_path / "pairs" / "pairs.txt").read_text().splitlines() == [
        "view_000.png view_001.png", "view_001.png view_002.png", "view_002.png view_003.png"]
    assert set(sp.seconds) == {"extract", "match", "triangulate"}
    full = sparse_reconstruct(images, cams, K, tmp_path / "all", SparseOptions(num_threads=1))
    assert full.matched_pairs == 6


def test_sparse_rejects_bad_pairs(renders, tmp_path) -> None:
    from vp_recon.errors import SparseError
    from vp_recon.sparse import sparse_reconstruct

    images, cams, K = renders
    with pytest.raises(SparseError, match="no image pair"):
        sparse_reconstruct(images, cams, K, tmp_path, pairs=[])
    with pytest.raises(ValueError, match="0..3"):
        sparse_reconstruct(images, cams, K, tmp_path, pairs=[(0, 4)])


def test_scaled_views_keep_the_projection() -> None:
    """A world point lands on u' = s (u + 1/2) - 1/2 of the half-size view (pixel centres at
    integers), and a mask keeps the pixels that were mostly foreground."""
    from vp_recon.dense import scaled_views
    from vp_scene.camera import intrinsics

    K = intrinsics(640, 480, math.pi / 2)
    img = np.zeros((480, 640, 3), np.uint8)
    mask = np.zeros((480, 640), bool)
    mask[100:200, 300:302] = True            # 2 px wide: one column at half size
    mask[300:302, 10:11] = True              # a quarter of one half-size pixel: dropped
    (im2,), (m2,), K2 = scaled_views([img], [mask], K, 0.5)
    assert im2.shape == (240, 320, 3) and m2.shape == (240, 320)
    assert m2[50:100, 150].all() and m2.sum() == 50
    X = np.array([0.3, -0.2, 2.0])           # camera frame, z forward
    u = K @ X / X[2]
    u2 = K2 @ X / X[2]
    np.testing.assert_allclose(u2[:2], 0.5 * (u[:2] + 0.5) - 0.5)
    np.testing.assert_allclose(K2, intrinsics(320, 240, math.pi / 2))   # the half-size camera itself
