"""Camera geometry of the suite: the pose convention, intrinsics and projection (one home).

Planner, reconstruction and dispatcher all import this module; nothing else defines a camera.

The camera convention (documented here once; README "Camera convention" quotes it)
----------------------------------------------------------------------------------
Units are metres and radians, frame ``map``, REP-103 axes (x forward/east, y left/north, z up;
the ground is z = 0). A camera is 6 numbers ``[cx, cy, cz, vx, vy, vz]``: its centre c and its
viewing direction v, **the optical axis** (v need not be unit). Its *body frame* has

* +x along the optical axis: x_b = v / |v|,
* +y to the camera's left and horizontal (no roll): y_b = (e_z x x_b) / |e_z x x_b|,
* +z up-ish: z_b = x_b x y_b (right-handed, z_b . e_z >= 0);

for a vertical v (e_z x x_b = 0), y_b = world +y. As a ``geometry_msgs/Pose`` (x, y, z, qx, qy,
qz, qw) the quaternion is the rotation R = [x_b y_b z_b] from the body frame to ``map`` (qw >=
0): the REP-103 body convention, so RViz's PoseArray arrows point where each camera looks.

Plans are levelled cameras [c, v]; what a camera *reported* is a **pose** (..., 7) = (x, y, z,
qx, qy, qz, qw) of that body frame with any attitude: a real camera is never exactly level (a
rig's mount, a drone without a roll gimbal), and its roll about the optical axis (:func:`roll_of`)
is kept. Everything downstream of a reported pose (captured views, reconstruction, registration,
image pairs, dense stereo, ground control, the viewer, poses.csv) takes poses; the functions of
this module that take a camera take either, the last axis deciding (6: [c, v], levelled; 7: a
pose, roll kept), and :func:`as_poses` turns a plan into the levelled poses it stands for.
The REP-103 *optical* frame (z forward, x right, y down), the one image pipelines use, is the
body frame turned by the fixed rotation between ``camera_link`` and ``camera_optical_frame``,
:data:`OPTICAL_IN_BODY` (quaternion x, y, z, w = -0.5, 0.5, -0.5, 0.5): x_o = -y_b, y_o = -z_b,
z_o = x_b. OpenCV and COLMAP use that optical frame; OpenGL (pyrender) uses x right, y up, z
backward.

Intrinsics
----------
Square pixels, principal point at the image centre, no distortion, horizontal field of view
``fov`` (Hartley & Zisserman, Multiple View Geometry, eq. 6.4)::

    f = (W / 2) / tan(fov / 2),   K = [[f, 0, (W-1)/2], [0, f, (H-1)/2], [0, 0, 1]],
    (u, v, 1)^T ~ K X_o,          X_o = R_cw X_w + t,  R_cw = [x_o y_o z_o]^T,  t = -R_cw c

with OpenCV pixel centres at integer coordinates (u right, v down). OpenGL and COLMAP put pixel
centres at +0.5, so their principal point is (W/2, H/2) (:func:`principal_point_gl`).

Bounds of what a user gives (one home)
--------------------------------------
Every coordinate read from a file or a flag (a plan's cameras and poses, a flight's poses, ground
control points) lies within :data:`MAX_COORDINATE` m of the origin of ``map`` on each axis
(:func:`check_coordinates`): a field flown from one launch point, far inside what float64 squares
and float32 renders keep exact to a millimetre (1e300 overflows the reward's squares; a point in
UTM, 500 km out, is another frame). An image has sides of :data:`IMAGE_SIDE_RANGE` pixels
(:func:`check_image_side`, :func:`image_side_arg` for the command lines).

Quaternions go through :class:`scipy.spatial.transform.Rotation`. Everything is vectorized
over leading dimensions and works on numpy arrays, except :func:`optical_axes`, the same axes
for torch tensors (the planner's batched rewards; torch is imported only there). ROS-free.
"""
from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

if TYPE_CHECKING:
    import torch

__all__ = [
    "OPTICAL_IN_BODY",
    "IMAGE_SIZE",
    "IMAGE_SIDE_RANGE",
    "MAX_COORDINATE",
    "check_coordinates",
    "check_image_side",
    "image_side_arg",
    "CameraModel",
    "rotation_matrix",
    "cameras_to_poses",
    "poses_to_cameras",
    "roll_of",
    "body_from_optical",
    "optical_orientation",
    "express_poses",
    "look_at",
    "direction",
    "azimuth_elevation",
    "intrinsics",
    "principal_point_gl",
    "world_to_camera",
    "camera_to_world_gl",
    "project",
    "project_with",
    "tan_half_fov",
    "optical_axes",
    "check_cameras",
    "as_poses",
    "check_poses",
]

