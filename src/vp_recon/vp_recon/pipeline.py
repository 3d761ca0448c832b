"""Render a camera plan, reconstruct it and score it against the truth (paper Sec. V-B, Table I).

For each wind realization k of a :class:`vp_scene.wind.NoisyScene`, the plan is *flown* under
the capture model ``config.capture`` (:mod:`vp_scene.capture`; issue "Flights, not renders"):

1. mesh: the plants' meshes displaced by realization k's wind (:mod:`vp_recon.meshing`),
2. render: one image per camera at ``width x height`` (:mod:`vp_recon.render`) from the camera's
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
   ``'known_poses'``: triangulation with the reported poses (an ablation); then, when the flight
   has ground control (the realistic capture lays 4 markers), the model placed on the control
   points and the reported centres together (:mod:`vp_recon.gcp`),
4. dense: SGBM on neighbouring pairs (:mod:`vp_recon.dense`; COLMAP PatchMatch needs CUDA) with
   the poses the sparse step gives (SfM's, in ``map``),
5. score: Chamfer distance etc. of the (dense, else sparse) cloud against realization k's true
   points ``noisy_scene.points[k]`` in ``map`` (the registration error is part of what a flight
   gets) and, beside it, ``chamfer_shape`` after a rigid ICP refinement (the shape alone)
   (:mod:`vp_recon.metrics`). The sparse cloud is cleaned like the dense one (cropped to the
   scene's box, points on background in some view dropped) and is always scored too
   (``sparse_score``), so that a plan can be judged on either.

``capture = IDEAL`` (``--capture ideal``) is the reconstruction before the capture model, bit for
bit: the planned poses flown and known exactly, noise-free images, pairs chosen with realization
k's true points, triangulation with the planned poses (``sparse_mode`` ``'auto'`` resolves to
``'known_poses'`` there). Background (``ground``; ``None``: by the capture): a flight renders a
textured soil plane under the plants and segments each (noisy) image alone, by excess green
(:func:`vp_recon.render.plant_mask`); the ideal capture keeps the blue screen and the renderer's
masks (colour key; with ``ground=True`` the segmentation pass, an oracle).

All distances in this module are metres; x100 (Table I) is applied by writers (cli, ROS node).
Errors are :class:`ReconError` with a ``code`` equal to the ``vp_interfaces/ReconstructionScore``
constants.

One loop over the realizations of a plan, :func:`reconstruct_plan`, used by the CLI, the recon
node and Table I alike, with one failure rule: **a plan is reconstructed only if every one of
its wind realizations is**; the first realization that fails stops the plan with its
:class:`ReconError` (``.realization`` says which). A mean Chamfer distance over the
realizations that happened to work would hide exactly the plans that reconstruct badly.
"""
from __future__ import annotations

import math
import os
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Optional, Sequence, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vp_scene.camera import IMAGE_SIZE
from vp_scene.capture import CaptureModel, REALISTIC

from .metrics import DEFAULT_FSCORE_THRESHOLD, CloudScore, EmptyCloudError, Scores, chamfer, chamfer_after_icp

__all__ = [
    "NONE", "UNKNOWN", "EMPTY_PLAN", "NO_SCENE", "NOTHING_VISIBLE", "RECONSTRUCTION_FAILED",
    "OUTPUT_NOT_WRITABLE", "WRONG_FRAME", "CAPTURE_MISSING", "PLAN_TOO_LARGE", "ERROR_NAMES", "MAX_CAMERAS",
    "MAX_MEGAPIXELS", "check_plan_size", "STAGES", "ReconError", "ReconCancelled", "ReconConfig",
    "RealizationResult", "PlanReconResult", "MATCHINGS", "MATCH_POSES_FROM", "matching_method", "validate_cameras",
    "ensure_writable_dir", "crop_box", "Prior", "ViewsResult", "render_flight", "reconstruct_views",
    "reconstruct_captured", "plan_result",
    "reconstruct_realization", "reconstruct_plan",
]

# Error codes: identical to vp_interfaces/msg/ReconstructionScore.msg.
NONE = 0
UNKNOWN = 1
EMPTY_PLAN = 2
NO_SCENE = 3
NOTHING_VISIBLE = 4
RECONSTRUCTION_FAILED = 5
OUTPUT_NOT_WRITABLE = 6
WRONG_FRAME = 7
CAPTURE_MISSING = 8
PLAN_TOO_LARGE = 9
ERROR_NAMES = {NONE: "NONE", UNKNOWN: "UNKNOWN", EMPTY_PLAN: "EMPTY_PLAN", NO_SCENE: "NO_SCENE",
               NOTHING_VISIBLE: "NOTHING_VISIBLE", RECONSTRUCTION_FAILED: "RECONSTRUCTION_FAILED",
               OUTPUT_NOT_WRITABLE: "OUTPUT_NOT_WRITABLE", WRONG_FRAME: "WRONG_FRAME",
               CAPTURE_MISSING: "CAPTURE_MISSING", PLAN_TOO_LARGE: "PLAN_TOO_LARGE"}

