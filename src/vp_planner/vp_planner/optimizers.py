"""View-planning methods behind one entry point, :func:`plan_views`.

Methods (all maximize the noisy reward r~ of eq. 7 with the same evaluation budget E, report
the best-so-far reward after every evaluation, and return the best *feasible* plan):

* ``egp``: the paper's EGP-VP, Bayesian optimization with an ensemble of 4 GPs and adaptive EI
  (Sec. IV-B), in the :class:`~vp_planner.space.ViewSpace` parameterization, via
  :func:`vp_planner.bo.optimize` (``ensemble=True``).
* ``gp``: single-GP EI BO (Sec. IV-A), same space and budget (``ensemble=False``).
* ``circle``: N cameras evenly spaced on a horizontal circle about the scene's centre, all
  facing the centre at mid-height; radius and altitude tuned by a grid search with the budget.
* ``arc``: N cameras ``arc_spacing`` apart in azimuth (default 30 degrees) on the tuned circle's
  radius and height, all facing the scene: the circle's grid search on all but 8 evaluations,
  then the arc at 8 azimuths about the scene; the best arc is returned (a pattern drone
  operators fly, and one that reconstructs much better than the full circle). Where the
  tuned radius would put neighbours closer than ``min_separation``, the arc moves out to the
  smallest radius that keeps them apart.
* ``sa``: the discrete formulation of Bacharis et al. 2022: a finite candidate set of
  viewpoints around the scene (azimuths x elevations x distances), each facing the scene,
  choose N of them by simulated annealing (swap one viewpoint for a nearby candidate,
  Metropolis acceptance, geometric cooling).
* ``random``: uniformly random feasible plans of the same space.
* ``lawnmower``: the grid survey farmers fly: flight lines along the field's longer side at the
  lowest height (at least ``min_standoff`` above the canopy) at which the N images cover the
  field with a set overlap, nadir or tilted (oblique); one evaluation, no tuning.

Fields (8-16 cameras, 48-96 dimensions): egp/gp plan by parts (:mod:`vp_planner.parts`) when
``parts`` (or its automatic choice) is above 1: each part of the field gets the budget of a plan,
then the union is refined jointly.

The initial design of egp/gp is ``initial_evaluations`` plans: a few structured plans
(:meth:`ViewSpace.structured`, clusters of cameras looking at the scene) followed by random
feasible plans (``structured_init`` sets how many structured ones; 0 gives the paper's purely
random initial design).

Size of a plan: 2 <= N <= :data:`MAX_CAMERAS`. Memory does not limit N by itself: both reward
models and the feasibility check work in chunks of a fixed number of elements (the paper
reward's pair term included), so one evaluation needs O(N^2) small arrays (pair indices, one
accumulator per pair) plus the coverage model's per-camera terms, N x K x min(P, 3000) elements
(:func:`estimate_memory`; a plan that would not fit in the memory available is refused before
anything is allocated). What limits N is time and feasibility: one evaluation costs O(N^2 K P)
(N = 100 on 5 x 4000 points: about 1e8 pair-point terms, a second or two on one core), the
BO methods work in 6N dimensions, and random feasible plans (min_separation between every pair)
become rare beyond a few dozen cameras. Hence the bound of 100 cameras, far above the paper's
N <= 6; a run is cancellable throughout (``should_stop``), the feasible-plan search included.

Size of a budget: 1 <= evaluations <= :data:`MAX_EVALUATIONS` [method] (:mod:`vp_planner.methods`,
the registry of the methods): 1000 for egp/gp (the
paper uses 100-200; a GP's fit costs O(n^3) time and O(n^2) memory in the n evaluations made,
four of them for egp, so 1000 is already hours of fitting) and 100000 for the baselines (each
evaluation is recorded: a few hundred bytes plus 150 bytes a camera). Planning by parts
multiplies the budget (:func:`total_evaluations`). Beyond the bound, or when
:func:`estimate_run_memory` of the run exceeds 80 % of the memory available, the request is
refused before anything is allocated (:class:`BudgetTooLargeError`; the planner node's
``BUDGET_TOO_LARGE``). Before this bound a goal of 4e9 evaluations grew the planner to 20 GB
until the kernel killed it.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Callable, Optional

import numpy as np
import torch
from numpy.typing import NDArray

from .methods import BAYESIAN, MAX_EVALUATIONS, METHODS
from .request import (MAX_CAMERAS, BudgetTooLargeError, InvalidBudgetError, InvalidFixedCamerasError,
                      InvalidNumCamerasError, InvalidReconstructionError, InvalidRequestError, PlanRequest,
                      UnknownMethodError, UnknownRewardModelError, check_lawnmower, check_reconstruction,
                      check_sortie_weighting)
from .reward_models import DEFAULT_REWARD_MODEL
from .space import (
    NoFeasiblePlanError,
    Objective,
    PlanningCancelled,
    ViewSpace,
    check_realizations,
)

__all__ = [
    "METHODS",
    "MAX_CAMERAS",
    "PlanRequest",
    "PlanResult",
    "plan_views",
    "check_lawnmower",
    "estimate_memory",
    "check_memory",
    "InvalidNumCamerasError",
    "UnknownMethodError",
    "InvalidBudgetError",
    "BudgetTooLargeError",
    "MAX_EVALUATIONS",
    "estimate_run_memory",
    "InvalidSceneError",
    "InvalidFixedCamerasError",
    "InvalidReconstructionError",
    "InvalidRequestError",
    "UnknownRewardModelError",
    "sortie_weights",
    "NoFeasiblePlanError",
]


Callback = Callable[[int, int, float, Optional[list]], bool]
StopCheck = Callable[[], bool]

#: Plans evaluated per reward call by the non-BO methods (bounds how late a cancel is seen) ...
_BATCH = 16
#: ... fewer for large plans: at most this many pair-point terms (N (N-1)/2 x K P) per call.
_BATCH_TERMS = 1e8


def _batch(space: ViewSpace) -> int:
    """Plans per reward call: 16, fewer when one plan alone is a large computation."""
    N = space.num_cameras
    pair_points = N * (N - 1) / 2 * space.realizations.shape[0] * space.realizations.shape[1]
    return int(max(1, min(_BATCH, _BATCH_TERMS // max(pair_points, 1.0))))


class InvalidSceneError(ValueError):
    """Empty or non-finite point cloud, or a wrong shape."""


#: Bytes a reconstruction point costs the hole weighting (the points and their KD-tree).
RECONSTRUCTION_POINT_BYTES = 64


def sortie_weights(realizations: NDArray[np.float64], reconstruction: Any, tau: float, reconstructed_weight: float,
                   available: Optional[int] = None) -> tuple[NDArray[np.float64], float]:
    """Point weights (K, P) of a second sortie (:func:`vp_planner.reward_models.reconstructed_weights`)
    and the fraction of points reconstructed; InvalidReconstructionError for a bad reconstruction,
    tau or weight, or a reconstruction the memory cannot hold."""
    from .reward_models import reconstructed_mask

    Q = check_reconstruction(reconstruction)
    need = len(Q) * RECONSTRUCTION_POINT_BYTES
    have = available_memory() if available is None else int(available)
    if have is not None and need > 0.8 * have:
        raise InvalidReconstructionError(f"the reconstruction's {len(Q)} points need about "
                                         f"{need / 2**30:.1f} GiB; {have / 2**30:.1f} GiB are available")
    check_sortie_weighting(tau, reconstructed_weight)
    try:
        mask = reconstructed_mask(realizations, Q, tau)
    except ValueError as exc:
        raise InvalidReconstructionError(str(exc)) from None
    return np.where(mask, float(reconstructed_weight), 1.0), float(mask.mean())


@dataclass
class PlanResult:
    """Outcome of :func:`plan_views`.

    Attributes:
        method: the method name.
        cameras: (N, 6) best feasible plan [cx, cy, cz, vx, vy, vz] ((0, 6) when cancelled
            before any feasible evaluation).
        reward: its noisy reward (eq. 7).
        trace: (evaluations,) best-so-far noisy reward after each evaluation.
        evaluations: evaluations made (< the budget when stopped).
        seconds: wall-clock planning time.
        ensemble_weights: the last ensemble weights w_t^m (egp only, else None).
        model_names: names of the ensemble's models (egp only, else None).
        stopped: True when the callback cancelled the run.
        rewards: (evaluations,) reward of every evaluated plan (0 for infeasible ones).
        reward_model: the reward model the plan maximizes.
        steps: egp/gp: one record per BO step (model drawn, weights, improved, trust region); by
            parts: the steps of the joint refinement.
        initial_best: egp/gp: the best reward of the initial design (by parts: of the union of
            the part plans, before the joint refinement).
        parts: egp/gp by parts: one record per part (cameras, points, evaluations, the part's own
            reward and its initial design's best); None otherwise.
        fixed_cameras: M, the cameras already flown the reward counted (0: a first sortie).
        reconstructed_fraction: with a reconstruction, the fraction of the planning cloud's
            points within tau of it (weighed ``reconstructed_weight``); else None.
    """

    method: str
    cameras: NDArray[np.float64]
    reward: float
    trace: NDArray[np.float64]
    evaluations: int
    seconds: float
    ensemble_weights: Optional[list] = None
    model_names: Optional[list] = None
    stopped: bool = False
    rewards: Optional[NDArray[np.float64]] = None
    reward_model: str = DEFAULT_REWARD_MODEL
    steps: Optional[list] = None
    initial_best: Optional[float] = None
    parts: Optional[list] = None
    fixed_cameras: int = 0
    reconstructed_fraction: Optional[float] = None

    def simple_regret(self, optimum: float = 1.0) -> NDArray[np.float64]:
        """SR(t) = r~(z*) - max_{tau <= t} r~(z_tau) (paper Sec. V-B), with r~(z*) = ``optimum``."""
        return float(optimum) - np.asarray(self.trace, dtype=np.float64)


# ---------------------------------------------------------------------- validation
def estimate_memory(num_cameras: int, num_realizations: int, num_points: int, reward: str) -> int:
    """Bytes one reward evaluation of an N-camera plan needs at most (an upper estimate).

    paper: its chunks (``reward.DEFAULT_MAX_ELEMENTS`` elements, about 10 float64 arrays of that
    size alive at once) plus per pair S = N (N - 1) / 2 an accumulator, two indices and the pair's
    coefficients (about 80 bytes). coverage: the per-camera terms, N x K x min(P, 3000) elements
    (each realization subsampled to 3000 points) of about 200 bytes in all (measured: 150), and
    its pair blocks (``max_elements`` = 2^22 float32 elements, about 6 arrays).
    """
    from .reward import DEFAULT_MAX_ELEMENTS
    from .reward_models import CoverageParams

    N, K, P = int(num_cameras), int(num_realizations), int(num_points)
    S = N * (N - 1) // 2
    if reward == "paper":
        return 10 * 8 * DEFAULT_MAX_ELEMENTS + 80 * S
    kp = K * min(P, CoverageParams().max_points or P)
    return 200 * N * kp + 6 * 4 * (1 << 22) + 80 * S


def estimate_run_memory(method: str, num_cameras: int, evaluations: int) -> int:
    """Bytes a run of ``evaluations`` reward evaluations (all of them, parts included) keeps
    beyond one evaluation's own (an upper estimate): every evaluation is recorded (its U row and
    its cameras, 6N float64 each with their array headers, the value and flags: about
    300 + 96 N bytes), the grid methods hold their candidate plans at once (48 N bytes each)
    and egp/gp's GPs hold n x n kernel matrices and their factors and gradients while fitting
    (four models of about six float64 matrices: 192 n^2 bytes)."""
    N, E = int(num_cameras), int(evaluations)
    need = E * (300 + 96 * N) + E * 48 * N
    if method in BAYESIAN:
        need += 192 * E * E
    return need


def check_budget_memory(method: str, num_cameras: int, evaluations: int,
                        available: Optional[int] = None) -> None:
    """BudgetTooLargeError when :func:`estimate_run_memory` exceeds 80 % of the available memory
    (``available`` bytes; default: :func:`available_memory`), before anything is allocated."""
    need = estimate_run_memory(method, num_cameras, evaluations)
    have = available_memory() if available is None else int(available)
    if have is not None and need > 0.8 * have:
        raise BudgetTooLargeError(
            f"{evaluations} evaluations of {num_cameras} cameras with {method} need about {need / 2**30:.1f} GiB; "
            f"{have / 2**30:.1f} GiB are available: use a smaller budget")


def available_memory() -> Optional[int]:
    """MemAvailable of /proc/meminfo in bytes (None where unknown)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def check_memory(num_cameras: int, realizations_shape: tuple, reward: str,
                 available: Optional[int] = None) -> None:
    """InvalidNumCamerasError when :func:`estimate_memory` exceeds 80 % of the available memory
    (``available`` bytes; default: :func:`available_memory`), before anything is allocated."""
    K, P = int(realizations_shape[0]), int(realizations_shape[1])
    need = estimate_memory(num_cameras, K, P, reward)
    have = available_memory() if available is None else int(available)
    if have is not None and need > 0.8 * have:
        raise InvalidNumCamerasError(
            f"num_cameras = {num_cameras} on {K} x {P} points needs about {need / 2**30:.1f} GiB for the "
            f"{reward} reward; {have / 2**30:.1f} GiB are available: use fewer cameras or points")


