"""Reconstruction quality against the true (noisy-realization) points.

For a reconstruction S and the truth T (point sets in metres), with d(x, Y) = min_{y in Y} |x - y|:

    accuracy     A = (1/|S|) sum_{s in S} d(s, T)      (how close reconstructed points are to the plant)
    completeness C = (1/|T|) sum_{t in T} d(t, S)      (how much of the plant is covered)
    Chamfer      CD = A + C

(the symmetric Chamfer distance; point-cloud-utils' ``chamfer_distance`` returns exactly this sum
of the two mean nearest-neighbour distances, checked in the tests; nearest neighbours here come
from scipy, see :func:`nn_distances`). The F-score at a threshold
tau (Knapitsch et al., "Tanks and Temples", SIGGRAPH 2017) is the harmonic mean of

    precision P(tau) = |{s : d(s, T) < tau}| / |S|,   recall R(tau) = |{t : d(t, S) < tau}| / |T|,
    F(tau) = 2 P R / (P + R)   (0 when P + R = 0).

Everything here is in metres (F in [0, 1]). Paper Table I reports the Chamfer distance x 100:
that scaling is applied only when writing results (``vp_recon.cli`` recon.json and the ROS
``ReconstructionScore`` message), never in this module.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["DEFAULT_FSCORE_THRESHOLD", "ICP_MAX_DISTANCE", "COVERAGE_TAU", "EmptyCloudError", "Scores", "CloudScore",
           "Coverage", "nn_distances", "chamfer", "chamfer_after_icp", "coverage_of_prior"]

#: m: correspondences of the rigid refinement of :func:`chamfer_after_icp` (several times the
#: registration error of a flight with RTK positions, 1-5 cm, and a leaf's width).
ICP_MAX_DISTANCE = 0.05

#: 2 cm: about 1% of a 2 m corn plant, the order of a leaf's width / 5.
DEFAULT_FSCORE_THRESHOLD = 0.02

#: m: tau of :func:`coverage_of_prior` (the F-score's threshold: a prior point counts as covered
#: where the reconstruction's recall would count a true point).
COVERAGE_TAU = DEFAULT_FSCORE_THRESHOLD


class EmptyCloudError(ValueError):
    """The reconstruction (or the truth) has no points: no distance is defined."""


@dataclass
class Scores:
    """The scores of a reconstruction against its truth (:func:`chamfer`): Chamfer = accuracy +
    completeness, metres; fscore, precision and recall unitless in [0, 1]. The fields every
    score record shares (:class:`CloudScore`, :class:`vp_recon.results.RealizationResult`)."""

    chamfer: float
    accuracy: float
    completeness: float
    fscore: float
    precision: float
    recall: float


@dataclass
class CloudScore(Scores):
    """:class:`Scores` at ``threshold`` metres, of a reconstruction of ``num_points`` points."""

    threshold: float
    num_points: int


def _cloud(name: str, x: ArrayLike) -> NDArray[np.float64]:
    p = np.asarray(x, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"{name} must have shape (M, 3), got {p.shape}")
    if len(p) == 0:
        raise EmptyCloudError(f"{name} point cloud is empty: nothing to score")
    if not np.all(np.isfinite(p)):
        raise ValueError(f"{name} contains NaN or infinite coordinates")
    return np.ascontiguousarray(p)


def nn_distances(query: ArrayLike, data: ArrayLike) -> NDArray[np.float64]:
    """d(q, data) for every query point (exact kd-tree search, scipy's cKDTree, all cores).

    Not point-cloud-utils' ``k_nearest_neighbors``: pcu 0.34 returns a wrong distance for a
    single query point (caught by the tests); its ``chamfer_distance`` agrees with
    :func:`chamfer` otherwise and is no faster.
    """
    from scipy.spatial import cKDTree

    q = _cloud("query", query)
    d = _cloud("data", data)
    dist, _ = cKDTree(d).query(q, k=1, workers=-1)
    return np.asarray(dist, dtype=np.float64).reshape(-1)


def chamfer(recon: ArrayLike, truth: ArrayLike, threshold: float = DEFAULT_FSCORE_THRESHOLD) -> CloudScore:
    """Accuracy, completeness, Chamfer (= A + C) and F-score at ``threshold`` (metres) of recon vs truth.

    Raises:
        EmptyCloudError: recon or truth has no points.
        ValueError: bad shapes, non-finite coordinates, or threshold <= 0.
    """
    if not (np.isfinite(threshold) and threshold > 0):
        raise ValueError(f"F-score threshold must be > 0 metres, got {threshold}")
    s = _cloud("reconstruction", recon)
    t = _cloud("truth", truth)
    d_st = nn_distances(s, t)
    d_ts = nn_distances(t, s)
    acc, comp = float(d_st.mean()), float(d_ts.mean())
    precision = float(np.mean(d_st < threshold))
    recall = float(np.mean(d_ts < threshold))
    f = 0.0 if precision + recall == 0 else 2 * precision * recall / (precision + recall)
    return CloudScore(chamfer=acc + comp, accuracy=acc, completeness=comp, fscore=f, precision=precision,
                      recall=recall, threshold=float(threshold), num_points=len(s))


def chamfer_after_icp(recon: ArrayLike, truth: ArrayLike, threshold: float = DEFAULT_FSCORE_THRESHOLD,
                      max_distance: float = ICP_MAX_DISTANCE) -> CloudScore:
    """:func:`chamfer` of ``recon`` after a rigid refinement onto ``truth``: the shape alone.

    Point-to-point ICP (Besl & McKay 1992; Open3D's ``registration_icp``, identity start,
    correspondences within ``max_distance`` m, at most 50 iterations). A reconstruction whose
    registration is off by more than about ``max_distance`` keeps (most of) that error. When the
    refinement finds no correspondence, or ends worse than it started (ICP on a cloud far off
    can slide into a wrong local minimum), the score is the unrefined one: a refinement never
    makes the shape worse than the registration.
    """
    import open3d as o3d

    s = _cloud("reconstruction", recon)
    t = _cloud("truth", truth)
    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(s))
    tgt = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(t))
    fit = o3d.pipelines.registration.registration_icp(
        src, tgt, float(max_distance), np.eye(4),
        o3d.pipelines.registration.TransformationEstimationPointToPoint(),
        o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=50))
    unrefined = chamfer(s, t, threshold)
    if fit.fitness <= 0:
        return unrefined
    T = np.asarray(fit.transformation)
    refined = chamfer(s @ T[:3, :3].T + T[:3, 3], t, threshold)
    return refined if refined.chamfer <= unrefined.chamfer else unrefined


@dataclass(frozen=True)
class Coverage:
    """Coverage of the prior (no ground truth read).

    Attributes:
        fraction: covered points of the best-covered realization of the prior, in [0, 1].
        per_plant: (P,) that fraction for each plant (index = plant index of the scene), each
            plant's best realization.
        covered: (M,) bool over the whole prior, which points are within ``tau`` of the reconstruction.
        realization: the prior's realization that ``fraction`` is of, and
        block: its (start, stop) indices in the prior.
        tau: metres.
    """

    fraction: float
    per_plant: tuple
    covered: NDArray[np.bool_]
    realization: int
    block: tuple
    tau: float


def coverage_of_prior(recon: ArrayLike, prior: ArrayLike, plant: ArrayLike, tau: float = COVERAGE_TAU,
                      realizations: int = 1) -> Coverage:
    """The fraction of the planning cloud ``prior`` within ``tau`` metres of the reconstruction,
    overall and per plant (``plant``: the plant index of each prior point).

    What a practitioner can check after a real flight: the prior is the noisy scene the planner
    saw, ``realizations`` blocks of the same points displaced by K winds ((K P, 3), or (K, P, 3));
    the wind of the moment is not known, so the coverage is that of the realization the
    reconstruction covers best, max_k |{p in prior_k : d(p, S) < tau}| / |prior_k| (the recall of
    the F-score with prior_k in place of the truth); per plant likewise, each plant's best. Over
    the whole prior (two realizations of a plant bent differently) a perfect reconstruction of one
    covers about half, which says more about the wind than about the plan.

    Raises:
        EmptyCloudError: no reconstructed or prior point. ValueError: bad shapes, tau <= 0.
    """
    if not (np.isfinite(tau) and tau > 0):
        raise ValueError(f"coverage tau must be > 0 metres, got {tau}")
    p = _cloud("prior", np.asarray(prior, dtype=np.float64).reshape(-1, 3))
    K = int(realizations)
    if K < 1 or len(p) % K:
        raise ValueError(f"the prior's {len(p)} points are not {realizations} realizations of equal size")
    idx = np.asarray(plant, dtype=np.int64).reshape(-1)
    if len(idx) == len(p) // K and K > 1:
        idx = np.tile(idx, K)
    if len(idx) != len(p) or (len(idx) and idx.min() < 0):
        raise ValueError(f"plant must give a plant index >= 0 for each of the {len(p)} prior points, got {idx.shape}")
    covered = nn_distances(p, _cloud("reconstruction", recon)) < tau
    frac = covered.reshape(K, -1).mean(axis=1)
    n_plants = int(idx.max()) + 1
    per = np.full((K, n_plants), np.nan)
    for k, (cov_k, idx_k) in enumerate(zip(covered.reshape(K, -1), idx.reshape(K, -1))):
        counts = np.bincount(idx_k, minlength=n_plants)
        hits = np.bincount(idx_k, weights=cov_k.astype(np.float64), minlength=n_plants)
        per[k] = np.where(counts > 0, hits / np.maximum(counts, 1), np.nan)
    best = int(np.argmax(frac))
    return Coverage(fraction=float(frac[best]), per_plant=tuple(float(x) for x in np.nanmax(per, axis=0)),
                    covered=covered, realization=best, block=(best * (len(p) // K), (best + 1) * (len(p) // K)),
                    tau=float(tau))