#: The most cameras a plan may have (a second sortie's flown cameras included): ``ReconConfig.
#: max_cameras``, the recon node's parameter ``max_cameras`` and ``--max-cameras`` of ``make
#: recon``; a larger plan is refused with PLAN_TOO_LARGE before anything is rendered. Every image
#: of a realization is held at once: measured peak RSS of ``python -m vp_recon.cli --plan`` (one
#: realization, 2000 x 1500, realistic capture, one_plant) 1.56 GB with 8 cameras, 2.12 GB with
#: 32, about 23 MB a camera (a 200-camera plan took 5.8 GB), so 256 cameras need about 7.3 GB.
#: The planner plans at most 100 cameras a sortie; 256 hold 16 drones over 16 sorties.
MAX_CAMERAS = 256
#: The most megapixels the images of a flight folder may have together (``--images``,
#: ``--max-megapixels``), read from their headers before any is decoded: a folder's memory is
#: its pixels (about 7.7 MB a megapixel, as above), whatever their number. The memory of
#: MAX_CAMERAS cameras of 2000 x 1500: hundreds of images of a few megapixels, 64 of 12 MP.
MAX_MEGAPIXELS = MAX_CAMERAS * 2000 * 1500 // 1_000_000

#: Stages reported to the progress callback, in order.
STAGES = ("render", "sparse", "dense", "score")

#: ``ReconConfig.matching``: which image pairs SIFT matching compares (see :func:`matching_method`).
MATCHINGS = ("auto", "exhaustive", "poses")
#: ``'auto'`` matches pairs chosen from the poses from this many cameras up, all pairs below.
#: Measured (bench/bench_matching.py, three Corn50 plants in a row): from 8 cameras on exhaustive
#: matching verifies false pairs over 90 degrees apart (2 of 7 at 8 cameras, 16-25 at 12) that
#: then become dense stereo partners (dense 5x slower, Chamfer worse); at 4-6 cameras both give
#: about the same, so today's 4-6 camera plans keep exhaustive matching and their results.
MATCH_POSES_FROM = 8

#: ``sparse_mode='auto'``: reported attitudes good to this many degrees (1 sigma) anchor the model
#: (a triangulation at poses that far off still finds its tracks with the anchored model's loose
#: first thresholds); rougher ones leave the poses to the images (incremental SfM).
#: Measured on Table I's seed-0 flights (2026-11-27): where both modes reconstruct, the anchored
#: model's map and shape Chamfer are those of the incremental mapper or better (three_row circle:
#: shape 2.09-2.89 against 3.59-5.50), and where the mapper's model fails its self-check the
#: anchored one reconstructs (README "Capture model").
ANCHOR_MAX_ATTITUDE_DEG = 2.0

#: progress(stage, realization) after each stage of each realization; returning False cancels.
ProgressFn = Callable[[str, int], Optional[bool]]
#: on_realization(result) as soon as a realization is reconstructed (e.g. to publish it).
RealizationFn = Callable[["RealizationResult"], None]
PathLike = Union[str, os.PathLike]


class ReconError(Exception):
    """A reconstruction failure with a ``ReconstructionScore`` error code (``.code``) and message;
    ``.realization`` is the wind realization that failed (None: the plan as a whole)."""

    def __init__(self, code: int, message: str, realization: Optional[int] = None) -> None:
        super().__init__(message)
        self.code = int(code)
        self.message = message
        self.realization = realization

    @property
    def name(self) -> str:
        """The code's constant name, e.g. ``'NOTHING_VISIBLE'``."""
        return ERROR_NAMES.get(self.code, "UNKNOWN")


class ReconCancelled(Exception):
    """The progress callback returned False."""


