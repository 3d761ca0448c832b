"""The continuous search space of camera plans: its encoding, feasibility and reward binding.

Random and structured plans of the space: :mod:`vp_planner.designs` (which imports this module,
never the other way); the objective the optimizers maximize on it: :mod:`vp_planner.objective`.

Why a shell-and-target parameterization
---------------------------------------
The paper optimizes z = [c_1, v_1, ..., c_N, v_N] in R^{6N}. With a plain box for positions and
v in [-1, 1]^3, most random plans score exactly 0 (a camera too close, looking away from the
plant, or every pair over theta_match), so a 100-evaluation optimizer learns
almost nothing. Here every camera is still 6 numbers (dim = 6N, as in the paper), but each
number in [0, 1] has a geometric meaning that makes almost every plan look at the scene:

    u = (u_az, u_el, u_dist, u_tx, u_ty, u_tz) in [0, 1]^6

* azimuth    phi = 2 pi u_az
* elevation  eps = eps_lo + (eps_hi - eps_lo) u_el       (angle above the horizontal)
* direction  d = (cos eps cos phi, cos eps sin phi, sin eps) from the scene's centre o
* distance   t = t_exit(d) + depth u_dist, where t_exit(d) is where the ray o + t d leaves the
             scene's bounding box grown by the stand-off distance s on every side:
             t_exit = min_a (h_a + s) / |d_a| (h = half extents of the box)
* position   c = o + t d, then c_z = max(c_z, min_altitude)
* target     T = lo_T + (hi_T - lo_T) * (u_tx, u_ty, u_tz), a look-at point inside the scene's
             bounding box (optionally shrunk towards its centre by ``target_scale``)
* view       v = T - c

The bounding box, its centre o (x, y and mid-height) and the extents come from all K
realizations. By construction:

* stand-off: c lies on or outside the box grown by s (per axis), so its L-infinity distance, and
  hence its Euclidean distance, to every scene point is >= s;
* altitude: c_z >= min_altitude (the clamp only moves a camera up; eps_lo is bounded so that a
  descending ray leaves the grown box through a side face, where moving up keeps it outside);
* v != 0 (c is outside the box, T inside).

Only the minimum separation between cameras is not guaranteed by the decode.

Handling infeasible candidates: :meth:`ViewSpace.feasible` checks all rules (altitude,
stand-off against every point of every realization with a KD-tree, separation, finiteness; the
rules live in the torch-free :mod:`vp_planner.feasibility`).
:class:`vp_planner.objective.Objective` returns 0 for an infeasible plan (still counted as an evaluation), BO
restricts its acquisition to feasible candidates through ``feasible``, and the plan a method
returns is always the best *feasible* plan evaluated (an error if none was).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Optional

import numpy as np
import torch
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from vp_scene.camera import IMAGE_SIZE, CameraModel, azimuth_elevation, direction

from .feasibility import Feasibility, FeasibilityRules, check_minima, check_realizations
from .reward import DEFAULT_FOV, DEFAULT_THETA_MATCH
from .reward_models import DEFAULT_REWARD_MODEL, RewardFunction, check_fixed_cameras, make_reward

__all__ = [
    "SceneExtent",
    "PlanReward",
    "ViewSpace",
    "PlanningCancelled",
    "NoFeasiblePlanError",
]

#: ``callback(done, total, best, weights) -> bool`` after every evaluation (False: stop).
Callback = Callable[[int, int, float, Optional[list]], bool]
#: ``should_stop() -> bool``, asked between evaluations (True: stop).
StopCheck = Callable[[], bool]


class NoFeasiblePlanError(ValueError):
    """No feasible plan could be found or was evaluated."""


class PlanningCancelled(Exception):
    """Raised inside an objective when the progress callback asks to stop."""


@dataclass(frozen=True)
class SceneExtent:
    """Axis-aligned bounds of all realizations."""

    lo: NDArray[np.float64]  # (3,)
    hi: NDArray[np.float64]  # (3,)

    @property
    def centre(self) -> NDArray[np.float64]:
        return 0.5 * (self.lo + self.hi)

    @property
    def half(self) -> NDArray[np.float64]:
        return 0.5 * (self.hi - self.lo)

    @property
    def size(self) -> float:
        """Largest side of the box (at least 1e-3)."""
        return float(max(1e-3, np.max(self.hi - self.lo)))

    @classmethod
    def of(cls, realizations: NDArray[np.float64]) -> "SceneExtent":
        flat = realizations.reshape(-1, 3)
        return cls(flat.min(axis=0), flat.max(axis=0))


def to_numpy(x: Any) -> tuple[NDArray[np.float64], bool]:
    if isinstance(x, torch.Tensor):
        return x.detach().cpu().to(torch.float64).numpy(), True
    return np.asarray(x, dtype=np.float64), False


class PlanReward:
    """The reward of a space's plans: its ``reward_model`` on its ``realizations`` with its
    ``fov``, ``theta_match``, ``image`` (a CameraModel), ``fixed_cameras`` and ``point_weights``
    (a ViewSpace's, a :class:`vp_planner.candidates.CandidateSpace`'s), built once per dtype
    into ``_rewards``."""

    def reward_function(self, dtype: torch.dtype = torch.float64) -> RewardFunction:
        """This space's reward model on its realizations (built once per dtype)."""
        if dtype not in self._rewards:
            self._rewards[dtype] = make_reward(self.reward_model, self.realizations, self.fov, self.theta_match,
                                               self.image, dtype=dtype, fixed_cameras=self.fixed_cameras,
                                               point_weights=self.point_weights)
        return self._rewards[dtype]

    def reward(self, cams: Any, dtype: torch.dtype = torch.float64) -> Any:
        """Reward (averaged over the wind realizations, eq. 7) of plans (..., N, 6) under this
        space's reward model, fov and theta_match (with its fixed cameras and point weights)."""
        return self.reward_function(dtype)(cams)


