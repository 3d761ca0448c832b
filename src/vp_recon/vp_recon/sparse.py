"""Sparse reconstruction with COLMAP (pycolmap, CPU) from rendered views.

Pipeline (Schönberger & Frahm, "Structure-from-Motion Revisited", CVPR 2016):

1. write the images (and optional masks) to ``workdir/images`` (``workdir/masks``),
2. SIFT features (Lowe 2004) on the CPU into ``workdir/database.db``; one PINHOLE camera with the
   known calibration ``f, f, cx, cy`` (COLMAP pixel convention: centres at +0.5),
3. matching with geometric verification: all N (N - 1) / 2 pairs (``pairs=None``), or only the
   listed ones (COLMAP's imported pair list, ``workdir/pairs.txt``: ``name1 name2`` per line;
   :func:`vp_recon.pairs.select_pairs` chooses them from the known poses),
4. ``mode='known_poses'``: a reconstruction holding the true poses (cam_from_world =
   (R_cw, t) of :func:`vp_scene.camera.world_to_camera`), then ``triangulate_points``;
   ``mode='anchored'``: the reconstruction anchored on the given (reported) poses
   (:func:`_anchored_model`): points triangulated from them with loose thresholds (a reported
   attitude is half a degree off: 9 pixels at f = 1000), a robust bundle adjustment of poses and
   points, the model registered back on the given poses, triangulated again with COLMAP's
   thresholds and adjusted once more. It cannot wander metres away (it starts at the reports and
   is registered on them) and needs only matches, not a chain of registrations;
   ``mode='incremental'``: ``incremental_mapping`` (unknown poses; with ``prior_centres`` the
   reported camera centres are pose priors of the bundle adjustment, COLMAP's
   ``use_prior_position``), every model of 3 or more images registered to the world on the given
   poses (the reported ones of a flight; never the true ones there) by
   :func:`similarity_from_poses`: the rotation from the images' attitudes and centres, each
   weighted by how well it is known (``prior_sigma``, ``attitude_sigma``: a rig whose attitudes
   are known only roughly is registered on its centres), scale and translation from the centres. Parts of a plan that share no matches become separate models, each placed
   on its own poses (:func:`_merge_models`); before, only the largest was kept, and a field
   planned by parts lost every part but one. The centres alone (Umeyama 1991) left a 4-camera Corn50 arc 27 cm x100
   Chamfer off in map (shape 9.1); with the attitudes 3.9 (shape 1.3).
5. *Self-check* (incremental): after the alignment each model's registered centres must lie near
   the poses they were aligned on; a model whose RMS centre residual exceeds
   ``MAX_RESIDUAL_SIGMAS`` (10) x ``prior_sigma`` is inconsistent (false matches among alike
   plants can make a model that registers every image and is 1 m off: on six_rect with all
   pairs matched, centres 0.8-2.2 m from the reported ones and two optical axes 133-161 degrees
   off, against 0.02-0.05 m and under 1 degree for the pose-chosen pairs' models). The largest
   such model fails the structure from motion, a smaller one is left out. The RMS over the
   kept models is reported (``centre_residual``, a metric without a ground truth).
6. *Choose, don't fail* (``fallback='anchored'``, the default of ``incremental``): when the
   structure from motion fails (no model, fewer than 3 images registered, a model its poses
   cannot place, or the self-check), the anchored model of the same matches is made instead
   and the SfM's reason is kept (``SparseResult.fallback``); only when that fails too is the
   sparse step a failure (SparseError with both reasons). The anchored model itself does not
   fail when its adjustment drifts (a weak model of a few dozen points, some false, lets the
   cameras slide more than the self-check's bound from the reports): the points triangulated at
   the reported poses are kept instead, nothing adjusted (:func:`_reported_pose_model`), and
   the drift is the ``fallback`` reason.

The 3D points come back in the world frame.
"""
from __future__ import annotations

import math
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple, Optional, Sequence

import cv2
import numpy as np
from numpy.typing import NDArray

from vp_scene.camera import as_poses, body_from_optical, check_poses, principal_point_gl, world_to_camera

from .pairs import check_pairs

__all__ = ["SparseError", "SparseResult", "sparse_reconstruct", "MODES", "MAX_RESIDUAL_SIGMAS"]

MODES = ("known_poses", "incremental", "anchored")
#: Self-check (module docstring, 5): a model whose registered centres lie further than this many
#: ``prior_sigma`` (RMS) from the poses it was aligned on is inconsistent.
MAX_RESIDUAL_SIGMAS: float = 10.0
#: The anchored model's first triangulation (module docstring): reprojection error (pixels) and
#: ray angle error (degrees) a track may have at the reported poses (COLMAP's defaults: 4 and 2).
ANCHOR_REPROJECTION_PX: float = 25.0
ANCHOR_ANGLE_DEG: float = 8.0
#: Rounds of adjust-register-retriangulate of the anchored model (measured: a second round adds
#: no point, 2026-11-27, one_plant arc k=0: 3147 -> 3497 -> 3494 points).
ANCHOR_ROUNDS: int = 2


