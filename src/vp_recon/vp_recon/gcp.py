"""Ground control in a reconstruction: find the control points and place the model on them.

A flight's model is placed in ``map`` on the poses the drones reported
(:func:`vp_recon.registration.similarity_from_poses`); its scale then rests on the spread of a few
camera centres, each known to RTK's 2 cm, and the plant lies metres away from them. Ground control
points (:mod:`vp_scene.ground_control`) surveyed around the plant hold the scale and the position
where the plant is. :func:`register` places the model on both:

1. observations: each control point's pixel in each image, given (OpenDroneMap's
   ``gcp_list.txt``) or found (:func:`detect_markers`: OpenCV's ArUco detector, a marker's centre
   the intersection of its square's diagonals, sub-pixel corners);
2. the similarity x_map = s R x_model + t that best explains, together, every observation (the
   surveyed point, taken into the model's frame by the similarity, must project onto its pixel in
   the model's camera: reprojection error over sigma_px, 1 pixel of detection and the survey's
   sigma at the point's depth) and the reported camera centres (their distance to the model's
   centres moved by the similarity, over ``camera_sigma``): robust least squares (scipy's
   ``least_squares``, soft-L1 at 3 sigma: a misread marker does not drag the model) in 7
   parameters, started at the identity (the model is already in ``map``). A point seen in one
   image constrains the model too: a circle of 4 cameras 90 degrees apart sees each marker once,
   and triangulating the markers first would place none;
3. with fewer than 3 control points seen (or 3 in a line) the model stays where the poses put it.

Before the fit every control point seen is checked against the model the reported poses placed
(the gate): the rays of the images that see it must pass (the median of them) within
:data:`GATE_SIGMAS` sigmas of the reported centres' and the survey's errors plus
:data:`GATE_ANGLE` at its depth (the model's attitude) of its surveyed position. A point farther
off (its id misread, its survey wrong, its file in another frame: markers.csv 1 km off) is
rejected and named with its distance, never fitted: a correction of centimetres cannot reach it,
and a robust fit would be dragged by it.

The similarity is a correction of a model already in ``map`` (a few centimetres and a percent
of scale); it is applied to the points and cameras, and :class:`Registration` says what was
used, what was rejected and why, and the residuals (no truth read; :func:`describe` is its one
line for a log). ROS-free: numpy, scipy, OpenCV.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np
from numpy.typing import NDArray

from vp_scene.camera import as_poses, world_to_camera
from vp_scene.ground_control import ARUCO_DICTIONARY, GcpObservation, GroundControl

__all__ = ["DETECTION_SIGMA_PX", "GATE_SIGMAS", "GATE_ANGLE", "Registration", "describe", "detect_markers",
           "register"]

#: pixels: the detection error of a marker's centre (its survey error is added at its depth).
DETECTION_SIGMA_PX: float = 1.0
#: The gate (module docstring): sigmas of the reported centres' and the survey's errors a control
#: point may lie from the rays that see it ...
GATE_SIGMAS: float = 10.0
#: ... plus this angle (rad) at its depth: the model's attitude, four times the 0.5 degrees an RTK
#: drone reports. At a marker 2 m deep under RTK's 2 cm and a 1 cm survey the gate is 0.29 m; at
#: 100 m, 3.7 m.
GATE_ANGLE: float = math.radians(2.0)


@dataclass
class Registration:
    """What :func:`register` did (distances m; no truth read).

    Attributes:
        listed: control points given (a file's, or the capture's markers).
        used: control points seen in the registered images that passed the gate (their
            observations placed the model).
        observations: their observations (point, image).
        rejected: {control point: why} of those seen that the gate rejected (module docstring).
        applied: whether the model was moved (3 or more control points seen, not in a line).
        scale: the correction's scale (1: none); shift: its translation at the points' centre, m;
            turn: its rotation, degrees.
        reprojection_px: RMS reprojection error of the observations after the correction, pixels;
            camera_residual: RMS distance of the cameras from the reported centres, m.
        reason: why the model was not moved ('' when it was).
    """

    listed: int = 0
    used: int = 0
    observations: int = 0
    rejected: dict = field(default_factory=dict)
    applied: bool = False
    scale: float = 1.0
    shift: float = 0.0
    turn: float = 0.0
    reprojection_px: float = math.nan
    camera_residual: float = math.nan
    reason: str = ""

    def to_dict(self) -> dict:
        """JSON form (recon.json); NaN as None."""
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in self.__dict__.items()}


def describe(control: dict) -> str:
    """One line of a :meth:`Registration.to_dict` for a log: what was used, rejected and why."""
    rejected = control.get("rejected") or {}
    unseen = control.get("listed", 0) - control.get("used", 0) - len(rejected)
    if control.get("applied"):
        text = (f"ground control: {control['used']} of {control.get('listed', 0)} control points placed the model "
                f"({control['observations']} observations, {control['reprojection_px']:.2f} px RMS; moved "
                f"{control['shift']:.3f} m, scale {control['scale']:.4f}, turned {control['turn']:.2f} degrees)")
    else:
        text = f"ground control not used: {control.get('reason', '')}; the reported poses alone placed the model"
    if rejected:
        text += "; rejected: " + "; ".join(f"{n} {why}" for n, why in sorted(rejected.items()))
    if unseen > 0:
        text += f"; {unseen} not seen in the registered images"
    return text


def _gate(obs: list, control: GroundControl, cams: NDArray[np.float64], index: dict, K: NDArray[np.float64],
          camera_sigma: float) -> dict:
    """{control point: why} of the points seen whose surveyed position the rays of their
    observations miss by more than the gate (module docstring), in the model's cameras."""
    by_point: dict = {}
    Kinv = np.linalg.inv(K)
    for o in obs:
        i = index[o.image]
        R_cw = world_to_camera(cams[i])[0]
        ray = R_cw.T @ (Kinv @ np.array([o.u, o.v, 1.0]))
        ray /= np.linalg.norm(ray)
        w = np.asarray(control.positions[o.name], dtype=np.float64) - cams[i, :3]
        along = float(w @ ray)
        miss = float(np.linalg.norm(w - along * ray)) if along > 0 else float(np.linalg.norm(w))  # behind: all of it
        gate = GATE_SIGMAS * math.hypot(camera_sigma, control.sigma) + max(along, 0.0) * math.tan(GATE_ANGLE)
        by_point.setdefault(o.name, []).append((miss, gate))
    out = {}
    for name, rows in by_point.items():
        miss, gate = (float(np.median([r[j] for r in rows])) for j in (0, 1))
        if miss > gate:
            out[name] = (f"lies {miss:.3g} m from the rays of the {len(rows)} image(s) that see it (the gate: "
                         f"{gate:.2g} m; its survey, id or frame is not the flight's)")
    return out


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