#: Quaternion (x, y, z, w) of the optical frame (z forward, x right, y down) in the body frame.
OPTICAL_IN_BODY: tuple[float, float, float, float] = (-0.5, 0.5, -0.5, 0.5)

#: |e_z x x_b| below this counts as a vertical viewing direction.
_VERTICAL_TOL = 1e-9


def check_cameras(cameras: ArrayLike) -> NDArray[np.float64]:
    """Cameras as an (N, 6) float64 array; ValueError naming the problem otherwise."""
    cams = np.asarray(cameras, dtype=np.float64)
    if cams.ndim == 1 and cams.size == 6:
        cams = cams[None]
    if cams.ndim != 2 or cams.shape[1] != 6:
        raise ValueError(f"cameras must have shape (N, 6) = [cx, cy, cz, vx, vy, vz], got {cams.shape}")
    if not np.all(np.isfinite(cams)):
        raise ValueError("cameras contain NaN or infinite values")
    if np.any(np.linalg.norm(cams[:, 3:], axis=1) <= 0):
        raise ValueError("a camera has a zero viewing direction")
    return cams


def as_poses(cameras: ArrayLike) -> NDArray[np.float64]:
    """Poses (..., 7) of cameras (..., 6) [c, v] (levelled: :func:`cameras_to_poses`) or of poses
    (..., 7) (the quaternion normalized, qw >= 0; roll kept). ValueError for another shape, a
    zero viewing direction or a zero quaternion."""
    a = np.asarray(cameras, dtype=np.float64)
    if a.shape[-1:] == (6,):
        return cameras_to_poses(a)
    if a.shape[-1:] != (7,):
        raise ValueError(f"cameras must have shape (..., 6) = [c, v] or poses (..., 7) = (x, y, z, qx, qy, qz, qw), "
                         f"got {a.shape}")
    n = np.linalg.norm(a[..., 3:], axis=-1, keepdims=True)
    if not np.all(np.isfinite(a)) or np.any(n <= 0):
        raise ValueError("poses must be finite with non-zero quaternions")
    return np.concatenate([a[..., :3], _canonical(a[..., 3:] / n)], axis=-1)


