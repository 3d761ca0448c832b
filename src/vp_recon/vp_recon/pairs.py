"""Image pairs worth matching, chosen from the known camera poses and the known scene.

Exhaustive matching compares all N (N - 1) / 2 image pairs. In a field planned with many cameras
most pairs see different plants or look at the same plant from too far apart for SIFT to match
(it matches most pairs up to about 45 degrees apart, few beyond 60). The poses are known, and so is the scene the renderer draws, so the pairs that
can match are known before any image is read. The rule, for cameras (the poses reported, any
attitude, or levelled ``[c, v]``, :mod:`vp_scene.camera`)
and the scene points {X}:

1. *Sample*: at most ``max_points`` points, evenly strided through the array (deterministic; a
   scene stores its plants one after another, so every plant keeps its share).
2. *In view*: V[i, s] = point s projects inside camera i's image, in front of it
   (:func:`vp_scene.camera.project`; no occlusion test). n_i = sum_s V[i, s]; camera i *sees the
   scene* when n_i > 0.
3. *Shared points*: S_ij = sum_s V[i, s] V[j, s]; overlap o_ij = S_ij / min(n_i, n_j).
4. *Triangulation angle* of a shared point X: alpha_ij(X) = angle(c_i - X, c_j - X), and
   a_ij = median of alpha_ij over the shared points.
5. *Qualifying pair*: S_ij >= ``min_shared`` and o_ij >= ``min_overlap`` and
   ``min_angle`` <= a_ij <= ``max_angle``.
6. *No orphan*: a camera i with q_i < ``min_partners`` qualifying partners is also paired with
   its ``min_partners - q_i`` best other cameras among those that share at least one point with
   it (S_ij >= 1) and do not qualify; best = smallest distance of a_ij from the window
   [min_angle, max_angle], ties broken by the larger overlap, then the lower index. The fill-up
   is computed from the qualifying pairs only (order-independent), so a camera can end with more
   partners than ``min_partners`` when others pick it. A camera that shares no point with any
   other camera (sees nothing, or sees what no other sees) stays unpaired: there is nothing to
   triangulate.

The result is the union of 5 and 6 as (i, j) with i < j, sorted, no duplicates.

Without an occlusion test two cameras on opposite sides of a plant "share" its points; the angle
window (a_ij near 180 degrees) is what keeps them apart.

The pairs may split the cameras into parts that share no pair (a second sortie's few cameras pair
among themselves; COLMAP then makes one model per part, each registered on its own poses). The
parts are not joined by each camera's best partners outside its part: those pairs are far apart,
and among alike plants they verify false matches, one model of all the images with its cameras
metres from the reported ones (README "A second sortie").

Cost: one projection per camera of at most ``max_points`` points, then a loop over cameras i
whose arrays are (N - i - 1, S): memory O(N S) whatever the number of scene points. ROS-free.
"""
from __future__ import annotations

import math
import operator
from typing import Iterable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vp_scene.camera import CameraModel, check_poses, project

__all__ = ["DEFAULT_MAX_ANGLE", "DEFAULT_MIN_PARTNERS", "sample_points", "in_view", "pair_geometry",
           "select_pairs", "check_pairs"]

#: Upper end of the triangulation-angle window, rad: SIFT on a plant mostly fails beyond 45-60 degrees.
DEFAULT_MAX_ANGLE: float = math.radians(45.0)
#: Partners every camera that shares points with others keeps (rule 6).
DEFAULT_MIN_PARTNERS: int = 2


def sample_points(points: NDArray[np.float64], max_points: int) -> NDArray[np.float64]:
    """At most ``max_points`` rows of ``points`` (P, 3), evenly strided (all of them when P <= max_points)."""
    if len(points) <= max_points:
        return points
    return points[np.linspace(0, len(points) - 1, max_points).round().astype(np.intp)]


def in_view(cameras: NDArray[np.float64], points: NDArray[np.float64], model: CameraModel) -> NDArray[np.bool_]:
    """(N, S) bool: point s projects inside camera i's image, in front of it (no occlusion test)."""
    vis = np.zeros((len(cameras), len(points)), dtype=bool)
    for i, cam in enumerate(cameras):
        vis[i] = project(points, cam, model.width, model.height, model.fov)[1]
    return vis