def register(points: NDArray[np.float64], cameras: NDArray[np.float64], names: Sequence[str],
             images: Sequence[NDArray[np.uint8]], K: NDArray[np.float64], reported: NDArray[np.float64],
             control: GroundControl, camera_sigma: float) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                                                   Registration]:
    """The model (``points`` (P, 3), ``cameras`` (N, 7) poses with NaN rows for images not registered,
    already in ``map`` from the reported poses) placed on the control points and the reported
    centres together (module docstring): (points, cameras, :class:`Registration`). Observations
    are ``control.observations`` when given, else the ArUco markers found in ``images``."""
    from scipy.optimize import least_squares
    from scipy.spatial.transform import Rotation

    cams = np.asarray(cameras, dtype=np.float64)
    ok = np.isfinite(cams).all(axis=1)
    index = {n: i for i, n in enumerate(names)}
    obs = [o for o in (list(control.observations) or detect_markers(images, names, set(control.positions)))
           if o.name in control.positions and o.image in index and ok[index[o.image]]]
    rejected = _gate(obs, control, cams, index, np.asarray(K, dtype=np.float64), camera_sigma)
    obs = [o for o in obs if o.name not in rejected]
    seen = sorted({o.name for o in obs})
    reg = Registration(listed=len(control.positions), used=len(seen), observations=len(obs), rejected=rejected)
    if len(seen) < 3:
        reg.reason = (f"{len(seen)} of the {len(seen) + len(rejected)} control points seen in the registered images "
                      "fit the reported poses (3 are needed)" if rejected else
                      f"{len(seen)} control point(s) seen in the registered images (3 are needed)")
        return points, cams, reg
    world = np.array([control.positions[n] for n in seen])
    if np.linalg.svd(world - world.mean(axis=0), compute_uv=False)[1] < 0.05:
        reg.reason = "the control points seen lie in a line"
        return points, cams, reg
    which = np.array([seen.index(o.name) for o in obs])
    cam_of = np.array([index[o.image] for o in obs])
    uv = np.array([[o.u, o.v] for o in obs])
    R_cw = np.full((len(cams), 3, 3), np.nan)
    R_cw[ok] = world_to_camera(cams[ok])[0]
    Ro, co = R_cw[cam_of], cams[cam_of, :3]
    depth = np.einsum("nj,nj->n", Ro[:, 2], world[which] - co)
    sigma_px = np.hypot(DETECTION_SIGMA_PX, control.sigma * K[0, 0] / np.maximum(depth, 1e-3))
    model_c, rep_c = cams[ok, :3], np.asarray(reported, dtype=np.float64)[ok, :3]

    def residuals(x: NDArray[np.float64]) -> NDArray[np.float64]:
        R, s, t = Rotation.from_rotvec(x[:3]).as_matrix(), math.exp(x[3]), x[4:7]
        X = (world[which] - t) @ R / s                      # the surveyed points in the model's frame
        y = np.einsum("nij,nj->ni", Ro, X - co)
        z = np.where(np.abs(y[:, 2]) > 1e-9, y[:, 2], 1e-9)
        proj = (y[:, :2] / z[:, None]) * K[[0, 1], [0, 1]] + K[:2, 2]
        return np.concatenate([((proj - uv) / sigma_px[:, None]).ravel(),
                               ((model_c @ (s * R).T + t - rep_c) / camera_sigma).ravel()])

    fit = least_squares(residuals, np.zeros(7), loss="soft_l1", f_scale=3.0, x_scale=np.r_[1e-2 * np.ones(4), 1e-2 * np.ones(3)])
    R, s, t = Rotation.from_rotvec(fit.x[:3]).as_matrix(), math.exp(fit.x[3]), fit.x[4:7]
    moved = points @ (s * R).T + t
    out = cams.copy()
    out[ok, :3] = model_c @ (s * R).T + t
    if out.shape[1] == 7:  # a pose: its attitude turned by R (roll kept)
        turned = (Rotation.from_matrix(R) * Rotation.from_quat(cams[ok, 3:])).as_quat()
        out[ok] = as_poses(np.hstack([out[ok, :3], turned]))
    else:
        out[ok, 3:] = cams[ok, 3:] @ R.T
    centre = points.mean(axis=0) if len(points) else world.mean(axis=0)
    r = residuals(fit.x)
    reg.applied, reg.scale = True, s
    reg.shift = float(np.linalg.norm(s * R @ centre + t - centre))
    reg.turn = float(np.degrees(np.linalg.norm(fit.x[:3])))
    reg.reprojection_px = float(np.sqrt(np.mean(np.sum((r[:2 * len(obs)].reshape(-1, 2) * sigma_px[:, None]) ** 2,
                                                       axis=1))))
    reg.camera_residual = float(np.sqrt(np.mean(np.sum((out[ok, :3] - rep_c) ** 2, axis=1))))
    return moved, out, reg
