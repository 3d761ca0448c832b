"""Camera <-> pose conversions (the camera convention of docs/CONTRACTS.md).

A camera is [cx, cy, cz, vx, vy, vz]: position c and viewing direction v (the optical axis, not
necessarily unit). As a ``geometry_msgs/Pose`` the camera body frame has

* +x along the optical axis: x_b = v / |v|,
* +y to the camera's left and horizontal (no roll): y_b = (e_z x x_b) / |e_z x x_b|,
* +z up-ish: z_b = x_b x y_b (right-handed, z_b . e_z >= 0).

For a vertical v (e_z x x_b = 0) +y is the world +y axis, y_b = e_y, and z_b = x_b x e_y.
A pose is (x, y, z, qx, qy, qz, qw) with the unit quaternion of R = [x_b y_b z_b] (columns),
the rotation from the body frame to the world frame ``map``; qw >= 0.
All functions are vectorized over leading dimensions and work on numpy arrays.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "rotation_matrix",
    "matrix_to_quaternion",
    "quaternion_to_matrix",
    "camera_to_pose",
    "cameras_to_poses",
    "pose_to_camera",
    "poses_to_cameras",
]

#: |e_z x x_b| below this counts as a vertical viewing direction.
_VERTICAL_TOL = 1e-9


def rotation_matrix(v: ArrayLike) -> NDArray[np.float64]:
    """Body-to-world rotation R (..., 3, 3) whose columns are x_b, y_b, z_b for directions v (..., 3).

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


def matrix_to_quaternion(R: ArrayLike) -> NDArray[np.float64]:
    """Unit quaternions (..., 4) as (qx, qy, qz, qw), qw >= 0, of rotation matrices (..., 3, 3).

    Shepperd's method: pick the largest of (trace, R_00, R_11, R_22) for numerical stability.
    """
    R = np.asarray(R, dtype=np.float64)
    m00, m11, m22 = R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]
    tr = m00 + m11 + m22
    cand = np.stack([tr, m00, m11, m22], axis=-1)
    k = np.argmax(cand, axis=-1)
    # case 0: w largest
    s0 = np.sqrt(np.maximum(1.0 + tr, 1e-300)) * 2.0
    q0 = np.stack([(R[..., 2, 1] - R[..., 1, 2]) / s0, (R[..., 0, 2] - R[..., 2, 0]) / s0,
                   (R[..., 1, 0] - R[..., 0, 1]) / s0, 0.25 * s0], axis=-1)
    s1 = np.sqrt(np.maximum(1.0 + m00 - m11 - m22, 1e-300)) * 2.0
    q1 = np.stack([0.25 * s1, (R[..., 0, 1] + R[..., 1, 0]) / s1,
                   (R[..., 0, 2] + R[..., 2, 0]) / s1, (R[..., 2, 1] - R[..., 1, 2]) / s1], axis=-1)
    s2 = np.sqrt(np.maximum(1.0 + m11 - m00 - m22, 1e-300)) * 2.0
    q2 = np.stack([(R[..., 0, 1] + R[..., 1, 0]) / s2, 0.25 * s2,
                   (R[..., 1, 2] + R[..., 2, 1]) / s2, (R[..., 0, 2] - R[..., 2, 0]) / s2], axis=-1)
    s3 = np.sqrt(np.maximum(1.0 + m22 - m00 - m11, 1e-300)) * 2.0
    q3 = np.stack([(R[..., 0, 2] + R[..., 2, 0]) / s3, (R[..., 1, 2] + R[..., 2, 1]) / s3,
                   0.25 * s3, (R[..., 1, 0] - R[..., 0, 1]) / s3], axis=-1)
    q = np.choose(k[..., None], [q0, q1, q2, q3])
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., 3:4] < 0, -q, q)


def quaternion_to_matrix(q: ArrayLike) -> NDArray[np.float64]:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4) given as (qx, qy, qz, qw)."""
    q = np.asarray(q, dtype=np.float64)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if not np.all(np.isfinite(q)) or np.any(n <= 0):
        raise ValueError("quaternions must be finite and non-zero")
    x, y, z, w = np.moveaxis(q / n, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=-1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=-1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=-2)


def camera_to_pose(c: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
    """Poses (..., 7) = (x, y, z, qx, qy, qz, qw) of cameras at c (..., 3) looking along v (..., 3)."""
    c = np.asarray(c, dtype=np.float64)
    if c.shape[-1] != 3:
        raise ValueError(f"c must have shape (..., 3), got {c.shape}")
    q = matrix_to_quaternion(rotation_matrix(v))
    shape = np.broadcast_shapes(c.shape[:-1], q.shape[:-1])
    return np.concatenate([np.broadcast_to(c, shape + (3,)), np.broadcast_to(q, shape + (4,))], axis=-1)


def cameras_to_poses(cameras: ArrayLike) -> NDArray[np.float64]:
    """Poses (..., 7) of cameras (..., 6) = [c, v]."""
    cams = np.asarray(cameras, dtype=np.float64)
    if cams.shape[-1] != 6:
        raise ValueError(f"cameras must have shape (..., 6), got {cams.shape}")
    return camera_to_pose(cams[..., :3], cams[..., 3:])


def pose_to_camera(pose7: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(c (..., 3), unit v (..., 3)) of poses (..., 7); v is the body +x axis in the world."""
    p = np.asarray(pose7, dtype=np.float64)
    if p.shape[-1] != 7:
        raise ValueError(f"pose must have shape (..., 7), got {p.shape}")
    R = quaternion_to_matrix(p[..., 3:])
    return p[..., :3].copy(), R[..., :, 0]


def poses_to_cameras(poses: ArrayLike) -> NDArray[np.float64]:
    """Cameras (..., 6) = [c, unit v] of poses (..., 7)."""
    c, v = pose_to_camera(poses)
    return np.concatenate([c, v], axis=-1)
