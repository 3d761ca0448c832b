"""The sparse step's models of a matched workspace (:class:`vp_recon.colmap_io.Matched`), one per mode.

* ``known_poses``: the images at the given poses, ``triangulate_points``.
* ``anchored`` (:func:`anchored_model`): points triangulated at the given (reported) poses with
  loose thresholds (a reported attitude half a degree off is 9 pixels at f = 1000), a robust
  bundle adjustment of poses and points, the model registered back on the given poses,
  triangulated again with COLMAP's thresholds and adjusted once more. It cannot wander metres
  away (it starts at the reports and is registered on them) and needs only matches, not a chain
  of registrations.
* ``incremental`` (:func:`incremental_model`): ``incremental_mapping`` (unknown poses; with
  pose priors the reported centres enter its bundle adjustment, COLMAP's
  ``use_prior_position``); every model of 3 or more images is registered on the given poses
  (:mod:`vp_recon.registration`). Parts of a plan that share no matches become separate
  models, each placed on its own poses (:func:`merge_models`).

*Self-check* (incremental): after the registration each model's centres must lie near the poses
they were registered on; a model whose RMS centre residual exceeds ``max_residual`` is
inconsistent (false matches among alike plants can make a model that registers every image and
is a metre off). The largest such model fails the structure from motion, a smaller one is left
out. The RMS over the kept models is reported (``centre_residual``, a metric without a ground
truth).

*Choose, don't fail* (:func:`build_model`, ``fallback='anchored'``): when the structure from
motion fails (no model, fewer than 3 images registered, a model its poses cannot place, or the
self-check), the anchored model of the same matches is made instead and the SfM's reason is kept;
only when that fails too is the sparse step a failure (SparseError with both reasons). The
anchored model itself does not fail when its adjustment drifts (a weak model of a few dozen
points, some false, lets the cameras slide further than the self-check's bound from the reports):
the points triangulated at the reported poses are kept instead, nothing adjusted
(:func:`reported_pose_model`), and the drift is the fallback's reason.
"""
from __future__ import annotations

from typing import Optional

import numpy as np
import pycolmap
from numpy.typing import NDArray

from vp_scene.camera import as_poses, body_from_optical

from .colmap_io import Matched, model_at_poses, read_points
from .errors import SparseError
from .registration import PoseAnchor, align_model, register_parts
from .results import SparseModel

__all__ = ["ANCHOR_REPROJECTION_PX", "ANCHOR_ANGLE_DEG", "ANCHOR_ROUNDS", "build_model",
           "known_poses_model", "incremental_model", "anchored_model", "reported_pose_model", "merge_models"]

#: The anchored model's first triangulation: reprojection error (pixels) and ray angle error
#: (degrees) a track may have at the reported poses (COLMAP's defaults: 4 and 2).
ANCHOR_REPROJECTION_PX: float = 25.0
ANCHOR_ANGLE_DEG: float = 8.0
#: Rounds of adjust-register-retriangulate of the anchored model (a further round adds no point).
ANCHOR_ROUNDS: int = 2


class _AdjustmentDrifted(SparseError):
    """The anchored model's adjustment took the cameras away from the reported poses (a weak model:
    a few dozen points, some of them false tracks, let the poses slide); :func:`build_model`
    then keeps :func:`reported_pose_model`."""


