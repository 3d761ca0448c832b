"""From a plan to a fleet: which drone flies to which camera pose, in the fleet's frame (ROS-free).

The dispatcher node (:mod:`vp_planner.dispatcher_node`) is a thin adapter around this module.

Assignment
----------
D drones at positions a_1..a_D and M <= D poses with positions g_1..g_M (same frame). The cost
of sending drone i to pose j is the straight-line distance d_ij = |a_i - g_j| (metres). An
assignment is an injective map sigma: {1..M} -> {1..D} (pose j goes to drone sigma(j); the D - M
drones outside its image are spare and get nothing).

* ``min_total`` minimizes the total travel  sum_j d_{sigma(j) j}: the linear sum assignment
  problem on the D x M distance matrix (:func:`scipy.optimize.linear_sum_assignment`, the
  Jonker-Volgenant algorithm, O(D M^2)).
* ``min_max`` minimizes the longest single flight  max_j d_{sigma(j) j}, which bounds the time
  until the whole fleet is in place: the linear *bottleneck* assignment problem. Its optimum t*
  is one of the entries of the matrix; the smallest entry t for which the bipartite graph
  {(i, j): d_ij <= t} has a matching that covers every pose is found by binary search over the
  sorted distinct entries (Hopcroft-Karp, :func:`scipy.sparse.csgraph.maximum_bipartite_matching`,
  for each test: O(E sqrt(V) log(DM))). Among the bottleneck-optimal assignments the one with
  the least total travel is returned (a linear sum assignment with the entries above t*
  forbidden), so that no drone flies further than needed.

Frames
------
Plans are in ``map``; drones report and take goals in the fleet's frame. The fleet frame is
given by a fixed transform from ``map`` (tf2 is not available from PyPI), as tf2's
``static_transform_publisher --x X --y Y --z Z --yaw YAW --frame-id map --child-frame-id fleet``
would publish it: the fleet frame's origin at (X, Y, Z) in ``map``, its axes turned by YAW about
``map``'s z axis. A point p_f in the fleet frame is p_m = R_z(YAW) p_f + (X, Y, Z) in ``map``;
plan poses go the other way (:meth:`FleetTransform.poses_to_fleet`).

Goal orientation: ``body`` keeps the plan's convention (the pose's +x axis is the optical axis,
:mod:`vp_scene.camera`); ``optical`` gives the REP-103 camera optical frame (z forward, x right,
y down, :func:`vp_scene.camera.optical_orientation`), as camera gimbal interfaces expect.

Feasibility
-----------
A plan is dispatched only if it satisfies the planner's rules (stand-off from every scene point,
altitude above the ground, separation between cameras). The rules have one home,
:class:`vp_planner.feasibility.FeasibilityRules` (torch-free; :class:`vp_planner.space.ViewSpace`
uses it too); :func:`plan_problems` asks it and, for a refused plan, explains which cameras break
what.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import linear_sum_assignment
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import maximum_bipartite_matching
from scipy.spatial.transform import Rotation

from vp_scene.camera import check_cameras, express_poses, optical_orientation

from .feasibility import Feasibility, FeasibilityRules

__all__ = [
    "ASSIGNMENTS",
    "ORIENTATIONS",
    "Assignment",
    "AssignmentError",
    "FleetTransform",
    "distance_matrix",
    "min_total_assignment",
    "bottleneck_assignment",
    "assign",
    "goal_orientations",
    "plan_problems",
]

#: Assignment objectives: total travel, or the longest single flight.
ASSIGNMENTS: tuple[str, ...] = ("min_total", "min_max")
#: Goal orientations: the plan's body convention (+x = optical axis) or the REP-103 optical frame.
ORIENTATIONS: tuple[str, ...] = ("body", "optical")


class AssignmentError(ValueError):
    """The poses cannot be assigned (more poses than drones, bad positions)."""


@dataclass(frozen=True)
class Assignment:
    """Drone ``drone_of_pose[j]`` flies to pose j; ``distances[j]`` is that flight (metres)."""

    drone_of_pose: NDArray[np.int64]
    distances: NDArray[np.float64]

    @property
    def total(self) -> float:
        """Sum of the flights, m."""
        return float(self.distances.sum())

    @property
    def max_distance(self) -> float:
        """The longest flight, m (0 for no poses)."""
        return float(self.distances.max()) if self.distances.size else 0.0

    def spare(self, num_drones: int) -> list[int]:
        """Indices of the drones that got no pose."""
        used = set(int(i) for i in self.drone_of_pose)
        return [i for i in range(num_drones) if i not in used]


def _points(x: ArrayLike, what: str) -> NDArray[np.float64]:
    p = np.asarray(x, dtype=np.float64)
    if p.ndim == 1 and p.size == 3:
        p = p[None]
    if p.ndim != 2 or p.shape[1] != 3:
        raise AssignmentError(f"{what} must have shape (n, 3), got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise AssignmentError(f"{what} contain NaN or infinite coordinates")
    return p


def distance_matrix(drones: ArrayLike, goals: ArrayLike) -> NDArray[np.float64]:
    """d_ij = |drones_i - goals_j| (D, M), Euclidean, for positions (D, 3) and (M, 3)."""
    a, g = _points(drones, "drone positions"), _points(goals, "goal positions")
    return np.linalg.norm(a[:, None, :] - g[None, :, :], axis=-1)


def _check_cost(cost: ArrayLike) -> NDArray[np.float64]:
    c = np.asarray(cost, dtype=np.float64)
    if c.ndim != 2:
        raise AssignmentError(f"the cost matrix must be 2-D (drones x poses), got shape {c.shape}")
    if not np.all(np.isfinite(c)):
        raise AssignmentError("the cost matrix contains NaN or infinite entries")
    d, m = c.shape
    if m > d:
        raise AssignmentError(f"{m} poses but only {d} drones: every pose needs its own drone")
    return c


def min_total_assignment(cost: ArrayLike) -> NDArray[np.int64]:
    """Drone per pose (M,) minimizing sum_j cost[sigma(j), j], sigma injective (D >= M).

    The linear sum assignment problem, solved exactly by :func:`scipy.optimize.linear_sum_assignment`
    on the transposed (poses x drones) matrix."""
    c = _check_cost(cost)
    if c.shape[1] == 0:
        return np.zeros(0, dtype=np.int64)
    rows, cols = linear_sum_assignment(c.T)
    out = np.empty(c.shape[1], dtype=np.int64)
    out[rows] = cols
    return out


def _covers_all_poses(allowed: NDArray[np.bool_]) -> bool:
    """Whether the bipartite graph (poses x drones) ``allowed.T`` has a matching covering every pose."""
    match = maximum_bipartite_matching(csr_matrix(allowed.T.astype(np.int8)), perm_type="column")
    return bool(np.all(match >= 0))


def bottleneck_assignment(cost: ArrayLike) -> NDArray[np.int64]:
    """Drone per pose (M,) minimizing max_j cost[sigma(j), j], then the total among those optima.

    Linear bottleneck assignment: binary search for the smallest distinct entry t* of the matrix
    whose threshold graph {cost <= t*} covers every pose with a matching; then a linear sum
    assignment with every entry above t* forbidden (it exists: that graph has such a matching)."""
    c = _check_cost(cost)
    if c.shape[1] == 0:
        return np.zeros(0, dtype=np.int64)
    values = np.unique(c)  # sorted; the largest always admits a matching (D >= M)
    lo, hi = 0, len(values) - 1
    while lo < hi:
        mid = (lo + hi) // 2
        if _covers_all_poses(c <= values[mid]):
            hi = mid
        else:
            lo = mid + 1
    t = values[lo]
    rows, cols = linear_sum_assignment(np.where(c <= t, c, np.inf).T)
    out = np.empty(c.shape[1], dtype=np.int64)
    out[rows] = cols
    return out


def assign(drones: ArrayLike, goals: ArrayLike, objective: str = "min_total") -> Assignment:
    """Assign goal positions (M, 3) to drone positions (D, 3), D >= M, by ``objective``
    (:data:`ASSIGNMENTS`); AssignmentError for fewer drones than goals or bad positions."""
    if objective not in ASSIGNMENTS:
        raise AssignmentError(f"unknown assignment {objective!r}; one of {', '.join(ASSIGNMENTS)}")
    cost = distance_matrix(drones, goals)
    solve = min_total_assignment if objective == "min_total" else bottleneck_assignment
    drone_of_pose = solve(cost)
    return Assignment(drone_of_pose, cost[drone_of_pose, np.arange(cost.shape[1])])


@dataclass(frozen=True)
class FleetTransform:
    """The fixed transform from ``map`` to the fleet's frame: the fleet frame's origin (x, y, z)
    in ``map`` and its yaw about ``map``'s z axis (rad). p_map = R_z(yaw) p_fleet + (x, y, z)."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    yaw: float = 0.0

    def __post_init__(self) -> None:
        for name in ("x", "y", "z", "yaw"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"the map -> fleet transform's {name} must be finite, got {getattr(self, name)}")

    @property
    def is_identity(self) -> bool:
        return self.x == 0.0 and self.y == 0.0 and self.z == 0.0 and math.remainder(self.yaw, 2 * math.pi) == 0.0

    def _rotation(self) -> Rotation:
        return Rotation.from_euler("z", self.yaw)

    def points_to_fleet(self, points_map: ArrayLike) -> NDArray[np.float64]:
        """Points (..., 3) in ``map`` -> the fleet frame: R^T (p - t)."""
        p = np.asarray(points_map, dtype=np.float64)
        return (p - np.array([self.x, self.y, self.z])) @ self._rotation().as_matrix()

    def points_to_map(self, points_fleet: ArrayLike) -> NDArray[np.float64]:
        """Points (..., 3) in the fleet frame -> ``map``: R p + t."""
        p = np.asarray(points_fleet, dtype=np.float64)
        return p @ self._rotation().as_matrix().T + np.array([self.x, self.y, self.z])

    def poses_to_fleet(self, poses_map: ArrayLike) -> NDArray[np.float64]:
        """Poses (N, 7) = (x, y, z, qx, qy, qz, qw) in ``map`` -> the fleet frame (qw >= 0)
        (:func:`vp_scene.camera.express_poses`)."""
        return express_poses(poses_map, self._rotation(), [self.x, self.y, self.z])


