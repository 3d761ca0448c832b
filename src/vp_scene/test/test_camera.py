"""The camera convention of vp_scene.camera: poses, optical frame, intrinsics, projection."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vp_scene.camera import (
    CameraModel,
    cameras_to_poses,
    intrinsics,
    look_at,
    optical_axes,
    optical_orientation,
    poses_to_cameras,
    project,
    project_with,
    rotation_matrix,
    tan_half_fov,
    world_to_camera,
)


def directions() -> np.ndarray:
    rng = np.random.default_rng(0)
    v = rng.normal(size=(500, 3)) * rng.uniform(0.01, 10, size=(500, 1))
    special = np.array([[0, 0, -1.0], [0, 0, 3.0], [1e-13, 0, -1.0], [1, 0, 0], [0, -2, 0], [-1, 0, 0]])
    return np.concatenate([v, special])


def quaternion_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices of (x, y, z, w) quaternions, written out (independent of scipy)."""
    x, y, z, w = np.moveaxis(q / np.linalg.norm(q, axis=-1, keepdims=True), -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=-1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=-1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=-2)


def test_round_trip_and_axes() -> None:
    v = directions()
    c = np.random.default_rng(1).normal(size=v.shape)
    pose = cameras_to_poses(np.concatenate([c, v], axis=1))
    assert pose.shape == (len(v), 7)
    np.testing.assert_allclose(np.linalg.norm(pose[:, 3:], axis=1), 1.0, atol=1e-12)
    assert np.all(pose[:, 6] >= 0)
    back = poses_to_cameras(pose)
    u = v / np.linalg.norm(v, axis=1, keepdims=True)
    np.testing.assert_allclose(back[:, :3], c, atol=1e-15)
    np.testing.assert_allclose(back[:, 3:], u, atol=1e-12)
    R = quaternion_matrix(pose[:, 3:])
    np.testing.assert_allclose(R[:, :, 0], u, atol=1e-12)  # +x of the pose is the optical axis
    np.testing.assert_allclose(np.einsum("nji,njk->nik", R, R), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    np.testing.assert_allclose(R[:, 2, 1], 0.0, atol=1e-12)  # no roll: +y horizontal
    assert np.all(R[:, 2, 2] >= -1e-12)  # +z up-ish
    np.testing.assert_allclose(rotation_matrix(v), R, atol=1e-12)


def test_convention_examples() -> None:
    np.testing.assert_allclose(cameras_to_poses([1, 2, 3, 2, 0, 0]), [1, 2, 3, 0, 0, 0, 1], atol=1e-12)
    R = rotation_matrix([0, 1, 0])  # looking along +y: +y_body = -x_world, yaw +90 degrees
    np.testing.assert_allclose(R[:, 1], [-1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(R[:, 2], [0, 0, 1], atol=1e-12)
    R = rotation_matrix([0, 0, -5])  # straight down: +y_body = world +y
    np.testing.assert_allclose(R[:, 0], [0, 0, -1], atol=1e-12)
    np.testing.assert_allclose(R[:, 1], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(R[:, 2], [1, 0, 0], atol=1e-12)
    R = rotation_matrix([1, 0, -1])  # 45 degrees down towards +x: +z_body leans forward and up
    np.testing.assert_allclose(R[:, 2], np.array([1, 0, 1]) / np.sqrt(2), atol=1e-12)


def test_optical_frame_matches_world_to_camera() -> None:
    """The REP-103 optical frame (z forward, x right, y down) is the frame of world_to_camera."""
    cams = np.concatenate([np.random.default_rng(2).normal(size=(50, 3)), directions()[:50]], axis=1)
    q_opt = optical_orientation(cameras_to_poses(cams)[:, 3:])
    R_opt = quaternion_matrix(q_opt)  # columns: optical axes in the world
    R_cw, _ = world_to_camera(cams)
    np.testing.assert_allclose(np.swapaxes(R_opt, -1, -2), R_cw, atol=1e-12)
    u = cams[:, 3:] / np.linalg.norm(cams[:, 3:], axis=1, keepdims=True)
    np.testing.assert_allclose(R_opt[:, :, 2], u, atol=1e-12)


def test_errors() -> None:
    with pytest.raises(ValueError):
        cameras_to_poses([0, 0, 0, 0, 0, 0])
    with pytest.raises(ValueError):
        cameras_to_poses([0, 0, 0, np.nan, 0, 1])
    with pytest.raises(ValueError):
        poses_to_cameras(np.zeros(6))
    with pytest.raises(ValueError):
        poses_to_cameras(np.zeros(7))  # zero quaternion
    with pytest.raises(ValueError):
        CameraModel(640, 480, 0.0)
    with pytest.raises(ValueError):
        CameraModel(640.5, 480)


def test_intrinsics_and_projection() -> None:
    K = intrinsics(640, 480, math.pi / 2)
    assert K[0, 0] == pytest.approx(320.0) and K[0, 2] == pytest.approx(319.5)
    m = CameraModel(2000, 1500, math.pi / 2)
    assert m.focal_px == pytest.approx(1000.0)
    assert m.half_fov_vertical == pytest.approx(math.atan(0.75))
    cam = look_at([0.0, 0.0, 1.0], [2.0, 0.0, 1.0])
    uv, inside = project([[2.0, 0.0, 1.0], [2.0, 0.5, 1.0], [2.0, 0.0, 1.5], [-2.0, 0.0, 1.0]], cam, 640, 480)
    np.testing.assert_allclose(uv[0], [319.5, 239.5], atol=1e-9)
    assert uv[1, 0] < 319.5  # +y (left) is to the left in the image
    assert uv[2, 1] < 239.5  # up is up
    assert inside.tolist() == [True, True, True, False]


def test_roll_and_the_optical_frame_back_to_the_body() -> None:
    """roll_of: 0 for the convention's poses (nadir included), the angle of a turn about the
    optical axis otherwise; body_from_optical inverts world_to_camera's rotation (a
    flight's poses read from COLMAP keep their roll, so that it can be refused)."""
    from scipy.spatial.transform import Rotation

    from vp_scene.camera import body_from_optical, cameras_to_poses, roll_of, world_to_camera

    cams = np.array([[1, 0, 1, -1, 0, -0.3], [0, 2, 1, 0, -1, 0], [0, 0, 3, 0, 0, -1], [1, 1, 1, 0.2, 0.1, 0.9]])
    poses = cameras_to_poses(cams)
    np.testing.assert_allclose(roll_of(poses), 0.0, atol=1e-12)
    np.testing.assert_allclose(body_from_optical(world_to_camera(cams)[0]), poses[:, 3:], atol=1e-12)
    for deg in (10.0, -35.0):
        turned = (Rotation.from_quat(poses[:, 3:]) * Rotation.from_euler("x", deg, degrees=True)).as_quat()
        np.testing.assert_allclose(np.degrees(roll_of(np.hstack([poses[:, :3], turned]))), deg, atol=1e-9)


def test_the_torch_axes_and_the_half_fov_are_the_conventions() -> None:
    """The planner's torch rewards take the optical axes from
    here (they re-derived them), and tan(fov / 2) has one definition."""
    import torch

    v = directions()
    c = np.random.default_rng(1).normal(size=v.shape)
    cams = np.concatenate([c, v], axis=1)
    R_cw, _ = world_to_camera(cams)
    centre, x_o, y_o, z_o = optical_axes(torch.as_tensor(cams))
    np.testing.assert_array_equal(centre.numpy(), c)
    for row, axis in enumerate((x_o, y_o, z_o)):
        np.testing.assert_allclose(axis.numpy(), R_cw[:, row], atol=1e-12)
    bad = torch.tensor([[0.0, 0.0, 1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, math.nan, 0.0, 1.0]])
    assert torch.all(optical_axes(bad)[3] == 0)  # no viewing direction: no axes (a reward of 0)
    cam = CameraModel(640, 480, 1.2)
    assert tan_half_fov(1.2) == math.tan(0.6) == cam.tan_half_fov
    assert cam.focal_px == 320 / tan_half_fov(1.2) == intrinsics(640, 480, 1.2)[0, 0]
    assert cam.tan_half_fov_vertical == pytest.approx(math.tan(cam.half_fov_vertical), rel=1e-12)


def test_projection_with_a_given_calibration() -> None:
    """project_with: project's pixels for any K (the reconstruction's silhouette filter)."""
    rng = np.random.default_rng(2)
    pts = rng.uniform(-1, 1, (400, 3)) + [0.0, 0.0, 1.0]
    cam = np.array([3.0, 0.0, 1.0, -1.0, 0.0, 0.0])
    uv, inside = project(pts, cam, 320, 240, 1.3)
    uv2, inside2 = project_with(pts, cam, intrinsics(320, 240, 1.3), 320, 240)
    np.testing.assert_array_equal(inside, inside2)
    np.testing.assert_array_equal(uv[inside], uv2[inside])
    ij = np.rint(uv2[inside2]).astype(int)
    assert inside.any() and ij.min() >= 0 and (ij < [320, 240]).all()
    _, far = project_with(pts, cam, intrinsics(320, 240, 1.3), 320, 240, min_depth=10.0)
    assert not far.any()


def test_poses_expressed_in_a_turned_and_shifted_frame() -> None:
    """express_poses: a camera at the other frame's origin looking along map +y is, in a frame
    turned by +90 deg about z, at its origin looking along its +x (the fleet frame's pose math)."""
    from scipy.spatial.transform import Rotation

    from vp_scene.camera import express_poses

    origin, turn = np.array([2.0, -1.0, 0.5]), Rotation.from_euler("z", math.pi / 2)
    pose = cameras_to_poses(np.array([[2.0, -1.0, 0.5, 0.0, 1.0, 0.0]]))
    out = express_poses(pose, turn, origin)
    np.testing.assert_allclose(out[0, :3], 0.0, atol=1e-12)
    np.testing.assert_allclose(poses_to_cameras(out)[0, 3:], [1.0, 0.0, 0.0], atol=1e-12)
    assert out[0, 6] >= 0
    assert express_poses(np.zeros((0, 7)), turn, origin).shape == (0, 7)


def test_direction_and_its_inverse_have_one_home() -> None:
    """Azimuth/elevation -> direction was written 3 times (space, patterns,
    designs) and its inverse twice; vp_scene.camera holds both, vectorized, and they invert."""
    from vp_scene.camera import azimuth_elevation, direction

    np.testing.assert_allclose(direction(0.0, 0.0), [1.0, 0.0, 0.0])
    np.testing.assert_allclose(direction(math.pi / 2, 0.0), [0.0, 1.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(direction(1.0, math.pi / 2), [0.0, 0.0, 1.0], atol=1e-15)
    rng = np.random.default_rng(0)
    az, el = rng.uniform(-math.pi, math.pi, (4, 5)), rng.uniform(-1.5, 1.5, (4, 5))
    d = direction(az, el)
    assert d.shape == (4, 5, 3)
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), 1.0)
    back_az, back_el = azimuth_elevation(3.0 * d)  # any length
    np.testing.assert_allclose(back_az, az, atol=1e-12)
    np.testing.assert_allclose(back_el, el, atol=1e-12)
    a, e = azimuth_elevation([0.0, -2.0, 0.0])
    assert a == -math.pi / 2 and e == 0.0
