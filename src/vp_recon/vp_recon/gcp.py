"""Ground control in a reconstruction: find the control points, triangulate them, place the model on them.

A flight's model is placed in ``map`` on the poses the drones reported
(:func:`vp_recon.sparse.similarity_from_poses`); its scale then rests on the spread of a few
camera centres, each known to RTK's 2 cm, and the plant lies metres away from them. Ground control
points (:mod:`vp_scene.ground_control`) surveyed around the plant hold the scale and the position
where the plant is. :func:`register` places the model on both:

1. observations: each control point's pixel in each image, given (OpenDroneMap's
   ``gcp_list.txt``) or found (:func:`detect_markers`: OpenCV's ArUco detector, a marker's centre
   the intersection of its square's diagonals, sub-pixel corners);
2. :func:`triangulate`: each point seen in 2 or more images, from the model's cameras (linear
   least squares of the rays, Hartley & Zisserman 12.2), kept when its rays meet at 2 degrees or
   more and it reprojects within :data:`MAX_REPROJECTION_PX` in every image;
3. the similarity x_map = s R x_model + t that best takes the model's camera centres to the
   reported ones (sigma ``camera_sigma`` per axis) **and** the triangulated control points to
   their surveyed positions (``control.sigma``): weighted least squares (Umeyama 1991 with
   weights 1 / sigma^2, :func:`weighted_similarity`); with fewer than 3 control points (or 3 in a
   line) the model is left where the poses put it.

The similarity is a correction of a model already in ``map`` (a few centimetres and a percent
of scale); it is applied to the points and cameras, and :class:`Registration` says what was
used and the residuals (no truth read). ROS-free: numpy, OpenCV.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np
from numpy.typing import NDArray

from vp_scene.camera import world_to_camera
from vp_scene.ground_control import ARUCO_DICTIONARY, GcpObservation, GroundControl

__all__ = ["MAX_REPROJECTION_PX", "MIN_RAY_ANGLE_DEG", "Registration", "detect_markers", "triangulate",
           "weighted_similarity", "register"]

#: A control point is kept when it reprojects within this many pixels in every image that sees it.
MAX_REPROJECTION_PX: float = 4.0
#: ... and when two of its rays meet at this angle or more (a point seen from one place has no depth).
MIN_RAY_ANGLE_DEG: float = 2.0


@dataclass
class Registration:
    """What :func:`register` did (distances m; no truth read).

    Attributes:
        used: control points the similarity used (seen in 2+ images, consistent).
        observed: control points seen in at least one image.
        applied: whether the model was moved (3 or more control points, not in a line).
        scale: the correction's scale (1: none); shift: its translation at the points' centre, m;
            turn: its rotation, degrees.
        control_residual: RMS distance of the used control points from their surveyed positions
            after the correction; camera_residual: of the cameras from the reported centres.
        reason: why the model was not moved ('' when it was).
    """

    used: int = 0
    observed: int = 0
    applied: bool = False
    scale: float = 1.0
    shift: float = 0.0
    turn: float = 0.0
    control_residual: float = math.nan
    camera_residual: float = math.nan
    reason: str = ""
    points: dict = field(default_factory=dict, repr=False)

    def to_dict(self) -> dict:
        """JSON form (recon.json): every field but the triangulated points; NaN as None."""
        out = {k: v for k, v in self.__dict__.items() if k != "points"}
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in out.items()}


def detect_markers(images: Sequence[NDArray[np.uint8]], names: Sequence[str],
                   wanted: Optional[set] = None) -> list:
    """ArUco markers of :data:`ARUCO_DICTIONARY` in RGB ``images``: one
    :class:`~vp_scene.ground_control.GcpObservation` per marker and image (named by its id; only
    ids in ``wanted`` when given), at the intersection of its square's diagonals (corners refined
    to sub-pixel). A marker seen twice in one image (a reflection, a duplicate print) is left out of it."""
    import cv2

    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, ARUCO_DICTIONARY))
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    detector = cv2.aruco.ArucoDetector(dictionary, params)
    out = []
    for name, im in zip(names, images):
        corners, ids, _ = detector.detectMarkers(cv2.cvtColor(np.asarray(im, np.uint8), cv2.COLOR_RGB2GRAY))
        if ids is None:
            continue
        ids = ids.ravel()
        for c, mid in zip(corners, ids):
            if (ids == mid).sum() > 1 or (wanted is not None and str(int(mid)) not in wanted):
                continue
            p = np.asarray(c, dtype=np.float64).reshape(4, 2)
            # the diagonals p0-p2 and p1-p3 meet at the square's centre (perspective keeps lines)
            a, b = p[2] - p[0], p[3] - p[1]
            s = np.linalg.solve(np.stack([a, -b], axis=1), p[1] - p[0])[0]
            u, v = p[0] + s * a
            out.append(GcpObservation(name=str(int(mid)), image=str(name), u=float(u), v=float(v)))
    return out


def _project(K: NDArray[np.float64], R: NDArray[np.float64], c: NDArray[np.float64],
             X: NDArray[np.float64]) -> NDArray[np.float64]:
    y = R @ (X - c)
    return (K @ (y / y[2]))[:2]


def triangulate(observations: Sequence[GcpObservation], names: Sequence[str], cameras: NDArray[np.float64],
                K: NDArray[np.float64]) -> dict:
    """{name: (x, y, z)} of the control points seen in 2+ images whose camera is known
    (``cameras`` (N, 6) [c, v] rows of the model, NaN rows: not registered), by linear least
    squares of their rays; kept when two rays meet at :data:`MIN_RAY_ANGLE_DEG` or more and the
    point reprojects within :data:`MAX_REPROJECTION_PX` in every one of those images."""
    cams = np.asarray(cameras, dtype=np.float64)
    index = {n: i for i, n in enumerate(names)}
    ok = np.isfinite(cams).all(axis=1)
    R_all = np.full((len(cams), 3, 3), np.nan)
    if ok.any():
        R_all[ok] = world_to_camera(cams[ok])[0]
    Kinv = np.linalg.inv(K)
    seen: dict = {}
    for o in observations:
        i = index.get(o.image)
        if i is not None and ok[i]:
            seen.setdefault(o.name, []).append((i, o.u, o.v))
    out = {}
    for name, obs in seen.items():
        if len(obs) < 2:
            continue
        centres = np.array([cams[i, :3] for i, _, _ in obs])
        rays = np.array([R_all[i].T @ (Kinv @ np.array([u, v, 1.0])) for i, u, v in obs])
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        # sum over rays of (I - d d^T)(X - c) = 0: the point closest to every ray
        P = np.eye(3)[None] - rays[:, :, None] * rays[:, None, :]
        try:
            X = np.linalg.solve(P.sum(axis=0), np.einsum("nij,nj->i", P, centres))
        except np.linalg.LinAlgError:
            continue
        widest = np.degrees(np.arccos(np.clip(np.min(rays @ rays.T), -1.0, 1.0)))
        if widest < MIN_RAY_ANGLE_DEG:
            continue
        err = max(float(np.linalg.norm(_project(K, R_all[i], cams[i, :3], X) - (u, v))) for i, u, v in obs)
        if err <= MAX_REPROJECTION_PX:
            out[name] = X
    return out


def weighted_similarity(src: NDArray[np.float64], dst: NDArray[np.float64],
                        weights: NDArray[np.float64]) -> tuple[float, NDArray[np.float64], NDArray[np.float64]]:
    """(s, R, t) minimizing sum_i w_i |s R src_i + t - dst_i|^2: Umeyama's closed form (1991) on
    weighted centroids and covariance (pycolmap's and scipy's estimators take no weights: the
    cameras' 2 cm and the control points' 1 cm must count as such)."""
    w = np.asarray(weights, dtype=np.float64) / np.sum(weights)
    mu_s, mu_d = w @ src, w @ dst
    a, b = src - mu_s, dst - mu_d
    U, S, Vt = np.linalg.svd((b * w[:, None]).T @ a)
    D = np.eye(3)
    D[2, 2] = np.sign(np.linalg.det(U @ Vt)) or 1.0
    R = U @ D @ Vt
    s = float(np.trace(np.diag(S) @ D) / (w @ np.sum(a * a, axis=1)))
    return s, R, mu_d - s * R @ mu_s


def register(points: NDArray[np.float64], cameras: NDArray[np.float64], names: Sequence[str],
             images: Sequence[NDArray[np.uint8]], K: NDArray[np.float64], reported: NDArray[np.float64],
             control: GroundControl, camera_sigma: float) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                                                   Registration]:
    """The model (``points`` (P, 3), ``cameras`` (N, 6) with NaN rows for images not registered,
    already in ``map`` from the reported poses) placed on the control points and the reported
    centres together (module docstring): (points, cameras, :class:`Registration`). Observations
    are ``control.observations`` when given, else the ArUco markers found in ``images``."""
    cams = np.asarray(cameras, dtype=np.float64)
    obs = list(control.observations) or detect_markers(images, names, set(control.positions))
    reg = Registration(observed=len({o.name for o in obs}))
    found = {n: X for n, X in triangulate(obs, names, cams, K).items() if n in control.positions}
    reg.points = found
    reg.used = len(found)
    if len(found) < 3:
        reg.reason = f"{len(found)} control point(s) seen in 2 or more images (3 are needed)"
        return points, cams, reg
    model_g = np.array(list(found.values()))
    world_g = np.array([control.positions[n] for n in found])
    if np.linalg.svd(world_g - world_g.mean(axis=0), compute_uv=False)[1] < 0.05:
        reg.reason = "the control points seen lie in a line"
        return points, cams, reg
    ok = np.isfinite(cams).all(axis=1)
    src = np.concatenate([cams[ok, :3], model_g])
    dst = np.concatenate([np.asarray(reported, np.float64)[ok, :3], world_g])
    w = np.concatenate([np.full(int(ok.sum()), 1.0 / camera_sigma ** 2), np.full(len(found), 1.0 / control.sigma ** 2)])
    s, R, t = weighted_similarity(src, dst, w)
    moved = points @ (s * R).T + t
    out = cams.copy()
    out[ok, :3] = cams[ok, :3] @ (s * R).T + t
    out[ok, 3:] = cams[ok, 3:] @ R.T
    centre = points.mean(axis=0) if len(points) else model_g.mean(axis=0)
    reg.applied, reg.scale = True, s
    reg.shift = float(np.linalg.norm(s * R @ centre + t - centre))
    reg.turn = float(np.degrees(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))
    reg.control_residual = float(np.sqrt(np.mean(np.sum((model_g @ (s * R).T + t - world_g) ** 2, axis=1))))
    reg.camera_residual = float(np.sqrt(np.mean(np.sum((out[ok, :3] - dst[:ok.sum()]) ** 2, axis=1))))
    return moved, out, reg
