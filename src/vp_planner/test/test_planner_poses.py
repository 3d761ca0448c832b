"""Camera <-> pose conversions: the convention of docs/CONTRACTS.md."""
from __future__ import annotations

import numpy as np
import pytest

from vp_planner.poses import (
    camera_to_pose,
    cameras_to_poses,
    matrix_to_quaternion,
    pose_to_camera,
    poses_to_cameras,
    quaternion_to_matrix,
    rotation_matrix,
)


def directions() -> np.ndarray:
    rng = np.random.default_rng(0)
    v = rng.normal(size=(500, 3)) * rng.uniform(0.01, 10, size=(500, 1))
    special = np.array([[0, 0, -1.0], [0, 0, 3.0], [1e-13, 0, -1.0], [1, 0, 0], [0, -2, 0], [-1, 0, 0]])
    return np.concatenate([v, special])


def test_round_trip_and_axes() -> None:
    v = directions()
    c = np.random.default_rng(1).normal(size=v.shape)
    pose = camera_to_pose(c, v)
    assert pose.shape == (len(v), 7)
    np.testing.assert_allclose(np.linalg.norm(pose[:, 3:], axis=1), 1.0, atol=1e-12)
    assert np.all(pose[:, 6] >= 0)
    c2, u = pose_to_camera(pose)
    np.testing.assert_allclose(c2, c, atol=1e-15)
    np.testing.assert_allclose(u, v / np.linalg.norm(v, axis=1, keepdims=True), atol=1e-12)
    R = quaternion_to_matrix(pose[:, 3:])
    # +x of the quaternion's rotation is the unit viewing direction
    np.testing.assert_allclose(R[:, :, 0], u, atol=1e-12)
    # rotations: orthonormal, right-handed
    np.testing.assert_allclose(np.einsum("nji,njk->nik", R, R), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    # no roll: +y horizontal, +z up-ish
    np.testing.assert_allclose(R[:, 2, 1], 0.0, atol=1e-12)
    assert np.all(R[:, 2, 2] >= -1e-12)
    np.testing.assert_allclose(rotation_matrix(v), R, atol=1e-12)
    np.testing.assert_allclose(matrix_to_quaternion(R), pose[:, 3:], atol=1e-12)


def test_convention_examples() -> None:
    # looking along +x: identity
    np.testing.assert_allclose(camera_to_pose([1, 2, 3], [2, 0, 0]), [1, 2, 3, 0, 0, 0, 1], atol=1e-12)
    # looking along +y: +y_body = -x_world (left of the camera), yaw of +90 degrees
    R = rotation_matrix([0, 1, 0])
    np.testing.assert_allclose(R[:, 1], [-1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(R[:, 2], [0, 0, 1], atol=1e-12)
    # straight down: +y_body = world +y
    R = rotation_matrix([0, 0, -5])
    np.testing.assert_allclose(R[:, 0], [0, 0, -1], atol=1e-12)
    np.testing.assert_allclose(R[:, 1], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(R[:, 2], [1, 0, 0], atol=1e-12)
    # looking down at 45 degrees towards +x: +z_body leans forward and up
    R = rotation_matrix([1, 0, -1])
    np.testing.assert_allclose(R[:, 2], np.array([1, 0, 1]) / np.sqrt(2), atol=1e-12)


def test_cameras_helpers_and_errors() -> None:
    cams = np.array([[0, 0, 1, 1, 1, -1], [2, 0, 1, -1, 0, 0.0]])
    poses = cameras_to_poses(cams)
    back = poses_to_cameras(poses)
    np.testing.assert_allclose(back[:, :3], cams[:, :3])
    np.testing.assert_allclose(back[:, 3:], cams[:, 3:] / np.linalg.norm(cams[:, 3:], axis=1, keepdims=True))
    with pytest.raises(ValueError):
        camera_to_pose([0, 0, 0], [0, 0, 0])
    with pytest.raises(ValueError):
        camera_to_pose([0, 0, 0], [np.nan, 0, 1])
    with pytest.raises(ValueError):
        pose_to_camera(np.zeros(6))