class SparseError(RuntimeError):
    """Nothing could be reconstructed (no features, no matches or no triangulated point)."""


@dataclass
class SparseResult:
    """Output of :func:`sparse_reconstruct`.

    Attributes:
        points: (M, 3) float64 world points.
        colors: (M, 3) uint8 RGB.
        registered: number of images with a pose in the reconstruction (that observe >= 1 point
            in ``known_poses`` mode).
        keypoints: SIFT keypoints per image.
        verified_pairs: image pairs with geometrically verified matches.
        mean_track_length: mean number of images observing a point.
        mean_reprojection_error: mean reprojection error of the model's points, pixels
            (COLMAP's ``compute_mean_reprojection_error``; a metric without a ground truth).
        pair_inliers: verified inlier matches per image pair (i, j), i < j (indices of ``images``).
        matched_pairs: image pairs handed to the matcher (N (N - 1) / 2 when exhaustive).
        seconds: wall time of ``extract``, ``match`` and ``triangulate`` (the model, either mode).
        cameras: (N, 7) the poses (x, y, z, qx, qy, qz, qw, :mod:`vp_scene.camera`) of the model's
            cameras in the world frame, roll kept: the given ones in ``known_poses`` mode; else
            the registered images' estimated poses after the alignment, NaN rows for images not
            registered.
        models: the models merged (``incremental``: every model of >= 3 registered images, each
            aligned to the world on its own, :func:`_merge_models`; 1 otherwise).
        centre_residual: ``incremental`` and ``anchored``: RMS distance, m, of the registered images'
            centres after the alignment from the given (reported) ones (the self-check's figure); NaN
            for ``known_poses``.
        mode: the model that was kept: ``'known_poses'``, ``'incremental'`` or ``'anchored'`` (also
            when the incremental mode fell back to it).
        fallback: why the structure from motion was not kept (its SparseError's message); '' when
            it was, or was not tried.
    """

    points: NDArray[np.float64]
    colors: NDArray[np.uint8]
    registered: int
    keypoints: list[int]
    verified_pairs: int
    mean_track_length: float
    pair_inliers: dict = field(default_factory=dict)
    matched_pairs: int = 0
    seconds: dict = field(default_factory=dict)
    cameras: Optional[NDArray[np.float64]] = None
    mean_reprojection_error: float = float("nan")
    models: int = 1
    centre_residual: float = float("nan")
    mode: str = "known_poses"
    fallback: str = ""


def _write_pairs(pairs: Sequence[tuple[int, int]], names: Sequence[str], path: Path) -> None:
    """COLMAP's image pair list: one ``name1 name2`` line per pair."""
    path.write_text("".join(f"{names[i]} {names[j]}\n" for i, j in pairs))


def _write_images(images: Sequence[NDArray[np.uint8]], masks: Optional[Sequence[NDArray[np.bool_]]],
                  workdir: Path) -> tuple[Path, Optional[Path], list[str]]:
    img_dir = workdir / "images"
    if img_dir.exists():
        shutil.rmtree(img_dir)
    img_dir.mkdir(parents=True)
    mask_dir = None
    if masks is not None:
        mask_dir = workdir / "masks"
        if mask_dir.exists():
            shutil.rmtree(mask_dir)
        mask_dir.mkdir(parents=True)
    names = []
    for i, img in enumerate(images):
        name = f"view_{i:03d}.png"
        if not cv2.imwrite(str(img_dir / name), cv2.cvtColor(np.asarray(img, np.uint8), cv2.COLOR_RGB2BGR)):
            raise OSError(f"cannot write {img_dir / name}")
        if mask_dir is not None:
            # COLMAP masks: <mask_path>/<image name>.png, features only where the mask is non-zero.
            # Dilate so that keypoints on the silhouette keep their support.
            m = cv2.dilate(np.asarray(masks[i], np.uint8) * 255, np.ones((9, 9), np.uint8))
            cv2.imwrite(str(mask_dir / f"{name}.png"), m)
        names.append(name)
    return img_dir, mask_dir, names


def _read_points(rec: object) -> tuple[NDArray[np.float64], NDArray[np.uint8], float]:
    pts = rec.points3D
    if len(pts) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.uint8), 0.0
    xyz = np.array([p.xyz for p in pts.values()], dtype=np.float64).reshape(-1, 3)
    rgb = np.array([p.color for p in pts.values()], dtype=np.uint8).reshape(-1, 3)
    track = float(np.mean([p.track.length() for p in pts.values()]))
    return xyz, rgb, track