@dataclass
class ReconConfig:
    """Reconstruction settings.

    Attributes:
        width, height: rendered image size (paper: 2000 x 1500).
        fov: horizontal field of view, rad (the planner's, default pi/2).
        sparse_mode: ``'known_poses'`` (triangulate with the reported poses), ``'anchored'``
            (the model anchored on the reported poses: triangulated from them, adjusted and
            registered on them, :mod:`vp_recon.sparse`), ``'incremental'`` (SfM with the reported
            centres as pose priors, the anchored model when it fails) or ``'auto'``: known_poses
            for the ideal capture; anchored when the reported attitudes are good to
            :data:`ANCHOR_MAX_ATTITUDE_DEG` (an RTK drone's gimbal and flight controller);
            incremental otherwise (a rig whose attitudes are rough: the images decide).
        capture: the capture model (:mod:`vp_scene.capture`; default: an RTK multirotor).
        dense: run dense stereo (else the sparse cloud is scored).
        fscore_threshold: F-score distance threshold, metres.
        mesh_cache: folder of cached Poisson meshes for point-cloud plant models (None: default).
        keep_workdir: keep the COLMAP workspace (images, database) under ``out_dir/work``.
        keep_images: keep the rendered images in the result (first realization only in
            :func:`reconstruct_plan`).
        voxel: voxel edge for downsampling the dense cloud, metres (0: none).
        crop_margin: margin around the scene's bounding box (union of all realizations), metres.
        neighbours: dense stereo partners per camera.
        sift_masks: restrict SIFT to the (dilated) foreground masks.
        min_foreground: pixels of plant an image needs to count as seeing the plant.
        max_features: SIFT features per image.
        sift_first_octave: SIFT's first octave (-1, COLMAP's default: the image doubled first; 0:
            its own resolution, about 4x less work).
        dense_scale: the dense step's stereo pairs are matched on the views resized by this factor
            (0 < s <= 1; :func:`vp_recon.dense.scaled_views`; SGM's cost about s^3).
        ground: render a textured soil plane under the plants (True) or a blue screen (False);
            None (default): soil for a realistic capture, the blue screen for the ideal one.
            A realistic capture's masks come from its images alone (excess green on soil,
            colour key on the sky); the ideal capture's from the renderer (see
            :mod:`vp_recon.render`).
        num_threads: threads of COLMAP and OpenCV (0: all cores).
        matching: ``'exhaustive'`` (all image pairs), ``'poses'`` (the pairs
            :func:`vp_recon.pairs.select_pairs` picks from the known poses and scene) or
            ``'auto'``: poses from :data:`MATCH_POSES_FROM` cameras up, exhaustive below.
        max_cameras: a plan of more cameras is refused (PLAN_TOO_LARGE, :func:`check_plan_size`).
        mask: how a flight's images are segmented over soil (:data:`vp_recon.masks.MASK_METHODS`):
            ``'auto'`` (excess green for a green plant, else the background model), ``'exg'`` or
            ``'background'`` (:mod:`vp_recon.masks`); the blue screen keeps its colour key.
    """

    width: int = IMAGE_SIZE[0]
    height: int = IMAGE_SIZE[1]
    fov: float = math.pi / 2
    sparse_mode: str = "auto"
    dense: bool = True
    fscore_threshold: float = DEFAULT_FSCORE_THRESHOLD
    mesh_cache: Optional[str] = None
    keep_workdir: bool = False
    keep_images: bool = True
    voxel: float = 0.002
    crop_margin: float = 0.05
    neighbours: int = 2
    sift_masks: bool = False
    min_foreground: int = 50
    max_features: int = 8192
    sift_first_octave: int = -1
    dense_scale: float = 1.0
    ground: Optional[bool] = None
    num_threads: int = 0
    matching: str = "auto"
    capture: CaptureModel = REALISTIC
    max_cameras: int = MAX_CAMERAS
    mask: str = "auto"

    @property
    def sparse_mode_used(self) -> str:
        """``sparse_mode`` with ``'auto'`` resolved by the capture."""
        if self.sparse_mode != "auto":
            return self.sparse_mode
        if self.capture.ideal:
            return "known_poses"
        return "anchored" if self.capture.report_attitude_sigma <= ANCHOR_MAX_ATTITUDE_DEG else "incremental"

    @property
    def ground_used(self) -> bool:
        """``ground`` with ``None`` resolved by the capture (soil for a flight)."""
        return (not self.capture.ideal) if self.ground is None else bool(self.ground)

    def validate(self) -> "ReconConfig":
        """Raise ValueError naming the first bad field; return self."""
        from .sparse import MODES

        for name in ("width", "height"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 16:
                raise ValueError(f"{name} must be an integer >= 16 pixels, got {v!r}")
        if not (isinstance(self.fov, (int, float)) and 0 < self.fov < math.pi):
            raise ValueError(f"fov must be in (0, pi) rad, got {self.fov!r}")
        if self.sparse_mode not in ("auto",) + MODES:
            raise ValueError(f"sparse_mode must be one of auto, {', '.join(MODES)}, got {self.sparse_mode!r}")
        if not isinstance(self.capture, CaptureModel):
            raise ValueError(f"capture must be a vp_scene.capture.CaptureModel, got {self.capture!r}")
        self.capture.validate()
        if self.ground is not None and not isinstance(self.ground, (bool, np.bool_)):
            raise ValueError(f"ground must be True, False or None (by the capture), got {self.ground!r}")
        if self.matching not in MATCHINGS:
            raise ValueError(f"matching must be one of {', '.join(MATCHINGS)}, got {self.matching!r}")
        if not (math.isfinite(self.fscore_threshold) and self.fscore_threshold > 0):
            raise ValueError(f"fscore_threshold must be > 0 metres, got {self.fscore_threshold!r}")
        if not (math.isfinite(self.voxel) and self.voxel >= 0):
            raise ValueError(f"voxel must be >= 0 metres, got {self.voxel!r}")
        if not (math.isfinite(self.crop_margin) and self.crop_margin >= 0):
            raise ValueError(f"crop_margin must be >= 0 metres, got {self.crop_margin!r}")
        if isinstance(self.num_threads, bool) or not isinstance(self.num_threads, (int, np.integer)) \
                or self.num_threads < 0:
            raise ValueError(f"num_threads must be an integer >= 0 (0: all cores), got {self.num_threads!r}")
        if int(self.neighbours) < 1 or int(self.min_foreground) < 1 or int(self.max_features) < 16:
            raise ValueError("neighbours and min_foreground must be >= 1, max_features >= 16")
        if isinstance(self.sift_first_octave, bool) or self.sift_first_octave not in (-1, 0, 1):
            raise ValueError(f"sift_first_octave must be -1, 0 or 1, got {self.sift_first_octave!r}")
        if not (isinstance(self.dense_scale, (int, float)) and 0 < self.dense_scale <= 1):
            raise ValueError(f"dense_scale must be in (0, 1], got {self.dense_scale!r}")
        from .masks import MASK_METHODS

        if self.mask not in MASK_METHODS:
            raise ValueError(f"mask must be one of {', '.join(MASK_METHODS)}, got {self.mask!r}")
        if isinstance(self.max_cameras, bool) or not isinstance(self.max_cameras, (int, np.integer)) \
                or self.max_cameras < 2:
            raise ValueError(f"max_cameras must be an integer >= 2, got {self.max_cameras!r}")
        return self


@dataclass
class RealizationResult(Scores):
    """One realization's reconstruction and scores (distances in metres; the :class:`Scores`
    fields first).

    Attributes:
        realization: k.
        chamfer, accuracy, completeness: metres (Chamfer = accuracy + completeness).
        fscore, precision, recall: at ``fscore_threshold`` metres, in [0, 1].
        points, colors: (M, 3) float64 world / uint8 RGB scored cloud.
        images: images registered in the sparse model (with a pose and >= 1 point).
        num_images: images rendered (= cameras).
        visible_images: images whose foreground has >= ``min_foreground`` pixels.
        source: ``'dense'`` or ``'sparse'`` (the dense cloud was disabled or empty).
        sparse_points: points of the sparse model (before cleaning).
        sparse_score: the cleaned sparse cloud's CloudScore (None when cleaning left nothing).
        pair_inliers: verified SIFT inlier matches per camera pair (i, j), i < j.
        matching: the matching that ran, ``'exhaustive'`` or ``'poses'`` (:func:`matching_method`).
        matched_pairs: camera pairs handed to the SIFT matcher.
        sparse_seconds: the sparse stage in parts: pairs (choosing them), extract, match, triangulate.
        dense_pairs: (reference, other) camera pairs that gave dense points, and
        dense_pair_points: the raw points each of them gave.
        rendered: the rendered RGB images (empty unless kept).
        seconds: wall time per stage: mesh, render, sparse, dense, score.
        chamfer_shape: Chamfer distance (m) after a rigid ICP refinement onto the truth (the
            shape alone, registration error removed).
        capture: the capture model's :meth:`~vp_scene.capture.CaptureModel.to_dict`.
        sparse_mode: the model the sparse step kept (``'known_poses'``, ``'incremental'`` or
            ``'anchored'``).
        mean_track_length, mean_reprojection_error: of the sparse model (images a point is seen
            in; pixels): metrics without a ground truth (issue 20, part 4).
        coverage: :class:`vp_recon.metrics.Coverage` of the planning cloud (no truth read).
        sparse_models: the structure-from-motion models merged, each registered to map on its own
            reported poses (parts of a plan that share no matches; :func:`vp_recon.sparse._merge_models`).
        centre_residual: incremental: RMS distance, m, of the registered cameras from the reported
            poses after the registration (the sparse step's self-check; no truth read); else NaN.
        sparse_fallback: why the structure from motion was not kept (the sparse step then made the
            model anchored on the reported poses, ``sparse_mode`` 'anchored'); '' otherwise.
        control: the registration on the flight's ground control
            (:meth:`vp_recon.gcp.Registration.to_dict`), None without control points.
        mask: how the images were segmented (:meth:`vp_recon.masks.MaskChoice.to_dict`; None:
            the renderer's masks or the blue screen's colour key).
        reported, K: the poses the drones reported (N, 6) and the intrinsics: with ``rendered``,
            the capture set (:meth:`captured_views`).
    """

    realization: int
    fscore_threshold: float
    points: NDArray[np.float64]
    colors: NDArray[np.uint8]
    images: int
    num_images: int
    visible_images: int
    source: str
    sparse_points: int
    sparse_score: Optional[CloudScore] = None
    pair_inliers: dict = field(default_factory=dict)
    matching: str = "exhaustive"
    matched_pairs: int = 0
    sparse_seconds: dict = field(default_factory=dict)
    dense_pairs: list = field(default_factory=list)
    dense_pair_points: list = field(default_factory=list)
    rendered: list = field(default_factory=list, repr=False)
    seconds: dict = field(default_factory=dict)
    chamfer_shape: float = math.nan
    capture: dict = field(default_factory=dict)
    sparse_mode: str = "known_poses"
    mean_track_length: float = math.nan
    mean_reprojection_error: float = math.nan
    coverage: object = None
    sparse_models: int = 1
    centre_residual: float = math.nan
    sparse_fallback: str = ""
    control: Optional[dict] = None
    mask: Optional[dict] = None
    reported: Optional[NDArray[np.float64]] = field(default=None, repr=False)
    K: Optional[NDArray[np.float64]] = field(default=None, repr=False)

    def captured_views(self) -> object:
        """The capture set this realization was reconstructed from
        (:class:`vp_recon.flight.CapturedViews`: its images, the poses reported, K), for
        :func:`vp_recon.flight.write_flight`; None when its images were not kept."""
        from .flight import CapturedViews

        if not self.rendered or self.reported is None:
            return None
        return CapturedViews(names=[f"view_{i:03d}.png" for i in range(len(self.rendered))], images=self.rendered,
                             reported=self.reported, K=self.K, realization=self.realization)


@dataclass
class PlanReconResult:
    """All realizations of one plan; chamfer_mean / chamfer_std (population std) and
    chamfer_shape_mean in metres."""

    realizations: list
    chamfer_mean: float
    chamfer_std: float
    seconds: dict
    chamfer_shape_mean: float = math.nan

    @property
    def num_images(self) -> int:
        """Images per realization (= cameras)."""
        return self.realizations[0].num_images if self.realizations else 0


def matching_method(matching: str, num_cameras: int) -> str:
    """The matching that runs: ``'poses'`` or ``'exhaustive'`` as asked; ``'auto'``: ``'poses'``
    when ``num_cameras >= MATCH_POSES_FROM``, else ``'exhaustive'``."""
    if matching not in MATCHINGS:
        raise ValueError(f"matching must be one of {', '.join(MATCHINGS)}, got {matching!r}")
    if matching == "auto":
        return "poses" if num_cameras >= MATCH_POSES_FROM else "exhaustive"
    return matching


def validate_cameras(cameras: object) -> NDArray[np.float64]:
    """The plan as an (N, 6) array with N >= 2; ReconError(EMPTY_PLAN) naming the problem otherwise."""
    try:
        cams = np.asarray(cameras, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ReconError(EMPTY_PLAN, f"cameras are not a numeric (N, 6) array: {exc}") from None
    if cams.size == 0:
        raise ReconError(EMPTY_PLAN, "the plan has no cameras")
    if cams.ndim == 1 and cams.size % 6 == 0:
        cams = cams.reshape(-1, 6)
    if cams.ndim != 2 or cams.shape[1] != 6:
        raise ReconError(EMPTY_PLAN, f"cameras must have shape (N, 6) = [cx, cy, cz, vx, vy, vz], got {cams.shape}")
    if not np.all(np.isfinite(cams)):
        raise ReconError(EMPTY_PLAN, "cameras contain NaN or infinite values")
    bad = np.flatnonzero(np.linalg.norm(cams[:, 3:], axis=1) <= 1e-12)
    if len(bad):
        raise ReconError(EMPTY_PLAN, f"camera(s) {bad.tolist()} have a zero viewing direction")
    if len(cams) < 2:
        raise ReconError(EMPTY_PLAN, f"a reconstruction needs at least 2 cameras, the plan has {len(cams)}")
    return cams


def check_plan_size(num_cameras: int, max_cameras: int = MAX_CAMERAS, setting: str = "max_cameras") -> None:
    """ReconError(PLAN_TOO_LARGE) for a plan of more than ``max_cameras`` cameras (``setting``:
    the name the user knows the cap by, in the message)."""
    if num_cameras > max_cameras:
        raise ReconError(PLAN_TOO_LARGE, f"the plan has {num_cameras} cameras; at most {max_cameras} are "
                         f"reconstructed ({setting}: every image of a realization is held at once)")


def _check_scene(noisy_scene: object) -> NDArray[np.float64]:
    pts = getattr(noisy_scene, "points", None)
    if noisy_scene is None or pts is None or getattr(noisy_scene, "scene", None) is None:
        raise ReconError(NO_SCENE, "no scene: give a vp_scene NoisyScene")
    pts = np.asarray(pts)
    if pts.ndim != 3 or pts.shape[0] == 0 or pts.shape[1] == 0 or pts.shape[2] != 3:
        raise ReconError(NO_SCENE, f"the scene has no points (realizations array of shape {pts.shape})")
    return pts


def ensure_writable_dir(path: PathLike) -> Path:
    """Create ``path`` if needed and check it is a writable folder; ReconError(OUTPUT_NOT_WRITABLE)."""
    p = Path(path)
    try:
        p.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=p, prefix=".write-test-"):
            pass
    except OSError as exc:
        raise ReconError(OUTPUT_NOT_WRITABLE, f"output folder {p} is not writable: {exc.strerror or exc}") from None
    return p


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


def _tick(progress: Optional[ProgressFn], stage: str, k: int) -> None:
    if progress is not None and progress(stage, k) is False:
        raise ReconCancelled(f"cancelled after {stage} of realization {k}")


@dataclass
class Prior:
    """The planning cloud (the noisy scene the planner saw): every realization's points, (M, 3)
    in ``map``, and which plant each belongs to (``plant``, (M,) int), K ``realizations`` blocks of the same points. It chooses image pairs
    (``matching='poses'``), crops the reconstruction to the scene's box and is what
    ``coverage_of_prior`` is measured on (:func:`vp_recon.metrics.coverage_of_prior`)."""

    points: NDArray[np.float64]
    plant: NDArray[np.int64]
    realizations: int = 1

    @classmethod
    def of_scene(cls, noisy_scene: object) -> "Prior":
        """All K realizations of a :class:`vp_scene.wind.NoisyScene` (the planner's cloud), in K
        blocks of the scene's P points."""
        pts = _check_scene(noisy_scene)
        plant = np.asarray(noisy_scene.scene.plant_index, dtype=np.int64)
        return cls(points=pts.reshape(-1, 3), plant=np.tile(plant, pts.shape[0]), realizations=int(pts.shape[0]))


@dataclass
class ViewsResult:
    """What :func:`reconstruct_views` makes of a capture set (distances metres; no truth read).

    Attributes:
        points, colors: the scored cloud (dense, else the cleaned sparse one), world / RGB.
        source: ``'dense'`` or ``'sparse'``.
        sparse: the :class:`vp_recon.sparse.SparseResult` (registered images, mean track length,
            mean reprojection error, ...); sparse_clean: its cloud cropped and silhouette-filtered.
        dense: the dense result (None when ``config.dense`` is off).
        seeing: indices of the images whose plant mask has >= ``min_foreground`` pixels.
        matching, mode: the matching and sparse step that ran; t_pairs: seconds choosing pairs.
        coverage: :class:`vp_recon.metrics.Coverage` of the prior (None without a prior).
        seconds: wall time of ``sparse`` and ``dense``.
        control: the :class:`vp_recon.gcp.Registration` on the flight's ground control (None
            without control points).
        mask: the :class:`vp_recon.masks.MaskChoice` of a flight segmented over soil (None: the
            renderer's masks or the blue screen's colour key).
    """

    points: NDArray[np.float64]
    colors: NDArray[np.uint8]
    source: str
    sparse: object
    sparse_clean: NDArray[np.float64]
    dense: object
    seeing: NDArray[np.int64]
    matching: str
    mode: str
    t_pairs: float
    coverage: object = None
    seconds: dict = field(default_factory=dict)
    control: object = None
    mask: object = None


def render_flight(noisy_scene: object, k: int, cameras: ArrayLike, config: Optional[ReconConfig] = None,
                  indices: Optional[Sequence[int]] = None) -> object:
    """Realization ``k`` of a plan flown under ``config.capture``: a
    :class:`vp_recon.flight.CapturedViews` of the images rendered from the actual poses (with
    sensor noise) and the poses the drones report. The ideal capture keeps the renderer's masks
    (an oracle: the capture before issue 18); a flight's masks come from its images alone
    (:func:`reconstruct_views`). ``views.seconds``: mesh, render. ReconError UNKNOWN when
    meshing or rendering fails.

    ``indices``: the cameras' indices i in their plan (default 0..N-1), which seed their capture
    draws: a simulated drone holding camera i of a plan renders ``render_flight(scene, k,
    [camera_i], config, indices=[i])`` and gets exactly the image and reported pose the whole
    plan's render gives camera i (tested), so the fleet and the render source see one flight."""
    from .flight import CapturedViews
    from .meshing import scene_meshes
    from .render import RenderError, Renderer, marker_meshes

    from vp_scene.camera import check_cameras

    cfg = (config or ReconConfig()).validate()
    try:  # one camera is a capture too (a drone's own)
        cams = check_cameras(cameras)
    except ValueError as exc:
        raise ReconError(EMPTY_PLAN, str(exc)) from None
    seconds = {}
    t0 = time.perf_counter()
    try:
        meshes = scene_meshes(noisy_scene, k, cfg.mesh_cache)
    except (RuntimeError, ValueError) as exc:
        raise ReconError(UNKNOWN, f"cannot mesh the plants: {exc}") from exc
    seconds["mesh"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    capture = cfg.capture
    ids = list(range(len(cams))) if indices is None else [int(i) for i in indices]
    if len(ids) != len(cams) or len(set(ids)) != len(ids) or min(ids) < 0:
        raise ReconError(EMPTY_PLAN, f"indices must be {len(cams)} distinct camera indices >= 0, got {ids}")
    # ideal: the planned cameras, flown and reported exactly
    flown = [capture.fly_camera(c, k, i) for c, i in zip(cams, ids)]
    actual = np.array([a for a, _ in flown]).reshape(-1, 6)
    reported = np.array([r for _, r in flown]).reshape(-1, 6)
    # the field's ground markers (capture.gcp_markers), around every realization's plants: one layout
    markers, control = capture.lay_markers(noisy_scene.points)
    try:
        renderer = Renderer(cfg.width, cfg.height, cfg.fov)
        images, masks, _ = renderer.render(meshes, actual, ground=cfg.ground_used,
                                           markers=marker_meshes(markers, capture.gcp_size))
    except RenderError as exc:
        raise ReconError(UNKNOWN, str(exc)) from exc
    images = [capture.expose(im, k, i) for i, im in zip(ids, images)]
    seconds["render"] = time.perf_counter() - t0
    return CapturedViews(names=[f"view_{i:03d}.png" for i in ids], images=images,
                         reported=reported, K=renderer.K, masks=masks if capture.ideal else None,
                         fov=cfg.fov, realization=k, seconds=seconds, control=control)


def reconstruct_views(views: object, config: Optional[ReconConfig] = None, workdir: Optional[PathLike] = None,
                      prior: Optional[Prior] = None, pair_cloud: Optional[NDArray[np.float64]] = None,
                      progress: Optional[ProgressFn] = None, k: int = 0) -> ViewsResult:
    """Reconstruct a capture set (:class:`vp_recon.flight.CapturedViews`: images, reported poses,
    one pinhole camera): the one path of rendered plans, flight folders and the fleet.

    Masks: ``views.masks`` when given (the ideal capture's renderer masks), else from the images
    alone: over soil by ``config.mask`` (:func:`vp_recon.masks.flight_masks`; the background model
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
    from .masks import flight_masks
    from .render import foreground_mask
    from .sparse import SparseError, sparse_reconstruct

    cfg = (config or ReconConfig()).validate()
    set_threads(cfg.num_threads)
    views.validate()
    images, reported, K = views.images, views.reported, views.K
    n = len(images)
    mask_choice = None
    if views.masks is not None:
        masks = views.masks
    elif not cfg.ground_used:
        masks = [foreground_mask(im) for im in images]
    else:
        masks, mask_choice = flight_masks(images, cfg.mask, reported, K,
                                          None if prior is None else crop_box(prior.points, cfg.crop_margin))
    fg = np.array([int(m.sum()) for m in masks])
    seeing = np.flatnonzero(fg >= cfg.min_foreground)
    if len(seeing) == 0:
        raise ReconError(NOTHING_VISIBLE, f"none of the {n} cameras sees a plant "
                                          f"(at most {int(fg.max())} plant pixels in an image)")
    if len(seeing) < 2:
        raise ReconError(NOTHING_VISIBLE, f"only camera {int(seeing[0])} of {n} sees a plant; "
                                          "a reconstruction needs at least 2 views of it")
    _tick(progress, "render", k)
    temp = workdir is None
    wd = Path(tempfile.mkdtemp(prefix="vp_recon_")) if temp else Path(workdir)
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
            mode = cfg.sparse_mode_used
            priors = None if capture.ideal or mode != "incremental" else reported[:, :3]
            sp = sparse_reconstruct(images, reported, K, wd, mode=mode,
                                    masks=masks if cfg.sift_masks else None, max_features=cfg.max_features,
                                    num_threads=cfg.num_threads or -1, pairs=pairs, prior_centres=priors,
                                    prior_sigma=max(capture.report_position_sigma, 0.01),
                                    sift_first_octave=cfg.sift_first_octave)
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
        _tick(progress, "sparse", k)

        t0 = time.perf_counter()
        # the poses the sparse step knows: the reported ones, or SfM's (in map) where registered
        # (ideal: the planned poses whatever the mode, as before the capture model)
        geo = reported if capture.ideal or mode == "known_poses" else \
            np.where(np.isfinite(sp.cameras), sp.cameras, reported)
        if prior is not None:
            box = crop_box(prior.points, cfg.crop_margin)
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
        _tick(progress, "dense", k)
    finally:
        if temp:
            shutil.rmtree(wd, ignore_errors=True)
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
    truth_all = _check_scene(noisy_scene)
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
    truth_all = _check_scene(noisy_scene)
    k = views.realization
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 0 <= int(k) < truth_all.shape[0]:
        raise ReconError(NO_SCENE, f"realization {k!r} does not exist (the scene has {truth_all.shape[0]})")
    k = int(k)
    temp = workdir is None
    wd = Path(tempfile.mkdtemp(prefix="vp_recon_")) if temp else ensure_writable_dir(workdir)
    try:
        seconds = dict(views.seconds)
        prior = Prior.of_scene(noisy_scene)
        # pairs: ideal: as before the capture model (realization k's truth); a flight: the planning cloud
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
        _tick(progress, "score", k)
    finally:
        if temp or not cfg.keep_workdir:
            shutil.rmtree(wd / f"realization_{k}", ignore_errors=True)
            if temp:
                shutil.rmtree(wd, ignore_errors=True)
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
        K=np.asarray(views.K, dtype=np.float64))


def plan_result(results: Sequence[RealizationResult], seconds: Optional[dict] = None) -> PlanReconResult:
    """The :class:`PlanReconResult` of the realizations' results (Chamfer mean, population std,
    shape mean; ``seconds`` summed per stage, plus ``total`` when given)."""
    ch = np.array([r.chamfer for r in results])
    secs = {s: float(sum(r.seconds.get(s, 0.0) for r in results)) for s in ("mesh",) + STAGES}
    secs.update(seconds or {})
    return PlanReconResult(realizations=list(results), chamfer_mean=float(ch.mean()), chamfer_std=float(ch.std()),
                           seconds=secs, chamfer_shape_mean=float(np.mean([r.chamfer_shape for r in results])))


def worker_call(reconstruct: Callable, *args, **kwargs) -> tuple:
    """``reconstruct(*args, **kwargs)`` on a Dask worker (:func:`reconstruct_realization`, or
    :func:`reconstruct_captured` for a fleet's capture set): ('ok', result) or ('error', code,
    message) (a ReconError travels as its fields: the exception's own pickling is not part of its
    contract)."""
    try:
        return ("ok", reconstruct(*args, **kwargs))
    except ReconError as exc:
        return ("error", exc.code, str(exc))


def worker_result(out: tuple, k: int) -> RealizationResult:
    """The result of a :func:`worker_call`, or its ReconError raised with ``.realization = k``."""
    if out[0] == "error":
        exc = ReconError(out[1], out[2])
        exc.realization = k
        raise exc
    return out[1]


def _on_cluster(client: object, noisy_scene: object, cams: NDArray[np.float64], cfg: ReconConfig,
                ks: list, work_root: Optional[Path], progress: Optional[ProgressFn],
                on_realization: Optional[RealizationFn]) -> list:
    """:func:`reconstruct_plan`'s loop on a Dask cluster (one task a realization)."""
    from distributed import as_completed

    scene = client.scatter(noisy_scene, broadcast=True)
    futures = {}
    for n, k in enumerate(ks):
        keep = cfg.keep_images and (n == 0 or on_realization is not None)
        sub = ReconConfig(**{**cfg.__dict__, "keep_images": keep, "num_threads": 1})
        futures[client.submit(worker_call, reconstruct_realization, scene, k, cams, sub, workdir=work_root,
                              pure=False)] = (n, k)
    done: dict = {}
    failed: dict = {}
    try:
        for fut in as_completed(list(futures)):
            n, k = futures[fut]
            try:
                res = worker_result(fut.result(), k)
            except ReconError as exc:
                failed[n] = exc
                continue
            for stage in STAGES:
                _tick(progress, stage, k)
            if on_realization is not None:
                on_realization(res)
            if n > 0:
                res.rendered = []
            done[n] = res
            if failed and min(failed) < min(set(range(len(ks))) - set(done) - set(failed), default=len(ks)):
                break  # the first failing realization in order is known: the plan fails with it
    finally:
        client.cancel([f for f in futures if not f.done()])
    if failed:
        raise failed[min(failed)]
    return [done[n] for n in range(len(ks))]


def reconstruct_plan(noisy_scene: object, cameras: ArrayLike, config: Optional[ReconConfig] = None,
                     out_dir: Optional[PathLike] = None, realizations: Optional[Sequence[int]] = None,
                     progress: Optional[ProgressFn] = None,
                     on_realization: Optional[RealizationFn] = None, client: object = None) -> PlanReconResult:
    """Reconstruct and score a plan on every (or the listed) wind realization(s), in order.

    The failure rule (module docstring): the first realization that fails stops the plan.
    With a Dask ``client`` (:func:`vp_scene.cluster.open_client`) the realizations reconstruct in
    parallel on its workers, one thread each; the result is the in-process one (same records, in
    the order asked), the failure rule reads "the failing realization first in that order", and
    ``progress`` / ``on_realization`` run in this process as each realization comes back.

    Args:
        out_dir: output folder, checked writable (created); the COLMAP workspaces go to
            ``out_dir/work`` when ``config.keep_workdir``. None: temporary workspaces only.
        realizations: indices k to run (default: all K of the scene), in order, no duplicates.
        progress: ``progress(stage, k)`` after every stage; returning False cancels.
        on_realization: ``on_realization(result)`` after each realization that succeeded, while
            its rendered images are still attached (when ``config.keep_images``).

    Returns:
        PlanReconResult with chamfer_mean and the population std over the realizations (metres).
        The first realization keeps its rendered images when ``config.keep_images`` (the others
        drop theirs after ``on_realization``: memory).

    Raises:
        ReconError as :func:`reconstruct_realization`, with ``.realization`` set to the failing
        realization's k (plan-level problems, such as an unknown realization, have None);
        PLAN_TOO_LARGE for more than ``config.max_cameras`` cameras, before anything is rendered.
        ReconCancelled: ``progress`` returned False.
    """
    cfg = (config or ReconConfig()).validate()
    cams = validate_cameras(cameras)
    check_plan_size(len(cams), cfg.max_cameras)
    pts = _check_scene(noisy_scene)
    K = pts.shape[0]
    ks = list(range(K)) if realizations is None else [int(x) for x in realizations]
    if not ks:
        raise ReconError(NO_SCENE, "no realization selected")
    bad = [x for x in ks if not 0 <= x < K]
    if bad:
        raise ReconError(NO_SCENE, f"realization(s) {bad} do not exist (the scene has {K}: 0..{K - 1})")
    if len(set(ks)) != len(ks):
        raise ReconError(NO_SCENE, f"duplicate realizations in {ks}")
    work_root = None
    if out_dir is not None:
        out = ensure_writable_dir(out_dir)
        if cfg.keep_workdir:
            work_root = ensure_writable_dir(out / "work")
    results = []
    t_all = time.perf_counter()
    if client is not None:
        results = _on_cluster(client, noisy_scene, cams, cfg, ks, work_root, progress, on_realization)
    for n, k in enumerate(ks if client is None else ()):
        keep = cfg.keep_images and (n == 0 or on_realization is not None)
        sub = ReconConfig(**{**cfg.__dict__, "keep_images": keep})
        try:
            res = reconstruct_realization(noisy_scene, k, cams, sub, workdir=work_root, progress=progress)
        except ReconError as exc:
            exc.realization = k
            raise
        if on_realization is not None:
            on_realization(res)
        if n > 0:
            res.rendered = []
        results.append(res)
    return plan_result(results, {"total": time.perf_counter() - t_all})
