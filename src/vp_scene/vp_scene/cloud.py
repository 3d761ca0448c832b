"""numpy <-> ``sensor_msgs/PointCloud2``.

Fields written: ``x, y, z`` float32, ``rgb`` float32 holding the packed 0x00RRGGBB uint32 as in
PCL (optional), and ``realization`` uint16 (optional, the wind realization index of each point).
Packing and parsing use numpy structured dtypes (no per-point Python loops). The ROS message
imports live in this module only.
"""
from __future__ import annotations

import array
from typing import Optional

import numpy as np
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import Header

__all__ = ["numpy_to_pointcloud2", "pointcloud2_to_numpy", "realizations_from_cloud", "pack_rgb", "unpack_rgb"]

_PF_DTYPES = {
    PointField.INT8: "i1", PointField.UINT8: "u1", PointField.INT16: "i2", PointField.UINT16: "u2",
    PointField.INT32: "i4", PointField.UINT32: "u4", PointField.FLOAT32: "f4", PointField.FLOAT64: "f8",
}


def pack_rgb(colors: np.ndarray) -> np.ndarray:
    """(N, 3) uint8 RGB -> (N,) float32 whose bits are the uint32 0x00RRGGBB (PCL's ``rgb``)."""
    c = np.asarray(colors)
    if c.ndim != 2 or c.shape[1] != 3:
        raise ValueError(f"colors must have shape (N, 3), got {c.shape}")
    c = c.astype(np.uint32)
    return ((c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]).astype(np.uint32).view(np.float32)


def unpack_rgb(rgb: np.ndarray) -> np.ndarray:
    """(N,) packed float32 (or uint32) ``rgb`` -> (N, 3) uint8."""
    u = np.ascontiguousarray(rgb)
    u = u.view(np.uint32) if u.dtype.itemsize == 4 else u.astype(np.uint32)
    return np.stack([(u >> 16) & 0xFF, (u >> 8) & 0xFF, u & 0xFF], axis=1).astype(np.uint8)


