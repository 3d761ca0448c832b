"""A sparse model registered to the world on the poses its images were given (a flight's reported ones).

A structure-from-motion model has its own gauge (frame and scale); a flight knows every image's
pose to a drone's accuracy, so the model is placed in the world by the similarity
x_world = s R x_model + t that takes its images to their given poses (:func:`similarity_from_poses`):
the rotation from the images' attitudes and centres, each weighted by how well it is known, the
scale and translation from the centres. A rig whose attitudes are known only roughly is
registered on its centres. :func:`align_model` registers a whole model, :func:`register_parts`
each connected part of one on its own (parts that share no points have a gauge each).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np
import pycolmap
from numpy.typing import NDArray

from vp_scene.camera import body_from_optical

from .errors import SparseError

__all__ = ["PoseAnchor", "similarity_from_poses", "align_model", "register_parts"]


@dataclass(frozen=True)
class PoseAnchor:
    """The poses a model is registered on, one per image in the workspace's order: ``centres``
    (N, 3) and ``attitudes`` (N, 3, 3) cam_from_world rotations in the world, and ``sigmas``
    (position m, attitude rad, per axis) that weigh the two in the rotation (None: the attitudes
    alone give it)."""

    centres: NDArray[np.float64]
    attitudes: NDArray[np.float64]
    sigmas: Optional[tuple] = None


def similarity_from_poses(model_centres: NDArray[np.float64], model_R_cw: NDArray[np.float64],
                          centres: NDArray[np.float64], R_cw: NDArray[np.float64],
                          sigmas: Optional[tuple] = None) -> NDArray[np.float64]:
    """The similarity x_world = s R x_model + t (3 x 4 matrix [sR | t]) of a model whose images'
    centres and attitudes (cam_from_world rotations) are known in the world, to a drone's accuracy.

    Rotation: each image gives one, R_i = R_cw_i^T R_cw_model_i (a direction d_model seen by the
    camera is R_cw_model d_model = R_cw d_world); their chordal L2 mean (scipy Rotation.mean).
    Scale and translation: least squares of s R c_model + t = c over the centres with R fixed,
    s = sum (R c'_model . c') / sum |c'_model|^2 on centred coordinates. Why not the centres
    alone (Umeyama): the rotation a few centres give is known to sigma / spread (2 cm over the
    1 m of a 4-camera plan: about 1 degree, worse for a tight arc), each reported attitude to
    its own sigma and independently. Degenerate: all centres at one point (no scale): SparseError.

    ``sigmas`` = (position m, attitude rad), per axis, of the reported poses: the rotation is
    then the most likely one given both, R maximizing tr(R^T A) with A = sum_i R_i / sigma_a^2 +
    2 s sum_i c'_i c'_model,i^T / sigma_p^2 (the log-likelihood of Gaussian centre errors and of
    small attitude errors, whose chordal distance |R - R_i|_F^2 is twice the squared angle; an
    orthogonal Procrustes solved by SVD, alternated with s three times). A small attitude sigma
    gives the attitudes' chordal mean above; a large one, a rig that reports its attitude only
    roughly (a camera mount tens of degrees off), Umeyama's rotation of the centres; between, both
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


def align_model(rec: object, names: Sequence[str], anchor: PoseAnchor,
                xyz: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The model's points ``xyz`` and cameras in the world: the similarity that takes its posed
    images to their ``anchor`` poses (:func:`similarity_from_poses`). Cameras as poses (N, 7),
    roll kept, NaN rows for the images the model does not hold; SparseError as the similarity."""
    idx = {n: i for i, n in enumerate(names)}
    reg = [im for im in rec.images.values() if im.has_pose]
    src = [np.asarray(im.projection_center()) for im in reg]
    tgt = [anchor.centres[idx[im.name]] for im in reg]
    model_R = np.array([np.asarray(im.cam_from_world().rotation.matrix()) for im in reg])
    M = similarity_from_poses(np.array(src), model_R, np.array(tgt),
                              np.asarray(anchor.attitudes)[[idx[im.name] for im in reg]], anchor.sigmas)
    rot = M[:, :3] / np.cbrt(np.linalg.det(M[:, :3]))  # the similarity's rotation
    est = np.full((len(names), 7), np.nan)
    for im, c in zip(reg, src):
        R_cw = np.asarray(im.cam_from_world().rotation.matrix())
        est[idx[im.name], :3] = M[:, :3] @ c + M[:, 3]
        est[idx[im.name], 3:] = body_from_optical(R_cw @ rot.T)  # x_world = rot x_model: R_cw,world = R_cw rot^T
    return xyz @ M[:, :3].T + M[:, 3], est


def register_parts(rec: object, names: Sequence[str], anchor: PoseAnchor) -> None:
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
            M = similarity_from_poses(model_c, model_R, anchor.centres[which], anchor.attitudes[which],
                                      anchor.sigmas)
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
