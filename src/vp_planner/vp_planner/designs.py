"""Plans of a :class:`~vp_planner.space.ViewSpace` drawn or built without optimizing: uniformly random
feasible plans (:func:`random_plans`, the ``random`` baseline and the random part of the BO
initial design) and structured plans (:func:`structured_plans`: caps, rings and arcs about the
scene, the structured part of the initial design). Both are functions of the space (this module
imports :mod:`vp_planner.space`, the space knows nothing of its designs); the directions of the
caps go through :func:`vp_scene.camera.direction` and :func:`vp_scene.camera.azimuth_elevation`.
"""
from __future__ import annotations

import math
from typing import Any, Optional

import numpy as np
from numpy.typing import NDArray

from vp_scene.camera import azimuth_elevation, direction

from .space import NoFeasiblePlanError, PlanningCancelled, StopCheck, ViewSpace

__all__ = ["random_plans", "structured_plans"]


def random_plans(space: ViewSpace, n: int, rng: Any = None, max_tries: int = 1000,
                 should_stop: Optional[StopCheck] = None) -> NDArray[np.float64]:
    """n feasible plans U (n, 6N) drawn uniformly from the cube, by rejection.

    Raises NoFeasiblePlanError when fewer than n were found in ``max_tries`` rounds, and
    PlanningCancelled as soon as ``should_stop()`` is True (asked every round: for large N
    the search can take minutes).
    """
    rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    out: list[NDArray[np.float64]] = []
    have = 0
    batch = max(16, 2 * n)
    for _ in range(max_tries):
        if have >= n:
            break
        if should_stop is not None and should_stop():
            raise PlanningCancelled()
        U = rng.random((batch, space.dim))
        U = U[space.feasible(U)]
        out.append(U)
        have += len(U)
    if have < n:
        raise NoFeasiblePlanError(
            f"no feasible plan: found {have} of {n} feasible plans in {max_tries * batch} random draws "
            f"(min_separation {space.min_separation}, min_standoff {space.min_standoff}, "
            f"min_altitude {space.min_altitude})")
    return np.concatenate(out)[:n] if n > 0 else np.zeros((0, space.dim))


def structured_plans(space: ViewSpace, max_plans: int = 20) -> NDArray[np.float64]:
    """Up to ``max_plans`` structured plans U (M, 6N), the patterns a good plan is made of.

    In this order (infeasible ones are dropped):

    * 4 caps: the N cameras on a small circle (a spherical cap) of angular radius
      rho = theta_match / 2 about a central direction (plus one camera on the axis for
      N >= 5), so that the widest pair is about theta_match as seen from the scene's centre,
      at elevations 35, 50, 20, 65 degrees and several distances;
    * 2 rings: N cameras evenly spread in azimuth at the elevation 90 - theta_match/2 + 2
      degrees, where opposite cameras meet at just under theta_match (the paper reward's
      best circle), at the shell's outer edge and a little inside it;
    * 12 arcs: N cameras 30 degrees apart in azimuth (the pattern that reconstructs best),
      at elevations 20, 40 and 60 degrees, close to the stand-off distance and farther out,
      facing the long side of the scene and the opposite side;
    * 4 more caps.

    Every camera looks at the scene's centre; positions are on the shell of the space.
    """
    N = space.num_cameras
    tm = space.theta_match
    span = space.elevation_hi - space.elevation_lo

    def u_el(deg: float) -> float:
        return float(np.clip((math.radians(deg) - space.elevation_lo) / span, 0.0, 1.0))

    def caps(variants) -> list:
        out = []
        for el_deg, az_deg, u_dist, spread in variants:
            centre_dir = direction(math.radians(az_deg), math.radians(el_deg))
            ring = N if N <= 4 else N - 1
            rho = spread * tm / 2.0
            dirs = [centre_dir] if N > 4 else []
            e1 = np.cross([0.0, 0.0, 1.0], centre_dir)
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(centre_dir, e1)
            for k in range(ring):
                a = 2 * math.pi * k / ring
                d = math.cos(rho) * centre_dir + math.sin(rho) * (math.cos(a) * e1 + math.sin(a) * e2)
                dirs.append(d / np.linalg.norm(d))
            out.append(np.array([_u_from_dir(space, d) + (u_dist,) for d in dirs]))
        return out

    def along(az0_deg: float, step_deg: float, el_deg: float, u_dist: float) -> NDArray[np.float64]:
        az = (az0_deg + step_deg * (np.arange(N) - 0.5 * (N - 1))) / 360.0
        return np.stack([np.mod(az, 1.0), np.full(N, u_el(el_deg)), np.full(N, u_dist)], axis=1)

    ring_el = min(85.0, 90.0 - math.degrees(tm) / 2.0 + 2.0)
    u_pos = caps([(35, 0, 1.0, 1.0), (50, 90, 0.75, 1.0), (20, 180, 1.0, 0.9), (65, 270, 0.5, 1.0)])
    u_pos += [along(0.0, 360.0 / N, ring_el, 1.0), along(0.0, 360.0 / N, ring_el, 0.6)]
    long_side = 90.0 if space.extent.half[0] >= space.extent.half[1] else 0.0
    u_pos += [along(long_side + side, 30.0, el, u_dist) for el in (60.0, 40.0, 20.0)
              for u_dist in (0.05, 0.4) for side in (0.0, 180.0)]
    u_pos += caps([(35, 45, 0.5, 0.8), (80, 135, 1.0, 1.0), (50, 225, 0.25, 1.1), (20, 315, 0.75, 1.0)])
    u_pos = u_pos[: max(0, max_plans)]
    if not u_pos:
        return np.zeros((0, space.dim))
    U = space.encode(np.array(u_pos), np.full((len(u_pos), N, 3), 0.5))
    return U[space.feasible(U)]


def _u_from_dir(space: ViewSpace, d: NDArray[np.float64]) -> tuple[float, float]:
    phi, eps = azimuth_elevation(d)
    u_el = (float(eps) - space.elevation_lo) / (space.elevation_hi - space.elevation_lo)
    return ((float(phi) % (2 * math.pi)) / (2 * math.pi), float(min(1.0, max(0.0, u_el))))
