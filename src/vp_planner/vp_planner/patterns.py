"""Fixed camera patterns that drone operators fly anyway: rings, arcs, spherical caps.

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

from vp_scene.camera import look_at

__all__ = ["ring", "arc", "cap", "direction"]


def direction(azimuth: float, elevation: float) -> NDArray[np.float64]:
    """Unit vector (3,) at ``azimuth`` (rad from +x, counter-clockwise) and ``elevation`` (rad up)."""
    ce = math.cos(elevation)
    return np.array([ce * math.cos(azimuth), ce * math.sin(azimuth), math.sin(elevation)])


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