def numpy_to_pointcloud2(points: np.ndarray, colors: Optional[np.ndarray] = None,
                         realization: Optional[np.ndarray] = None, frame_id: str = "map",
                         stamp=None) -> PointCloud2:
    """Pack points (N, 3), optional colours (N, 3) uint8 and realization indices (N,) into an
    unorganized (height 1) little-endian PointCloud2 with fields x, y, z[, rgb][, realization].
    ``stamp`` is a ``builtin_interfaces/Time`` (default zero)."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {pts.shape}")
    n = pts.shape[0]
    names, formats, offsets = ["x", "y", "z"], ["<f4"] * 3, [0, 4, 8]
    fields = [PointField(name=a, offset=4 * i, datatype=PointField.FLOAT32, count=1) for i, a in enumerate("xyz")]
    off = 12
    if colors is not None:
        if np.asarray(colors).shape != (n, 3):
            raise ValueError(f"colors must have shape ({n}, 3), got {np.asarray(colors).shape}")
        names.append("rgb"); formats.append("<f4"); offsets.append(off)
        fields.append(PointField(name="rgb", offset=off, datatype=PointField.FLOAT32, count=1))
        off += 4
    if realization is not None:
        r = np.asarray(realization)
        if r.shape != (n,):
            raise ValueError(f"realization must have shape ({n},), got {r.shape}")
        if n and (r.min() < 0 or r.max() > 0xFFFF):
            raise ValueError("realization indices must fit in uint16")
        names.append("realization"); formats.append("<u2"); offsets.append(off)
        fields.append(PointField(name="realization", offset=off, datatype=PointField.UINT16, count=1))
        off += 2
    step = (off + 3) // 4 * 4
    dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": step})
    buf = np.zeros(n, dtype=dtype)
    buf["x"], buf["y"], buf["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
    if colors is not None:
        buf["rgb"] = pack_rgb(colors)
    if realization is not None:
        buf["realization"] = np.asarray(realization).astype(np.uint16)

    msg = PointCloud2()
    msg.header = Header(frame_id=frame_id)
    if stamp is not None:
        msg.header.stamp = stamp
    msg.height, msg.width = 1, n
    msg.fields = fields
    msg.is_bigendian = False
    msg.point_step = step
    msg.row_step = step * n
    msg.is_dense = bool(np.isfinite(pts).all())
    data = array.array("B")
    data.frombytes(buf.tobytes())
    msg.data = data
    return msg


def pointcloud2_to_numpy(msg: PointCloud2) -> tuple[np.ndarray, Optional[np.ndarray], Optional[np.ndarray]]:
    """Parse a PointCloud2 into (points (N, 3) float64, colors (N, 3) uint8 or None,
    realization (N,) uint16 or None). Handles any field order, padding, endianness and
    organized clouds (height > 1). Raises ValueError when x, y or z is missing or the data
    size does not match the header."""
    fields = {f.name: f for f in msg.fields}
    for a in "xyz":
        if a not in fields:
            raise ValueError(f"PointCloud2 has no '{a}' field (fields: {', '.join(fields) or 'none'})")
    n = int(msg.width) * int(msg.height)
    step, row_step = int(msg.point_step), int(msg.row_step)
    raw = np.frombuffer(msg.data, dtype=np.uint8) if len(msg.data) else np.zeros(0, np.uint8)
    if n == 0:
        return np.zeros((0, 3)), (np.zeros((0, 3), np.uint8) if ("rgb" in fields or "rgba" in fields) else None), \
            (np.zeros(0, np.uint16) if "realization" in fields else None)
    if row_step < step * int(msg.width) or len(raw) < row_step * (int(msg.height) - 1) + step * int(msg.width):
        raise ValueError(f"PointCloud2 data size {len(raw)} does not match {msg.height} x {msg.width} points "
                         f"(point_step {step}, row_step {row_step})")
    endian = ">" if msg.is_bigendian else "<"
    wanted = [k for k in ("x", "y", "z", "rgb", "rgba", "realization") if k in fields]
    for k in wanted:
        if fields[k].datatype not in _PF_DTYPES:
            raise ValueError(f"PointCloud2 field '{k}' has unknown datatype {fields[k].datatype}")
    dtype = np.dtype({"names": wanted,
                      "formats": [endian + _PF_DTYPES[fields[k].datatype] for k in wanted],
                      "offsets": [int(fields[k].offset) for k in wanted], "itemsize": step})
    rows = [np.frombuffer(raw, dtype=dtype, count=int(msg.width), offset=r * row_step) for r in range(int(msg.height))]
    table = rows[0] if len(rows) == 1 else np.concatenate(rows)
    points = np.stack([table["x"], table["y"], table["z"]], axis=1).astype(np.float64)
    colors = None
    ckey = "rgb" if "rgb" in fields else ("rgba" if "rgba" in fields else None)
    if ckey is not None:
        c = np.ascontiguousarray(table[ckey])
        if c.dtype.itemsize != 4:
            raise ValueError(f"PointCloud2 field '{ckey}' must be 4 bytes (packed 0x00RRGGBB)")
        # reinterpret the 4 bytes as uint32 in the array's own byte order: bit-exact for float32 rgb
        colors = unpack_rgb(c.view(np.dtype(c.dtype.byteorder.replace("|", "=") + "u4")).astype(np.uint32))
    realization = table["realization"].astype(np.uint16) if "realization" in fields else None
    return points, colors, realization



def realizations_from_cloud(msg: PointCloud2) -> np.ndarray:
    """The scene node's ``/scene/noisy_points`` cloud as a (K, P, 3) array (realization order).

    A cloud without a ``realization`` field counts as K = 1. Raises ValueError for an empty cloud
    or realizations of different sizes."""
    points, _colors, realization = pointcloud2_to_numpy(msg)
    if points.shape[0] == 0:
        raise ValueError("the noisy scene cloud is empty")
    if realization is None:
        return points[None]
    groups = [points[realization == k] for k in np.unique(realization)]
    if len({g.shape[0] for g in groups}) != 1:
        raise ValueError("realizations of the noisy scene have different point counts")
    return np.stack(groups)
