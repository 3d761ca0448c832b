"""Render a camera plan, reconstruct it and score it against the truth (paper Sec. V-B, Table I).

For each wind realization k of a :class:`vp_scene.wind.NoisyScene`, the plan is *flown* under
the capture model ``config.capture`` (:mod:`vp_scene.capture`):

1. mesh: the plants' meshes displaced by realization k's wind (:mod:`vp_scene.meshing`),
2. render: one image per camera at ``width x height`` (:mod:`vp_scene.render`; the simulated
   drones' :func:`vp_scene.sim_drone.photograph`) from the camera's
   ACTUAL pose (planned + hover error), with sensor noise; the drone REPORTS its pose with a
   localization error,
3. sparse: COLMAP SIFT + matching (:mod:`vp_recon.sparse`); the pairs matched are all of them,
   or, from :data:`MATCH_POSES_FROM` cameras up (``matching='auto'``), those
   :func:`vp_recon.pairs.select_pairs` picks from the reported poses and the planning cloud
   (all K realizations of the noisy scene: what the planner saw); then
   ``sparse_mode='anchored'`` (the default of a realistic capture): the model anchored on the
   reported poses (triangulated from them, bundle-adjusted, registered back on their centres and
   attitudes); ``'incremental'``: COLMAP's incremental SfM with the reported centres as pose
   priors, registered to ``map`` on the reported poses, the anchored model when it fails;
   reported attitudes rougher than :data:`vp_recon.config.ANCHOR_MAX_ATTITUDE_DEG` are weighed
   against the centres by their sigma (a rig reporting its attitude roughly is registered on its
   centres), and the SfM's failure is then the step's (no anchored fallback);
   ``'known_poses'``: triangulation with the reported poses (an ablation); then, when the flight
   has ground control (the realistic capture lays its markers), the model placed on the control
   points and the reported centres together (:mod:`vp_recon.gcp`),
4. dense: SGBM on neighbouring pairs (:mod:`vp_recon.dense`; COLMAP PatchMatch needs CUDA) with
   the poses the sparse step gives (SfM's, in ``map``),
5. score: Chamfer distance etc. of the (dense, else sparse) cloud against realization k's true
   points ``noisy_scene.points[k]`` in ``map`` (the registration error is part of what a flight
   gets) and, beside it, ``chamfer_shape`` after a rigid ICP refinement (the shape alone)
   (:mod:`vp_recon.metrics`). The sparse cloud is cleaned like the dense one (cropped to the
   scene's box, points on background in some view dropped) and is always scored too
   (``sparse_score``), so that a plan can be judged on either.

``capture = IDEAL`` (``--capture ideal``) flies the planned poses and knows them exactly:
noise-free images, pairs chosen with realization k's true points, triangulation with the planned
poses (``sparse_mode`` ``'auto'`` resolves to
``'known_poses'`` there). Background (``ground``; ``None``: by the capture): a flight renders a
textured soil plane under the plants and segments each (noisy) image alone, by excess green
(:func:`vp_recon.segment.plant_mask`); the ideal capture keeps the blue screen and the renderer's
masks (colour key; with ``ground=True`` the segmentation pass, an oracle).

All distances in this module are metres; x100 (Table I) is applied by writers (cli, ROS node).
Errors are :class:`vp_recon.errors.ReconError` with a ``code`` equal to the
``vp_interfaces/ReconstructionScore`` constants. The rooms beside it: :mod:`vp_recon.config` (the
settings and caps), :mod:`vp_recon.errors` (the codes and the input checks), :mod:`vp_recon.results`
(what it returns), :mod:`vp_recon.progress` (stages, cancel), :mod:`vp_recon.tasks` (Dask).

One loop, :func:`reconstruct_sets`, over the capture sets of a plan's realizations, whatever
their source: rendered here (:func:`rendered`; :func:`reconstruct_plan`, used by the CLI, the
recon node and Table I alike) or sent by the fleet as they arrive
(:meth:`vp_recon.fleet_captures.FleetCaptures.capture_sets`), in this process or on a Dask
cluster, with one failure rule: **a plan is reconstructed only if every one of its wind
realizations is**; the first realization that fails stops the plan with its
:class:`ReconError` (``.realization`` says which). A mean Chamfer distance over the
realizations that happened to work would hide exactly the plans that reconstruct badly. One
capture set is :func:`reconstruct_set` (:func:`reconstruct_captured`: a set given,
:func:`reconstruct_realization`: one rendered first); a flight folder without realizations,
:func:`reconstruct_views`.
"""
from __future__ import annotations