def build_model(matched: Matched, mode: str, cams: NDArray[np.float64], anchor: PoseAnchor,
                max_residual: float, num_threads: int, use_priors: bool = False,
                fallback: Optional[str] = "anchored") -> tuple[SparseModel, str, str]:
    """The model of ``mode`` (module docstring), the anchored one in place of a structure from
    motion that failed when ``fallback`` says so: (model, the mode kept, why the SfM was not
    kept or ''). ``cams`` (N, 7): the poses given; ``anchor``: what the models are registered on;
    ``use_priors``: the database holds pose priors (incremental). SparseError."""
    options = pycolmap.IncrementalPipelineOptions()
    options.num_threads = num_threads
    # Few views: keep points seen by only two images (COLMAP drops them by default).
    options.triangulation.ignore_two_view_tracks = False
    if mode == "known_poses":
        return known_poses_model(matched, cams, options), mode, ""
    why = ""
    if mode == "incremental":
        try:
            return incremental_model(matched, options, anchor, use_priors, max_residual), mode, ""
        except SparseError as exc:
            if fallback is None:
                raise
            why = str(exc)
    # anchored, asked for or in place of a structure from motion that failed (then triangulated
    # with the mapper's settings, which incremental_model set on ``options``)
    try:
        try:
            model = anchored_model(matched, options, cams, anchor, max_residual)
        except _AdjustmentDrifted as drift:  # choose, don't fail: the points at the reported poses
            model = reported_pose_model(matched, options, cams)
            why = (f"{why}; " if why else "") + f"{drift}: kept the points triangulated at the reported poses"
    except SparseError as exc:
        raise SparseError(f"{why}; the model anchored on the reported poses failed too: {exc}"
                          if why else str(exc)) from None
    return model, "anchored", why


def known_poses_model(matched: Matched, cams: NDArray[np.float64], options: object) -> SparseModel:
    """Tracks triangulated at the given poses; an image counts as registered when it observes a point."""
    rec = model_at_poses(matched, cams)
    rec = pycolmap.triangulate_points(rec, matched.database, matched.image_dir, matched.model_dir,
                                      clear_points=True, options=options)
    xyz, rgb, track = read_points(rec)
    seen = sum(1 for im in rec.images.values() if im.has_pose and im.num_points3D > 0)
    return SparseModel(xyz, rgb, track, as_poses(cams), int(seen), float(rec.compute_mean_reprojection_error()), 1,
                 float("nan"))


def incremental_model(matched: Matched, options: object, anchor: PoseAnchor, use_priors: bool,
                      max_residual: float) -> SparseModel:
    """COLMAP's incremental structure from motion of the matched images (its settings set on
    ``options``: intrinsics fixed, thresholds for a small textured plant), every model registered
    on the given poses (:func:`merge_models`); SparseError when it makes nothing usable."""
    options.ba_refine_focal_length = False
    options.ba_refine_extra_params = False
    options.mapper.abs_pose_refine_focal_length = False
    # small textured plant, few hundred keypoints a view: relax COLMAP's defaults (100 / 30 / 10)
    options.mapper.init_min_num_inliers = 30
    options.mapper.abs_pose_min_num_inliers = 15
    options.min_model_size = 3
    if use_priors:
        options.use_prior_position = True
        options.use_robust_loss_on_prior_position = True
    models = pycolmap.incremental_mapping(matched.database, matched.image_dir, matched.model_dir, options=options)
    n = len(matched.names)
    if not models:
        raise SparseError(f"incremental mapping registered no image pair: 0 of {n} images "
                          f"registered ({matched.verified} verified pairs)")
    return merge_models(list(models.values()), matched.names, anchor, max_residual)


