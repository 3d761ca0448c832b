"""Wind noise of paper Sec. V-A.

"We considered L levels of the plants and for each level l in {1, ..., L} we have applied a
noise value l x n_wind where n_wind ~ N(n_wind; 0, 0.002) [...] we considered five distinct
realizations of n_wind to create five different noisy environments."

Here: a point's level l in {1..L} comes from its height inside its plant's ``z_range`` (L equal
height bands, l = 1 at the ground, L at the top); the point moves by ``l * n_wind`` horizontally
along the wind direction (rad from +x). 0.002 is the *variance* of n_wind (std = sqrt(0.002)).
One n_wind per realization, shared by all plants of the scene; K realizations.

ROS-free: numpy only.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .limits import check_seed
from .scenario import Scene
from .scene_spec import SCENE

__all__ = ["WindConfig", "NoisyScene", "draw_n_wind", "levels_of", "displace", "make_noisy_scene", "noisy_scene_of"]


@dataclass(frozen=True)
class WindConfig:
    """Wind model parameters (validated on construction; ValueError when invalid).

    Attributes:
        levels: L >= 1 height levels.
        realizations: K >= 1 realizations of n_wind.
        variance: variance of n_wind ~ N(0, variance), >= 0 (paper: 0.002).
        direction: horizontal wind direction, rad from +x.
    """

    levels: int = SCENE.levels
    realizations: int = SCENE.realizations
    variance: float = SCENE.wind_variance
    direction: float = SCENE.wind_direction

    def __post_init__(self) -> None:
        for name in ("levels", "realizations"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
                raise ValueError(f"wind {name} must be an integer >= 1, got {v!r}")
            if v < 1:
                raise ValueError(f"wind {name} must be >= 1, got {v}"
                                 + (" (L, the number of height levels)" if name == "levels"
                                    else " (K, the number of wind realizations)"))
        for name in ("variance", "direction"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                    or not math.isfinite(v):
                raise ValueError(f"wind {name} must be a finite number, got {v!r}")
        if self.variance < 0:
            raise ValueError(f"wind variance must be >= 0, got {self.variance}")


def draw_n_wind(config: WindConfig, seed: int) -> np.ndarray:
    """The K values n_wind ~ N(0, variance) (paper Sec. V-A), from ``default_rng([seed, 1])``
    (independent of the scene-layout stream ``[seed, 0]``)."""
    rng = np.random.default_rng([check_seed("seed", seed), 1])
    return rng.normal(0.0, math.sqrt(config.variance), size=config.realizations)


def levels_of(z: np.ndarray, z_range: np.ndarray, levels: int) -> np.ndarray:
    """Level l in {1..L} of heights z: L equal bands of ``z_range`` ((2,) or (P, 2) per point)."""
    z = np.asarray(z, dtype=np.float64)
    zr = np.asarray(z_range, dtype=np.float64)
    lo, hi = (zr[0], zr[1]) if zr.ndim == 1 else (zr[:, 0], zr[:, 1])
    h = np.maximum(hi - lo, 1e-12)
    lev = np.floor((z - lo) / h * levels) + 1
    return np.clip(lev, 1, levels).astype(np.int64)


def displace(points: np.ndarray, z_range: np.ndarray, n_wind: float, levels: int,
             direction: float = 0.0) -> np.ndarray:
    """One wind realization: point of level l moves by ``l * n_wind`` along (cos d, sin d, 0).

    Args:
        points: (P, 3) scene points.
        z_range: (2,) min / max height for all points, or (P, 2) per point (its plant's range).
        n_wind: the realization's n_wind.
        levels: L >= 1.
        direction: rad from +x.

    Returns:
        (P, 3) displaced copy (z unchanged).
    """
    if isinstance(levels, bool) or int(levels) != levels or levels < 1:
        raise ValueError(f"levels must be an integer >= 1, got {levels!r}")
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points must have shape (P, 3), got {p.shape}")
    zr = np.asarray(z_range, dtype=np.float64)
    if zr.shape != (2,) and zr.shape != (p.shape[0], 2):
        raise ValueError(f"z_range must have shape (2,) or ({p.shape[0]}, 2), got {zr.shape}")
    shift = levels_of(p[:, 2], zr, int(levels)) * float(n_wind)
    out = p.copy()
    out[:, 0] += shift * math.cos(direction)
    out[:, 1] += shift * math.sin(direction)
    return out


@dataclass
class NoisyScene:
    """K wind realizations of a scene.

    Attributes:
        scene: the noise-free scene.
        config: the wind parameters.
        seed: the seed of the n_wind draws.
        n_wind: (K,) the drawn n_wind values.
        points: (K, P, 3) displaced points; same point order (and colours) as ``scene``.
    """

    scene: Scene
    config: WindConfig
    seed: int
    n_wind: np.ndarray
    points: np.ndarray

    @property
    def colors(self) -> np.ndarray:
        """(P, 3) uint8 colours, identical in every realization."""
        return self.scene.colors


def make_noisy_scene(scene: Scene, config: WindConfig, seed: int) -> NoisyScene:
    """K noisy copies of ``scene`` (paper Sec. V-A), each point's level from its plant's z_range."""
    return noisy_scene_of(scene, config, draw_n_wind(config, seed), seed)


def noisy_scene_of(scene: Scene, config: WindConfig, n_wind: np.ndarray, seed: int) -> NoisyScene:
    """The noisy copies of ``scene`` under the given ``n_wind`` values (one realization each; a
    simulated flight's own winds, :mod:`vp_scene.flights`); ``seed`` is recorded as the draws' seed
    and ``config.realizations`` set to their number."""
    n_wind = np.asarray(n_wind, dtype=np.float64).reshape(-1)
    if not len(n_wind) or not np.isfinite(n_wind).all():
        raise ValueError(f"n_wind must be one or more finite values, got {n_wind!r}")
    if config.realizations != len(n_wind):
        config = WindConfig(levels=config.levels, realizations=len(n_wind), variance=config.variance,
                            direction=config.direction)
    zr = scene.z_ranges[scene.plant_index]
    pts = np.stack([displace(scene.points, zr, w, config.levels, config.direction) for w in n_wind])
    return NoisyScene(scene=scene, config=config, seed=int(seed), n_wind=n_wind, points=pts)