import os
import shutil
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Callable, Iterable, Iterator, NamedTuple, Optional, Sequence, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vp_scene.camera import as_poses
from vp_scene.folders import OwnedFolder

from .config import ReconConfig, matching_method
from .errors import EMPTY_PLAN, NO_SCENE, NOTHING_VISIBLE, OUTPUT_NOT_WRITABLE, RECONSTRUCTION_FAILED, UNKNOWN, \
    ReconError, SparseError, check_plan_size, check_realizations, check_scene, validate_cameras
from .errors import ensure_writable_dir
from .metrics import EmptyCloudError, chamfer, chamfer_after_icp
from .progress import ProgressFn, tick
from .results import PlanReconResult, Prior, RealizationFn, RealizationResult, ViewsResult, plan_result
from .tasks import ClusterQueue

__all__ = ["crop_box", "set_threads", "render_flight", "reconstruct_views", "reconstruct_captured",
           "reconstruct_realization", "Rendered", "rendered", "reconstruct_set", "reconstruct_sets", "reconstruct_plan"]

PathLike = Union[str, os.PathLike]


def crop_box(noisy_scene: object, margin: float) -> NDArray[np.float64]:
    """(2, 3) [lo, hi]: bounding box of all realizations' points (the scene's extent under any
    of its winds, not realization k's truth alone; or of any (..., 3) cloud given instead of a
    scene) grown by ``margin``."""
    pts = np.asarray(getattr(noisy_scene, "points", noisy_scene), dtype=np.float64).reshape(-1, 3)
    return np.stack([pts.min(axis=0) - margin, pts.max(axis=0) + margin])


def set_threads(n: int) -> None:
    """OpenCV's threads (``n``; 0: all cores) for this process; COLMAP takes its count per call."""
    import cv2

    cv2.setNumThreads(int(n) if n > 0 else (os.cpu_count() or 1))


def render_flight(noisy_scene: object, k: int, cameras: ArrayLike, config: Optional[ReconConfig] = None,
                  indices: Optional[Sequence[int]] = None) -> object:
    """Realization ``k`` of a plan flown under ``config.capture`` by the simulated drones
    (:func:`vp_scene.sim_drone.photograph`: the world renders it), as the capture set a flight
    hands to the reconstruction: a :class:`vp_recon.flight.CapturedViews` of the images rendered
    from the actual poses (with sensor noise) and the poses the drones report. The ideal capture
    keeps the renderer's masks (an oracle); a flight's masks come
    from its images alone (:func:`reconstruct_views`). ``views.seconds``: mesh, render.
    ReconError EMPTY_PLAN for bad cameras or indices, UNKNOWN when meshing or rendering fails.

    ``indices``: the cameras' indices i in their plan (default 0..N-1), which seed their capture
    draws: a simulated drone holding camera i of a plan renders ``render_flight(scene, k,
    [camera_i], config, indices=[i])`` and gets exactly the image and reported pose the whole
    plan's render gives camera i (tested), so the fleet and the render source see one flight."""
    from vp_scene.render import RenderError
    from vp_scene.sim_drone import photograph

    from .flight import CapturedViews

    cfg = (config or ReconConfig()).validate()
    try:
        shot = photograph(noisy_scene, k, cameras, cfg.capture, cfg.width, cfg.height, cfg.fov, ground=cfg.ground,
                          mesh_cache=cfg.mesh_cache, indices=indices, masks=cfg.capture.ideal)
    except RenderError as exc:
        raise ReconError(UNKNOWN, str(exc)) from exc
    except ValueError as exc:  # the cameras or their indices
        raise ReconError(EMPTY_PLAN, str(exc)) from None
    ids = list(range(len(shot.images))) if indices is None else [int(i) for i in indices]
    return CapturedViews(names=[f"view_{i:03d}.png" for i in ids], images=shot.images, reported=shot.reported,
                         K=shot.K, masks=shot.masks, fov=cfg.fov, realization=k,
                         seconds=shot.seconds, control=shot.control)


