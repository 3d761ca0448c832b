"""vp_recon.segment: a flight's plant mask from its image alone, against the renderer's oracle."""
from __future__ import annotations

import numpy as np
import pytest


@pytest.mark.parametrize("corn50", [False, True])
def test_plant_mask_from_the_image_alone_matches_the_segmentation_pass(corn50) -> None:
    """A flight's mask (excess green on the noisy image over soil) against the segmentation pass
    (the oracle that knows the scene): IoU at least 0.8 on average and 0.7 in every view."""
    from pathlib import Path

    from vp_recon.segment import image_mask
    from vp_scene.build import build_noisy_scene
    from vp_scene.capture import REALISTIC
    from vp_scene.meshing import scene_meshes
    from vp_scene.render import Renderer

    corn = Path(__file__).resolve().parents[3].parent / "shared" / "data" / "corn50"
    if corn50 and not corn.is_dir():
        pytest.skip(f"Corn50 is not at {corn}")
    ns, _ = build_noisy_scene("one_plant", models=str(corn) if corn50 else None, seed=0, points_per_plant=3000,
                              realizations=1)
    a = np.deg2rad(45.0 * np.arange(8))
    c = np.stack([1.4 * np.cos(a), 1.4 * np.sin(a), np.full(8, 1.2)], axis=1)
    cams = np.concatenate([np.concatenate([c, [0.0, 0.0, 0.9] - c], axis=1), [[0.3, 0.2, 2.8, -0.3, -0.2, -1.9]]])
    images, oracle, _ = Renderer(640, 480).render(scene_meshes(ns, 0, None), cams, ground=True)
    iou = []
    for i, (img, m) in enumerate(zip(images, oracle)):
        p = image_mask(REALISTIC.expose(img, 0, i), ground=True)
        assert m.sum() > 1000, f"view {i} sees too little plant to judge a mask"
        iou.append((p & m).sum() / max((p | m).sum(), 1))
    assert np.mean(iou) > 0.8 and min(iou) > 0.7, iou