def anchored_model(matched: Matched, options: object, cams: NDArray[np.float64], anchor: PoseAnchor,
                   max_residual: float) -> SparseModel:
    """The reconstruction anchored on the given poses (module docstring).

    1. the images at the given poses, tracks triangulated from the verified matches with loose
       thresholds (:data:`ANCHOR_REPROJECTION_PX`, :data:`ANCHOR_ANGLE_DEG`);
    2. :data:`ANCHOR_ROUNDS` times: a bundle adjustment of poses and points (Cauchy loss,
       intrinsics fixed), the model registered back on the given poses
       (:func:`vp_recon.registration.register_parts`), tracks triangulated again from scratch
       with COLMAP's thresholds;
    3. a last adjustment and registration.

    Why not COLMAP's pose-prior bundle adjuster: its priors are positions only, and on a small
    arc it turned every camera by degrees: the attitudes the drones report are what pins a small
    plan's rotation. The plain adjustment keeps the gauge where the reports put it and the
    registration (centres and attitudes) restores it. An image that observes no point is not
    registered (NaN row). _AdjustmentDrifted when the adjusted centres lie further than
    ``max_residual`` (RMS) from the reported ones."""
    names = matched.names
    loose = _loose(options)
    ba = pycolmap.BundleAdjustmentOptions()
    ba.refine_focal_length = ba.refine_principal_point = ba.refine_extra_params = False
    ba.ceres.loss_function_type = pycolmap.LossFunctionType.CAUCHY
    ba.print_summary = False
    rec = model_at_poses(matched, cams)
    rec = pycolmap.triangulate_points(rec, matched.database, matched.image_dir, matched.model_dir,
                                      clear_points=True, options=loose)
    for _ in range(ANCHOR_ROUNDS):
        if len(rec.points3D) == 0:
            break
        _adjust(rec, ba)
        register_parts(rec, names, anchor)
        rec = pycolmap.triangulate_points(rec, matched.database, matched.image_dir, matched.model_dir,
                                          clear_points=True, options=options)
    if len(rec.points3D) == 0:
        raise SparseError(f"no track triangulates at the reported poses: 0 of {len(names)} images registered (the "
                          "matched images see no common point from far enough apart)")
    _adjust(rec, ba)
    register_parts(rec, names, anchor)
    xyz, rgb, track = read_points(rec)
    est = np.full((len(names), 7), np.nan)
    idx = {n: i for i, n in enumerate(names)}
    for im in rec.images.values():
        if im.has_pose and im.num_points3D > 0:
            R_cw = np.asarray(im.cam_from_world().rotation.matrix())
            est[idx[im.name]] = np.concatenate([np.asarray(im.projection_center()), body_from_optical(R_cw)])
    kept = np.isfinite(est[:, 0])
    residual = float(np.sqrt(np.mean(np.sum((est[kept, :3] - anchor.centres[kept]) ** 2, axis=1))))
    if not residual <= max_residual:
        raise _AdjustmentDrifted(f"the adjusted model's camera centres lay {residual:.2f} m (RMS) from the reported "
                                 f"ones (more than {max_residual:.2f} m; {len(xyz)} points)")
    return SparseModel(xyz, rgb, track, est, int(kept.sum()), float(rec.compute_mean_reprojection_error()), 1, residual)


def reported_pose_model(matched: Matched, options: object, cams: NDArray[np.float64]) -> SparseModel:
    """The anchored model's last resort (module docstring): the tracks triangulated at the
    reported poses with the loose thresholds of its first step, nothing adjusted; consistent with
    the reports by construction (centre residual 0), as accurate as they are: a poor model of
    cameras that share few points, but where the reports put it, and said so in the fallback's
    reason. SparseError when no track triangulates."""
    names = matched.names
    rec = model_at_poses(matched, cams)
    rec = pycolmap.triangulate_points(rec, matched.database, matched.image_dir, matched.model_dir,
                                      clear_points=True, options=_loose(options))
    if len(rec.points3D) == 0:
        raise SparseError(f"no track triangulates at the reported poses: 0 of {len(names)} images registered (the "
                          "matched images see no common point from far enough apart)")
    xyz, rgb, track = read_points(rec)
    est = np.full((len(names), 7), np.nan)
    poses = as_poses(cams)
    idx = {n: i for i, n in enumerate(names)}
    for im in rec.images.values():
        if im.num_points3D > 0:
            est[idx[im.name]] = poses[idx[im.name]]
    return SparseModel(xyz, rgb, track, est, int(np.isfinite(est[:, 0]).sum()),
                 float(rec.compute_mean_reprojection_error()), 1, 0.0)


