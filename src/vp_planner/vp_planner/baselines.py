"""The baselines of :func:`vp_planner.optimizers.plan_views`: ``circle``, ``arc``, ``sa``, ``random``
and ``lawnmower`` (the methods' descriptions: :mod:`vp_planner.optimizers`).

Each ``plan_<method>(space, obj, ...)`` spends its budget on the :class:`~vp_planner.objective.Objective`
``obj`` of the :class:`~vp_planner.space.ViewSpace` ``space`` (which records every evaluation and
the best feasible plan, reports progress and sees a cancel); none returns a plan of its own.
``run_<method>(space, obj, request, rng, parts)`` is the registry's planner of each
(:class:`vp_planner.methods.Method`): the method's settings read from the request.
"""
from __future__ import annotations

import math
from typing import Callable, Optional

import numpy as np
from numpy.typing import NDArray

from .designs import random_plans
from .objective import Objective
from .request import ArcSpec, LawnmowerSpec, PlanRequest
from .space import NoFeasiblePlanError, ViewSpace

__all__ = ["CircleFamily", "ARC_PHASES", "batch_size", "evaluate_plans", "plan_circle", "plan_arc", "plan_sa",
           "plan_random", "plan_lawnmower", "sa_candidates", "anneal_subsets", "run_circle", "run_arc", "run_sa", "run_random",
           "run_lawnmower"]

#: Plans evaluated per reward call by the non-BO methods (bounds how late a cancel is seen) ...
_BATCH = 16
#: ... fewer for large plans: at most this many pair-point terms (N (N-1)/2 x K P) per call.
_BATCH_TERMS = 1e8


