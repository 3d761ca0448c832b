"""The field's place on Earth: its geographic origin and the map <-> geodetic conversions (ROS-free).

``map`` (REP-103/105) is a local tangent plane at the origin: z is up (the ellipsoid's normal
there) and x is turned by ``yaw`` (rad, counter-clockwise seen from above) from east, so with
``yaw = 0`` map is ENU (x east, y north). A map point p is the ENU point R_z(yaw) p of the
origin's tangent plane; ENU <-> geodetic (WGS84 latitude, longitude in degrees, ellipsoidal
height in metres) is pymap3d's (``enu2geodetic``, ``geodetic2enu``): no geodesy here.

Directions are turned the same way and then expressed in the tangent plane of the point they
start from (pymap3d's ``enu2uvw`` and ``uvw2enu``: ENU at the origin -> ECEF -> ENU at the
point), so a heading is the one a compass reads there (0 north, 90 east, clockwise, degrees) and
a pitch is from that point's horizontal (positive up): the meridians converge across a field,
by about 1e-3 degrees a hundred metres east or west at 45 degrees of latitude.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .ranged import CodedError, bounded, check_ranges

__all__ = ["GEO_CODES", "GeoError", "GeoOrigin"]

#: The refusals of :class:`GeoOrigin`.
GEO_CODES = ("INVALID_ORIGIN",)


class GeoError(CodedError):
    """A refusal with its code (:data:`GEO_CODES`) and a one-line message."""


@dataclass(frozen=True)
class GeoOrigin:
    """The map's origin on Earth, validated once (GeoError INVALID_ORIGIN naming the field, its
    value and its range; each field's range is in its metadata)."""

    latitude: float = bounded(0.0, -90.0, 90.0, "deg", "WGS84 latitude of the map's origin")
    longitude: float = bounded(0.0, -180.0, 180.0, "deg", "WGS84 longitude of the map's origin")
    height: float = bounded(0.0, -1000.0, 10000.0, "m", "ellipsoidal (WGS84) height of the map's origin")
    yaw: float = bounded(0.0, -2 * math.pi, 2 * math.pi, "rad", "the map's x axis from east, counter-clockwise")

    def __post_init__(self) -> None:
        check_ranges(self, "INVALID_ORIGIN", GeoError, prefix="origin ")

    @classmethod
    def parse(cls, text: str, yaw: float = 0.0) -> "GeoOrigin":
        """``LAT,LON,HEIGHT`` (degrees, degrees, metres); GeoError INVALID_ORIGIN, one line."""
        parts = [p.strip() for p in str(text).split(",")]
        if len(parts) != 3:
            raise GeoError("INVALID_ORIGIN", f"origin must be LAT,LON,HEIGHT (degrees, degrees, metres), got {text!r}")
        try:
            values = [float(p) for p in parts]
        except ValueError:
            raise GeoError("INVALID_ORIGIN", f"origin must be three numbers LAT,LON,HEIGHT, got {text!r}") from None
        return cls(*values, yaw=yaw)

    def _enu(self, xyz: NDArray[np.float64]) -> NDArray[np.float64]:
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return np.stack([c * xyz[..., 0] - s * xyz[..., 1], s * xyz[..., 0] + c * xyz[..., 1], xyz[..., 2]], axis=-1)

    def _map(self, enu: NDArray[np.float64]) -> NDArray[np.float64]:
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return np.stack([c * enu[..., 0] + s * enu[..., 1], -s * enu[..., 0] + c * enu[..., 1], enu[..., 2]], axis=-1)

    def to_geodetic(self, points: ArrayLike) -> NDArray[np.float64]:
        """Map points (..., 3) -> (..., 3) latitude, longitude (deg), ellipsoidal height (m)."""
        import pymap3d

        enu = self._enu(np.asarray(points, dtype=np.float64))
        lat, lon, h = pymap3d.enu2geodetic(enu[..., 0], enu[..., 1], enu[..., 2], self.latitude, self.longitude,
                                           self.height)
        return np.stack([np.asarray(lat), np.asarray(lon), np.asarray(h)], axis=-1)

    def to_map(self, geodetic: ArrayLike) -> NDArray[np.float64]:
        """(..., 3) latitude, longitude (deg), ellipsoidal height (m) -> map points (..., 3)."""
        import pymap3d

        g = np.asarray(geodetic, dtype=np.float64)
        e, n, u = pymap3d.geodetic2enu(g[..., 0], g[..., 1], g[..., 2], self.latitude, self.longitude, self.height)
        return self._map(np.stack([np.asarray(e), np.asarray(n), np.asarray(u)], axis=-1))

    def heading_pitch(self, points: ArrayLike, directions: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Map directions (..., 3) starting at map points (..., 3) -> (heading, pitch) in degrees
        at each point (module docstring): heading in [0, 360), 0 north, clockwise; pitch in
        [-90, 90], positive up."""
        import pymap3d

        p = np.asarray(points, dtype=np.float64)
        d = self._enu(np.asarray(directions, dtype=np.float64))
        geo = self.to_geodetic(p)
        x, y, z = pymap3d.enu2uvw(d[..., 0], d[..., 1], d[..., 2], self.latitude, self.longitude)
        e, n, u = pymap3d.uvw2enu(x, y, z, geo[..., 0], geo[..., 1])
        e, n, u = (np.asarray(a, dtype=np.float64) for a in (e, n, u))
        heading = np.mod(np.degrees(np.arctan2(e, n)), 360.0)
        pitch = np.degrees(np.arctan2(u, np.hypot(e, n)))
        return heading, pitch
