"""The planner's feasibility rules for camera plans (torch-free: the dispatcher checks plans with
them without loading torch).

A plan of N cameras ``(N, 6) = [c, v]`` is feasible when

* every number is finite and every view direction is non-zero (v != 0);
* every camera is at least ``min_altitude`` above the ground: c_z >= min_altitude;
* every camera is at least ``min_standoff`` from every obstacle point (the points of all wind
  realizations of the scene, or those of the whole field when a space plans one part of it),
  checked with a KD-tree: min_p ||c - p|| >= min_standoff;
* every two cameras are at least ``min_separation`` apart, and so is every camera from the
  ``fixed_positions`` of cameras planned elsewhere: ||c_i - c_j|| >= min_separation.

Each comparison allows 1e-9 of round-off. Degenerate cases: a rule whose minimum is 0 is not
checked (``min_standoff = 0``: no obstacle tree is built); an empty batch gives an empty verdict;
non-finite positions are replaced by 0 for the tree queries (the finiteness rule already refuses
them). Memory: the pairwise separation of a batch is computed a chunk of plans at a time, so that
the (chunk, N, N) distance array holds at most ``SEPARATION_ELEMENTS`` numbers whatever B and N.

:class:`vp_planner.space.ViewSpace` (the optimizers' search space) and
:func:`vp_planner.fleet.plan_problems` (the dispatcher's check) both use :class:`FeasibilityRules`.
The rules' minima and their defaults have one home, :class:`Feasibility` (a plan request's
``feasibility``, the planner's and the dispatcher's parameters, the CLI's flags read it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Optional

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

__all__ = ["Feasibility", "FeasibilityRules", "check_minima", "check_realizations", "SEPARATION_ELEMENTS"]

#: Bound on the elements of the pairwise-distance array of one feasibility chunk.
SEPARATION_ELEMENTS = 1 << 20


def check_realizations(realizations: Any) -> NDArray[np.float64]:
    """Validate noisy scene realizations and return them as a (K, P, 3) float64 array.

    A (P, 3) cloud counts as K = 1; a torch tensor is accepted (converted without importing
    torch here). Raises ValueError for a wrong shape, an empty cloud or non-finite coordinates.
    """
    if hasattr(realizations, "detach"):  # a torch tensor
        realizations = realizations.detach().cpu().numpy()
    R = np.asarray(realizations, dtype=np.float64)
    if R.ndim == 2:
        R = R[None]
    if R.ndim != 3 or R.shape[-1] != 3:
        raise ValueError(f"realizations must have shape (K, P, 3), got {R.shape}")
    if R.shape[0] == 0 or R.shape[1] == 0:
        raise ValueError("the point cloud is empty")
    if not np.all(np.isfinite(R)):
        raise ValueError("the point cloud contains non-finite coordinates")
    return R


def check_minima(min_standoff: float, min_altitude: float, min_separation: float) -> None:
    """ValueError unless the rules' minima are finite and >= 0."""
    for name, val in (("min_standoff", min_standoff), ("min_altitude", min_altitude),
                      ("min_separation", min_separation)):
        try:
            ok = math.isfinite(val) and val >= 0
        except TypeError:
            ok = False
        if not ok:
            raise ValueError(f"{name} must be finite and >= 0, got {val}")


@dataclass(frozen=True)
class Feasibility:
    """The minima of the feasibility rules (m), validated on construction (finite, >= 0;
    ValueError naming the field): ``min_standoff`` from every scene point, ``min_altitude``
    above the ground, ``min_separation`` between cameras. The defaults here are the suite's; each
    field's metadata gives its help and range (the planner's parameters and flags read them)."""

    min_standoff: float = field(default=0.5, metadata={"help": "m from every scene point", "range": (0.0, math.inf)})
    min_altitude: float = field(default=0.3, metadata={"help": "m above the ground", "range": (0.0, math.inf)})
    min_separation: float = field(default=0.5, metadata={"help": "m between cameras", "range": (0.0, math.inf)})

    def __post_init__(self) -> None:
        check_minima(self.min_standoff, self.min_altitude, self.min_separation)
        for name in ("min_standoff", "min_altitude", "min_separation"):
            object.__setattr__(self, name, float(getattr(self, name)))


