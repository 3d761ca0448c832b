"""The dense step's pair budget (vp_recon.dense._pair_points' max_cost): a pair over the budget is
matched on scaled rectified views and still lands on the surface. A textured ground plane seen
by two cameras, the images made by the plane's homographies (no renderer: the test is the
rectification and disparity algebra)."""
from __future__ import annotations

import cv2
import numpy as np

from vp_recon import dense
from vp_scene.camera import look_at, world_to_camera

W, H, F = 320, 240, 260.0
K = np.array([[F, 0.0, (W - 1) / 2], [0.0, F, (H - 1) / 2], [0.0, 0.0, 1.0]])
TEX_PX_PER_M = 256.0


def plane_views(cams: np.ndarray) -> tuple[list, list]:
    """RGB views of the textured plane z = 0 (x, y in [-1, 1] m) and their masks."""
    rng = np.random.default_rng(5)
    tex = cv2.GaussianBlur((rng.random((512, 512)) * 255).astype(np.uint8), (0, 0), 1.5)
    tex = cv2.cvtColor(tex, cv2.COLOR_GRAY2RGB)
    A = np.array([[1 / TEX_PX_PER_M, 0.0, -1.0], [0.0, 1 / TEX_PX_PER_M, -1.0], [0.0, 0.0, 1.0]])  # texel -> (x, y, 1)
    R, t = world_to_camera(cams)
    images, masks = [], []
    for Ri, ti in zip(R, t):
        Hm = K @ np.column_stack([Ri[:, 0], Ri[:, 1], ti]) @ A
        images.append(cv2.warpPerspective(tex, Hm, (W, H), borderValue=(0, 0, 255)))
        masks.append(cv2.warpPerspective(np.ones((512, 512), np.uint8), Hm, (W, H)) > 0)
    return images, masks


def test_a_pair_over_the_budget_is_matched_smaller_and_lands_on_the_surface(monkeypatch) -> None:
    cams = look_at(np.array([[-0.25, -1.6, 1.4], [0.25, -1.6, 1.4]]), np.zeros((2, 3)))
    images, masks = plane_views(cams)
    R, t = world_to_camera(cams)
    g = np.stack(np.meshgrid(np.linspace(-0.6, 0.6, 7), np.linspace(-0.6, 0.6, 7), [0.0], indexing="ij"),
                 axis=-1).reshape(-1, 3)
    sizes = []
    create = cv2.StereoSGBM.create

    def spy(**kw):  # the widths SGM is given
        matcher = create(**kw)

        class Spy:
            def compute(self, left, right):
                sizes.append(left.shape)
                return matcher.compute(left, right)
        return Spy()

    monkeypatch.setattr(cv2.StereoSGBM, "create", spy)

    def pair(max_cost):
        for a, b in ((0, 1), (1, 0)):  # the order with positive disparities
            p, _ = dense._pair_points(images[a], images[b], masks[a], masks[b], R[a], t[a], R[b], t[b], K, g, 5,
                                      W, max_cost)
            if len(p):
                return p
        return p

    full = pair(None)
    assert len(sizes) == 1 and len(full) > 5000
    rows, cols = sizes[0]
    small = pair(10 ** 6)  # about a tenth of this pair's work: matched on views scaled by about 1/2
    assert len(sizes) == 2 and sizes[1][0] < 0.6 * rows, sizes  # matched on smaller views
    assert 0 < len(small) < 0.5 * len(full)
    for p in (full, small):  # on the plane, within the depth step
        assert np.median(np.abs(p[:, 2])) < 0.01 and np.percentile(np.abs(p[:, 2]), 90) < 0.04
    # over the budget or not, the same part of the plane
    assert np.all(np.abs(np.median(small[:, :2], axis=0) - np.median(full[:, :2], axis=0)) < 0.05)
    assert dense._sgm_cost(10, 20, 16) == 10 * 36 * 16