def _check_parts(parts: int, method: str, realizations: NDArray[np.float64], num_cameras: int) -> int:
    """The number of parts a run plans by (1 for methods other than egp/gp): ``parts`` (an integer
    >= 0, :class:`PlanRequest`), or :func:`vp_planner.parts.auto_parts` for 0.
    InvalidNumCamerasError for more parts than pairs of cameras."""
    if method not in BAYESIAN:
        return 1
    if parts == 0:
        from .parts import auto_parts

        return auto_parts(realizations, num_cameras)
    if 2 * int(parts) > num_cameras:
        raise InvalidNumCamerasError(f"parts = {parts} needs at least {2 * int(parts)} cameras (2 a part), got {num_cameras}")
    return int(parts)


def total_evaluations(method: str, evaluations: int, parts: int) -> int:
    """Reward evaluations a run makes: ``evaluations``; for egp/gp by G > 1 parts, G times that
    (one plan's budget a part) plus ``evaluations // 2`` for the joint refinement; for
    ``lawnmower`` 1 (a survey is flown as planned, not tuned)."""
    if method == "lawnmower":
        return 1
    if method in BAYESIAN and parts > 1:
        return parts * int(evaluations) + max(1, int(evaluations) // 2)
    return int(evaluations)


# ---------------------------------------------------------------------- baselines
class _CircleFamily:
    """Horizontal rings of N cameras about the scene's centre facing it at mid-height,
    parameterized by a height h and a = (radius - rho_lo(h)) / (rho_hi - rho_lo(h)) in [0, 1].

    Heights h are spread over [min_altitude, z_max + s + depth]; for each h the radius runs from
    the smallest feasible one, rho_lo(h) = max(min_sep / (2 sin(pi/N)), max_p r_p + sqrt(s^2 -
    (z_p - h)^2) over points within s of the height h) (so every camera is >= s from every point
    whatever the azimuth), to rho_hi = max_p r_p + s + depth.
    """

    def __init__(self, space: ViewSpace) -> None:
        R = space.realizations.reshape(-1, 3)
        ext = space.extent
        self.centre = ext.centre[:2]
        self.target = np.array([self.centre[0], self.centre[1], float(ext.centre[2])])
        self.s = space.min_standoff
        self.N = space.num_cameras
        self.r_p = np.hypot(R[:, 0] - self.centre[0], R[:, 1] - self.centre[1])
        self.z_p = R[:, 2]
        self.rho_sep = space.min_separation / (2.0 * math.sin(math.pi / self.N))
        self.rho_hi = float(self.r_p.max()) + self.s + space.shell_depth
        self.h_lo = space.min_altitude
        self.h_hi = float(ext.hi[2]) + self.s + space.shell_depth

    def rho_lo(self, h: float) -> float:
        dz = np.abs(self.z_p - h)
        near = dz < self.s
        need = float((self.r_p[near] + np.sqrt(self.s ** 2 - dz[near] ** 2)).max()) * (1 + 1e-9) if near.any() else 0.0
        return max(self.rho_sep, need)

    def plan(self, a: float, h: float) -> NDArray[np.float64]:
        from .patterns import ring

        lo = self.rho_lo(h)
        return ring(self.centre, self.target, [lo + a * max(0.0, self.rho_hi - lo)], [h], self.N)[0]


def _circle(space: ViewSpace, obj: Objective, evaluations: int, rng: np.random.Generator,
            candidate: bool = True) -> NDArray[np.float64]:
    """Grid search over (radius, height) of :class:`_CircleFamily`; returns the best ring.

    The grid has n_h = floor(sqrt(E)) heights x floor(E / n_h) radii, evaluated in order (trace =
    best so far); the remaining evaluations (fewer than n_h) jitter around the best cell.
    """
    fam = _CircleFamily(space)
    n_h = max(1, int(math.isqrt(evaluations)))
    n_r = max(1, evaluations // n_h)
    hs = np.linspace(fam.h_lo, fam.h_hi, n_h) if n_h > 1 else np.array([0.5 * (fam.h_lo + fam.h_hi)])
    As = np.linspace(0.0, 1.0, n_r) if n_r > 1 else np.array([0.5])
    grid = [(a, h) for h in hs for a in As]
    extra = evaluations - len(grid)
    first = obj.count
    _evaluate_plans(obj, np.array([fam.plan(a, h) for a, h in grid]), candidate)
    values = np.where(obj.feasible_flags[first:], obj.values[first:], -np.inf)
    if extra > 0:
        a0, h0 = grid[int(np.argmax(values))]
        da = 0.5 / max(1, n_r - 1)
        dh = 0.5 * (fam.h_hi - fam.h_lo) / max(1, n_h - 1)
        pts = [(float(np.clip(a0 + rng.uniform(-da, da), 0, 1)),
                float(np.clip(h0 + rng.uniform(-dh, dh), fam.h_lo, fam.h_hi))) for _ in range(extra)]
        _evaluate_plans(obj, np.array([fam.plan(a, h) for a, h in pts]), candidate)
        values = np.where(obj.feasible_flags[first:], obj.values[first:], -np.inf)
    return obj.cameras[first + int(np.argmax(values))]


def _evaluate_plans(obj: Objective, cams: NDArray[np.float64], candidate: bool = True) -> None:
    """Evaluate camera plans in small batches (one recorded evaluation each)."""
    nanU = np.full((1, obj.space.dim), np.nan)
    step = _batch(obj.space)
    for b0 in range(0, len(cams), step):
        chunk = cams[b0 : b0 + step]
        obj.record(np.repeat(nanU, len(chunk), axis=0), chunk, candidate=candidate)


#: Azimuths at which the ``arc`` baseline tries its arc.
ARC_PHASES = 8


def _arc(space: ViewSpace, obj: Objective, evaluations: int, rng: np.random.Generator,
         spacing: float = math.radians(30.0)) -> None:
    """The ``arc`` baseline (module docstring): tune the circle, then place the arc on it. N
    cameras ``spacing`` apart would wrap past a full turn when N spacing > 2 pi (N > 12 at 30
    degrees): the arc is then the full ring, 2 pi / N apart."""
    from .patterns import arc

    spacing = min(float(spacing), 2.0 * math.pi / space.num_cameras)
    phases = min(ARC_PHASES, evaluations)
    tune = evaluations - phases
    if tune > 0:
        ring = _circle(space, obj, tune, rng, candidate=False)
    else:
        fam = _CircleFamily(space)
        ring = fam.plan(0.5, 0.5 * (fam.h_lo + fam.h_hi))
    centre = space.extent.centre
    radius = float(np.hypot(*(ring[0, :2] - centre[:2])))
    # neighbours closer than the full ring's: move out until they keep min_separation
    radius = max(radius, space.min_separation / (2.0 * math.sin(0.5 * spacing)) * (1.0 + 1e-9))
    height = float(ring[0, 2])
    target = ring[0, :3] + ring[0, 3:]
    plans = [arc(centre[:2], target, radius, height, space.num_cameras, spacing, 2 * math.pi * k / phases)
             for k in range(phases)]
    _evaluate_plans(obj, np.array(plans))


def _lawnmower(space: ViewSpace, obj: Objective, overlap: float, tilt: float) -> None:
    """The ``lawnmower`` baseline: a grid survey (:func:`vp_planner.patterns.lawnmower`) over the
    field's bounding box at the lowest height, in 1 cm steps from ``min_standoff`` above the
    canopy, at which the N images cover the field with ``overlap`` and the plan is feasible.
    One evaluation: a survey is flown as planned, not tuned to the reward."""
    from .patterns import lawnmower

    ext = space.extent
    top = float(ext.hi[2])
    lo_d = max(space.min_standoff, space.min_altitude - top, 0.01)
    plan = None
    for d in lo_d + 0.01 * np.arange(10000):
        obj.check_stop()
        cams = lawnmower(ext.lo[:2], ext.hi[:2], top, float(d), space.num_cameras, space.image, overlap, tilt,
                         min_spacing=space.min_separation * (1 + 1e-6))
        if cams is not None and space.feasible(cams):
            plan = cams
            break
    if plan is None:
        raise NoFeasiblePlanError(f"no feasible lawnmower survey of {space.num_cameras} images with overlap "
                                  f"{overlap} up to {lo_d + 100:.0f} m above the canopy")
    _evaluate_plans(obj, plan[None])


def _random(space: ViewSpace, obj: Objective, evaluations: int, rng: np.random.Generator) -> None:
    done = 0
    step = _batch(space)
    while done < evaluations:
        n = min(step, evaluations - done)
        U = space.sample(n, rng, should_stop=obj.should_stop)
        obj(U)
        done += n


def sa_candidates(space: ViewSpace, n_azimuth: int = 16, elevations_deg: tuple[float, ...] = (10.0, 30.0, 50.0, 70.0),
                  distances: tuple[float, ...] = (0.0, 0.5, 1.0)) -> NDArray[np.float64]:
    """The discrete viewpoint set of the ``sa`` baseline: cameras (M, 6).

    Positions: ``n_azimuth`` azimuths x elevations x shell distances (u_dist fractions) on the
    same shell as :class:`ViewSpace`; each looks at the nearest point of the scene's core: the
    scene box at mid-height, shrunk in x and y by its smaller horizontal half extent (the centre
    for one plant, the row's axis for a row). Candidates violating altitude or stand-off are
    dropped.
    """
    lo, hi = space.elevation_lo, space.elevation_hi
    u_el = [(math.radians(e) - lo) / (hi - lo) for e in elevations_deg]
    u_el = [min(1.0, max(0.0, u)) for u in u_el]
    grid = np.array([(k / n_azimuth, ue, ud) for ud in distances for ue in u_el for k in range(n_azimuth)])
    c = space.positions(grid)
    ext = space.extent
    m = float(min(ext.half[0], ext.half[1]))
    core_lo = np.array([ext.lo[0] + m, ext.lo[1] + m])
    core_hi = np.array([ext.hi[0] - m, ext.hi[1] - m])
    tgt_xy = np.clip(c[:, :2], np.minimum(core_lo, core_hi), np.maximum(core_lo, core_hi))
    tgt = np.concatenate([tgt_xy, np.full((len(c), 1), ext.centre[2])], axis=1)
    cams = np.concatenate([c, tgt - c], axis=1)
    # per-camera feasibility (altitude, stand-off, v != 0)
    ok = np.isfinite(cams).all(1) & (np.linalg.norm(cams[:, 3:], axis=1) > 0)
    ok &= c[:, 2] >= space.min_altitude - 1e-9
    if space.min_standoff > 0:
        d, _ = space.tree.query(c, k=1, distance_upper_bound=space.min_standoff)
        ok &= d >= space.min_standoff - 1e-9
    return cams[ok]


def _sa(space: ViewSpace, obj: Objective, evaluations: int, rng: np.random.Generator,
        t0: float = 0.02, t_end: float = 2e-5, neighbours: int = 8, p_local: float = 0.8) -> None:
    """Simulated annealing over N-subsets of :func:`sa_candidates`.

    Move: replace one chosen viewpoint by one of its ``neighbours`` nearest candidates (by
    position) with probability ``p_local``, else by a random candidate; moves that break the
    separation rule are redrawn. Metropolis acceptance exp((r_new - r_cur) / T), geometric
    cooling T_k = t0 (t_end / t0)^(k / E). Every proposal costs one evaluation.
    """
    cand = sa_candidates(space)
    N = space.num_cameras
    M = len(cand)
    if M < N:
        raise NoFeasiblePlanError(f"no feasible plan: only {M} feasible candidate viewpoints for {N} cameras")
    pos = cand[:, :3]
    D = np.linalg.norm(pos[:, None] - pos[None], axis=-1)
    sep_ok = D >= space.min_separation - 1e-9
    np.fill_diagonal(sep_ok, False)
    order = np.argsort(D, axis=1)[:, 1 : neighbours + 1]

    def valid(sel: NDArray[np.int64]) -> bool:
        sub = sep_ok[np.ix_(sel, sel)]
        return bool(sub[np.triu_indices(N, 1)].all())

    cur = None
    for attempt in range(10000):
        if attempt % 100 == 0:
            obj.check_stop()
        sel = rng.choice(M, size=N, replace=False)
        if valid(sel):
            cur = sel
            break
    if cur is None:
        raise NoFeasiblePlanError(f"no feasible plan: no {N} candidate viewpoints at least "
                                  f"{space.min_separation} m apart")
    nanU = np.full((1, space.dim), np.nan)
    r_cur = float(obj.record(nanU, cand[cur][None])[0])
    alpha = (t_end / t0) ** (1.0 / max(1, evaluations - 1))
    T = t0
    for _k in range(1, evaluations):
        T *= alpha
        prop = None
        for _try in range(200):
            slot = int(rng.integers(N))
            if rng.random() < p_local:
                new = int(order[cur[slot], rng.integers(order.shape[1])])
            else:
                new = int(rng.integers(M))
            if new in cur:
                continue
            sel = cur.copy()
            sel[slot] = new
            if valid(sel):
                prop = sel
                break
        if prop is None:
            prop = cur.copy()
        r_new = float(obj.record(nanU, cand[prop][None])[0])
        if r_new >= r_cur or rng.random() < math.exp((r_new - r_cur) / max(T, 1e-300)):
            cur, r_cur = prop, r_new


# ---------------------------------------------------------------------- BO
def initial_design(space: ViewSpace, n: int, rng: np.random.Generator, structured: int = 20,
                   should_stop: Optional[StopCheck] = None) -> NDArray[np.float64]:
    """n initial plans U (n, 6N): up to ``structured`` structured plans, then random feasible ones
    (PlanningCancelled as soon as ``should_stop()`` is True)."""
    S = space.structured(max_plans=max(0, min(structured, n))) if structured > 0 else np.zeros((0, space.dim))
    S = S[:n]
    try:
        rest = space.sample(n - len(S), rng, should_stop=should_stop) if n > len(S) else np.zeros((0, space.dim))
    except NoFeasiblePlanError as exc:
        # The range egp/gp serve (issue 19, item 4; README "Planner node"): their space is a
        # shell about the scene, and random plans in it keep min_separation only up to a few
        # dozen cameras (one plant, 0.5 m: 40 cameras found 10 feasible plans, 44 none, in 16000
        # draws). The ring methods widen their circle instead and serve every N up to 100.
        raise NoFeasiblePlanError(f"{exc}; egp/gp plan up to about 40 cameras a plant (more: circle, arc, sa "
                                  f"or lawnmower, or a field planned by parts)") from None
    return np.concatenate([S, rest], axis=0)


def _bo(space: ViewSpace, obj: Objective, evaluations: int, initial_evaluations: int, seed: int,
        rng: np.random.Generator, ensemble: bool, structured_init: int, bo_mode: str) -> dict:
    X0 = initial_design(space, initial_evaluations, rng, structured_init, obj.should_stop)
    return _optimize(space, obj, X0, evaluations, initial_evaluations, seed, ensemble, bo_mode)


def _optimize(space: Any, obj: Objective, X0: NDArray[np.float64], evaluations: int, initial_evaluations: int,
              seed: int, ensemble: bool, bo_mode: str) -> dict:
    """:func:`vp_planner.bo.optimize` on ``obj`` in ``space`` (a ViewSpace, or the JointSpace of
    planning by parts) from the initial design X0; the run's weights, models, steps and the
    initial design's best."""
    from . import bo  # imported lazily: botorch is heavy

    info: dict = {"weights": None, "model_names": None}

    def objective(U: torch.Tensor) -> torch.Tensor:
        return obj(U).to(U.dtype) if isinstance(U, torch.Tensor) else torch.as_tensor(obj(U))

    def feasible(U: torch.Tensor) -> torch.Tensor:
        # BO's rejection sampling and acquisition ask this for every candidate batch: the place to
        # see a cancel between evaluations (PlanningCancelled leaves bo.optimize)
        obj.check_stop()
        return space.feasible(U)

    def bo_callback(done: int, total: int, best: float, weights: Optional[list]) -> bool:
        if weights is not None:
            obj.weights = info["weights"] = [float(x) for x in weights]
        return not obj.cancelled

    res = bo.optimize(objective, space.dim, evaluations, initial_evaluations, seed, ensemble=ensemble,
                      feasible=feasible, initial_design=torch.as_tensor(X0, dtype=torch.float64),
                      callback=bo_callback, settings=bo.BOSettings(mode=bo_mode),
                      periodic=torch.as_tensor(space.periodic),
                      groups=torch.arange(space.dim) % 6)  # the 6 parameters of a camera
    if ensemble and res.steps:
        info["weights"] = [float(x) for x in res.steps[-1].weights]
    info["model_names"] = list(res.model_names)
    info["steps"] = [st.as_dict(res.model_names) for st in res.steps]
    info["initial_best"] = float(res.best_initial) if math.isfinite(res.best_initial) else None
    return info


def _bo_by_parts(space: ViewSpace, obj: Objective, evaluations: int, initial_evaluations: int, seed: int,
                 ensemble: bool, structured_init: int, bo_mode: str, parts: int) -> dict:
    """EGP-EI (GP-EI) by parts (:mod:`vp_planner.parts`): each of the ``parts`` parts gets the budget
    of a plan (``evaluations``, ``initial_evaluations``) on its own points, then the union of the
    part plans is refined on the whole field's reward with ``evaluations // 2`` evaluations.

    ``obj`` is the whole run's objective (the joint space's): it counts the part evaluations too
    (recorded with reward 0 and ``candidate=False``: a part's reward is not a plan's) so that the
    budget, the progress callback and cancelling work as for any method."""
    from .parts import JointSpace, allocate_cameras, partition

    R = space.realizations
    labels = partition(R, parts, seed)
    counts = allocate_cameras(np.bincount(labels, minlength=parts), space.num_cameras)
    fixed = np.zeros((0, 3))
    part_spaces, part_U, records = [], [], []
    for g in range(parts):
        sub = ViewSpace(R[:, labels == g], int(counts[g]), min_standoff=space.min_standoff,
                        min_altitude=space.min_altitude, min_separation=space.min_separation, fov=space.fov,
                        theta_match=space.theta_match, reward_model=space.reward_model,
                        image_size=(space.image.width, space.image.height), obstacles=R, fixed_positions=fixed,
                        fixed_cameras=space.fixed_cameras,
                        point_weights=None if space.point_weights is None else space.point_weights[:, labels == g])
        part_obj = Objective(sub, evaluations, dtype=obj.dtype, should_stop=obj.should_stop,
                             callback=_forward(obj))
        info = _bo(sub, part_obj, evaluations, initial_evaluations, seed + g, np.random.default_rng([seed, g]),
                   ensemble, structured_init, bo_mode)
        best = part_obj.best_cameras()
        if best is None:
            raise NoFeasiblePlanError(f"no feasible plan for part {g + 1} of {parts} ({counts[g]} cameras)")
        fixed = np.concatenate([fixed, best[:, :3]])
        part_spaces.append(sub)
        part_U.append(part_obj.U[part_obj.best_index])
        records.append({"part": g, "cameras": int(counts[g]), "points": int(sub.realizations.shape[1]),
                        "evaluations": part_obj.count, "reward": float(part_obj.best_value),
                        "initial_best": info.get("initial_best")})
    joint = JointSpace(space, part_spaces)
    obj.space = joint
    info = _optimize(joint, obj, np.concatenate(part_U)[None], max(1, evaluations // 2), 1, seed, ensemble,
                     "trust_region")
    info["parts"] = records
    return info


def _forward(obj: Objective) -> Callback:
    """A part objective's callback: count the evaluation in the whole run's objective
    (:meth:`Objective.record_part_evaluation`), whose callback and cancel then see it."""
    def callback(done: int, total: int, best: float, weights: Optional[list]) -> bool:
        if weights is not None:
            obj.weights = weights
        return obj.record_part_evaluation()
    return callback


# ---------------------------------------------------------------------- entry point
def plan_views(request: PlanRequest, realizations: Any, callback: Optional[Callback] = None,
               should_stop: Optional[StopCheck] = None) -> PlanResult:
    """Plan ``request.num_cameras`` views of the noisy scene with ``request.method`` (one of
    :data:`METHODS`); every setting is a field of the :class:`~vp_planner.request.PlanRequest`
    (validated there, its docstring gives the units and rules).

    Args:
        request: what to plan: method, N, budget, seed, feasibility rules, reward, the method's
            settings, a second sortie's cameras already flown and reconstruction.
        realizations: (K, P, 3) noisy scene realizations (the reward is their mean, eq. 7).
        callback: ``callback(done, total, best, weights) -> bool`` after every evaluation
            (``weights``: latest ensemble weights for egp, else None); returning False stops
            the run within one evaluation and returns the best plan so far (``stopped=True``).
        should_stop: ``should_stop() -> bool``, asked between evaluations and inside the
            feasible-plan searches (rejection sampling, BO candidate batches, SA's start); True
            stops the run as a callback returning False does (a cancel, a node shutting down).

    Planning by parts (egp/gp, ``request.parts``): each part gets ``evaluations``, the joint
    refinement ``evaluations // 2``, all counted in the result; 0: :func:`vp_planner.parts.auto_parts`
    (1 for N <= 7); 1: one space. Cameras already flown (``request.fixed_cameras``) count in every
    method's reward with the plan (pairs with them like pairs within it); the plan need not keep
    min_separation from them (README "A second sortie"). The realizations' points within ``tau``
    of ``request.reconstruction`` weigh ``reconstructed_weight`` in the reward, the others 1
    (:func:`vp_planner.reward_models.reconstructed_weights`).

    Raises:
        TypeError when ``request`` is not a PlanRequest; InvalidSceneError (a ValueError) for bad
        realizations; InvalidNumCamerasError for a plan the memory cannot hold
        (:func:`check_memory`) or more parts than pairs of cameras; BudgetTooLargeError for a run
        the memory cannot hold (:func:`check_budget_memory`); InvalidFixedCamerasError,
        InvalidReconstructionError when the cameras already flown or the reconstruction do not fit
        in memory (nothing planned); NoFeasiblePlanError (ValueError) when no feasible plan was
        found.
    """
    if not isinstance(request, PlanRequest):
        raise TypeError(f"plan_views takes a vp_planner.request.PlanRequest, got {type(request).__name__}")
    q = request
    method, num_cameras, evaluations = q.method, q.num_cameras, q.evaluations
    try:
        R = check_realizations(realizations)
    except ValueError as exc:
        raise InvalidSceneError(str(exc)) from None
    check_memory(num_cameras, R.shape, q.reward)
    F = q.fixed_cameras
    if len(F):
        try:
            check_memory(num_cameras + len(F), R.shape, q.reward)
        except ValueError as exc:
            raise InvalidFixedCamerasError(f"fixed cameras: {exc}") from None
    W, done = (None, None) if q.reconstruction is None else sortie_weights(R, q.reconstruction, q.tau,
                                                                            q.reconstructed_weight)
    n_parts = _check_parts(q.parts, method, R, num_cameras)
    budget = total_evaluations(method, evaluations, n_parts)
    check_budget_memory(method, num_cameras, budget)
    start = time.perf_counter()
    space = ViewSpace(R, num_cameras, min_standoff=q.min_standoff, min_altitude=q.min_altitude,
                      min_separation=q.min_separation, fov=q.fov, theta_match=q.theta_match,
                      shell_depth=q.shell_depth, reward_model=q.reward, image_size=q.image_size, fixed_cameras=F,
                      point_weights=W)
    obj = Objective(space, budget, callback=callback, dtype=getattr(torch, q.dtype), should_stop=should_stop)
    seed = q.seed
    rng = np.random.default_rng(seed)
    torch.manual_seed(seed)
    info: dict = {}
    try:
        if method == "circle":
            _circle(space, obj, evaluations, rng)
        elif method == "arc":
            _arc(space, obj, evaluations, rng, q.arc_spacing)
        elif method == "sa":
            _sa(space, obj, evaluations, rng)
        elif method == "random":
            _random(space, obj, evaluations, rng)
        elif method == "lawnmower":
            _lawnmower(space, obj, q.lawnmower_overlap, q.lawnmower_tilt)
        elif n_parts > 1:
            info = _bo_by_parts(space, obj, evaluations, q.initial_evaluations, seed, method == "egp",
                                q.structured_init, q.bo_mode, n_parts)
        else:
            info = _bo(space, obj, evaluations, q.initial_evaluations, seed, rng, method == "egp",
                       q.structured_init, q.bo_mode)
    except PlanningCancelled:
        pass
    stopped = obj.cancelled or obj.count < budget
    best = obj.best_cameras()
    if best is None:
        if not stopped:
            raise NoFeasiblePlanError(f"no feasible plan among the {obj.count} evaluated plans")
        best = np.zeros((0, 6))
    weights = info.get("weights") if method == "egp" else None
    names = None
    if method == "egp":
        from .gp import MODEL_NAMES

        names = info.get("model_names") or list(MODEL_NAMES)
    return PlanResult(
        method=method,
        cameras=np.asarray(best, dtype=np.float64),
        reward=float(obj.best_value),
        trace=obj.trace(),
        evaluations=obj.count,
        seconds=time.perf_counter() - start,
        ensemble_weights=weights,
        model_names=names,
        stopped=bool(stopped),
        rewards=np.asarray(obj.values, dtype=np.float64),
        reward_model=q.reward,
        steps=info.get("steps"),
        initial_best=info.get("initial_best"),
        parts=info.get("parts"),
        fixed_cameras=len(F),
        reconstructed_fraction=done,
    )
