"""The ``cmaes`` method: CMA-ES (the `cma` package) on the unit cube of a :class:`~vp_planner.space.ViewSpace`.

CMA-ES samples each generation g a population of lambda plans

    x_k = m_g + sigma_g B_g D_g z_k,    z_k ~ N(0, I_{6N}),    k = 1..lambda,

ranks them by f(x) = -r~(x) (the :class:`~vp_planner.objective.Objective`'s reward: eq. 7, 0 for
an infeasible plan, which therefore ranks with the worst), moves the mean to the weighted mean
of the mu = lambda / 2 best, m_{g+1} = sum_i w_i x_{i:lambda}, adapts the covariance
C = B D^2 B^T by its rank-one (evolution path) and rank-mu updates and the step sigma by
cumulative step-size adaptation. The population is cma's default, lambda = 4 + floor(3 ln 6N)
(13 for 4 cameras, 16 for 12). No gradient and no model: a generation costs lambda reward
evaluations and O(lambda (6N)^2) arithmetic, so the method runs at the reward's own speed.

The cube: every coordinate but the azimuths is bounded to [0, 1] by cma's ``BoundTransform``
(a smooth map of each sampled point into the box: the evaluated plans stay in the cube and the
distribution still adapts at a bound). The azimuths u_az (:attr:`ViewSpace.periodic`) are
unbounded, u and u + 1 being one plan: they are wrapped mod 1 before the plan is evaluated and
recorded, so a camera circles the scene freely.

Start: ``x0`` is the best of the space's structured plans (:func:`vp_planner.designs.structured_plans`,
evaluated first, counted in the budget), or one random feasible plan when none is feasible;
``sigma0`` = 0.1, a tenth of the cube's side. Restarts (IPOP): when cma's termination criteria
stop a run (flat fitness, tolfun, tolx, stagnation, ...), a new one starts from a point drawn
uniformly in the cube with twice the population (at most the evaluations left), while the
budget lasts (Auger and Hansen 2005). A budget that ends within a
generation evaluates the generation's first plans and stops.

Randomness: cma draws its normal samples through ``randn`` from the method's numpy Generator
(seeded by the request), never from numpy's global state, so a seed gives one plan.
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np
from numpy.typing import NDArray

from .baselines import batch_size
from .designs import random_plans, structured_plans
from .objective import Objective
from .request import PlanRequest
from .space import ViewSpace

__all__ = ["SIGMA0", "plan_cmaes", "run_cmaes"]

#: The initial step, in units of the cube's side.
SIGMA0 = 0.1


def plan_cmaes(space: ViewSpace, obj: Objective, rng: np.random.Generator, sigma0: float = SIGMA0,
               structured_start: bool = True) -> dict:
    """CMA-ES with IPOP restarts on ``obj`` until its budget (``obj.total``) is spent (module
    docstring). Returns the run's CMA-ES runs as ``steps`` (population, generations, best reward,
    why cma stopped) and the best structured plan's reward as ``initial_best`` (None without a
    structured start)."""
    import cma  # imported on use: the registry's planners are loaded lazily

    periodic = space.periodic
    lo = [None if p else 0.0 for p in periodic]
    hi = [None if p else 1.0 for p in periodic]
    x0, initial_best = _start(space, obj, rng, structured_start)
    steps: list[dict] = []
    popsize = default = 0
    while obj.count < obj.total:
        opts = {"bounds": [lo, hi], "randn": lambda *shape: rng.standard_normal(shape), "seed": math.nan,
                "verbose": -9, "verb_log": 0, "verb_disp": 0}
        if popsize:
            opts["popsize"] = popsize
        es = cma.CMAEvolutionStrategy(x0, sigma0, opts)
        popsize, default = es.popsize, default or es.popsize
        record = {"popsize": popsize, "generations": 0, "best": 0.0, "stop": "budget"}
        steps.append(record)
        while not es.stop() and obj.count < obj.total:
            X = np.asarray(es.ask(), dtype=np.float64)
            r = _evaluate(space, obj, X)
            record["generations"] += 1
            record["best"] = max(record["best"], float(r.max()) if len(r) else 0.0)
            if len(r) < len(X):  # the budget ended within this generation
                break
            es.tell(list(X), list(-r))
        if es.stop():
            record["stop"] = ", ".join(sorted(es.stop()))
        popsize = min(2 * popsize, max(default, obj.total - obj.count))  # no larger than the budget left
        x0 = rng.random(space.dim)
    return {"steps": steps, "initial_best": initial_best}


def _start(space: ViewSpace, obj: Objective, rng: np.random.Generator,
           structured: bool) -> tuple[NDArray[np.float64], Optional[float]]:
    """(x0, the best structured reward): the best structured plan (evaluated within the budget,
    one evaluation left for CMA-ES), else (no structured start, or none scores above 0) a random
    feasible plan."""
    best = None
    if structured:
        S = structured_plans(space)[: max(0, obj.total - 1)]
        if len(S):
            r = _evaluate(space, obj, S)
            best = float(r.max())
            if best > 0.0:
                return S[int(np.argmax(r))], best
    return random_plans(space, 1, rng, should_stop=obj.should_stop)[0], best


def _evaluate(space: ViewSpace, obj: Objective, X: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rewards of the plans X (B, 6N), azimuths wrapped mod 1, evaluated in small batches (a cancel
    is seen between them) and no further than the budget: fewer than B when it ends."""
    U = np.where(space.periodic, np.mod(X, 1.0), X)[: max(0, obj.total - obj.count)]
    step = batch_size(space)
    return np.concatenate([np.asarray(obj(U[b: b + step]), dtype=np.float64) for b in range(0, len(U), step)]
                          or [np.zeros(0)])


def run_cmaes(space: ViewSpace, obj: Objective, request: PlanRequest, rng: np.random.Generator, parts: int) -> dict:
    """The registry's planner of ``cmaes`` (:class:`vp_planner.methods.Method`): one space, the
    request's budget and seed."""
    return plan_cmaes(space, obj, rng)