#: The temporary COLMAP workspaces: ``<temp dir>/vp_recon_<pid>-<random>`` (vp_scene.folders.OwnedFolder).
WORK_PREFIX = "vp_recon_"


def _scratch() -> OwnedFolder:
    """A temporary COLMAP workspace owned by this process (removed by the caller; one a killed run
    left is removed as the next is made); ReconError(OUTPUT_NOT_WRITABLE) when none can be made."""
    try:
        return OwnedFolder(WORK_PREFIX)
    except OSError as exc:
        raise ReconError(OUTPUT_NOT_WRITABLE, f"cannot make a work folder in {tempfile.gettempdir()}: "
                         f"{exc.strerror or exc}") from None


def reconstruct_views(views: object, config: Optional[ReconConfig] = None, workdir: Optional[PathLike] = None,
                      prior: Optional[Prior] = None, pair_cloud: Optional[NDArray[np.float64]] = None,
                      progress: Optional[ProgressFn] = None, k: int = 0) -> ViewsResult:
    """Reconstruct a capture set (:class:`vp_recon.flight.CapturedViews`: images, reported poses,
    one pinhole camera): the one path of rendered plans, flight folders and the fleet.

    Masks: ``views.masks`` when given (the ideal capture's renderer masks), else from the images
    alone: over soil by ``config.mask`` (:func:`vp_recon.segment.flight_masks`; the background model
    learns outside the prior's box projected), the blue screen's colour key otherwise. Sparse step
    ``config.sparse_mode_used`` with the reported centres as pose priors (incremental, unless the
    capture is ideal); the sparse cloud is cropped to the prior's box (+ ``crop_margin``; without
    a prior: the box of its points on plant pixels) and silhouette-filtered, then dense stereo.

    Args:
        workdir: the COLMAP workspace (created, kept); None: a temporary one, deleted.
        prior: the planning cloud: pairs (``matching='poses'``), crop box, coverage of the prior.
        pair_cloud: the cloud pairs are chosen from (default: the prior's points).
        progress, k: ``progress(stage, k)`` after render (the images checked), sparse and dense.

    Raises:
        ReconError: NOTHING_VISIBLE, RECONSTRUCTION_FAILED, OUTPUT_NOT_WRITABLE (workdir).
    """
    from vp_scene.camera import CameraModel

    from .dense import crop_to_box, dense_reconstruct, silhouette_filter
    from .metrics import coverage_of_prior
    from .pairs import select_pairs
    from .segment import flight_masks, image_mask
    from .sparse import sparse_reconstruct

    cfg = (config or ReconConfig()).validate()
    set_threads(cfg.num_threads)
    views.validate()
    images, reported, K = views.images, views.reported, views.K
    n = len(images)
    prior_box = None if prior is None else crop_box(prior.points, cfg.crop_margin)  # the masks' and the crop's
    mask_choice = None
    if views.masks is not None:
        masks = views.masks
    elif not cfg.ground_used:
        masks = [image_mask(im, ground=False) for im in images]
    else:
        masks, mask_choice = flight_masks(images, cfg.mask, reported, K, prior_box)
    fg = np.array([int(m.sum()) for m in masks])
    seeing = np.flatnonzero(fg >= cfg.min_foreground)
    if len(seeing) == 0:
        raise ReconError(NOTHING_VISIBLE, f"none of the {n} cameras sees a plant "
                                          f"(at most {int(fg.max())} plant pixels in an image)")
    if len(seeing) < 2:
        raise ReconError(NOTHING_VISIBLE, f"only camera {int(seeing[0])} of {n} sees a plant; "
                                          "a reconstruction needs at least 2 views of it")
    tick(progress, "render", k)
    scratch = _scratch() if workdir is None else None
    wd = scratch.path if scratch is not None else Path(workdir)
    seconds: dict = {}
    try:
        t0 = time.perf_counter()
        matching = matching_method(cfg.matching, n)
        cloud = pair_cloud if pair_cloud is not None else (prior.points if prior is not None else None)
        if matching == "poses" and cloud is None:
            matching = "exhaustive"  # no scene to choose pairs from (a flight folder without a prior)
        pairs = None
        if matching == "poses":
            pairs = select_pairs(reported, cloud, CameraModel(*views.size, views.horizontal_fov))
            if not pairs:
                raise ReconError(RECONSTRUCTION_FAILED, f"no two of the {n} cameras see a common part of "
                                                        "the scene: no image pair to match (matching 'poses')")
        t_pairs = time.perf_counter() - t0
        capture = cfg.capture
        try:
            options = cfg.sparse_options()
            priors = None if capture.ideal or options.mode != "incremental" else reported[:, :3]
            sp = sparse_reconstruct(images, reported, K, wd, options, masks=masks if cfg.sift_masks else None,
                                    pairs=pairs, prior_centres=priors)
        except SparseError as exc:
            raise ReconError(RECONSTRUCTION_FAILED, f"sparse reconstruction failed: {exc}") from exc
        except OSError as exc:
            raise ReconError(OUTPUT_NOT_WRITABLE, f"cannot write the COLMAP workspace in {wd}: {exc}") from exc
        mode = sp.mode  # the incremental mode may have fallen back to the anchored model
        control = None
        if views.control is not None and mode != "known_poses" and not capture.ideal:
            from .gcp import register

            # the model placed on the ground control and the reported centres together
            sp.points, sp.cameras, control = register(sp.points, sp.cameras, views.names, images, K, reported,
                                                      views.control, max(capture.report_position_sigma, 0.01))
        seconds["sparse"] = time.perf_counter() - t0
        tick(progress, "sparse", k)

        t0 = time.perf_counter()
        # the poses the sparse step knows: the reported ones, or SfM's (in map) where registered
        # (ideal: the planned poses whatever the mode)
        geo = reported if capture.ideal or mode == "known_poses" else \
            np.where(np.isfinite(sp.cameras), sp.cameras, as_poses(reported))
        if prior is not None:
            box = prior_box
            keep = crop_to_box(sp.points, box[0], box[1])
            keep[keep] = silhouette_filter(sp.points[keep], geo, K, masks)
        else:
            keep = silhouette_filter(sp.points, geo, K, masks)
            if not keep.any():
                raise ReconError(RECONSTRUCTION_FAILED, f"none of the {len(sp.points)} sparse points lies on "
                                                        "plant pixels in every view that sees it")
            box = crop_box(sp.points[keep], cfg.crop_margin)
        points, colors, source = sp.points[keep], sp.colors[keep], "sparse"
        clean = points
        dn = None
        if cfg.dense:
            dn = dense_reconstruct(images, masks, geo, K, box, guide=sp.points,
                                   neighbours=cfg.neighbours, voxel=cfg.voxel, pair_inliers=sp.pair_inliers,
                                   scale=cfg.dense_scale)
            if len(dn.points):
                points, colors, source = dn.points, dn.colors, "dense"
        seconds["dense"] = time.perf_counter() - t0
        tick(progress, "dense", k)
    finally:
        if scratch is not None:
            scratch.remove()
    coverage = coverage_of_prior(points, prior.points, prior.plant, realizations=prior.realizations) \
        if prior is not None and len(points) else None
    return ViewsResult(points=points, colors=colors, source=source, sparse=sp, sparse_clean=clean, dense=dn,
                       seeing=seeing, matching=matching, mode=mode, t_pairs=t_pairs, coverage=coverage,
                       seconds=seconds, control=control, mask=mask_choice)