def sparse_reconstruct(images: Sequence[NDArray[np.uint8]], cameras: NDArray[np.float64], K: NDArray[np.float64],
                       workdir: Path, mode: str = "known_poses",
                       masks: Optional[Sequence[NDArray[np.bool_]]] = None,
                       max_features: int = 8192, num_threads: int = -1, quiet: bool = True,
                       pairs: Optional[Sequence[tuple[int, int]]] = None,
                       prior_centres: Optional[NDArray[np.float64]] = None,
                       prior_sigma: float = 0.02, sift_first_octave: int = -1,
                       fallback: Optional[str] = "anchored",
                       attitude_sigma: Optional[float] = None) -> SparseResult:
    """SIFT + matching (all pairs, or the given ones) + triangulation of the rendered ``images`` (N RGB uint8).

    Args:
        images: N rendered RGB images, all of the same size.
        cameras: (N, 7) the poses of the cameras that took them (the reported ones; any attitude)
            or (N, 6) levelled cameras [c, v] (:mod:`vp_scene.camera`).
        K: 3x3 calibration in the OpenCV pixel convention (:func:`vp_scene.camera.intrinsics`).
        workdir: scratch folder (images, masks, database.db, sparse/); created when missing.
        mode: ``'known_poses'`` (triangulate with the true poses) or ``'incremental'`` (SfM).
        masks: optional foreground masks; features are then extracted on (dilated) plant pixels only.
        max_features: SIFT features per image; num_threads: -1 = all cores.
        quiet: silence COLMAP's INFO / WARNING log lines (errors still show).
        pairs: image index pairs (i, j) to match (order and duplicates do not matter); None:
            exhaustive matching.
        prior_centres: incremental mode: (N, 3) camera centres known to ``prior_sigma`` m per
            axis (a drone's reported positions), written as COLMAP pose priors and used by its
            bundle adjustment (``use_prior_position``); None: none (the alignment then uses the
            centres of ``cameras``). ``prior_sigma`` also scales the self-check (module docstring, 5).
        fallback: incremental mode: ``'anchored'`` (default): the anchored model of the same
            matches when the structure from motion fails (module docstring, 6); None: fail.
        attitude_sigma: degrees per axis to which the attitudes of ``cameras`` are known: the
            registration on them weighs them against the centres (known to ``prior_sigma``,
            :func:`similarity_from_poses`); None: the attitudes alone give its rotation.
        sift_first_octave: SIFT's first octave: -1 (COLMAP's default) doubles the image first, 0
            starts at its own resolution (about 4x fewer pixels to filter, no sub-pixel-scale features).

    Raises:
        ValueError: bad mode, image count, image sizes or pairs.
        SparseError: no features, no pair to match, no verified pair, or no triangulated point.
    """
    import pycolmap

    level = pycolmap.logging.minloglevel
    if quiet:
        pycolmap.logging.minloglevel = 2
    try:
        return _sparse(pycolmap, images, cameras, K, Path(workdir), mode, masks, max_features, num_threads, pairs,
                       prior_centres, prior_sigma, sift_first_octave, fallback, attitude_sigma)
    finally:
        pycolmap.logging.minloglevel = level


