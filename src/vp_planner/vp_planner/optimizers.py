"""View-planning methods behind one entry point, :func:`plan_views`.

The rooms: :mod:`vp_planner.request` (:class:`~vp_planner.request.PlanRequest`, what to plan, its
validation and its checks against the scene and the memory), :mod:`vp_planner.baselines` (circle,
arc, sa, random, lawnmower), :mod:`vp_planner.bo_planning` (egp, gp, by parts); this module
builds the space and the objective of a request, hands them to the method's entry of the
registry (:class:`vp_planner.methods.Method`, which knows the room that plans it) and returns a
:class:`PlanResult`. The names of the other rooms are imported from their own module (no
re-exports here): the request, its errors and checks from :mod:`vp_planner.request`, the methods
and their bounds from :mod:`vp_planner.methods`, the space's errors from :mod:`vp_planner.space`.

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
* ``cmaes``: CMA-ES (the ``cma`` package, :mod:`vp_planner.cmaes`) in the same space, from the
  best of its structured plans, with IPOP restarts while the budget lasts.
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

Size of a plan: 2 <= N <= :data:`vp_planner.request.MAX_CAMERAS`. Memory does not limit N by itself: both reward
models and the feasibility check work in chunks of a fixed number of elements (the paper
reward's pair term included), so one evaluation needs O(N^2) small arrays (pair indices, one
accumulator per pair) plus the coverage model's per-camera terms, N x K x min(P, 3000) elements
(:func:`vp_planner.request.estimate_memory`; a plan that would not fit in the memory available is refused before
anything is allocated). What limits N is time and feasibility: one evaluation costs O(N^2 K P)
(N = 100 on 5 x 4000 points: about 1e8 pair-point terms), the
BO methods work in 6N dimensions, and random feasible plans (min_separation between every pair)
become rare beyond a few dozen cameras. Hence the bound of 100 cameras, far above the paper's
N <= 6; a run is cancellable throughout (``should_stop``), the feasible-plan search included.

Size of a budget: 1 <= evaluations <= :data:`vp_planner.methods.MAX_EVALUATIONS` [method] (:mod:`vp_planner.methods`,
the registry of the methods): 1000 for egp/gp (the
paper uses 100-200; a GP's fit costs O(n^3) time and O(n^2) memory in the n evaluations made,
four of them for egp, so 1000 is already hours of fitting) and 100000 for the baselines (each
evaluation is recorded: a few hundred bytes plus 150 bytes a camera). Planning by parts
multiplies the budget (:func:`vp_planner.request.total_evaluations`). Beyond the bound, or when
:func:`vp_planner.request.estimate_run_memory` of the run exceeds the share of the available memory a request
may take (:data:`vp_scene.limits.MEMORY_FRACTION`), the request is
refused before anything is allocated (:class:`vp_planner.request.BudgetTooLargeError`; the planner node's
``BUDGET_TOO_LARGE``).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Optional

import numpy as np
import torch
from numpy.typing import NDArray

from .feasibility import check_realizations
from .methods import BY_NAME
from .flight_planning import OnFlight, flight_stage, patterns
from .objective import Objective
from .request import (InvalidReconstructionError, PlanRequest, check_budget_memory, check_parts, check_plan_memory,
                      check_reconstruction_memory, total_evaluations)
from .reward_models import DEFAULT_REWARD_MODEL
from .space import Callback, NoFeasiblePlanError, PlanningCancelled, StopCheck, ViewSpace

__all__ = ["PlanResult", "plan_views", "InvalidSceneError", "sortie_weights"]


class InvalidSceneError(ValueError):
    """Empty or non-finite point cloud, or a wrong shape."""


def sortie_weights(realizations: NDArray[np.float64], reconstruction: Any, tau: float, reconstructed_weight: float,
                   available: Optional[int] = None) -> tuple[NDArray[np.float64], float]:
    """Point weights (K, P) of a second sortie (:func:`vp_planner.reward_models.reconstructed_weights`)
    and the fraction of points reconstructed, for a request's :class:`~vp_planner.request.Sortie`
    (which checked the points, tau and the weight); InvalidReconstructionError for a
    reconstruction the memory cannot hold (or, from the mask's own checks, bad points or tau)."""
    from .reward_models import reconstructed_mask

    Q = np.asarray(reconstruction, dtype=np.float64).reshape(-1, 3)
    check_reconstruction_memory(len(Q), available)
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
            parts: the steps of the joint refinement; cmaes: one record per CMA-ES run (population,
            generations, best reward, why it stopped).
        initial_best: egp/gp: the best reward of the initial design (by parts: of the union of
            the part plans, before the joint refinement); cmaes: of the structured plans it
            starts from.
        parts: egp/gp by parts: one record per part (cameras, points, evaluations, the part's own
            reward and its initial design's best); None otherwise.
        fixed_cameras: M, the cameras already flown the reward counted (0: a first sortie).
        reconstructed_fraction: with a reconstruction, the fraction of the planning cloud's
            points within tau of it (weighed ``reconstructed_weight``); else None.
        selected: among candidates, the indices (N,) of the chosen candidates in the request's
            candidate list (the order of ``cameras``); None in free space.
        chosen_by: ``'reward'`` (the cheap reward's best plan) or ``'flights'`` (the simulated
            flights chose it, :mod:`vp_planner.flight_planning`).
        flights: every simulated flight flown (records: plan index, source, draw, score), None
            when none was; ``flight_plans``: the plans flown (cameras, reward, source, score);
            ``flight_score``: the chosen plan's mean map Chamfer over its flights (m);
            ``flights_note``: why the flights asked for were not flown ('' when they were).
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
    selected: Optional[list] = None
    chosen_by: str = "reward"
    flights: Optional[list] = None
    flight_plans: Optional[list] = None
    flight_score: Optional[float] = None
    flights_note: str = ""

    def simple_regret(self, optimum: float = 1.0) -> NDArray[np.float64]:
        """SR(t) = r~(z*) - max_{tau <= t} r~(z_tau) (paper Sec. V-B), with r~(z*) = ``optimum``."""
        return float(optimum) - np.asarray(self.trace, dtype=np.float64)


# ---------------------------------------------------------------------- entry point
def plan_views(request: PlanRequest, realizations: Any, callback: Optional[Callback] = None,
               should_stop: Optional[StopCheck] = None, simulator: Any = None,
               on_flight: Optional[OnFlight] = None) -> PlanResult:
    """Plan ``request.cameras.num_cameras`` views of the noisy scene with ``request.method`` (one of
    :data:`METHODS`, planned by its registry entry's planner); every setting is a field of the
    :class:`~vp_planner.request.PlanRequest` (validated there, its docstring gives the units and rules).

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
        simulator: the :class:`vp_scene.flights.FlightSimulator` of the scene (handed in by the
            caller: the CLI, a benchmark, the planner node's client of the recon node); with
            flights to make (``request.flights.flights_of(method)``) the cheap stage's plans are
            checked by simulated flights and the flights choose (:mod:`vp_planner.flight_planning`);
            None: the cheap reward chooses (``flights_note`` says so when flights were asked for).
        on_flight: ``on_flight(done, total, score)`` after every flight.

    Planning by parts (egp/gp, ``request.bo.parts``): each part gets ``evaluations``, the joint
    refinement ``evaluations // 2``, all counted in the result; 0: :func:`vp_planner.parts.auto_parts`
    (1 for N <= 7); 1: one space. Cameras already flown (``request.sortie.fixed_cameras``) count in every
    method's reward with the plan (pairs with them like pairs within it); the plan need not keep
    min_separation from them (README "A second sortie"). The realizations' points within ``tau``
    of ``request.sortie.reconstruction`` weigh ``reconstructed_weight`` in the reward, the others 1
    (:func:`vp_planner.reward_models.reconstructed_weights`).

    Raises:
        TypeError when ``request`` is not a PlanRequest; InvalidSceneError (a ValueError) for bad
        realizations; InvalidNumCamerasError for a plan the memory cannot hold
        (:func:`vp_planner.request.check_plan_memory`) or more parts than pairs of cameras; BudgetTooLargeError
        for a run the memory cannot hold (:func:`vp_planner.request.check_budget_memory`);
        InvalidFixedCamerasError, InvalidReconstructionError when the cameras already flown or the
        reconstruction do not fit in memory (nothing planned); NoFeasiblePlanError (ValueError)
        when no feasible plan was found.
    """
    if not isinstance(request, PlanRequest):
        raise TypeError(f"plan_views takes a vp_planner.request.PlanRequest, got {type(request).__name__}")
    q, entry = request, BY_NAME[request.method]
    num_cameras, model = q.cameras.num_cameras, q.reward.name
    try:
        R = check_realizations(realizations)
    except ValueError as exc:
        raise InvalidSceneError(str(exc)) from None
    check_plan_memory(q, R.shape)
    F = q.sortie.fixed_cameras
    sortie = q.sortie
    W, done = (None, None) if sortie.reconstruction is None else sortie_weights(
        R, sortie.reconstruction, sortie.tau, sortie.reconstructed_weight)
    among = q.candidates.poses is not None
    n_parts = 1 if among else check_parts(q.bo.parts, q.method, R, num_cameras)
    budget = total_evaluations(q.method, q.evaluations, n_parts)
    check_budget_memory(q.method, num_cameras, budget)
    start = time.perf_counter()
    feas = q.feasibility
    spec = q.reward.model_spec()  # the reward model with the flight's reported-pose errors
    if among:  # N of the candidate poses (vp_planner.candidates): no feasibility rules, no free space
        from .candidates import CandidateSpace

        space = CandidateSpace(q.candidates.poses, num_cameras, R, fov=q.cameras.fov, theta_match=q.reward.theta_match,
                               reward_model=spec, image_size=q.cameras.image_size, fixed_cameras=F, point_weights=W)
    else:
        space = ViewSpace(R, num_cameras, min_standoff=feas.min_standoff, min_altitude=feas.min_altitude,
                          min_separation=feas.min_separation, fov=q.cameras.fov, theta_match=q.reward.theta_match,
                          shell_depth=q.cameras.shell_depth, reward_model=spec, image_size=q.cameras.image_size,
                          fixed_cameras=F, point_weights=W)
    obj = Objective(space, budget, callback=callback, dtype=getattr(torch, q.reward.dtype), should_stop=should_stop)
    n_flights = q.flights.flights_of(q.method)
    warm_up = getattr(simulator, "warm_up", None) if n_flights else None
    if callable(warm_up):  # the simulator's workers get ready while the cheap stage computes
        warm_up()
    rng = np.random.default_rng(q.seed)
    torch.manual_seed(q.seed)
    info: dict = {}
    try:
        info = entry.plan_candidates(space, obj, q, rng) if among else entry.plan(space, obj, q, rng, n_parts)
    except PlanningCancelled:
        pass
    # among candidates a method may need fewer evaluations than its budget (circle: one a phase)
    stopped = obj.cancelled or (obj.count < budget and not among)
    best = obj.best_cameras()
    if among and best is not None:  # in the order of the selected indices
        best = space.decode(obj.U[obj.best_index])
    if best is None:
        if not stopped:
            raise NoFeasiblePlanError(f"no feasible plan among the {obj.count} evaluated plans")
        best = np.zeros((0, 6))
    outcome, note = None, ""
    if n_flights and simulator is None:
        note = "no flight simulator: the cheap reward chose"
    elif n_flights and not stopped and best is not None:
        try:
            outcome = flight_stage(space, obj, simulator, n_flights, q.seed, patterns(space, obj, q, budget, rng),
                                   float(getattr(simulator, "wind_variance")), on_flight=on_flight,
                                   should_stop=should_stop)
        except PlanningCancelled:
            stopped = True
    chosen_U = obj.U[obj.best_index] if obj.best_index >= 0 else None
    if outcome is not None:  # among candidates in the order of the selected indices
        best, chosen_U = (space.decode(outcome.U) if among else outcome.cameras), outcome.U
        if not np.isfinite(outcome.score):
            note = "every simulated flight failed: the cheap reward chose"
    weights = info.get("weights") if entry.ensemble else None
    names = None
    if entry.ensemble:
        from .gp import MODEL_NAMES

        names = info.get("model_names") or list(MODEL_NAMES)
    return PlanResult(
        method=q.method,
        cameras=np.asarray(best, dtype=np.float64),
        reward=float(obj.best_value if outcome is None else outcome.reward),
        trace=obj.trace(),
        evaluations=obj.count,
        seconds=time.perf_counter() - start,
        ensemble_weights=weights,
        model_names=names,
        stopped=bool(stopped),
        rewards=np.asarray(obj.values, dtype=np.float64),
        reward_model=model,
        steps=info.get("steps"),
        initial_best=info.get("initial_best"),
        parts=info.get("parts"),
        fixed_cameras=len(F),
        reconstructed_fraction=done,
        selected=space.indices(chosen_U).tolist() if among and chosen_U is not None else None,
        chosen_by="flights" if outcome is not None and np.isfinite(outcome.score) else "reward",
        flights=None if outcome is None else outcome.flights,
        flight_plans=None if outcome is None else outcome.plans,
        flight_score=None if outcome is None or not np.isfinite(outcome.score) else float(outcome.score),
        flights_note=note,
    )