def reconstruct_realization(noisy_scene: object, k: int, cameras: ArrayLike, config: Optional[ReconConfig] = None,
                            workdir: Optional[PathLike] = None, progress: Optional[ProgressFn] = None
                            ) -> RealizationResult:
    """Render, reconstruct and score realization ``k`` of ``noisy_scene`` seen by ``cameras`` (N, 6):
    :func:`render_flight`, :func:`reconstruct_views` (the path of every capture set), then the
    scores against realization k's truth.

    Args:
        workdir: COLMAP workspace (created; kept). None: a temporary folder, deleted afterwards.
        progress: called as ``progress(stage, k)`` after each of :data:`STAGES`; False cancels.

    Raises:
        ReconError: EMPTY_PLAN (no / malformed cameras), NO_SCENE, NOTHING_VISIBLE (fewer than 2
            images see a plant), RECONSTRUCTION_FAILED (nothing matched / triangulated),
            OUTPUT_NOT_WRITABLE (workdir), UNKNOWN (rendering or meshing failed).
        ReconCancelled: the progress callback returned False.
    """
    cfg = (config or ReconConfig()).validate()
    cams = validate_cameras(cameras)
    truth_all = check_scene(noisy_scene)
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 0 <= int(k) < truth_all.shape[0]:
        raise ReconError(NO_SCENE, f"realization {k!r} does not exist (the scene has {truth_all.shape[0]})")
    views = render_flight(noisy_scene, int(k), cams, cfg)
    return reconstruct_captured(noisy_scene, views, cfg, workdir=workdir, progress=progress)