def _sparse(pycolmap: object, images: Sequence[NDArray[np.uint8]], cameras: NDArray[np.float64],
            K: NDArray[np.float64], workdir: Path, mode: str, masks: Optional[Sequence[NDArray[np.bool_]]],
            max_features: int, num_threads: int, pairs: Optional[Sequence[tuple[int, int]]],
            prior_centres: Optional[NDArray[np.float64]] = None, prior_sigma: float = 0.02,
            sift_first_octave: int = -1, fallback: Optional[str] = "anchored",
            attitude_sigma: Optional[float] = None) -> SparseResult:
    if mode not in MODES:
        raise ValueError(f"unknown sparse mode {mode!r}; expected one of {', '.join(MODES)}")
    if fallback not in (None, "anchored"):
        raise ValueError(f"fallback must be 'anchored' or None, got {fallback!r}")
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
    seconds = {}
    t0 = time.perf_counter()
    workdir.mkdir(parents=True, exist_ok=True)
    img_dir, mask_dir, names = _write_images(images, masks, workdir)
    db_path = workdir / "database.db"
    if db_path.exists():
        db_path.unlink()
    cx, cy = principal_point_gl(K)
    reader = pycolmap.ImageReaderOptions()
    reader.camera_model = "PINHOLE"
    reader.camera_params = ",".join(repr(float(x)) for x in (K[0, 0], K[1, 1], cx, cy))
    if mask_dir is not None:
        reader.mask_path = str(mask_dir)
    extraction = pycolmap.FeatureExtractionOptions()
    extraction.num_threads = num_threads
    extraction.sift.max_num_features = int(max_features)
    extraction.sift.first_octave = int(sift_first_octave)
    device = pycolmap.Device.cpu
    pycolmap.extract_features(db_path, img_dir, image_names=names, camera_mode=pycolmap.CameraMode.SINGLE,
                              reader_options=reader, extraction_options=extraction, device=device)
    if prior_centres is not None and mode == "incremental":
        _write_priors(pycolmap, db_path, names, np.asarray(prior_centres, dtype=np.float64).reshape(-1, 3),
                      prior_sigma)
    seconds["extract"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    matching = pycolmap.FeatureMatchingOptions()
    matching.num_threads = num_threads
    if todo is None:
        pycolmap.match_exhaustive(db_path, matching_options=matching, device=device)
        matched = len(names) * (len(names) - 1) // 2
    else:
        pair_file = workdir / "pairs.txt"
        _write_pairs(todo, names, pair_file)
        pycolmap.match_image_pairs(db_path, matching_options=matching,
                                   pairing_options=pycolmap.ImportedPairingOptions(match_list_path=str(pair_file)),
                                   device=device)
        matched = len(todo)
    seconds["match"] = time.perf_counter() - t0

    with pycolmap.Database.open(db_path) as db:
        db_images = {im.name: im for im in db.read_all_images()}
        db_cameras = db.read_all_cameras()
        keypoints = [db.num_keypoints_for_image(db_images[n].image_id) if n in db_images else 0 for n in names]
        verified = int(db.num_verified_image_pairs())
        index = {db_images[n].image_id: i for i, n in enumerate(names) if n in db_images}
        pair_inliers = {}
        for pair_id, n_inl in zip(*db.read_two_view_geometry_num_inliers()):
            a, b = (index.get(x) for x in pycolmap.pair_id_to_image_pair(pair_id))
            if a is not None and b is not None and n_inl > 0:
                pair_inliers[(min(a, b), max(a, b))] = int(n_inl)
    if sum(keypoints) == 0:
        raise SparseError("no SIFT features in any image (is the plant visible?)")
    if verified == 0:
        raise SparseError(f"no image pair could be matched ({matched} pairs tried, keypoints per image: "
                          f"{keypoints}); views too far apart or seeing different sides of the plant")

    t0 = time.perf_counter()
    out_dir = workdir / "sparse"
    out_dir.mkdir(exist_ok=True)
    options = pycolmap.IncrementalPipelineOptions()
    options.num_threads = num_threads
    # Few views: keep points seen by only two images (COLMAP drops them by default).
    options.triangulation.ignore_two_view_tracks = False
    anchor = cams[:, :3] if prior_centres is None else np.asarray(prior_centres, dtype=np.float64).reshape(-1, 3)
    attitudes = world_to_camera(cams)[0]
    max_residual = MAX_RESIDUAL_SIGMAS * max(float(prior_sigma), 1e-3)
    # the registration's weights: position m, attitude rad (floors: an exact report is still a measurement)
    sigmas = None if attitude_sigma is None else (max(float(prior_sigma), 1e-3),
                                                  np.radians(max(float(attitude_sigma), 0.01)))
    why = ""
    if mode == "known_poses":
        rec = _known_pose_model(pycolmap, db_cameras, db_images, names, cams)
        rec = pycolmap.triangulate_points(rec, db_path, img_dir, out_dir, clear_points=True, options=options)
        xyz, rgb, track = _read_points(rec)
        seen = sum(1 for im in rec.images.values() if im.has_pose and im.num_points3D > 0)
        model = MergedModels(xyz, rgb, track, as_poses(cams), int(seen), float(rec.compute_mean_reprojection_error()),
                             1, float("nan"))
    else:
        model = None
        if mode == "incremental":
            try:
                model = _incremental_model(pycolmap, db_path, img_dir, out_dir, options, names, anchor, attitudes,
                                           prior_centres is not None, len(names), verified, max_residual, sigmas)
            except SparseError as exc:
                if fallback is None:
                    raise
                why = str(exc)
        if model is None:  # anchored, asked for or in place of a structure from motion that failed
            try:
                try:
                    model = _anchored_model(pycolmap, db_path, img_dir, out_dir, options, db_cameras, db_images,
                                            names, cams, anchor, attitudes, max_residual, sigmas)
                except _AdjustmentDrifted as drift:  # choose, don't fail: the points at the reported poses
                    model = _reported_pose_model(pycolmap, db_path, img_dir, out_dir, options, db_cameras, db_images,
                                                 names, cams)
                    why = (f"{why}; " if why else "") + f"{drift}: kept the points triangulated at the reported poses"
            except SparseError as exc:
                raise SparseError(f"{why}; the model anchored on the reported poses failed too: {exc}"
                                  if why else str(exc)) from None
            mode = "anchored"
    xyz, rgb, track, est, seen, reprojection, n_models, residual = model
    if len(xyz) == 0:
        raise SparseError(f"no 3D point triangulated ({verified} verified image pairs, keypoints {keypoints})")
    seconds["triangulate"] = time.perf_counter() - t0
    return SparseResult(points=xyz, colors=rgb, registered=int(seen), keypoints=[int(k) for k in keypoints],
                        verified_pairs=verified, mean_track_length=track, pair_inliers=pair_inliers,
                        matched_pairs=matched, seconds=seconds, cameras=est,
                        mean_reprojection_error=reprojection, models=n_models, centre_residual=residual,
                        mode=mode, fallback=why)


def _incremental_model(pycolmap: object, db_path: Path, img_dir: Path, out_dir: Path, options: object,
                       names: Sequence[str], anchor: NDArray[np.float64], attitudes: NDArray[np.float64],
                       use_priors: bool, n: int, verified: int, max_residual: float,
                       sigmas: Optional[tuple] = None) -> "MergedModels":
    """COLMAP's incremental structure from motion of the matched images, every model registered on
    the given poses (:func:`_merge_models`); SparseError when it makes nothing usable."""
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
    models = pycolmap.incremental_mapping(db_path, img_dir, out_dir, options=options)
    if not models:
        raise SparseError(f"incremental mapping registered no image pair: 0 of {n} images "
                          f"registered ({verified} verified pairs)")
    # every model registered on the poses given (a flight: the reported ones), attitudes included
    return _merge_models(pycolmap, list(models.values()), names, anchor, attitudes, max_residual, sigmas)


def _anchored_model(pycolmap: object, db_path: Path, img_dir: Path, out_dir: Path, options: object,
                    db_cameras: list, db_images: dict, names: Sequence[str], cams: NDArray[np.float64],
                    anchor: NDArray[np.float64], attitudes: NDArray[np.float64],
                    max_residual: float, sigmas: Optional[tuple] = None) -> "MergedModels":
    """The reconstruction anchored on the given poses (module docstring, ``mode='anchored'``).

    1. the images at the given poses, tracks triangulated from the verified matches with loose
       thresholds (:data:`ANCHOR_REPROJECTION_PX`, :data:`ANCHOR_ANGLE_DEG`);
    2. :data:`ANCHOR_ROUNDS` times: a bundle adjustment of poses and points (Cauchy loss,
       intrinsics fixed), the model registered back on the given poses (:func:`_register_parts`),
       tracks triangulated again from scratch with COLMAP's thresholds;
    3. a last adjustment and registration.

    Why not COLMAP's pose-prior bundle adjuster (pycolmap 4.2 ``create_pose_prior_bundle_adjuster``):
    its priors are positions only, and on a 4-camera arc it turned every camera 5.5-6.7 degrees
    (measured 2026-11-27, one_plant arc k=0, 0.09 px mean reprojection error): the attitudes the
    drones report are what pins a small plan's rotation. The plain adjustment keeps the gauge where
    the reports put it and the registration (centres and attitudes) restores it: on the same arc
    the cameras end 0.13-0.31 degrees and 1.5-2.1 cm from the true poses, as the incremental
    mapper's model does. An image that observes no point is not registered (NaN row)."""
    loose = _loose(pycolmap, options)
    ba = pycolmap.BundleAdjustmentOptions()
    ba.refine_focal_length = ba.refine_principal_point = ba.refine_extra_params = False
    ba.ceres.loss_function_type = pycolmap.LossFunctionType.CAUCHY
    ba.print_summary = False
    rec = _known_pose_model(pycolmap, db_cameras, db_images, names, cams)
    rec = pycolmap.triangulate_points(rec, db_path, img_dir, out_dir, clear_points=True, options=loose)
    for _ in range(ANCHOR_ROUNDS):
        if len(rec.points3D) == 0:
            break
        _adjust(pycolmap, rec, ba)
        _register_parts(pycolmap, rec, names, anchor, attitudes, sigmas)
        rec = pycolmap.triangulate_points(rec, db_path, img_dir, out_dir, clear_points=True, options=options)
    if len(rec.points3D) == 0:
        raise SparseError(f"no track triangulates at the reported poses: 0 of {len(names)} images registered (the "
                          "matched images see no common point from far enough apart)")
    _adjust(pycolmap, rec, ba)
    _register_parts(pycolmap, rec, names, anchor, attitudes, sigmas)
    xyz, rgb, track = _read_points(rec)
    est = np.full((len(names), 7), np.nan)
    idx = {n: i for i, n in enumerate(names)}
    for im in rec.images.values():
        if im.has_pose and im.num_points3D > 0:
            R_cw = np.asarray(im.cam_from_world().rotation.matrix())
            est[idx[im.name]] = np.concatenate([np.asarray(im.projection_center()), body_from_optical(R_cw)])
    kept = np.isfinite(est[:, 0])
    residual = float(np.sqrt(np.mean(np.sum((est[kept, :3] - anchor[kept]) ** 2, axis=1))))
    if not residual <= max_residual:
        raise _AdjustmentDrifted(f"the adjusted model's camera centres lay {residual:.2f} m (RMS) from the reported "
                                 f"ones (more than {max_residual:.2f} m; {len(xyz)} points)")
    return MergedModels(xyz, rgb, track, est, int(kept.sum()), float(rec.compute_mean_reprojection_error()), 1,
                        residual)


def _loose(pycolmap: object, options: object) -> object:
    """``options`` with the anchored model's loose triangulation thresholds
    (:data:`ANCHOR_REPROJECTION_PX`, :data:`ANCHOR_ANGLE_DEG`)."""
    loose = pycolmap.IncrementalPipelineOptions(options.todict())
    for name in ("merge_max_reproj_error", "complete_max_reproj_error"):
        setattr(loose.triangulation, name, ANCHOR_REPROJECTION_PX)
    loose.triangulation.create_max_angle_error = loose.triangulation.continue_max_angle_error = ANCHOR_ANGLE_DEG
    loose.mapper.filter_max_reproj_error = ANCHOR_REPROJECTION_PX
    return loose


class _AdjustmentDrifted(SparseError):
    """The anchored model's adjustment took the cameras away from the reported poses (a weak model:
    a few dozen points, some of them false tracks, let the poses slide); :func:`sparse_reconstruct`
    then keeps :func:`_reported_pose_model`."""


def _reported_pose_model(pycolmap: object, db_path: Path, img_dir: Path, out_dir: Path, options: object,
                         db_cameras: list, db_images: dict, names: Sequence[str],
                         cams: NDArray[np.float64]) -> "MergedModels":
    """The anchored model's last resort (module docstring, 6): the tracks triangulated at the
    reported poses with the loose thresholds of its first step, nothing adjusted; consistent with
    the reports by construction (centre residual 0), as accurate as they are. Measured on the
    realistic plan-quality study (2026-11-28, realization 0): every one of its 10 failures in 152
    plans was this drift (0.21-1.98 m), all of plans whose cameras share few points (wide arcs,
    circles, random plans); three of them kept this way scored Chamfer x100 12.6, 25.2 and 49.5
    (shape 12.0, 25.2, 44.7): poor models, but where the reports put them, and said so.
    SparseError when no track triangulates."""
    rec = _known_pose_model(pycolmap, db_cameras, db_images, names, cams)
    rec = pycolmap.triangulate_points(rec, db_path, img_dir, out_dir, clear_points=True,
                                      options=_loose(pycolmap, options))
    if len(rec.points3D) == 0:
        raise SparseError(f"no track triangulates at the reported poses: 0 of {len(names)} images registered (the "
                          "matched images see no common point from far enough apart)")
    xyz, rgb, track = _read_points(rec)
    est = np.full((len(names), 7), np.nan)
    poses = as_poses(cams)
    idx = {n: i for i, n in enumerate(names)}
    for im in rec.images.values():
        if im.num_points3D > 0:
            est[idx[im.name]] = poses[idx[im.name]]
    return MergedModels(xyz, rgb, track, est, int(np.isfinite(est[:, 0]).sum()),
                        float(rec.compute_mean_reprojection_error()), 1, 0.0)


def _adjust(pycolmap: object, rec: object, options: object) -> None:
    """``pycolmap.bundle_adjustment`` with COLMAP's log level kept: the call sets glog's
    ``minloglevel`` to 0 (pycolmap 4.2.1, measured: 2 before, 0 after), and every later call of the
    reconstruction then printed its INFO lines (60 for one anchored model)."""
    level = pycolmap.logging.minloglevel
    try:
        pycolmap.bundle_adjustment(rec, options)
    finally:
        pycolmap.logging.minloglevel = level


def _register_parts(pycolmap: object, rec: object, names: Sequence[str], anchor: NDArray[np.float64],
                    attitudes: NDArray[np.float64], sigmas: Optional[tuple] = None) -> None:
    """Register each connected part of ``rec`` (images linked by shared points; parts of a field
    flown by parts share none and each has its own gauge in an adjustment) on its images' given
    poses, in place: :func:`similarity_from_poses` of the images that observe a point. A part of
    one image, or whose centres give no scale, stays where it is."""
    idx = {n: i for i, n in enumerate(names)}
    parent = {iid: iid for iid, im in rec.images.items() if im.has_pose and im.num_points3D > 0}

    def root(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for p in rec.points3D.values():
        ids = [el.image_id for el in p.track.elements if el.image_id in parent]
        for other in ids[1:]:
            parent[root(other)] = root(ids[0])
    parts: dict = {}
    for iid in parent:
        parts.setdefault(root(iid), []).append(iid)
    for members in parts.values():
        if len(members) < 2:
            continue
        ims = [rec.images[i] for i in members]
        model_c = np.array([np.asarray(im.projection_center()) for im in ims])
        model_R = np.array([np.asarray(im.cam_from_world().rotation.matrix()) for im in ims])
        which = [idx[im.name] for im in ims]
        try:
            M = similarity_from_poses(model_c, model_R, anchor[which], attitudes[which], sigmas)
        except SparseError:
            continue
        s = float(np.cbrt(np.linalg.det(M[:, :3])))
        R, t = M[:, :3] / s, M[:, 3]
        points = {p3 for im in ims for p3 in (pt.point3D_id for pt in im.points2D if pt.has_point3D())}
        for pid in points:
            rec.points3D[pid].xyz = M[:, :3] @ np.asarray(rec.points3D[pid].xyz) + t
        for im, c, R_cw in zip(ims, model_c, model_R):
            R_new = R_cw @ R.T
            im.frame.rig_from_world = pycolmap.Rigid3d(pycolmap.Rotation3d(R_new),
                                                       (-R_new @ (s * R @ c + t)).reshape(3, 1))



class MergedModels(NamedTuple):
    """What :func:`_merge_models` makes of the mapper's models: points (P, 3) in the world and
    their colours, mean track length and mean reprojection error (point-weighted over the
    models), the (N, 7) camera poses (NaN rows: not registered), the images registered, the
    number of models merged and the RMS centre residual (m) of their images."""

    points: NDArray[np.float64]
    colors: NDArray[np.uint8]
    mean_track_length: float
    cameras: NDArray[np.float64]
    registered: int
    mean_reprojection_error: float
    models: int
    centre_residual: float


def _merge_models(pycolmap: object, models: list, names: Sequence[str], anchor: NDArray[np.float64],
                  attitudes: NDArray[np.float64], max_residual: float = float("inf"),
                  sigmas: Optional[tuple] = None) -> MergedModels:
    """Every model COLMAP's incremental mapper made, each registered to the world on its own
    images' given poses (:func:`_align`), as one cloud.

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
    est = np.full((len(names), 7), np.nan)
    xyz, rgb, tracks, errors = [], [], [], []
    for rank, rec in enumerate(usable):
        p, c, track = _read_points(rec)
        try:
            p, e = _align(pycolmap, rec, names, anchor, p, lambda im: im.has_pose, attitudes, sigmas)
            mine = np.isfinite(e[:, 0])
            rms = float(np.sqrt(np.mean(np.sum((e[mine, :3] - anchor[mine]) ** 2, axis=1))))
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
    residual = float(np.sqrt(np.mean(np.sum((est[kept, :3] - anchor[kept]) ** 2, axis=1))))
    return MergedModels(np.concatenate(xyz), np.concatenate(rgb), mean(tracks), est, seen,
                        mean(errors) if n else float("nan"), len(xyz), residual)


def _known_pose_model(pycolmap: object, db_cameras: list, db_images: dict, names: Sequence[str],
                      cams: NDArray[np.float64]) -> object:
    """A reconstruction holding the images at the poses of ``cams`` (no points yet)."""
    rec = pycolmap.Reconstruction()
    for cam in db_cameras:
        rec.add_camera_with_trivial_rig(cam)
    R, t = world_to_camera(cams)
    for i, name in enumerate(names):
        dbi = db_images[name]
        image = pycolmap.Image(name=name, camera_id=dbi.camera_id, image_id=dbi.image_id)
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(R[i]), t[i].reshape(3, 1))
        rec.add_image_with_trivial_frame(image, pose)
    return rec


def similarity_from_poses(model_centres: NDArray[np.float64], model_R_cw: NDArray[np.float64],
                          centres: NDArray[np.float64], R_cw: NDArray[np.float64],
                          sigmas: Optional[tuple] = None) -> NDArray[np.float64]:
    """The similarity x_world = s R x_model + t (3 x 4 matrix [sR | t]) of a model whose images'
    centres and attitudes (cam_from_world rotations) are known in the world, to a drone's accuracy.

    Rotation: each image gives one, R_i = R_cw_i^T R_cw_model_i (a direction d_model seen by the
    camera is R_cw_model d_model = R_cw d_world); their chordal L2 mean (scipy Rotation.mean).
    Scale and translation: least squares of s R c_model + t = c over the centres with R fixed,
    s = sum (R c'_model . c') / sum |c'_model|^2 on centred coordinates. Why not the centres
    alone (Umeyama, :func:`pycolmap.estimate_sim3d`): the rotation a few centres give is known to
    sigma / spread (2 cm over the 1 m of a 4-camera plan: about 1 degree, worse for a tight arc),
    each reported attitude to 0.5 degree and independently. Degenerate: all centres at one point
    (no scale): SparseError.

    ``sigmas`` = (position m, attitude rad), per axis, of the reported poses: the rotation is
    then the most likely one given both, R maximizing tr(R^T A) with A = sum_i R_i / sigma_a^2 +
    2 s sum_i c'_i c'_model,i^T / sigma_p^2 (the log-likelihood of Gaussian centre errors and of
    small attitude errors, whose chordal distance |R - R_i|_F^2 is twice the squared angle; an
    orthogonal Procrustes solved by SVD, alternated with s three times). A small attitude sigma
    gives the attitudes' chordal mean above; a large one, a rig that reports its attitude only
    roughly (a camera mount 20 degrees off), Umeyama's rotation of the centres; between, both
    count (collinear centres leave the turn about their line to the attitudes).
    """
    from scipy.spatial.transform import Rotation

    per = np.einsum("nji,njk->nik", R_cw, model_R_cw)  # R_cw^T R_cw_model for every image
    m = model_centres - model_centres.mean(axis=0)
    w = centres - centres.mean(axis=0)
    spread = float((m * m).sum())
    if spread <= 1e-12:
        raise SparseError("the registered images share one centre: the model's scale is unknown")
    if sigmas is None:
        R = Rotation.from_matrix(per).mean().as_matrix()
    else:
        sigma_p, sigma_a = (float(x) for x in sigmas)
        scale = math.sqrt(float((w * w).sum()) / spread)  # |s| from the spreads, before any rotation
        for _ in range(3):
            U, _s, Vt = np.linalg.svd(per.sum(axis=0) / sigma_a ** 2 + 2.0 * scale * (w.T @ m) / sigma_p ** 2)
            R = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0]) @ Vt
            scale = float(((m @ R.T) * w).sum()) / spread
            if not scale > 0:
                break
    scale = float(((m @ R.T) * w).sum()) / spread
    if not scale > 0:
        raise SparseError("cannot align the reconstruction to the camera poses (negative scale)")
    t = centres.mean(axis=0) - scale * R @ model_centres.mean(axis=0)
    return np.hstack([scale * R, t[:, None]])


def _align(pycolmap: object, rec: object, names: Sequence[str], anchor: NDArray[np.float64],
           xyz: NDArray[np.float64], use: object,
           attitudes: Optional[NDArray[np.float64]] = None,
           sigmas: Optional[tuple] = None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The model's points and cameras in the world: the similarity that takes the images
    ``use(image)`` accepts to their ``anchor`` centres: with ``attitudes`` (N, 3, 3) (their
    cam_from_world rotations in the world) :func:`similarity_from_poses` (weighted by
    ``sigmas``), else the one of the centres alone (Umeyama). Cameras as poses (N, 7), roll
    kept, NaN rows for the other images."""
    idx = {n: i for i, n in enumerate(names)}
    src, tgt, reg = [], [], []
    for im in rec.images.values():
        if use(im):
            src.append(np.asarray(im.projection_center()))
            tgt.append(anchor[idx[im.name]])
            reg.append(im)
    if attitudes is not None:
        model_R = np.array([np.asarray(im.cam_from_world().rotation.matrix()) for im in reg])
        M = similarity_from_poses(np.array(src), model_R, np.array(tgt),
                                  np.asarray(attitudes)[[idx[im.name] for im in reg]], sigmas)
    else:
        sim = pycolmap.estimate_sim3d(np.array(src), np.array(tgt))
        if sim is None:
            raise SparseError("cannot align the reconstruction to the camera positions")
        M = np.asarray(sim.matrix())
    rot = M[:, :3] / np.cbrt(np.linalg.det(M[:, :3]))  # the similarity's rotation
    est = np.full((len(names), 7), np.nan)
    for im, c in zip(reg, src):
        R_cw = np.asarray(im.cam_from_world().rotation.matrix())
        est[idx[im.name], :3] = M[:, :3] @ c + M[:, 3]
        est[idx[im.name], 3:] = body_from_optical(R_cw @ rot.T)  # x_world = rot x_model: R_cw,world = R_cw rot^T
    return xyz @ M[:, :3].T + M[:, 3], est


def _write_priors(pycolmap: object, db_path: Path, names: Sequence[str], centres: NDArray[np.float64],
                  sigma: float) -> None:
    """Each image's camera centre as a COLMAP pose prior (Cartesian, isotropic ``sigma`` m)."""
    if centres.shape != (len(names), 3) or not np.all(np.isfinite(centres)):
        raise ValueError(f"prior_centres must be finite, ({len(names)}, 3), got shape {centres.shape}")
    cov = np.eye(3) * max(float(sigma), 1e-3) ** 2
    with pycolmap.Database.open(db_path) as db:
        by_name = {im.name: im for im in db.read_all_images()}
        for name, c in zip(names, centres):
            im = by_name.get(name)
            if im is None:
                continue
            prior = pycolmap.PosePrior(position=c.reshape(3, 1), position_covariance=cov,
                                       coordinate_system=pycolmap.PosePriorCoordinateSystem.CARTESIAN)
            prior.corr_data_id = pycolmap.data_t(pycolmap.sensor_t(pycolmap.SensorType.CAMERA, im.camera_id),
                                                 im.image_id)
            db.write_pose_prior(prior)
