"""Fixed camera patterns that drone operators fly anyway: rings, arcs, spherical caps, surveys.

Each function returns cameras ``[c, v]`` (frame ``map``, :mod:`vp_scene.camera` convention),
all looking at a target point; they are the building blocks of the ``circle`` and ``arc``
baselines and of the plan families of ``bench/plan_quality.py``. Pure geometry, vectorized over
a leading batch dimension where stated; no feasibility checks (the callers own those).
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vp_scene.camera import CameraModel, direction, look_at

__all__ = ["ring", "arc", "cap", "footprint", "lawnmower"]


def ring(centre_xy: ArrayLike, target: ArrayLike, radius: ArrayLike, height: ArrayLike, n: int,
         spacing: Optional[float] = None, phase: float = 0.0) -> NDArray[np.float64]:
    """Plans (B, n, 6): n cameras on horizontal circles of ``radius`` (B,) at ``height`` (B,)
    about ``centre_xy``, all looking at ``target`` (3,).

    ``spacing`` (rad) between neighbours; None spreads them evenly over the full circle
    (2 pi / n, the paper's circle). With a spacing the cameras form an arc centred on azimuth
    ``phase``; without, camera 0 is at ``phase``.
    """
    radius = np.atleast_1d(np.asarray(radius, dtype=np.float64))[:, None]
    height = np.atleast_1d(np.asarray(height, dtype=np.float64))[:, None]
    if spacing is None:
        a = phase + 2.0 * math.pi * np.arange(n) / n
    else:
        a = phase + float(spacing) * (np.arange(n) - 0.5 * (n - 1))
    cx, cy = np.asarray(centre_xy, dtype=np.float64)[:2]
    radius, height = np.broadcast_arrays(radius, height)
    c = np.stack([cx + radius * np.cos(a), cy + radius * np.sin(a), np.broadcast_to(height, radius.shape[:1] + (n,))],
                 axis=-1)
    return look_at(c, np.broadcast_to(np.asarray(target, dtype=np.float64), c.shape))


def arc(centre_xy: ArrayLike, target: ArrayLike, radius: float, height: float, n: int,
        spacing: float = math.radians(30.0), azimuth: float = 0.0) -> NDArray[np.float64]:
    """One plan (n, 6): n cameras ``spacing`` rad apart in azimuth on the circle (radius, height),
    centred on ``azimuth``, all looking at ``target``."""
    return ring(centre_xy, target, [radius], [height], n, spacing=spacing, phase=azimuth)[0]


def cap(centre: ArrayLike, target: ArrayLike, distance: float, n: int, azimuth: float, elevation: float,
        half_angle: float, with_centre: Optional[bool] = None) -> NDArray[np.float64]:
    """One plan (n, 6): cameras at ``distance`` from ``centre`` on a spherical cap about the
    direction (azimuth, elevation): a ring of angular radius ``half_angle`` around it, plus one
    camera on the axis when ``with_centre`` (default: n >= 5). All look at ``target``.
    The widest pair of the ring is about 2 ``half_angle`` apart, seen from ``centre``.
    """
    axis = direction(azimuth, elevation)
    with_centre = n >= 5 if with_centre is None else bool(with_centre)
    ring_n = n - 1 if with_centre else n
    e1 = np.cross([0.0, 0.0, 1.0], axis)
    if np.linalg.norm(e1) < 1e-9:
        e1 = np.array([1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    dirs = [axis] if with_centre else []
    for k in range(ring_n):
        a = 2.0 * math.pi * k / ring_n
        d = math.cos(half_angle) * axis + math.sin(half_angle) * (math.cos(a) * e1 + math.sin(a) * e2)
        dirs.append(d / np.linalg.norm(d))
    c = np.asarray(centre, dtype=np.float64) + distance * np.array(dirs)
    return look_at(c, np.broadcast_to(np.asarray(target, dtype=np.float64), c.shape))


def footprint(distance: float, image: CameraModel, tilt: float = 0.0) -> tuple[float, float]:
    """(along, across): the extent of an image on a horizontal plane ``distance`` below the
    camera, for a camera pitched ``tilt`` rad from nadir along the track with its image width
    across it (a survey camera)::

        along  = d (tan(tilt + b_v) - tan(tilt - b_v)),   b_v = half the vertical FoV
        across = 2 d tan(b_h) / cos(tilt),                b_h = half the horizontal FoV

    (``across`` at the footprint's centre line; a tilted footprint is a trapezoid). Requires
    tilt + b_v < pi / 2 (the upper image edge must meet the plane)."""
    b_v = image.half_fov_vertical
    if not (0.0 <= tilt and tilt + b_v < 0.5 * math.pi):
        raise ValueError(f"tilt {tilt:.3f} rad: the image's upper edge does not meet the ground (max "
                         f"{0.5 * math.pi - b_v:.3f} rad)")
    along = distance * (math.tan(tilt + b_v) - math.tan(tilt - b_v))
    return along, 2.0 * distance * image.tan_half_fov / math.cos(tilt)


def lawnmower(lo_xy: ArrayLike, hi_xy: ArrayLike, plane_z: float, distance: float, n: int, image: CameraModel,
              overlap: float, tilt: float = 0.0, min_spacing: float = 0.0) -> Optional[NDArray[np.float64]]:
    """A grid survey (n, 6) over the box [lo_xy, hi_xy] at ``distance`` above the plane z =
    ``plane_z`` (the canopy top), or None when n images cannot cover the box with ``overlap``.

    Flight lines run along the box's longer side (the track), ``m`` lines across it; each image
    covers a :func:`footprint` on the plane. With ``overlap`` o the footprint centres are at most
    (1 - o) footprint apart along and across the track, and the outer footprints reach the box's
    edges: a line needs ``ceil((L - F) / ((1 - o) F)) + 1`` images, and ``m`` lines likewise
    across. The n cameras are spread over the m lines (the first n mod m lines get one more),
    evenly from end to end of each line (at least ``min_spacing`` apart, centred when the line is
    shorter). Lines are flown back and forth (boustrophedon): a tilted camera (``tilt`` > 0, an
    oblique survey) pitches forward along its line's direction, so neighbouring lines look from
    opposite sides; nadir cameras look straight down. Positions are set back by d tan(tilt) so
    that the optical axis meets the plane at the footprint centre.
    """
    lo = np.asarray(lo_xy, dtype=np.float64)[:2]
    hi = np.asarray(hi_xy, dtype=np.float64)[:2]
    a = 0 if hi[0] - lo[0] >= hi[1] - lo[1] else 1   # along-track axis
    c = 1 - a
    along, across = footprint(distance, image, tilt)
    if tilt == 0.0 and a == 1:
        # a nadir camera's image width is along world y (vp_scene.camera: y_b = +y for a vertical
        # view), which is along the track when the lines run along y
        along, across = across, along
    step = 1.0 - float(overlap)

    def count(length: float, size: float) -> int:
        return int(math.ceil(max(0.0, length - size) / (step * size) - 1e-9)) + 1

    m = count(hi[c] - lo[c], across)
    per_line = count(hi[a] - lo[a], along)
    if m * per_line > n or m > n:
        return None
    line_pos = _spread(lo[c] + 0.5 * across, hi[c] - 0.5 * across, m, min_spacing)
    counts = np.full(m, n // m)
    counts[: n % m] += 1
    cams = []
    for k, (pos_c, n_k) in enumerate(zip(line_pos, counts)):
        sign = 1.0 if k % 2 == 0 else -1.0
        for pos_a in _spread(lo[a] + 0.5 * along, hi[a] - 0.5 * along, int(n_k), min_spacing)[::int(sign)]:
            centre = np.zeros(3)
            centre[a], centre[c], centre[2] = pos_a, pos_c, plane_z
            v = np.zeros(3)
            v[a], v[2] = sign * math.sin(tilt), -math.cos(tilt)
            pos = centre - distance / math.cos(tilt) * v
            cams.append(np.concatenate([pos, v]))
    return np.array(cams)


def _spread(lo: float, hi: float, n: int, min_spacing: float) -> NDArray[np.float64]:
    """n positions evenly from lo to hi (their midpoint for n = 1), at least ``min_spacing`` apart
    (spread about the midpoint when [lo, hi] is too short)."""
    mid = 0.5 * (lo + hi)
    if n == 1:
        return np.array([mid])
    half = 0.5 * max(hi - lo, min_spacing * (n - 1))
    return np.linspace(mid - half, mid + half, n)