def reconstruct_captured(noisy_scene: object, views: object, config: Optional[ReconConfig] = None,
                         workdir: Optional[PathLike] = None, progress: Optional[ProgressFn] = None
                         ) -> RealizationResult:
    """Reconstruct a capture set of realization ``views.realization`` of ``noisy_scene`` (rendered
    by :func:`render_flight`, or sent by the fleet) and score it against that realization's
    truth: :func:`reconstruct_views` with the scene as the prior, then Chamfer, ``chamfer_shape``
    and the sparse cloud's score. Arguments and errors as :func:`reconstruct_realization`."""
    cfg = (config or ReconConfig()).validate()
    truth_all = check_scene(noisy_scene)
    k = views.realization
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 0 <= int(k) < truth_all.shape[0]:
        raise ReconError(NO_SCENE, f"realization {k!r} does not exist (the scene has {truth_all.shape[0]})")
    k = int(k)
    scratch = _scratch() if workdir is None else None
    wd = scratch.path if scratch is not None else ensure_writable_dir(workdir)
    try:
        seconds = dict(views.seconds)
        prior = Prior.of_scene(noisy_scene)
        # pairs: ideal: from realization k's truth; a flight: from the planning cloud
        vr = reconstruct_views(views, cfg, wd / f"realization_{k}", prior=prior,
                               pair_cloud=truth_all[k] if cfg.capture.ideal else None, progress=progress, k=k)
        seconds.update(vr.seconds)
        t0 = time.perf_counter()
        sparse_score = chamfer(vr.sparse_clean, truth_all[k], cfg.fscore_threshold) if len(vr.sparse_clean) else None
        try:
            score = chamfer(vr.points, truth_all[k], cfg.fscore_threshold)
            shape = chamfer_after_icp(vr.points, truth_all[k], cfg.fscore_threshold)
        except EmptyCloudError as exc:  # registered, but nothing in the prior's box on plant pixels
            raise ReconError(RECONSTRUCTION_FAILED, f"the reconstruction is empty: {vr.sparse.registered} of "
                             f"{len(views.images)} images registered, {len(vr.sparse.points)} sparse points, none "
                             "of them inside the planning cloud's box on plant pixels (a registration to map "
                             f"that is off?): {exc}") from exc
        seconds["score"] = time.perf_counter() - t0
        tick(progress, "score", k)
    finally:
        if scratch is not None:
            scratch.remove()
        elif not cfg.keep_workdir:
            shutil.rmtree(wd / f"realization_{k}", ignore_errors=True)
    sp, dn = vr.sparse, vr.dense
    return RealizationResult(
        realization=k, chamfer=score.chamfer, accuracy=score.accuracy, completeness=score.completeness,
        fscore=score.fscore, precision=score.precision, recall=score.recall, fscore_threshold=score.threshold,
        points=vr.points, colors=vr.colors, images=sp.registered, num_images=len(views.images),
        visible_images=len(vr.seeing), source=vr.source, sparse_points=len(sp.points), sparse_score=sparse_score,
        pair_inliers=dict(sp.pair_inliers), matching=vr.matching, matched_pairs=sp.matched_pairs,
        sparse_seconds={"pairs": vr.t_pairs, **sp.seconds},
        dense_pairs=list(dn.pairs) if dn is not None else [], dense_pair_points=list(dn.pair_points) if dn is not None else [],
        rendered=views.images if cfg.keep_images else [], seconds=seconds, chamfer_shape=shape.chamfer,
        capture=cfg.capture.to_dict(), sparse_mode=vr.mode, mean_track_length=sp.mean_track_length,
        mean_reprojection_error=sp.mean_reprojection_error, coverage=vr.coverage, sparse_models=sp.models,
        centre_residual=sp.centre_residual, sparse_fallback=sp.fallback,
        control=vr.control.to_dict() if vr.control is not None else None,
        mask=vr.mask.to_dict() if vr.mask is not None else None,
        reported=np.asarray(views.reported, dtype=np.float64),
        K=np.asarray(views.K, dtype=np.float64), ground_control=views.control)


