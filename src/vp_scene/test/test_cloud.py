"""numpy <-> sensor_msgs/PointCloud2 packing."""
from __future__ import annotations

import numpy as np
import pytest

from sensor_msgs.msg import PointCloud2, PointField

from vp_scene.cloud import numpy_to_pointcloud2, pack_rgb, pointcloud2_to_numpy, unpack_rgb


def test_round_trip_with_realization() -> None:
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(1000, 3))
    cols = rng.integers(0, 256, (1000, 3)).astype(np.uint8)
    real = np.repeat(np.arange(4, dtype=np.uint16), 250)
    msg = numpy_to_pointcloud2(pts, cols, realization=real, frame_id="map")
    assert [f.name for f in msg.fields] == ["x", "y", "z", "rgb", "realization"]
    assert [f.datatype for f in msg.fields] == [PointField.FLOAT32] * 4 + [PointField.UINT16]
    assert msg.width == 1000 and msg.height == 1 and msg.row_step == msg.point_step * 1000
    assert len(msg.data) == msg.row_step and msg.header.frame_id == "map" and msg.is_dense
    p, c, r = pointcloud2_to_numpy(msg)
    np.testing.assert_allclose(p, pts.astype(np.float32))
    np.testing.assert_array_equal(c, cols)
    np.testing.assert_array_equal(r, real)


def test_without_optional_fields_and_empty() -> None:
    pts = np.arange(12, dtype=float).reshape(4, 3)
    p, c, r = pointcloud2_to_numpy(numpy_to_pointcloud2(pts))
    np.testing.assert_array_equal(p, pts)
    assert c is None and r is None
    p, c, r = pointcloud2_to_numpy(numpy_to_pointcloud2(np.zeros((0, 3)), np.zeros((0, 3), np.uint8)))
    assert p.shape == (0, 3) and c.shape == (0, 3) and r is None


def test_rgb_packed_like_pcl() -> None:
    packed = pack_rgb(np.array([[0x12, 0x34, 0x56]], np.uint8))
    assert packed.dtype == np.float32 and packed.view(np.uint32)[0] == 0x00123456
    np.testing.assert_array_equal(unpack_rgb(packed), [[0x12, 0x34, 0x56]])


def test_parse_foreign_layout() -> None:
    """Padding, other field order, big-endian data, an organized (2 x 2) cloud with row padding."""
    dt = np.dtype({"names": ["rgb", "z", "y", "x"], "formats": [">u4", ">f8", ">f4", ">f4"],
                   "offsets": [0, 8, 16, 24], "itemsize": 32})
    arr = np.zeros(4, dt)
    arr["x"], arr["y"], arr["z"] = [1, 2, 3, 4], [5, 6, 7, 8], [9, 10, 11, 12]
    arr["rgb"] = [0xFF0000, 0x00FF00, 0x0000FF, 0x010203]
    rows = [arr[:2].tobytes() + b"\x00" * 8, arr[2:].tobytes() + b"\x00" * 8]
    msg = PointCloud2(height=2, width=2, is_bigendian=True, point_step=32, row_step=72,
                      fields=[PointField(name="rgb", offset=0, datatype=PointField.UINT32, count=1),
                              PointField(name="z", offset=8, datatype=PointField.FLOAT64, count=1),
                              PointField(name="y", offset=16, datatype=PointField.FLOAT32, count=1),
                              PointField(name="x", offset=24, datatype=PointField.FLOAT32, count=1)],
                      data=b"".join(rows))
    p, c, r = pointcloud2_to_numpy(msg)
    np.testing.assert_array_equal(p, [[1, 5, 9], [2, 6, 10], [3, 7, 11], [4, 8, 12]])
    np.testing.assert_array_equal(c, [[255, 0, 0], [0, 255, 0], [0, 0, 255], [1, 2, 3]])
    assert r is None


def test_bad_input() -> None:
    with pytest.raises(ValueError, match="points"):
        numpy_to_pointcloud2(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="colors"):
        numpy_to_pointcloud2(np.zeros((3, 3)), np.zeros((2, 3), np.uint8))
    with pytest.raises(ValueError, match="realization"):
        numpy_to_pointcloud2(np.zeros((3, 3)), realization=np.array([0, 1, 70000]))
    msg = numpy_to_pointcloud2(np.zeros((3, 3)))
    msg.width = 10
    with pytest.raises(ValueError, match="data size"):
        pointcloud2_to_numpy(msg)
    with pytest.raises(ValueError, match="'z'"):
        pointcloud2_to_numpy(PointCloud2(fields=[PointField(name="x", offset=0, datatype=7, count=1),
                                                 PointField(name="y", offset=4, datatype=7, count=1)]))


def test_realizations_from_cloud() -> None:
    from vp_scene.cloud import realizations_from_cloud

    rng = np.random.default_rng(0)
    pts = rng.normal(size=(3, 50, 3))
    msg = numpy_to_pointcloud2(pts.reshape(-1, 3), realization=np.repeat(np.arange(3, dtype=np.uint16), 50))
    np.testing.assert_allclose(realizations_from_cloud(msg), pts, atol=1e-6)  # float32 on the wire
    assert realizations_from_cloud(numpy_to_pointcloud2(pts[0])).shape == (1, 50, 3)
    with pytest.raises(ValueError, match="empty"):
        realizations_from_cloud(numpy_to_pointcloud2(np.zeros((0, 3))))
    uneven = numpy_to_pointcloud2(pts[0], realization=np.array([0] * 20 + [1] * 30, dtype=np.uint16))
    with pytest.raises(ValueError, match="different point counts"):
        realizations_from_cloud(uneven)