def pair_geometry(cameras: NDArray[np.float64], points: NDArray[np.float64], visible: NDArray[np.bool_]
                  ) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """(S (N, N) shared points in view, a (N, N) median triangulation angle in rad, NaN where none).

    S_ij = sum_s V[i, s] V[j, s] (diagonal: n_i); a_ij = median over the shared points X of the
    angle between c_i - X and c_j - X (a_ii = NaN). One row at a time: memory O(N S).
    """
    n = len(cameras)
    vf = visible.astype(np.float32)
    shared = np.rint(vf @ vf.T).astype(np.int64)          # exact: counts < 2^24
    rays = cameras[:, None, :3] - points[None, :, :]        # (N, S, 3), camera minus point
    rays /= np.maximum(np.linalg.norm(rays, axis=-1, keepdims=True), 1e-12)
    angle = np.full((n, n), np.nan)
    for i in range(n - 1):
        both = visible[i] & visible[i + 1:]                  # (N - i - 1, S)
        count = both.sum(axis=1)
        if not count.any():
            continue
        cos = np.einsum("sk,jsk->js", rays[i], rays[i + 1:])
        alpha = np.where(both, np.arccos(np.clip(cos, -1.0, 1.0)), np.inf)
        alpha.sort(axis=1)                                   # shared points first, +inf after
        lo = np.take_along_axis(alpha, np.maximum(count - 1, 0)[:, None] // 2, axis=1)[:, 0]
        hi = np.take_along_axis(alpha, (count // 2)[:, None], axis=1)[:, 0]
        med = np.where(count > 0, 0.5 * (lo + hi), np.nan)
        angle[i, i + 1:] = med
        angle[i + 1:, i] = med
    return shared, angle


def _check_points(points: ArrayLike) -> NDArray[np.float64]:
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (P, 3), got {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("points contain NaN or infinite values")
    return pts


def select_pairs(cameras: ArrayLike, points: ArrayLike, model: CameraModel, *,
                 max_angle: float = DEFAULT_MAX_ANGLE, min_angle: float = 0.0, min_shared: int = 10,
                 min_overlap: float = 0.1, min_partners: int = DEFAULT_MIN_PARTNERS,
                 max_points: int = 2000) -> list[tuple[int, int]]:
    """The image pairs (i, j), i < j, sorted, that are worth matching (rules 1-6 of the module docstring).

    Args:
        cameras: (N, 7) poses (roll kept) or (N, 6) ``[c, v]``.
        points: (P, 3) the scene the images show (e.g. a wind realization's true points).
        model: image size and field of view of every camera.
        max_angle, min_angle: window of the median triangulation angle a_ij, rad.
        min_shared: shared points in view (of the sample) a qualifying pair needs.
        min_overlap: S_ij / min(n_i, n_j) a qualifying pair needs, in [0, 1].
        min_partners: partners each camera that shares points keeps (0: the window alone decides).
        max_points: scene points sampled (bounds time and memory).

    Raises:
        ValueError: malformed cameras or points, or a parameter out of range.
    """
    cams = check_poses(cameras)
    pts = _check_points(points)
    if not (0.0 <= min_angle <= max_angle <= math.pi):
        raise ValueError(f"need 0 <= min_angle <= max_angle <= pi rad, got {min_angle!r}, {max_angle!r}")
    if not 0.0 <= min_overlap <= 1.0:
        raise ValueError(f"min_overlap must be in [0, 1], got {min_overlap!r}")
    if int(min_shared) < 1 or int(min_partners) < 0 or int(max_points) < 1:
        raise ValueError(f"need min_shared >= 1, min_partners >= 0, max_points >= 1; got {min_shared!r}, "
                         f"{min_partners!r}, {max_points!r}")
    sample = sample_points(pts, int(max_points))
    visible = in_view(cams, sample, model)
    shared, angle = pair_geometry(cams, sample, visible)
    seen = np.diag(shared).copy()
    np.fill_diagonal(shared, 0)
    overlap = shared / np.maximum(np.minimum.outer(seen, seen), 1)
    with np.errstate(invalid="ignore"):                      # NaN angle: no shared point, never qualifies
        qualify = (shared >= min_shared) & (overlap >= min_overlap) & (angle >= min_angle) & (angle <= max_angle)
        gap = np.where(angle < min_angle, min_angle - angle, np.maximum(angle - max_angle, 0.0))
    chosen = qualify.copy()
    missing = np.maximum(int(min_partners) - qualify.sum(axis=1), 0)
    for i in np.flatnonzero(missing):
        cand = np.flatnonzero(~qualify[i] & (shared[i] > 0))
        best = cand[np.lexsort((cand, -overlap[i, cand], gap[i, cand]))][:missing[i]]
        chosen[i, best] = True
    a, b = np.nonzero(np.triu(chosen | chosen.T, 1))         # row-major: sorted by (i, j)
    return [(int(i), int(j)) for i, j in zip(a, b)]


def check_pairs(pairs: Iterable[tuple[int, int]], num_images: int) -> list[tuple[int, int]]:
    """Pairs as sorted, unique (i, j) with 0 <= i < j < ``num_images`` ((j, i) counts as (i, j));
    ValueError for a pair that is not two distinct image indices in range."""
    out = set()
    for p in pairs:
        try:
            i, j = (operator.index(x) for x in p)
        except (TypeError, ValueError):
            raise ValueError(f"an image pair must be two integers, got {p!r}") from None
        if i == j or not (0 <= i < num_images and 0 <= j < num_images):
            raise ValueError(f"image pair {p!r} is not two distinct indices in 0..{num_images - 1}")
        out.add((min(i, j), max(i, j)))
    return sorted(out)