class ViewSpace(PlanReward):
    """Unit-cube parameterization of N-camera plans (dim = 6N) with feasibility rules.

    Args:
        realizations: (K, P, 3) noisy scene realizations (the bounds use all of them).
        num_cameras: N >= 2.
        min_standoff: minimum distance (m) from every camera to every scene point.
        min_altitude: minimum camera height above the ground z = 0.
        min_separation: minimum distance between any two cameras.
        fov, theta_match: reward parameters (kept here so that the objective uses the same).
        reward_model: name of the reward model (:data:`vp_planner.reward_models.REWARD_MODELS`), or a
            ``(name, CoverageParams)`` spec of :func:`~vp_planner.reward_models.make_reward` (the request's)
            or a ``(name, params)`` spec.
        image_size: (width, height) in pixels of the images the cameras will take (the
            ``coverage`` model's resolution term).
        shell_depth: radial thickness of the shell of positions beyond the grown box
            (default: max(1.0, the scene's largest side)). The reward grows with distance (far
            cameras see the whole scene and keep pair angles uniform), so this outer bound is a
            real design choice: it caps how far (and how small in the image) the scene may be.
        elevation_range: (eps_lo, eps_hi) in radians; eps_lo is raised if needed so that
            descending rays leave the grown box through a side face (see module docstring).
        target_scale: look-at targets lie in the scene box scaled by this factor about its centre.
        obstacles: points (K, P, 3) or (M, 3) every camera must keep ``min_standoff`` from
            (default: the realizations). A space for one part of a field rewards views of that
            part's points but keeps its cameras clear of every plant of the field.
        fixed_positions: (M, 3) positions of cameras planned elsewhere (another part of the
            field) that every camera of this space must keep ``min_separation`` from.
        fixed_cameras: (M, 6) cameras already flown (an earlier sortie): every reward model
            scores a plan together with them (pairs with them count like pairs within the
            plan); no separation from them is required (they flew at another time).
        point_weights: (K, P) weights w_p of the realizations' points in the reward (None: 1;
            :func:`vp_planner.reward_models.reconstructed_weights`).
    """

    def __init__(
        self,
        realizations: Any,
        num_cameras: int,
        min_standoff: float = Feasibility.min_standoff,
        min_altitude: float = Feasibility.min_altitude,
        min_separation: float = Feasibility.min_separation,
        fov: float = DEFAULT_FOV,
        theta_match: float = DEFAULT_THETA_MATCH,
        shell_depth: Optional[float] = None,
        elevation_range: tuple[float, float] = (math.radians(-20.0), math.radians(89.0)),
        target_scale: float = 1.0,
        reward_model: Any = DEFAULT_REWARD_MODEL,
        image_size: tuple[int, int] = IMAGE_SIZE,
        obstacles: Any = None,
        fixed_positions: Any = None,
        fixed_cameras: Any = None,
        point_weights: Any = None,
    ) -> None:
        if int(num_cameras) != num_cameras or num_cameras < 2:
            raise ValueError(f"num_cameras must be an integer >= 2, got {num_cameras}")
        check_minima(min_standoff, min_altitude, min_separation)
        self.realizations = check_realizations(realizations)
        self.num_cameras = int(num_cameras)
        self.dim = 6 * self.num_cameras
        self.min_standoff = float(min_standoff)
        self.min_altitude = float(min_altitude)
        self.min_separation = float(min_separation)
        self.fov = float(fov)
        self.theta_match = float(theta_match)
        self.extent = SceneExtent.of(self.realizations)
        self.origin = self.extent.centre.copy()
        # Half extents of the box grown by the stand-off distance (tiny margin for round-off).
        self.grown_half = self.extent.half + self.min_standoff * (1.0 + 1e-9) + 1e-9
        self.shell_depth = float(shell_depth) if shell_depth is not None else max(1.0, self.extent.size)
        lo_el, hi_el = float(elevation_range[0]), float(elevation_range[1])
        # A descending ray must leave the grown box through a side face: tan|eps| * r_xy < h_z.
        r_xy = float(np.hypot(self.grown_half[0], self.grown_half[1]))
        floor = -0.95 * math.atan2(float(self.grown_half[2]), r_xy)
        self.elevation_lo = max(lo_el, floor)
        self.elevation_hi = min(hi_el, math.radians(90.0))
        if not self.elevation_lo < self.elevation_hi:
            raise ValueError(f"empty elevation range {elevation_range}")
        ts = float(target_scale)
        if not 0.0 <= ts <= 1.0:
            raise ValueError(f"target_scale must be in [0, 1], got {target_scale}")
        self.target_lo = self.extent.centre - ts * self.extent.half
        self.target_hi = self.extent.centre + ts * self.extent.half
        self.rules = FeasibilityRules(self.realizations if obstacles is None else obstacles, self.num_cameras,
                                      self.min_standoff, self.min_altitude, self.min_separation, fixed_positions)
        self.obstacles = None if obstacles is None else self.rules.obstacles
        self.fixed_positions = self.rules.fixed_positions
        self.reward_model = reward_model
        self.fixed_cameras = check_fixed_cameras(fixed_cameras)
        self.point_weights = None if point_weights is None else np.asarray(point_weights, dtype=np.float64)
        self.image = CameraModel(int(image_size[0]), int(image_size[1]), self.fov)
        self._rewards: dict = {}

    # ------------------------------------------------------------------ geometry
    @property
    def tree(self) -> cKDTree:
        """KD-tree over the stand-off obstacles: the points of all realizations, or ``obstacles``
        (built on first use)."""
        return self.rules.tree

    def directions(self, u_az: NDArray, u_el: NDArray) -> NDArray[np.float64]:
        """Unit directions (..., 3) from the scene's centre at azimuth 2 pi u_az and elevation
        eps_lo + (eps_hi - eps_lo) u_el (:func:`vp_scene.camera.direction`)."""
        return direction(2.0 * math.pi * u_az, self.elevation_lo + (self.elevation_hi - self.elevation_lo) * u_el)

    def exit_distance(self, d: NDArray[np.float64]) -> NDArray[np.float64]:
        """t_exit(d) = min_a (h_a + s) / |d_a|: where the ray o + t d leaves the grown box."""
        ad = np.abs(d)
        with np.errstate(divide="ignore"):
            t = np.where(ad > 1e-12, self.grown_half / np.maximum(ad, 1e-300), np.inf)
        return t.min(axis=-1)

    def positions(self, u_pos: NDArray[np.float64]) -> NDArray[np.float64]:
        """Camera positions (..., 3) from (..., 3) = (u_az, u_el, u_dist)."""
        d = self.directions(u_pos[..., 0], u_pos[..., 1])
        t = self.exit_distance(d) + self.shell_depth * u_pos[..., 2]
        c = self.origin + t[..., None] * d
        c[..., 2] = np.maximum(c[..., 2], self.min_altitude)
        return c

    def targets(self, u_tgt: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.target_lo + (self.target_hi - self.target_lo) * u_tgt

    def decode(self, U: Any) -> Any:
        """Plans (B, N, 6) = [c, v] from U (B, 6N): azimuths wrap (mod 1), the rest is clipped to [0, 1].

        Returns the same kind (numpy or torch, float64) as the input; a (6N,) vector gives (N, 6).
        """
        X, is_torch = to_numpy(U)
        single = X.ndim == 1
        X = np.atleast_2d(X)
        if X.shape[-1] != self.dim:
            raise ValueError(f"U must have {self.dim} columns, got shape {X.shape}")
        X = np.nan_to_num(X, nan=0.5).reshape(X.shape[0], self.num_cameras, 6)
        X = np.concatenate([np.mod(X[..., :1], 1.0), np.clip(X[..., 1:], 0.0, 1.0)], axis=-1)  # azimuth wraps
        c = self.positions(X[..., :3])
        v = self.targets(X[..., 3:]) - c
        cams = np.concatenate([c, v], axis=-1)
        if single:
            cams = cams[0]
        return torch.from_numpy(cams) if is_torch else cams

    @property
    def periodic(self) -> NDArray[np.bool_]:
        """(6N,) True at the azimuth coordinates u_az (periodic: u_az and u_az + 1 are the same plan)."""
        return np.tile(np.array([True, False, False, False, False, False]), self.num_cameras)

    def encode_cameras(self, cameras: Any) -> NDArray[np.float64]:
        """U (B, 6N) of camera plans (B, N, 6) (or one (N, 6)): the inverse of :meth:`decode` for
        plans this space can express; others are projected onto it.

        Position: the direction from the scene's centre gives (u_az, u_el) (elevation clipped to
        the space's range), the distance beyond the grown box gives u_dist (clipped to the
        shell). Target: the point of the viewing ray nearest the scene's centre, clipped to
        the target box. ``decode(encode_cameras(z)) == z`` up to scale of v for a plan whose
        cameras lie in the shell, above the altitude floor, and look at a point of the box.
        """
        cams = np.asarray(cameras, dtype=np.float64)
        single = cams.ndim == 2
        cams = cams.reshape(-1, self.num_cameras, 6)
        c, v = cams[..., :3], cams[..., 3:]
        rel = c - self.origin
        dist = np.linalg.norm(rel, axis=-1)
        d = rel / np.maximum(dist, 1e-12)[..., None]
        phi, eps = azimuth_elevation(d)
        u_az = np.mod(phi / (2 * math.pi), 1.0)
        u_el = np.clip((eps - self.elevation_lo) / (self.elevation_hi - self.elevation_lo), 0.0, 1.0)
        d_used = self.directions(u_az, u_el)
        u_dist = np.clip((dist - self.exit_distance(d_used)) / self.shell_depth, 0.0, 1.0)
        vn = v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)
        s = np.einsum("...i,...i->...", self.extent.centre - c, vn)
        tgt = c + np.maximum(s, 0.0)[..., None] * vn
        span = np.where(self.target_hi > self.target_lo, self.target_hi - self.target_lo, 1.0)
        u_tgt = np.clip((tgt - self.target_lo) / span, 0.0, 1.0)
        U = self.encode(np.stack([u_az, u_el, u_dist], axis=-1), u_tgt)
        return U[0] if single else U

    def encode(self, u_pos: NDArray[np.float64], u_tgt: NDArray[np.float64]) -> NDArray[np.float64]:
        """U (B, 6N) from per-camera position parameters (B, N, 3) and target parameters (B, N, 3)."""
        u = np.concatenate([np.asarray(u_pos, float), np.asarray(u_tgt, float)], axis=-1)
        return np.clip(u, 0.0, 1.0).reshape(u.shape[0], -1)

    # ------------------------------------------------------------------ feasibility
    def feasible(self, x: Any) -> Any:
        """Feasibility of plans: U (B, 6N) or cameras (B, N, 6) (or a single (6N,) / (N, 6)).

        A plan is feasible when all cameras are finite with a non-zero v, at least
        ``min_altitude`` above the ground, at least ``min_standoff`` from every point of every
        realization, and pairwise at least ``min_separation`` apart. Returns a bool array (B,)
        (a torch BoolTensor for torch input; a Python bool for a single plan).
        """
        X, is_torch = to_numpy(x)
        if X.ndim in (1, 2) and X.shape[-1] == self.dim and not (X.ndim == 2 and X.shape == (self.num_cameras, 6)):
            single = X.ndim == 1
            cams = self.decode(np.atleast_2d(X))
        elif X.ndim in (2, 3) and X.shape[-2:] == (self.num_cameras, 6):
            single = X.ndim == 2
            cams = X.reshape(-1, self.num_cameras, 6)
        else:
            raise ValueError(f"expected U (B, {self.dim}) or cameras (B, {self.num_cameras}, 6), got {X.shape}")
        ok = self._feasible_cameras(cams)
        if single:
            return bool(ok[0])
        return torch.from_numpy(ok) if is_torch else ok

    def _feasible_cameras(self, cams: NDArray[np.float64]) -> NDArray[np.bool_]:
        return self.rules(cams)