def check_poses(cameras: ArrayLike) -> NDArray[np.float64]:
    """Cameras (N, 6) [c, v] or poses (N, 7) as a float64 array of that shape, checked (finite, a
    non-zero viewing direction or quaternion) but not converted: a plan's [c, v] rows stay as
    they are (their geometry bit for bit; :func:`as_poses` gives their poses). ValueError
    naming the problem otherwise (the pose-aware twin of :func:`check_cameras`)."""
    a = np.asarray(cameras, dtype=np.float64)
    if a.ndim == 1 and a.size in (6, 7):
        a = a[None]
    if a.ndim != 2 or a.shape[1] not in (6, 7):
        raise ValueError(f"cameras must have shape (N, 6) = [c, v] or (N, 7) = poses, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError("cameras contain NaN or infinite values")
    as_poses(a)  # the checks of a viewing direction or quaternion
    return a


def _body_axes(camera: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(centres (..., 3), body-to-world rotations (..., 3, 3)) of cameras (..., 6) (levelled) or
    poses (..., 7) (roll kept)."""
    cam = np.asarray(camera, dtype=np.float64)
    if cam.shape[-1:] == (6,):
        return cam[..., :3], rotation_matrix(cam[..., 3:])
    if cam.shape[-1:] == (7,):
        return cam[..., :3], _rotations(cam[..., 3:])
    raise ValueError(f"camera must have shape (..., 6) = [c, v] or (..., 7) = a pose, got {cam.shape}")


def rotation_matrix(v: ArrayLike) -> NDArray[np.float64]:
    """Body-to-world rotation R (..., 3, 3), columns x_b, y_b, z_b, for viewing directions v (..., 3).

    Raises:
        ValueError: for a zero or non-finite viewing direction.
    """
    v = np.asarray(v, dtype=np.float64)
    if v.shape[-1] != 3:
        raise ValueError(f"v must have shape (..., 3), got {v.shape}")
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    if not np.all(np.isfinite(v)) or np.any(n <= 0):
        raise ValueError("viewing directions must be finite and non-zero")
    x = v / n
    # y_b = e_z x x_b = (-x_y, x_x, 0), normalized; world +y for a vertical axis.
    y = np.stack([-x[..., 1], x[..., 0], np.zeros_like(x[..., 0])], axis=-1)
    yn = np.linalg.norm(y, axis=-1, keepdims=True)
    vertical = yn[..., 0] < _VERTICAL_TOL
    y = np.where(vertical[..., None], np.array([0.0, 1.0, 0.0]), y / np.where(yn > 0, yn, 1.0))
    z = np.cross(x, y)
    z /= np.linalg.norm(z, axis=-1, keepdims=True)
    return np.stack([x, y, z], axis=-1)


def _canonical(q: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.where(q[..., 3:4] < 0, -q, q)


def cameras_to_poses(cameras: ArrayLike) -> NDArray[np.float64]:
    """Poses (..., 7) = (x, y, z, qx, qy, qz, qw), qw >= 0, of cameras (..., 6) = [c, v]."""
    cams = np.asarray(cameras, dtype=np.float64)
    if cams.shape[-1] != 6:
        raise ValueError(f"cameras must have shape (..., 6), got {cams.shape}")
    R = rotation_matrix(cams[..., 3:])
    q = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_quat().reshape(R.shape[:-2] + (4,))
    return np.concatenate([cams[..., :3], _canonical(q)], axis=-1)


def _rotations(quaternions: NDArray[np.float64]) -> NDArray[np.float64]:
    q = np.asarray(quaternions, dtype=np.float64)
    n = np.linalg.norm(q, axis=-1)
    if not np.all(np.isfinite(q)) or np.any(n <= 0):
        raise ValueError("quaternions must be finite and non-zero")
    return Rotation.from_quat(q.reshape(-1, 4)).as_matrix().reshape(q.shape[:-1] + (3, 3))


def poses_to_cameras(poses: ArrayLike) -> NDArray[np.float64]:
    """Cameras (..., 6) = [c, unit v] of poses (..., 7); v is the body +x axis in ``map``.

    The quaternion is normalized (any non-zero length is accepted); ValueError otherwise."""
    p = np.asarray(poses, dtype=np.float64)
    if p.shape[-1] != 7:
        raise ValueError(f"poses must have shape (..., 7), got {p.shape}")
    R = _rotations(p[..., 3:])
    return np.concatenate([p[..., :3], R[..., :, 0]], axis=-1)


def roll_of(poses: ArrayLike) -> NDArray[np.float64]:
    """Roll (..., ) in radians, (-pi, pi], of poses (..., 7): the angle about the optical axis
    x_b from the levelled body frame of the convention (:func:`rotation_matrix` of the pose's x_b)
    to the pose's own, atan2(y_b . z_level, y_b . y_level). A camera of the suite has none (a
    pose's roll is dropped by :func:`poses_to_cameras`); a camera looking straight down has its
    yaw here (the convention puts its y_b on world +y)."""
    p = np.asarray(poses, dtype=np.float64)
    if p.shape[-1] != 7:
        raise ValueError(f"poses must have shape (..., 7), got {p.shape}")
    R = _rotations(p[..., 3:])
    level = rotation_matrix(R[..., :, 0])
    y = R[..., :, 1]
    return np.arctan2(np.einsum("...i,...i->...", y, level[..., :, 2]), np.einsum("...i,...i->...", y, level[..., :, 1]))


def body_from_optical(R_cw: ArrayLike) -> NDArray[np.float64]:
    """Body-frame quaternions (..., 4) (x, y, z, w; qw >= 0) of cameras given by their
    world-to-optical rotations R_cw (..., 3, 3) (OpenCV / COLMAP ``cam_from_world``): x_b = z_o,
    y_b = -x_o, z_b = -y_o, roll kept (:func:`roll_of`)."""
    R_wc = np.swapaxes(np.asarray(R_cw, dtype=np.float64), -1, -2)  # columns x_o, y_o, z_o in the world
    body = np.stack([R_wc[..., :, 2], -R_wc[..., :, 0], -R_wc[..., :, 1]], axis=-1)
    q = Rotation.from_matrix(body.reshape(-1, 3, 3)).as_quat().reshape(body.shape[:-2] + (4,))
    return _canonical(q)


def optical_orientation(quaternions: ArrayLike) -> NDArray[np.float64]:
    """Quaternions (..., 4) of the REP-103 optical frame for body-frame quaternions (..., 4)."""
    q = np.asarray(quaternions, dtype=np.float64)
    body = Rotation.from_quat(q.reshape(-1, 4))
    out = (body * Rotation.from_quat(OPTICAL_IN_BODY)).as_quat().reshape(q.shape)
    return _canonical(out)


def express_poses(poses: ArrayLike, rotation: Rotation, origin: ArrayLike) -> NDArray[np.float64]:
    """Poses (N, 7) = (x, y, z, qx, qy, qz, qw) expressed in another frame, whose origin o (3,)
    and axes R (a scipy Rotation) are given in the poses' frame (tf's parent -> child transform):
    positions R^T (p - o), orientations R^-1 q (qw >= 0)."""
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 7)
    q = (rotation.inv() * Rotation.from_quat(p[:, 3:])).as_quat() if len(p) else np.zeros((0, 4))
    positions = (p[:, :3] - np.asarray(origin, dtype=np.float64)) @ rotation.as_matrix()
    return np.concatenate([positions, _canonical(q)], axis=1)


def look_at(positions: ArrayLike, targets: ArrayLike) -> NDArray[np.float64]:
    """Cameras (..., 6) at ``positions`` (..., 3) looking at ``targets`` (..., 3) (v = target - c)."""
    c = np.asarray(positions, dtype=np.float64)
    t = np.asarray(targets, dtype=np.float64)
    c, t = np.broadcast_arrays(c, t)
    return np.concatenate([c, t - c], axis=-1)


def direction(azimuth: ArrayLike, elevation: ArrayLike) -> NDArray[np.float64]:
    """Unit vectors (..., 3) at ``azimuth`` (rad from +x, counter-clockwise) and ``elevation`` (rad
    above the horizontal): (cos el cos az, cos el sin az, sin el); scalars give one (3,) vector.
    The one home of this map (search space, patterns, designs); :func:`azimuth_elevation` inverts it."""
    ce = np.cos(elevation)
    return np.stack([ce * np.cos(azimuth), ce * np.sin(azimuth), np.sin(elevation)], axis=-1)


def azimuth_elevation(directions: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(azimuth in (-pi, pi], elevation in [-pi/2, pi/2]) of directions (..., 3) of any length: the
    inverse of :func:`direction`, atan2(y, x) and asin(z / |d|) (clipped to [-1, 1]).

    Python's ``math.atan2`` and ``math.asin``, element by element: numpy's ``arctan2`` and ``arcsin``
    differ from them in the last bit for some inputs, and the structured initial design
    (:func:`vp_planner.designs.structured_plans`) is pinned bit for bit with math's
    (tests/test_reference_plans.py)."""
    d = np.asarray(directions, dtype=np.float64)
    z = np.clip(d[..., 2] / np.maximum(np.linalg.norm(d, axis=-1), 1e-300), -1.0, 1.0)
    return (np.vectorize(math.atan2, otypes=[np.float64])(d[..., 1], d[..., 0]),
            np.vectorize(math.asin, otypes=[np.float64])(z))


#: (width, height) of the cameras' images, pixels, by default (the paper's): the one home of the
#: suite's default image size (planner, simulated drones, reconstruction, entry script, benchmarks).
IMAGE_SIZE: tuple[int, int] = (2000, 1500)
#: Pixels a side of an image may have, [lo, hi], wherever a size is given (flags, parameters, plan
#: files, a flight's intrinsics): below 16 SIFT finds nothing; 16384 is OpenGL's largest render
#: buffer on Mesa's llvmpipe (GL_MAX_RENDERBUFFER_SIZE; a 100000-pixel render failed with a
#: GLError) and above the side of any survey camera's sensor.
IMAGE_SIDE_RANGE: tuple[int, int] = (16, 16384)
#: m: every coordinate a user gives lies in [-MAX_COORDINATE, MAX_COORDINATE] on each axis of
#: ``map`` (module docstring).
MAX_COORDINATE: float = 10_000.0


def check_image_side(name: str, value: object) -> int:
    """``value`` as an image side in :data:`IMAGE_SIDE_RANGE` pixels (an integer; bools refused),
    else ValueError naming ``name``, the value and the range."""
    lo, hi = IMAGE_SIDE_RANGE
    try:
        ok = not isinstance(value, (bool, np.bool_)) and int(value) == value and lo <= int(value) <= hi
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise ValueError(f"{name} must be an integer of {lo} to {hi} pixels, got {value!r}")
    return int(value)


def image_side_arg(text: str) -> int:
    """argparse type of an image side flag (``--width``, ``--image-height``, ...): checked at parse
    time against :data:`IMAGE_SIDE_RANGE` (argparse names the flag)."""
    try:
        return check_image_side("an image side", int(text))
    except ValueError as exc:
        lo, hi = IMAGE_SIDE_RANGE
        raise argparse.ArgumentTypeError(f"must be an integer of {lo} to {hi} pixels, got {text!r}") from exc


def check_coordinates(values: ArrayLike, what: str) -> NDArray[np.float64]:
    """``values`` (any shape: positions in metres of ``map``, and the viewing directions or
    quaternions beside them) as float64 when every one is finite and within
    [-:data:`MAX_COORDINATE`, :data:`MAX_COORDINATE`], else ValueError naming ``what``, the first
    value out and the range."""
    a = np.asarray(values, dtype=np.float64)
    bad = ~(np.abs(a) <= MAX_COORDINATE)  # NaN too
    if bad.any():
        v = float(a.reshape(-1)[np.flatnonzero(bad.reshape(-1))[0]])
        if not math.isfinite(v):
            raise ValueError(f"{what} holds {v:g}, which is not finite")
        raise ValueError(f"{what} holds {v:g}, outside [-{MAX_COORDINATE:g}, {MAX_COORDINATE:g}]: positions are "
                         f"metres of map within {MAX_COORDINATE / 1000:g} km of its origin (the field's own frame)")
    return a


@dataclass(frozen=True)
class CameraModel:
    """Pinhole intrinsics shared by all cameras of a plan: image size and horizontal field of view.

    Attributes:
        width, height: pixels (default :data:`IMAGE_SIZE`, the paper's 2000 x 1500).
        fov: horizontal field of view, rad, in (0, pi) (the paper: pi / 2).
    """

    width: int = IMAGE_SIZE[0]
    height: int = IMAGE_SIZE[1]
    fov: float = math.pi / 2

    def __post_init__(self) -> None:
        _check_size(self.width, self.height, self.fov)

    @property
    def focal_px(self) -> float:
        """f = (W / 2) / tan(fov / 2), pixels."""
        return 0.5 * self.width / tan_half_fov(self.fov)

    @property
    def tan_half_fov(self) -> float:
        """tan(fov / 2): the image's half-width at unit depth."""
        return tan_half_fov(self.fov)

    @property
    def tan_half_fov_vertical(self) -> float:
        """tan(fov / 2) H / W: the image's half-height at unit depth (square pixels)."""
        return self.tan_half_fov * self.height / self.width

    @property
    def K(self) -> NDArray[np.float64]:
        return intrinsics(self.width, self.height, self.fov)

    @property
    def half_fov_vertical(self) -> float:
        """atan((H / 2) / f), rad."""
        return math.atan(0.5 * self.height / self.focal_px)


def _check_size(width: int, height: int, fov: float) -> None:
    if isinstance(width, bool) or isinstance(height, bool) or int(width) != width or int(height) != height:
        raise ValueError(f"image size must be integers, got {width!r} x {height!r}")
    if int(width) < 2 or int(height) < 2:
        raise ValueError(f"image size must be at least 2 x 2, got {width} x {height}")
    if not (math.isfinite(fov) and 0 < fov < math.pi):
        raise ValueError(f"fov must be in (0, pi) rad, got {fov}")


def tan_half_fov(fov: float) -> float:
    """tan(fov / 2) of a field of view ``fov`` (rad): the half-extent of the image at unit depth,
    f = (W / 2) / tan(fov / 2) (the module docstring)."""
    return math.tan(0.5 * fov)


def intrinsics(width: int, height: int, fov: float = math.pi / 2) -> NDArray[np.float64]:
    """3x3 calibration K (OpenCV pixel centres) from the horizontal field of view, square pixels."""
    _check_size(width, height, fov)
    f = 0.5 * width / tan_half_fov(fov)
    return np.array([[f, 0.0, 0.5 * (width - 1)], [0.0, f, 0.5 * (height - 1)], [0.0, 0.0, 1.0]])


def principal_point_gl(K: ArrayLike) -> tuple[float, float]:
    """Principal point in the OpenGL / COLMAP pixel convention (pixel centres at +0.5)."""
    K = np.asarray(K, dtype=np.float64)
    return float(K[0, 2] + 0.5), float(K[1, 2] + 0.5)


def world_to_camera(camera6: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(R_cw (..., 3, 3), t (..., 3)): X_o = R_cw X_w + t in the optical (OpenCV / COLMAP) frame,
    of cameras (..., 6) [c, v] (levelled) or poses (..., 7) (roll kept).

    R_cw has rows x_o = -y_b, y_o = -z_b, z_o = x_b; t = -R_cw c.
    """
    c, R_bw = _body_axes(camera6)
    R_wc = np.stack([-R_bw[..., :, 1], -R_bw[..., :, 2], R_bw[..., :, 0]], axis=-1)
    R_cw = np.swapaxes(R_wc, -1, -2)
    t = -np.einsum("...ij,...j->...i", R_cw, c)
    return R_cw, t


def camera_to_world_gl(camera6: ArrayLike) -> NDArray[np.float64]:
    """4x4 OpenGL camera-to-world pose (x right, y up, z backward) of one camera [c, v] or pose, for pyrender."""
    c, R_bw = _body_axes(np.asarray(camera6, dtype=np.float64).reshape(-1))
    T = np.eye(4)
    T[:3, :3] = np.stack([-R_bw[:, 1], R_bw[:, 2], -R_bw[:, 0]], axis=-1)
    T[:3, 3] = c
    return T


def project(points: ArrayLike, camera6: ArrayLike, width: int, height: int,
            fov: float = math.pi / 2) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Pixels (M, 2) = (u, v) of world points (M, 3) and whether each is in front and in the image.

    (u, v, 1)^T ~ K (R_cw X + t); a point is in the image when its depth is > 0 and
    -0.5 <= u < W - 0.5, -0.5 <= v < H - 0.5 (no occlusion test). Points behind get NaN.
    """
    return project_with(points, camera6, intrinsics(width, height, fov), width, height)


def project_with(points: ArrayLike, camera6: ArrayLike, K: ArrayLike, width: int, height: int,
                 min_depth: float = 1e-9) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """:func:`project` with a given calibration ``K`` (3, 3) (a reconstruction's, say): pixels
    (M, 2) and in-image flags of world points (M, 3); a point is in front when its depth is above
    ``min_depth`` (m). Rounding the pixels of the points in the image (``np.rint``) gives pixel
    indices in [0, W) x [0, H)."""
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    K = np.asarray(K, dtype=np.float64)
    R, t = world_to_camera(camera6)
    Xc = P @ R.T + t
    z = Xc[:, 2]
    front = z > min_depth
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = (Xc[:, :2] / np.where(front, z, np.nan)[:, None]) * K[[0, 1], [0, 1]] + K[:2, 2]
    inside = front & (uv[:, 0] >= -0.5) & (uv[:, 0] < width - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] < height - 0.5)
    return uv, inside


def optical_axes(cameras: "torch.Tensor") -> tuple["torch.Tensor", "torch.Tensor", "torch.Tensor", "torch.Tensor"]:
    """Camera centres c and optical-frame axes x_o, y_o, z_o (each (..., 3)) of cameras (..., 6)
    given as a torch tensor: the rows of :func:`world_to_camera`'s R_cw (x_o = -y_b, y_o = -z_b,
    z_o = x_b of :func:`rotation_matrix`), computed in torch for batched (and differentiable)
    rewards. A camera with a zero or non-finite viewing direction gets z_o = 0 instead of an
    error (the rewards score it 0)."""
    import torch  # only here: the rest of the module is numpy

    c = cameras[..., :3]
    v = cameras[..., 3:]
    n = torch.linalg.vector_norm(v, dim=-1, keepdim=True)
    ok = (n > 0) & torch.isfinite(n)
    z_o = torch.where(ok, v / torch.where(ok, n, torch.ones_like(n)), torch.zeros_like(v))
    ez = torch.tensor([0.0, 0.0, 1.0], dtype=cameras.dtype)
    y_b = torch.linalg.cross(ez.expand_as(z_o), z_o)
    yn = torch.linalg.vector_norm(y_b, dim=-1, keepdim=True)
    vertical = yn < _VERTICAL_TOL
    y_b = torch.where(vertical, torch.tensor([0.0, 1.0, 0.0], dtype=cameras.dtype).expand_as(y_b),
                      y_b / torch.where(vertical, torch.ones_like(yn), yn))
    z_b = torch.linalg.cross(z_o, y_b)
    return c, -y_b, -z_b, z_o
