"""What a reconstruction gives: one realization's reconstruction and scores
(:class:`RealizationResult`), a plan's over its realizations (:class:`PlanReconResult`,
:func:`plan_result`), a capture set's reconstruction before any truth is read
(:class:`ViewsResult`) and its sparse step's (:class:`SparseResult`, the :class:`SparseModel` kept
and what matching found), and the planning cloud it is given as its prior (:class:`Prior`).
Distances in metres."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Optional, Sequence

import numpy as np
from numpy.typing import NDArray

from .errors import check_scene
from .metrics import CloudScore, Scores
from .progress import STAGES

__all__ = ["RealizationResult", "RealizationFn", "PlanReconResult", "plan_result", "Prior", "SparseModel",
           "SparseResult", "ViewsResult"]


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
            in; pixels): metrics without a ground truth.
        coverage: :class:`vp_recon.metrics.Coverage` of the planning cloud (no truth read).
        sparse_models: the structure-from-motion models merged, each registered to map on its own
            reported poses (parts of a plan that share no matches; :func:`vp_recon.sparse_modes.merge_models`).
        centre_residual: incremental: RMS distance, m, of the registered cameras from the reported
            poses after the registration (the sparse step's self-check; no truth read); else NaN.
        sparse_fallback: why the structure from motion was not kept (the sparse step then made the
            model anchored on the reported poses, ``sparse_mode`` 'anchored'); '' otherwise.
        control: the registration on the flight's ground control
            (:meth:`vp_recon.gcp.Registration.to_dict`), None without control points.
        mask: how the images were segmented (:meth:`vp_recon.segment.MaskChoice.to_dict`; None:
            the renderer's masks or the blue screen's colour key).
        reported, K: the poses the drones reported ((N, 6) [c, v] or (N, 7) poses) and the
            intrinsics: with ``rendered``, the capture set (:meth:`captured_views`).
        ground_control: the capture set's ground control points
            (:class:`vp_scene.ground_control.GroundControl`: the field's markers), None without.
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
    ground_control: object = field(default=None, repr=False)

    def captured_views(self) -> object:
        """The capture set this realization was reconstructed from
        (:class:`vp_recon.flight.CapturedViews`: its images, the poses reported, K, the ground
        control), for :func:`vp_recon.flight.write_flight`; None when its images were not kept."""
        from .flight import CapturedViews

        if not self.rendered or self.reported is None:
            return None
        return CapturedViews(names=[f"view_{i:03d}.png" for i in range(len(self.rendered))], images=self.rendered,
                             reported=self.reported, K=self.K, realization=self.realization,
                             control=self.ground_control)


#: on_realization(result) as soon as a realization is reconstructed (e.g. to publish it).
RealizationFn = Callable[["RealizationResult"], None]


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


def plan_result(results: Sequence[RealizationResult], seconds: Optional[dict] = None) -> PlanReconResult:
    """The :class:`PlanReconResult` of the realizations' results (Chamfer mean, population std,
    shape mean; ``seconds`` summed per stage, plus ``total`` when given)."""
    ch = np.array([r.chamfer for r in results])
    secs = {s: float(sum(r.seconds.get(s, 0.0) for r in results)) for s in ("mesh",) + STAGES}
    secs.update(seconds or {})
    return PlanReconResult(realizations=list(results), chamfer_mean=float(ch.mean()), chamfer_std=float(ch.std()),
                           seconds=secs, chamfer_shape_mean=float(np.mean([r.chamfer_shape for r in results])))


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
        pts = check_scene(noisy_scene)
        plant = np.asarray(noisy_scene.scene.plant_index, dtype=np.int64)
        return cls(points=pts.reshape(-1, 3), plant=np.tile(plant, pts.shape[0]), realizations=int(pts.shape[0]))


@dataclass
class SparseModel:
    """A sparse model in the world, as each mode of the sparse step makes it (:mod:`vp_recon.sparse_modes`).

    Attributes:
        points: (M, 3) float64 world points; colors: (M, 3) uint8 RGB.
        mean_track_length: mean number of images observing a point.
        cameras: (N, 7) the poses (x, y, z, qx, qy, qz, qw, :mod:`vp_scene.camera`) of the model's
            cameras in the world frame, roll kept: the given ones in ``known_poses`` mode; else
            the registered images' estimated poses after the alignment, NaN rows for images not
            registered.
        registered: images with a pose in the model (that observe >= 1 point).
        mean_reprojection_error: mean reprojection error of the model's points, pixels (COLMAP's
            ``compute_mean_reprojection_error``, point-weighted over merged models; a metric
            without a ground truth).
        models: the models merged (``incremental``: every model of >= 3 registered images, each
            aligned to the world on its own, :func:`vp_recon.sparse_modes.merge_models`; 1 otherwise).
        centre_residual: ``incremental`` and ``anchored``: RMS distance, m, of the registered images'
            centres after the alignment from the given (reported) ones (the self-check's figure); NaN
            for ``known_poses``.
    """

    points: NDArray[np.float64]
    colors: NDArray[np.uint8]
    mean_track_length: float
    cameras: NDArray[np.float64]
    registered: int
    mean_reprojection_error: float
    models: int
    centre_residual: float


@dataclass
class SparseResult(SparseModel):
    """What :func:`vp_recon.sparse.sparse_reconstruct` gives: the model kept (the
    :class:`SparseModel` fields) and what extraction and matching found.

    Attributes:
        keypoints: SIFT keypoints per image.
        verified_pairs: image pairs with geometrically verified matches.
        pair_inliers: verified inlier matches per image pair (i, j), i < j (indices of the images).
        matched_pairs: image pairs handed to the matcher (N (N - 1) / 2 when exhaustive).
        seconds: wall time of ``extract``, ``match`` and ``triangulate`` (the model, any mode).
        mode: the model that was kept: ``'known_poses'``, ``'incremental'`` or ``'anchored'`` (also
            when the incremental mode fell back to it).
        fallback: why the structure from motion was not kept (its SparseError's message); '' when
            it was, or was not tried.
    """

    keypoints: list = field(default_factory=list)
    verified_pairs: int = 0
    pair_inliers: dict = field(default_factory=dict)
    matched_pairs: int = 0
    seconds: dict = field(default_factory=dict)
    mode: str = "known_poses"
    fallback: str = ""


@dataclass
class ViewsResult:
    """What :func:`reconstruct_views` makes of a capture set (distances metres; no truth read).

    Attributes:
        points, colors: the scored cloud (dense, else the cleaned sparse one), world / RGB.
        source: ``'dense'`` or ``'sparse'``.
        sparse: the :class:`SparseResult` (registered images, mean track length,
            mean reprojection error, ...); sparse_clean: its cloud cropped and silhouette-filtered.
        dense: the dense result (None when ``config.dense`` is off).
        seeing: indices of the images whose plant mask has >= ``min_foreground`` pixels.
        matching, mode: the matching and sparse step that ran; t_pairs: seconds choosing pairs.
        coverage: :class:`vp_recon.metrics.Coverage` of the prior (None without a prior).
        seconds: wall time of ``sparse`` and ``dense``.
        control: the :class:`vp_recon.gcp.Registration` on the flight's ground control (None
            without control points).
        mask: the :class:`vp_recon.segment.MaskChoice` of a flight segmented over soil (None: the
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