def goal_orientations(quaternions: ArrayLike, orientation: str = "body") -> NDArray[np.float64]:
    """Goal quaternions (N, 4) for plan quaternions (N, 4) in the body convention (+x = optical
    axis): unchanged for ``body``, the REP-103 optical frame for ``optical``."""
    q = np.asarray(quaternions, dtype=np.float64).reshape(-1, 4)
    if orientation == "body":
        return q.copy()
    if orientation == "optical":
        return optical_orientation(q) if len(q) else q.copy()
    raise ValueError(f"unknown orientation {orientation!r}; one of {', '.join(ORIENTATIONS)}")


def plan_problems(cameras: ArrayLike, realizations: Optional[ArrayLike], min_standoff: float = Feasibility.min_standoff,
                  min_altitude: float = Feasibility.min_altitude,
                  min_separation: float = Feasibility.min_separation) -> list[str]:
    """Why the plan breaks the planner's feasibility rules ([] when it does not).

    ``cameras`` (N, 6) = [c, v] in the scene's frame; ``realizations`` (K, P, 3) the scene's wind
    realizations, or None when no scene is known: then the stand-off rule cannot be checked and
    is left out (the caller decides whether that is acceptable). The verdict is
    :class:`vp_planner.feasibility.FeasibilityRules` (the rules' one home, torch-free; a
    one-camera plan is checked as that camera twice, with no separation rule); the returned
    sentences only explain a refusal: the cameras below ``min_altitude``, nearer than
    ``min_standoff`` to a scene point, and the pairs nearer than ``min_separation`` to each other.
    """
    cams = check_cameras(cameras)
    n = len(cams)
    plan, separation = (cams, min_separation) if n >= 2 else (np.concatenate([cams, cams]), 0.0)
    # without a scene the stand-off rule is off
    standoff = min_standoff if realizations is not None else 0.0
    rules = FeasibilityRules(realizations, len(plan), min_standoff=standoff, min_altitude=min_altitude,
                             min_separation=separation)
    if rules(plan[None])[0]:
        return []
    problems = []
    c = cams[:, :3]
    for i in np.flatnonzero(c[:, 2] < min_altitude - 1e-9):
        problems.append(f"camera {i} at {_fmt(c[i])} is {c[i, 2]:.3f} m above the ground "
                        f"(min_altitude {min_altitude:g} m)")
    if standoff > 0:
        near, _ = rules.tree.query(c, k=1)
        for i in np.flatnonzero(near < standoff - 1e-9):
            problems.append(f"camera {i} at {_fmt(c[i])} is {near[i]:.3f} m from the nearest scene point "
                            f"(min_standoff {standoff:g} m)")
    if separation > 0:
        d = np.linalg.norm(c[:, None] - c[None], axis=-1)
        for i, j in zip(*np.triu_indices(n, 1)):
            if d[i, j] < separation - 1e-9:
                problems.append(f"cameras {i} and {j} are {d[i, j]:.3f} m apart (min_separation {separation:g} m)")
    return problems or ["the plan breaks the planner's feasibility rules (vp_planner.feasibility)"]


def _fmt(p: Sequence[float]) -> str:
    return "(" + ", ".join(f"{float(x):+.2f}" for x in p) + ")"