class Rendered(NamedTuple):
    """A capture set still to be flown: realization ``realization`` of a plan of ``cameras`` (N, 6),
    rendered by the simulated drones where it is reconstructed (on a Dask worker: the images do
    not travel)."""

    realization: int
    cameras: NDArray[np.float64]


def rendered(cameras: NDArray[np.float64], realizations: Iterable[int]) -> Iterator[Rendered]:
    """The render source of :func:`reconstruct_sets`: the plan's realizations, in order."""
    return (Rendered(int(k), cameras) for k in realizations)


def reconstruct_set(noisy_scene: object, capture: object, config: Optional[ReconConfig] = None,
                    workdir: Optional[PathLike] = None, progress: Optional[ProgressFn] = None) -> RealizationResult:
    """One capture set of ``noisy_scene`` reconstructed and scored against its realization's truth:
    a :class:`Rendered` one flown first (:func:`reconstruct_realization`), a
    :class:`vp_recon.flight.CapturedViews` as it came (:func:`reconstruct_captured`).
    Arguments and errors as :func:`reconstruct_realization`."""
    if isinstance(capture, Rendered):
        return reconstruct_realization(noisy_scene, capture.realization, capture.cameras, config, workdir, progress)
    return reconstruct_captured(noisy_scene, capture, config, workdir, progress)


