"""The ``cmaes`` method (vp_planner.cmaes): CMA-ES from the cma package in the unit cube of a ViewSpace.

The behaviour every method shares (a feasible plan, its reward re-evaluated, the trace, progress,
a seed's plan twice, a cancel within one evaluation) is in test_planner_optimizers'
``test_baselines`` and ``test_cancel_within_one_evaluation``; here what is CMA-ES's own.
"""
from __future__ import annotations

import numpy as np
import pytest

from vp_planner.cmaes import plan_cmaes
from vp_planner.designs import structured_plans
from vp_planner.objective import Objective
from vp_planner.optimizers import plan_views
from vp_planner.request import PlanRequest
from vp_planner.space import ViewSpace


def test_cmaes_starts_from_the_best_structured_plan_and_improves_on_it(small_realizations) -> None:
    """The structured plans come first (counted in the budget), CMA-ES's generations after; the
    recorded plans are all in the cube (azimuths wrapped mod 1), the plan is feasible."""
    n, budget = 3, 80
    space = ViewSpace(small_realizations, n)
    S = structured_plans(space)
    res = plan_views(PlanRequest.of("cmaes", n, evaluations=budget, seed=3), small_realizations)
    assert res.evaluations == budget and not res.stopped
    assert res.initial_best == pytest.approx(float(res.rewards[: len(S)].max()))
    assert res.reward > res.initial_best  # the generations found a better plan than the patterns
    assert space.feasible(res.cameras)
    assert res.steps[0]["popsize"] == 4 + int(3 * np.log(6 * n))  # cma's default population
    assert sum(s["generations"] for s in res.steps) == -(-(budget - len(S)) // res.steps[0]["popsize"])

    obj = Objective(space, budget)
    plan_cmaes(space, obj, np.random.default_rng(3))
    U = np.asarray(obj.U)
    np.testing.assert_allclose(U[: len(S)], S)
    assert U.min() >= 0.0 and U.max() <= 1.0
    assert np.ptp(U[len(S):, space.periodic]) > 0  # the azimuths move


def test_a_seed_is_one_plan_and_numpy_global_state_is_left_alone(small_realizations) -> None:
    """cma samples from the method's Generator (its ``randn`` option), not np.random's global state."""
    np.random.seed(123)
    before = np.random.get_state()[1].copy()
    runs = [plan_views(PlanRequest.of("cmaes", 3, evaluations=50, seed=s), small_realizations) for s in (5, 5, 6)]
    np.testing.assert_array_equal(np.random.get_state()[1], before)
    np.testing.assert_array_equal(runs[0].rewards, runs[1].rewards)
    np.testing.assert_array_equal(runs[0].cameras, runs[1].cameras)
    assert not np.array_equal(runs[0].rewards, runs[2].rewards)


def test_restarts_with_twice_the_population_while_the_budget_lasts(small_realizations) -> None:
    """A flat reward (a field of view of 0.01 rad sees almost nothing: every plan scores about 0)
    stops each CMA-ES run at once (tolfun); IPOP restarts it with twice the population, the last
    one no larger than the evaluations left, until the budget is spent exactly."""
    budget = 140
    res = plan_views(PlanRequest.of("cmaes", 3, evaluations=budget, seed=0, fov=0.01), small_realizations)
    assert res.evaluations == budget and not res.stopped and res.reward < 0.01
    structured = len(structured_plans(ViewSpace(small_realizations, 3, fov=0.01)))
    p0 = res.steps[0]["popsize"]
    left = budget - structured - 7 * p0
    assert 0 < left < 8 * p0
    assert [s["popsize"] for s in res.steps] == [p0, 2 * p0, 4 * p0, left]
    assert all(s["generations"] == 1 and s["stop"] == "tolfun" for s in res.steps)


def test_should_stop_ends_a_run_between_batches(small_realizations) -> None:
    asked = []
    res = plan_views(PlanRequest.of("cmaes", 3, evaluations=500, seed=0), small_realizations,
                     should_stop=lambda: asked.append(1) or len(asked) > 4)
    assert res.stopped and 0 < res.evaluations < 500 and res.cameras.shape == (3, 6)
