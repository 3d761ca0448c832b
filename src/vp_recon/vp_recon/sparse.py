"""Sparse reconstruction with COLMAP (pycolmap, CPU) of a capture set's views.

Pipeline (Schönberger & Frahm, "Structure-from-Motion Revisited", CVPR 2016):

1. the images (and masks, when features are restricted to the plant) written to a COLMAP
   workspace (:mod:`vp_recon.colmap_io`),
2. SIFT features (Lowe 2004) on the CPU into its database; one PINHOLE camera with the known
   calibration,
3. matching with geometric verification: all N (N - 1) / 2 pairs (``pairs=None``), or only the
   listed ones (:func:`vp_recon.pairs.select_pairs` chooses them from the known poses),
4. the model of ``options.mode`` (:mod:`vp_recon.sparse_modes`): triangulated at the given
   poses (``known_poses``), anchored on them (``anchored``), or COLMAP's incremental structure
   from motion registered to the world on them (``incremental``; the anchored model when it
   fails, ``options.fallback``); the registration on the poses: :mod:`vp_recon.registration`.

The 3D points come back in the world frame.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Optional, Sequence

import numpy as np
from numpy.typing import NDArray

from vp_scene.camera import check_poses, world_to_camera

from .config import SparseOptions
from .errors import SparseError
from .pairs import check_pairs
from .results import SparseResult

__all__ = ["sparse_reconstruct", "MAX_RESIDUAL_SIGMAS"]

#: Self-check (:mod:`vp_recon.sparse_modes`): a model whose registered centres lie further than
#: this many ``prior_sigma`` (RMS) from the poses it was aligned on is inconsistent.
MAX_RESIDUAL_SIGMAS: float = 10.0


def sparse_reconstruct(images: Sequence[NDArray[np.uint8]], cameras: NDArray[np.float64], K: NDArray[np.float64],
                       workdir: Path, options: SparseOptions = SparseOptions(),
                       masks: Optional[Sequence[NDArray[np.bool_]]] = None,
                       pairs: Optional[Sequence[tuple[int, int]]] = None,
                       prior_centres: Optional[NDArray[np.float64]] = None) -> SparseResult:
    """SIFT + matching (all pairs, or the given ones) + the model of ``options.mode`` of the
    ``images`` (N RGB uint8).

    Args:
        images: N views, all of the same size.
        cameras: (N, 7) the poses of the cameras that took them (the reported ones; any attitude)
            or (N, 6) levelled cameras [c, v] (:mod:`vp_scene.camera`).
        K: 3x3 calibration in the OpenCV pixel convention (:func:`vp_scene.camera.intrinsics`).
        workdir: the COLMAP workspace (:mod:`vp_recon.colmap_io`); created when missing.
        options: the mode, SIFT, threads, how well the poses are known, the fallback.
        masks: foreground masks; features are then extracted on (dilated) plant pixels only.
        pairs: image index pairs (i, j) to match (order and duplicates do not matter); None:
            exhaustive matching.
        prior_centres: incremental mode: (N, 3) camera centres known to ``options.prior_sigma`` m
            per axis (a drone's reported positions), written as COLMAP pose priors and used by its
            bundle adjustment, and the centres the models are registered on; None: the centres of
            ``cameras``. ``prior_sigma`` also scales the self-check (:data:`MAX_RESIDUAL_SIGMAS`).

    Raises:
        ValueError: bad image count, image sizes or pairs.
        SparseError: no features, no pair to match, no verified pair, or no triangulated point.
    """
    from .colmap_io import log_level

    with log_level(2 if options.quiet else None):
        return _sparse(images, cameras, K, Path(workdir), options, masks, pairs, prior_centres)


def _sparse(images: Sequence[NDArray[np.uint8]], cameras: NDArray[np.float64], K: NDArray[np.float64],
            workdir: Path, options: SparseOptions, masks: Optional[Sequence[NDArray[np.bool_]]],
            pairs: Optional[Sequence[tuple[int, int]]], prior_centres: Optional[NDArray[np.float64]]) -> SparseResult:
    from .colmap_io import extract_and_match
    from .registration import PoseAnchor
    from .sparse_modes import build_model

    cams = check_poses(cameras)
    if len(images) != len(cams):
        raise ValueError(f"{len(images)} images for {len(cams)} cameras")
    if len(images) < 2:
        raise SparseError("sparse reconstruction needs at least 2 images")
    shapes = {np.asarray(i).shape for i in images}
    if len(shapes) != 1:
        raise ValueError(f"images differ in size: {sorted(shapes)}")
    todo = None if pairs is None else check_pairs(pairs, len(images))
    if todo is not None and not todo:
        raise SparseError("no image pair to match (the pair list is empty)")
    incremental = options.mode == "incremental"
    matched, seconds = extract_and_match(workdir, images, masks, K, todo, options,
                                         prior_centres if incremental else None)
    if sum(matched.keypoints) == 0:
        raise SparseError("no SIFT features in any image (is the plant visible?)")
    if matched.verified == 0:
        raise SparseError(f"no image pair could be matched ({matched.matched} pairs tried, keypoints per image: "
                          f"{matched.keypoints}); views too far apart or seeing different sides of the plant")

    t0 = time.perf_counter()
    matched.model_dir.mkdir(exist_ok=True)
    centres = cams[:, :3] if prior_centres is None else np.asarray(prior_centres, dtype=np.float64).reshape(-1, 3)
    floor = max(float(options.prior_sigma), 1e-3)  # an exact report is still a measurement
    sigmas = None if options.attitude_sigma is None else (floor, np.radians(max(float(options.attitude_sigma), 0.01)))
    anchor = PoseAnchor(centres, world_to_camera(cams)[0], sigmas)
    model, mode, why = build_model(matched, options.mode, cams, anchor, MAX_RESIDUAL_SIGMAS * floor,
                                   options.num_threads, prior_centres is not None, options.fallback)
    if len(model.points) == 0:
        raise SparseError(f"no 3D point triangulated ({matched.verified} verified image pairs, keypoints "
                          f"{matched.keypoints})")
    seconds["triangulate"] = time.perf_counter() - t0
    return SparseResult(**vars(model), keypoints=[int(k) for k in matched.keypoints],
                        verified_pairs=matched.verified, pair_inliers=matched.pair_inliers,
                        matched_pairs=matched.matched, seconds=seconds, mode=mode, fallback=why)