def reconstruct_sets(noisy_scene: object, captures: Iterable, config: Optional[ReconConfig] = None,
                     out_dir: Optional[PathLike] = None, progress: Optional[ProgressFn] = None,
                     on_realization: Optional[RealizationFn] = None, client: object = None,
                     should_stop: Optional[Callable[[], bool]] = None) -> PlanReconResult:
    """The one loop: every capture set ``captures`` gives (:class:`Rendered` ones of
    :func:`rendered`, the fleet's :class:`vp_recon.flight.CapturedViews` as they arrive),
    reconstructed and scored in the order given (:func:`reconstruct_set`), with the failure rule
    of the module docstring: the first set that fails stops the plan with its ReconError
    (``.realization`` set).

    With a Dask ``client`` each set is reconstructed on the cluster as soon as the source gives it
    (one thread a task, :class:`vp_recon.tasks.ClusterQueue`), while the source makes the next;
    the results are the in-process ones, taken back in the order given, and ``progress`` /
    ``on_realization`` run in this process as each is taken back.

    Args:
        out_dir: output folder, checked writable (created); the COLMAP workspaces go to
            ``out_dir/work`` when ``config.keep_workdir``. None: temporary workspaces only.
        progress: ``progress(stage, k)`` after every stage; returning False cancels.
        on_realization: ``on_realization(result)`` after each set that succeeded, while its
            images are still attached (when ``config.keep_images``).
        should_stop: checked while the cluster's results are awaited; True cancels.

    Returns:
        PlanReconResult with chamfer_mean and the population std over the sets (metres). The
        first set keeps its images when ``config.keep_images`` (the others drop theirs after
        ``on_realization``: memory).

    Raises:
        ReconError as :func:`reconstruct_realization`; ReconCancelled.
    """
    cfg = (config or ReconConfig()).validate()
    work_root = None
    if out_dir is not None:
        out = ensure_writable_dir(out_dir)
        if cfg.keep_workdir:
            work_root = ensure_writable_dir(out / "work")
    results: list = []
    t_all = time.perf_counter()

    def report(res: RealizationResult) -> None:
        if on_realization is not None:
            on_realization(res)
        if results:  # only the first set keeps its images (memory)
            res.rendered = []
        results.append(res)

    queue = None if client is None else ClusterQueue(client, noisy_scene, should_stop)
    try:
        for n, capture in enumerate(captures):
            sub = replace(cfg, keep_images=cfg.keep_images and (n == 0 or on_realization is not None))
            if queue is not None:
                queue.submit(capture.realization, reconstruct_set, capture, replace(sub, num_threads=1), work_root)
                for res in queue.take(progress, block=False):
                    report(res)
                continue
            try:
                res = reconstruct_set(noisy_scene, capture, sub, work_root, progress)
            except ReconError as exc:
                exc.realization = capture.realization
                raise
            report(res)
        for res in queue.take(progress, block=True) if queue is not None else ():
            report(res)
    finally:
        if queue is not None:
            queue.cancel()
    return plan_result(results, {"total": time.perf_counter() - t_all})


def reconstruct_plan(noisy_scene: object, cameras: ArrayLike, config: Optional[ReconConfig] = None,
                     out_dir: Optional[PathLike] = None, realizations: Optional[Sequence[int]] = None,
                     progress: Optional[ProgressFn] = None, on_realization: Optional[RealizationFn] = None,
                     client: object = None, should_stop: Optional[Callable[[], bool]] = None) -> PlanReconResult:
    """Reconstruct and score a plan on every (or the listed) wind realization(s), in order: the
    plan checked, then :func:`reconstruct_sets` of its :func:`rendered` realizations.

    Args:
        realizations: indices k to run (default: all K of the scene), in order, no duplicates.
        out_dir, progress, on_realization, client, should_stop: as :func:`reconstruct_sets`.

    Raises:
        ReconError as :func:`reconstruct_sets`, with ``.realization`` set to the failing
        realization's k (plan-level problems, such as an unknown realization, have None);
        PLAN_TOO_LARGE for more than ``config.max_cameras`` cameras, before anything is rendered.
        ReconCancelled: ``progress`` returned False.
    """
    cfg = (config or ReconConfig()).validate()
    cams = validate_cameras(cameras)
    check_plan_size(len(cams), cfg.max_cameras)
    ks = check_realizations(realizations, check_scene(noisy_scene).shape[0])
    return reconstruct_sets(noisy_scene, rendered(cams, ks), cfg, out_dir, progress, on_realization, client,
                            should_stop)