def batch_size(space: ViewSpace) -> int:
    """Plans per reward call: 16, fewer when one plan alone is a large computation."""
    N = space.num_cameras
    pair_points = N * (N - 1) / 2 * space.realizations.shape[0] * space.realizations.shape[1]
    return int(max(1, min(_BATCH, _BATCH_TERMS // max(pair_points, 1.0))))



class CircleFamily:
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

    @staticmethod
    def grid_shape(evaluations: int) -> tuple[int, int]:
        """(n_h, n_r) of a grid search of ``evaluations``: floor(sqrt(E)) heights x floor(E / n_h) radii."""
        n_h = max(1, int(math.isqrt(evaluations)))
        return n_h, max(1, evaluations // n_h)

    def grid(self, evaluations: int) -> list[tuple[float, float]]:
        """The (a, h) cells of a grid search of ``evaluations`` (:meth:`grid_shape`): the heights
        evenly from h_lo to h_hi, the radii evenly over a in [0, 1]."""
        n_h, n_r = self.grid_shape(evaluations)
        hs = np.linspace(self.h_lo, self.h_hi, n_h) if n_h > 1 else np.array([0.5 * (self.h_lo + self.h_hi)])
        As = np.linspace(0.0, 1.0, n_r) if n_r > 1 else np.array([0.5])
        return [(float(a), float(h)) for h in hs for a in As]


def plan_circle(space: ViewSpace, obj: Objective, evaluations: int, rng: np.random.Generator,
            candidate: bool = True) -> NDArray[np.float64]:
    """Grid search over (radius, height) of :class:`CircleFamily`; returns the best ring.

    The grid has n_h = floor(sqrt(E)) heights x floor(E / n_h) radii, evaluated in order (trace =
    best so far); the remaining evaluations (fewer than n_h) jitter around the best cell.
    """
    fam = CircleFamily(space)
    n_h, n_r = fam.grid_shape(evaluations)
    grid = fam.grid(evaluations)
    extra = evaluations - len(grid)
    first = obj.count
    evaluate_plans(obj, np.array([fam.plan(a, h) for a, h in grid]), candidate)
    values = np.where(obj.feasible_flags[first:], obj.values[first:], -np.inf)
    if extra > 0:
        a0, h0 = grid[int(np.argmax(values))]
        da = 0.5 / max(1, n_r - 1)
        dh = 0.5 * (fam.h_hi - fam.h_lo) / max(1, n_h - 1)
        pts = [(float(np.clip(a0 + rng.uniform(-da, da), 0, 1)),
                float(np.clip(h0 + rng.uniform(-dh, dh), fam.h_lo, fam.h_hi))) for _ in range(extra)]
        evaluate_plans(obj, np.array([fam.plan(a, h) for a, h in pts]), candidate)
        values = np.where(obj.feasible_flags[first:], obj.values[first:], -np.inf)
    return obj.cameras[first + int(np.argmax(values))]


def evaluate_plans(obj: Objective, cams: NDArray[np.float64], candidate: bool = True) -> None:
    """Evaluate camera plans in small batches (one recorded evaluation each)."""
    nanU = np.full((1, obj.space.dim), np.nan)
    step = batch_size(obj.space)
    for b0 in range(0, len(cams), step):
        chunk = cams[b0 : b0 + step]
        obj.record(np.repeat(nanU, len(chunk), axis=0), chunk, candidate=candidate)


#: Azimuths at which the ``arc`` baseline tries its arc.
ARC_PHASES = 8


def plan_arc(space: ViewSpace, obj: Objective, evaluations: int, rng: np.random.Generator, arc_spec: ArcSpec) -> None:
    """The ``arc`` baseline (module docstring): tune the circle, then place the arc on it. N
    cameras ``arc_spec.spacing`` apart would wrap past a full turn when N spacing > 2 pi (N > 12
    at 30 degrees): the arc is then the full ring, 2 pi / N apart."""
    from .patterns import arc

    spacing = min(float(arc_spec.spacing), 2.0 * math.pi / space.num_cameras)
    phases = min(ARC_PHASES, evaluations)
    tune = evaluations - phases
    if tune > 0:
        ring = plan_circle(space, obj, tune, rng, candidate=False)
    else:
        fam = CircleFamily(space)
        ring = fam.plan(0.5, 0.5 * (fam.h_lo + fam.h_hi))
    centre = space.extent.centre
    radius = float(np.hypot(*(ring[0, :2] - centre[:2])))
    # neighbours closer than the full ring's: move out until they keep min_separation
    radius = max(radius, space.min_separation / (2.0 * math.sin(0.5 * spacing)) * (1.0 + 1e-9))
    height = float(ring[0, 2])
    target = ring[0, :3] + ring[0, 3:]
    plans = [arc(centre[:2], target, radius, height, space.num_cameras, spacing, 2 * math.pi * k / phases)
             for k in range(phases)]
    evaluate_plans(obj, np.array(plans))


def plan_lawnmower(space: ViewSpace, obj: Objective, survey: LawnmowerSpec) -> None:
    """The ``lawnmower`` baseline: a grid survey (:func:`vp_planner.patterns.lawnmower`) over the
    field's bounding box at the lowest height, in 1 cm steps from ``min_standoff`` above the
    canopy, at which the N images cover the field with ``survey.overlap`` (the camera tilted
    ``survey.tilt``) and the plan is feasible. One evaluation: a survey is flown as planned, not
    tuned to the reward."""
    from .patterns import lawnmower

    overlap, tilt = survey.overlap, survey.tilt
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
    evaluate_plans(obj, plan[None])


def plan_random(space: ViewSpace, obj: Objective, evaluations: int, rng: np.random.Generator) -> None:
    done = 0
    step = batch_size(space)
    while done < evaluations:
        n = min(step, evaluations - done)
        U = random_plans(space, n, rng, should_stop=obj.should_stop)
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


def plan_sa(space: ViewSpace, obj: Objective, evaluations: int, rng: np.random.Generator,
        t0: float = 0.02, t_end: float = 2e-5, neighbours: int = 8, p_local: float = 0.8) -> None:
    """Simulated annealing over N-subsets of :func:`sa_candidates` (:func:`anneal_subsets`),
    keeping the separation rule."""
    cand = sa_candidates(space)
    N = space.num_cameras
    if len(cand) < N:
        raise NoFeasiblePlanError(f"no feasible plan: only {len(cand)} feasible candidate viewpoints for {N} cameras")
    anneal_subsets(cand, N, obj, evaluations, rng, space.min_separation, t0, t_end, neighbours, p_local)


def anneal_subsets(cand: NDArray[np.float64], N: int, obj: Objective, evaluations: int, rng: np.random.Generator,
                   min_separation: float = 0.0, t0: float = 0.02, t_end: float = 2e-5, neighbours: int = 8,
                   p_local: float = 0.8, encode: Optional[Callable] = None) -> None:
    """Simulated annealing over N-subsets of the candidate cameras ``cand`` (M, 6): ``sa``, and
    ``sa`` among given candidates (:mod:`vp_planner.candidates`).

    Move: replace one chosen viewpoint by one of its ``neighbours`` nearest candidates (by
    position) with probability ``p_local``, else by a random candidate; moves that put two
    cameras closer than ``min_separation`` are redrawn. Metropolis acceptance
    exp((r_new - r_cur) / T), geometric cooling T_k = t0 (t_end / t0)^(k / E). Every proposal
    costs one evaluation, recorded with ``encode(subset)`` as its U row (None: NaN, the subset
    is not a point of the objective's space).
    """
    M = len(cand)
    pos = cand[:, :3]
    D = np.linalg.norm(pos[:, None] - pos[None], axis=-1)
    sep_ok = D >= min_separation - 1e-9
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
                                  f"{min_separation} m apart")
    nanU = np.full((1, obj.space.dim), np.nan)

    def record(sel: NDArray[np.int64]) -> float:
        U = nanU if encode is None else np.asarray(encode(sel), dtype=np.float64).reshape(1, -1)
        return float(obj.record(U, cand[sel][None])[0])

    r_cur = record(cur)
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
        r_new = record(prop)
        if r_new >= r_cur or rng.random() < math.exp((r_new - r_cur) / max(T, 1e-300)):
            cur, r_cur = prop, r_new


# ---------------------------------------------------------------------- the registry's planners
def run_circle(space: ViewSpace, obj: Objective, request: PlanRequest, rng: np.random.Generator, parts: int) -> None:
    plan_circle(space, obj, request.evaluations, rng)


def run_arc(space: ViewSpace, obj: Objective, request: PlanRequest, rng: np.random.Generator, parts: int) -> None:
    plan_arc(space, obj, request.evaluations, rng, request.arc)


def run_sa(space: ViewSpace, obj: Objective, request: PlanRequest, rng: np.random.Generator, parts: int) -> None:
    plan_sa(space, obj, request.evaluations, rng)


def run_random(space: ViewSpace, obj: Objective, request: PlanRequest, rng: np.random.Generator, parts: int) -> None:
    plan_random(space, obj, request.evaluations, rng)


def run_lawnmower(space: ViewSpace, obj: Objective, request: PlanRequest, rng: np.random.Generator,
                  parts: int) -> None:
    plan_lawnmower(space, obj, request.lawnmower)