class FeasibilityRules:
    """The feasibility rules of N-camera plans around one set of obstacle points.

    Args:
        obstacles: (K, P, 3) or (M, 3) points every camera must keep ``min_standoff`` from
            (validated with :func:`check_realizations`); may be None only when min_standoff is 0.
        num_cameras: N, the cameras of every plan checked.
        min_standoff, min_altitude, min_separation: the rules' minima (m), finite and >= 0.
        fixed_positions: (M, 3) positions of cameras planned elsewhere that every camera must
            keep ``min_separation`` from.
    """

    def __init__(self, obstacles: Any, num_cameras: int, min_standoff: float = Feasibility.min_standoff,
                 min_altitude: float = Feasibility.min_altitude, min_separation: float = Feasibility.min_separation,
                 fixed_positions: Any = None) -> None:
        check_minima(min_standoff, min_altitude, min_separation)
        self.num_cameras = int(num_cameras)
        self.min_standoff = float(min_standoff)
        self.min_altitude = float(min_altitude)
        self.min_separation = float(min_separation)
        if obstacles is None and self.min_standoff > 0:
            raise ValueError("the stand-off rule needs obstacle points")
        self.obstacles = None if obstacles is None else check_realizations(obstacles).reshape(-1, 3)
        fixed = np.zeros((0, 3)) if fixed_positions is None else np.asarray(fixed_positions, dtype=np.float64)
        if fixed.ndim != 2 or fixed.shape[1] != 3 or not np.all(np.isfinite(fixed)):
            raise ValueError(f"fixed_positions must be finite (M, 3) positions, got shape {fixed.shape}")
        self.fixed_positions = fixed
        self._tree: Optional[cKDTree] = None

    @property
    def tree(self) -> cKDTree:
        """KD-tree over the obstacle points (built on first use)."""
        if self._tree is None:
            self._tree = cKDTree(self.obstacles)
        return self._tree

    def __call__(self, cams: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Feasibility (B,) of camera plans (B, N, 6)."""
        B = cams.shape[0]
        c, v = cams[..., :3], cams[..., 3:]
        ok = np.isfinite(cams).all(axis=(1, 2))
        ok &= (np.linalg.norm(v, axis=-1) > 0).all(axis=1)
        ok &= (c[..., 2] >= self.min_altitude - 1e-9).all(axis=1)
        if self.min_separation > 0 and B:
            # pairwise distances of a chunk of plans at a time: (chunk, N, N) stays bounded
            N = self.num_cameras
            iu = np.triu_indices(N, 1)
            step = max(1, SEPARATION_ELEMENTS // (N * N))
            for b0 in range(0, B, step):
                cb = c[b0:b0 + step]
                dist = np.linalg.norm(cb[:, :, None, :] - cb[:, None, :, :], axis=-1)
                ok[b0:b0 + step] &= (dist[:, iu[0], iu[1]] >= self.min_separation - 1e-9).all(axis=1)
            if len(self.fixed_positions):
                far, _ = cKDTree(self.fixed_positions).query(np.where(np.isfinite(c), c, 0.0).reshape(-1, 3), k=1)
                ok &= (far.reshape(B, N) >= self.min_separation - 1e-9).all(axis=1)
        if self.min_standoff > 0 and B:
            flat = np.where(np.isfinite(c), c, 0.0).reshape(-1, 3)
            dist, _ = self.tree.query(flat, k=1, distance_upper_bound=self.min_standoff)
            ok &= (dist.reshape(B, self.num_cameras) >= self.min_standoff - 1e-9).all(axis=1)
        return ok