def merge_models(models: list, names: list, anchor: PoseAnchor, max_residual: float = float("inf")) -> SparseModel:
    """Every model COLMAP's incremental mapper made, each registered to the world on its own
    images' given poses (:func:`vp_recon.registration.align_model`), as one cloud.

    The mapper starts a new model when the images left share no verified matches with the current
    one: a plan whose parts see different plants (a field planned by parts) gives one model per
    part. Each model has its own gauge (frame and scale), but a flight knows every image's pose to a
    few cm, so each is placed in the world on its own, as COLMAP's model_aligner would. Largest
    first; an image in two models counts in the larger. Models of fewer than 3 registered images
    are left out (the scale of 2 centres 2 cm apart each is too loose); none of 3: SparseError.
    A smaller model that cannot be placed (its centres' spread in the model disagrees with the
    reported one: a negative scale, say) is left out too; the largest one must be placed
    (SparseError), as when it was the only one kept. Self-check: a model whose aligned centres
    lie further than ``max_residual`` m (RMS) from their ``anchor`` ones is inconsistent, left
    out, or SparseError when it is the largest.
    """
    models = sorted(models, key=lambda r: -r.num_reg_images())
    usable = [r for r in models if r.num_reg_images() >= 3]
    if not usable:
        raise SparseError(f"incremental mapping registered {models[0].num_reg_images()} of {len(names)} images "
                          f"in its largest model; aligning to the world needs 3")
    centres = anchor.centres
    est = np.full((len(names), 7), np.nan)
    xyz, rgb, tracks, errors = [], [], [], []
    for rank, rec in enumerate(usable):
        p, c, track = read_points(rec)
        try:
            p, e = align_model(rec, names, anchor, p)
            mine = np.isfinite(e[:, 0])
            rms = float(np.sqrt(np.mean(np.sum((e[mine, :3] - centres[mine]) ** 2, axis=1))))
            if not rms <= max_residual:
                raise SparseError(f"the model of {int(mine.sum())} registered images is inconsistent: its camera "
                                  f"centres lie {rms:.2f} m (RMS) from the reported ones after the alignment "
                                  f"(more than {max_residual:.2f} m; false matches between alike views?)")
        except SparseError:
            if rank == 0:
                raise
            continue
        new = np.isnan(est[:, 0]) & np.isfinite(e[:, 0])
        est[new] = e[new]
        xyz.append(p)
        rgb.append(c)
        tracks.append((track, len(p)))
        errors.append((float(rec.compute_mean_reprojection_error()), len(p)))
    n = sum(k for _, k in tracks)
    mean = (lambda pairs: float(sum(v * k for v, k in pairs) / n) if n else 0.0)
    kept = np.isfinite(est[:, 0])
    seen = int(kept.sum())
    residual = float(np.sqrt(np.mean(np.sum((est[kept, :3] - centres[kept]) ** 2, axis=1))))
    return SparseModel(np.concatenate(xyz), np.concatenate(rgb), mean(tracks), est, seen,
                 mean(errors) if n else float("nan"), len(xyz), residual)


def _adjust(rec: object, options: object) -> None:
    """Global bundle adjustment of ``rec`` as ``pycolmap.bundle_adjustment`` makes it (COLMAP's
    BundleAdjustmentController: the observations behind their camera dropped, every registered
    image refined, the gauge fixed by two cameras, the points' errors updated; the same result to
    the last bit, tested), from pycolmap's own parts. pycolmap's call prints a heading and a timer
    at INFO level every time, whatever the log level (it sets the level to 0 itself): lines on every
    flight's stderr, from every worker."""
    pycolmap.ObservationManager(rec).filter_observations_with_negative_depth()
    config = pycolmap.BundleAdjustmentConfig()
    for image_id in rec.reg_image_ids():
        config.add_image(image_id)
    config.fix_gauge(pycolmap.BundleAdjustmentGauge.TWO_CAMS_FROM_WORLD)
    pycolmap.create_default_bundle_adjuster(options, config, rec).solve()
    rec.update_point_3d_errors()


def _loose(options: object) -> object:
    """``options`` with the anchored model's loose triangulation thresholds
    (:data:`ANCHOR_REPROJECTION_PX`, :data:`ANCHOR_ANGLE_DEG`)."""
    loose = pycolmap.IncrementalPipelineOptions(options.todict())
    for name in ("merge_max_reproj_error", "complete_max_reproj_error"):
        setattr(loose.triangulation, name, ANCHOR_REPROJECTION_PX)
    loose.triangulation.create_max_angle_error = loose.triangulation.continue_max_angle_error = ANCHOR_ANGLE_DEG
    loose.mapper.filter_max_reproj_error = ANCHOR_REPROJECTION_PX
    return loose
