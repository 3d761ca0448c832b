"""The reconstruction's settings: :class:`ReconConfig` (image size, capture model, sparse and dense
steps, matching) and its caps (:data:`MAX_CAMERAS`, :data:`MAX_MEGAPIXELS`), with the rules that
resolve its ``'auto'`` choices (:func:`matching_method`, ``ReconConfig.sparse_mode_used``)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from vp_scene.camera import IMAGE_SIZE, check_image_side
from vp_scene.capture import CaptureModel, REALISTIC
from vp_scene.sim_drone import ground_under

from .metrics import DEFAULT_FSCORE_THRESHOLD

__all__ = ["MAX_CAMERAS", "MAX_MEGAPIXELS", "MATCHINGS", "MATCH_POSES_FROM", "ANCHOR_MAX_ATTITUDE_DEG", "SPARSE_MODES",
           "SparseOptions", "ReconConfig", "matching_method"]

#: The most cameras a plan may have (a second sortie's flown cameras included): ``ReconConfig.
#: max_cameras``, the recon node's parameter ``max_cameras`` and ``--max-cameras`` of ``make
#: recon``; a larger plan is refused with PLAN_TOO_LARGE before anything is rendered. Every image
#: of a realization is held at once, so a reconstruction's memory grows with its cameras; the cap
#: leaves room for several sorties of the planner's (at most 100 cameras a sortie).
MAX_CAMERAS = 256
#: The most megapixels the images of a flight folder may have together (``--images``,
#: ``--max-megapixels``), read from their headers before any is decoded: a folder's memory is
#: its pixels, whatever their number. The pixels of MAX_CAMERAS cameras of 2000 x 1500: hundreds
#: of images of a few megapixels, 64 of 12 MP.
MAX_MEGAPIXELS = MAX_CAMERAS * 2000 * 1500 // 1_000_000

#: ``ReconConfig.matching``: which image pairs SIFT matching compares (see :func:`matching_method`).
MATCHINGS = ("auto", "exhaustive", "poses")
#: ``'auto'`` matches pairs chosen from the poses from this many cameras up, all pairs below:
#: on larger plans exhaustive matching verifies false pairs of views far apart, which then become
#: dense stereo partners (a slower dense step, a worse Chamfer distance); on smaller ones both
#: matchings give about the same.
MATCH_POSES_FROM = 8

#: ``sparse_mode='auto'``: reported attitudes good to this many degrees (1 sigma) anchor the model
#: (a triangulation at poses that far off still finds its tracks with the anchored model's loose
#: first thresholds); rougher ones leave the poses to the images (incremental SfM). Where both
#: modes reconstruct, the anchored model's map and shape Chamfer distances are the incremental
#: mapper's or better, and where the mapper's model fails its self-check the anchored one
#: reconstructs (README "Capture model").
ANCHOR_MAX_ATTITUDE_DEG = 2.0

#: The sparse step's models (``ReconConfig.sparse_mode`` besides ``'auto'``; :mod:`vp_recon.sparse`).
SPARSE_MODES = ("known_poses", "incremental", "anchored")


@dataclass(frozen=True)
class SparseOptions:
    """How the sparse step runs (:func:`vp_recon.sparse.sparse_reconstruct`); ValueError for a
    mode or fallback it does not know.

    Attributes:
        mode: ``'known_poses'`` (triangulate at the given poses), ``'incremental'`` (COLMAP's
            structure from motion) or ``'anchored'`` (the model anchored on the given poses).
        max_features: SIFT features per image.
        num_threads: COLMAP's threads (-1: all cores).
        sift_first_octave: SIFT's first octave: -1 (COLMAP's default) doubles the image first, 0
            starts at its own resolution (about 4x fewer pixels to filter).
        prior_sigma: m per axis to which the given centres are known (a drone's reported
            positions): the incremental mode's pose priors, the registration's weight of the
            centres and the scale of the self-check.
        attitude_sigma: degrees per axis to which the given attitudes are known: the registration
            weighs them against the centres; None: the attitudes alone give its rotation.
        fallback: incremental: ``'anchored'``, the anchored model of the same matches when the
            structure from motion fails; None: its failure is the sparse step's.
        quiet: silence COLMAP's INFO / WARNING log lines (errors still show).
    """

    mode: str = "known_poses"
    max_features: int = 8192
    num_threads: int = -1
    sift_first_octave: int = -1
    prior_sigma: float = 0.02
    attitude_sigma: Optional[float] = None
    fallback: Optional[str] = "anchored"
    quiet: bool = True

    def __post_init__(self) -> None:
        if self.mode not in SPARSE_MODES:
            raise ValueError(f"unknown sparse mode {self.mode!r}; expected one of {', '.join(SPARSE_MODES)}")
        if self.fallback not in (None, "anchored"):
            raise ValueError(f"fallback must be 'anchored' or None, got {self.fallback!r}")


@dataclass
class ReconConfig:
    """Reconstruction settings.

    Attributes:
        width, height: rendered image size (paper: 2000 x 1500), each side in
            :data:`vp_scene.camera.IMAGE_SIDE_RANGE`.
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
            :mod:`vp_scene.render`).
        num_threads: threads of COLMAP and OpenCV (0: all cores).
        matching: ``'exhaustive'`` (all image pairs), ``'poses'`` (the pairs
            :func:`vp_recon.pairs.select_pairs` picks from the known poses and scene) or
            ``'auto'``: poses from :data:`MATCH_POSES_FROM` cameras up, exhaustive below.
        max_cameras: a plan of more cameras is refused (PLAN_TOO_LARGE, :func:`check_plan_size`).
        mask: how a flight's images are segmented over soil (:data:`vp_recon.segment.MASK_METHODS`):
            ``'auto'`` (excess green for a green plant, else the background model), ``'exg'`` or
            ``'background'`` (:func:`vp_recon.segment.flight_masks`); the blue screen keeps its colour key.
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

    def sparse_options(self) -> SparseOptions:
        """The sparse step's options of these settings: ``sparse_mode_used``, the reported centres
        known to the capture's localization error (at least 1 cm). Reported attitudes rougher than
        :data:`ANCHOR_MAX_ATTITUDE_DEG` (a rig's mount tens of degrees off) are weighed against the
        centres by their sigma, and the anchored model, triangulated at them, is then no fallback:
        at attitudes that far off it registers every image and keeps a handful of points. Good
        attitudes alone give the registration's rotation."""
        capture = self.capture
        rough = not capture.ideal and capture.report_attitude_sigma > ANCHOR_MAX_ATTITUDE_DEG
        return SparseOptions(mode=self.sparse_mode_used, max_features=self.max_features,
                             num_threads=self.num_threads or -1, sift_first_octave=self.sift_first_octave,
                             prior_sigma=max(capture.report_position_sigma, 0.01),
                             attitude_sigma=capture.report_attitude_sigma if rough else None,
                             fallback=None if rough else "anchored")

    @property
    def ground_used(self) -> bool:
        """``ground`` with ``None`` resolved by the capture (soil for a flight)."""
        return ground_under(self.capture, self.ground)

    def validate(self) -> "ReconConfig":
        """Raise ValueError naming the first bad field; return self."""
        for name in ("width", "height"):
            v = getattr(self, name)
            if not isinstance(v, (int, np.integer)):
                raise ValueError(f"{name} must be an integer of pixels, got {v!r}")
            check_image_side(name, v)
        if not (isinstance(self.fov, (int, float)) and 0 < self.fov < math.pi):
            raise ValueError(f"fov must be in (0, pi) rad, got {self.fov!r}")
        if self.sparse_mode not in ("auto",) + SPARSE_MODES:
            raise ValueError(f"sparse_mode must be one of auto, {', '.join(SPARSE_MODES)}, got {self.sparse_mode!r}")
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
        from .segment import MASK_METHODS

        if self.mask not in MASK_METHODS:
            raise ValueError(f"mask must be one of {', '.join(MASK_METHODS)}, got {self.mask!r}")
        if isinstance(self.max_cameras, bool) or not isinstance(self.max_cameras, (int, np.integer)) \
                or self.max_cameras < 2:
            raise ValueError(f"max_cameras must be an integer >= 2, got {self.max_cameras!r}")
        return self


def matching_method(matching: str, num_cameras: int) -> str:
    """The matching that runs: ``'poses'`` or ``'exhaustive'`` as asked; ``'auto'``: ``'poses'``
    when ``num_cameras >= MATCH_POSES_FROM``, else ``'exhaustive'``."""
    if matching not in MATCHINGS:
        raise ValueError(f"matching must be one of {', '.join(MATCHINGS)}, got {matching!r}")
    if matching == "auto":
        return "poses" if num_cameras >= MATCH_POSES_FROM else "exhaustive"
    return matching
