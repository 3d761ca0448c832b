"""plan_views: baselines, BO methods, cancel, and input errors."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest

from vp_planner.methods import METHODS
from vp_planner.optimizers import InvalidSceneError, plan_views
from vp_planner.request import (MAX_CAMERAS, InvalidBudgetError, InvalidNumCamerasError, PlanRequest, UnknownMethodError,
                                check_memory, estimate_memory)
from vp_planner.reward_models import make_reward
from vp_planner.space import NoFeasiblePlanError, ViewSpace


def check_result(res, method: str, realizations: np.ndarray, n: int, evaluations: int) -> None:
    """Behaviour, not construction: the returned plan is feasible, its reward is the reward model
    evaluated afresh on its cameras, no recorded evaluation beat it, and the trace after every
    evaluation is the best of the rewards recorded so far."""
    assert res.method == method
    assert res.cameras.shape == (n, 6)
    assert res.evaluations == evaluations and not res.stopped
    assert res.trace.shape == (evaluations,) and res.rewards.shape == (evaluations,)
    expected = make_reward(res.reward_model, realizations)(res.cameras[None])[0]
    assert res.reward == pytest.approx(float(expected), abs=1e-6) and res.reward > 0
    assert ViewSpace(realizations, n).feasible(res.cameras)
    if method != "arc":  # arc's circle-tuning evaluations are never candidates (own test)
        assert res.reward == pytest.approx(float(res.rewards.max()), abs=1e-12)
        best = [max(res.rewards[: i + 1].max(), 0.0) for i in range(evaluations)]
        np.testing.assert_allclose(res.trace, best, atol=1e-12)
    np.testing.assert_allclose(res.simple_regret(), 1.0 - res.trace)
    assert res.seconds > 0


@pytest.mark.parametrize("method", ["circle", "arc", "sa", "random", "cmaes"])
def test_baselines(method: str, realizations: np.ndarray) -> None:
    progress = []

    def cb(done, total, best, weights):
        progress.append((done, total, best, weights))
        return True

    res = plan_views(PlanRequest.of(method, 3, evaluations=30, seed=1), realizations, callback=cb)
    check_result(res, method, realizations, 3, 30)
    assert [p[0] for p in progress] == list(range(1, 31))
    assert all(p[1] == 30 and p[3] is None for p in progress)
    np.testing.assert_allclose([p[2] for p in progress], res.trace)
    assert res.ensemble_weights is None
    again = plan_views(PlanRequest.of(method, 3, evaluations=30, seed=1), realizations)
    np.testing.assert_allclose(again.trace, res.trace)


def test_arc_is_the_tuned_circle_with_fixed_spacing(realizations: np.ndarray) -> None:
    """arc: N cameras 30 degrees apart on the radius and height of the circle tuned with the
    rest of the budget, all facing the circle's target; only arcs are ever returned."""
    res = plan_views(PlanRequest.of("arc", 4, evaluations=28, seed=2), realizations)
    circle = plan_views(PlanRequest.of("circle", 4, evaluations=20, seed=2), realizations)
    centre = ViewSpace(realizations, 4).extent.centre
    c = res.cameras[:, :3]
    rad = np.hypot(c[:, 0] - centre[0], c[:, 1] - centre[1])
    rad_circle = np.hypot(circle.cameras[0, 0] - centre[0], circle.cameras[0, 1] - centre[1])
    rad_sep = 0.5 / (2 * math.sin(math.radians(15.0)))  # min_separation 0.5 between neighbours
    np.testing.assert_allclose(rad, max(rad_circle, rad_sep), rtol=1e-6)
    np.testing.assert_allclose(c[:, 2], circle.cameras[0, 2], atol=1e-9)
    az = np.unwrap(np.arctan2(c[:, 1] - centre[1], c[:, 0] - centre[0]))
    np.testing.assert_allclose(np.abs(np.diff(az)), math.radians(30.0), atol=1e-9)
    target = c + res.cameras[:, 3:]
    np.testing.assert_allclose(target, target[:1].repeat(4, 0), atol=1e-9)
    assert np.all(res.trace[:20] == 0.0) and res.trace[-1] > 0  # the circle tuning is never returned
    wide = plan_views(PlanRequest.of("arc", 4, evaluations=28, seed=2, arc_spacing=math.radians(45.0)), realizations)
    az = np.unwrap(np.arctan2(wide.cameras[:, 1] - centre[1], wide.cameras[:, 0] - centre[0]))
    np.testing.assert_allclose(np.abs(np.diff(az)), math.radians(45.0), atol=1e-9)
    # 14 cameras 30 degrees apart would wrap past a full turn onto each other: a full ring instead
    ring = plan_views(PlanRequest.of("arc", 14, evaluations=20, seed=2), realizations)
    az = np.sort(np.mod(np.arctan2(ring.cameras[:, 1] - centre[1], ring.cameras[:, 0] - centre[0]), 2 * math.pi))
    np.testing.assert_allclose(np.diff(az), 2 * math.pi / 14, atol=1e-9)
    assert ViewSpace(realizations, 14).feasible(ring.cameras)


def test_circle_geometry(realizations: np.ndarray) -> None:
    res = plan_views(PlanRequest.of("circle", 4, evaluations=20), realizations)
    c, v = res.cameras[:, :3], res.cameras[:, 3:]
    np.testing.assert_allclose(c[:, 2], c[0, 2])  # one height
    centre = ViewSpace(realizations, 4).extent.centre
    rad = np.hypot(c[:, 0] - centre[0], c[:, 1] - centre[1])
    np.testing.assert_allclose(rad, rad[0])  # one radius
    az = np.sort(np.arctan2(c[:, 1] - centre[1], c[:, 0] - centre[0]) % (2 * math.pi))
    np.testing.assert_allclose(np.diff(az), math.pi / 2, atol=1e-9)  # evenly spaced
    np.testing.assert_allclose(c + v, np.broadcast_to(centre, c.shape), atol=1e-9)  # facing the centre


@pytest.mark.parametrize("method", ["circle", "sa", "random", "cmaes"])
def test_cancel_within_one_evaluation(method: str, realizations: np.ndarray) -> None:
    res = plan_views(PlanRequest.of(method, 3, evaluations=40), realizations, callback=lambda d, t, b, w: d < 7)
    assert res.stopped and res.evaluations == 7 and res.trace.shape == (7,)
    assert res.cameras.shape == (3, 6)
    first = plan_views(PlanRequest.of(method, 3, evaluations=40), realizations, callback=lambda d, t, b, w: False)
    assert first.stopped and first.evaluations == 1


@pytest.mark.parametrize("method", ["egp", "gp"])
def test_bo_methods(method: str, realizations: np.ndarray) -> None:
    seen = []

    def cb(done, total, best, weights):
        seen.append((done, weights))
        return True

    # 3 cameras: a pair of the space's shell is mostly wider than the window and scores ~0
    res = plan_views(PlanRequest.of(method, 3, evaluations=12, initial_evaluations=8, seed=0), realizations,
                     callback=cb)
    check_result(res, method, realizations, 3, 12)
    assert [s[0] for s in seen] == list(range(1, 13))
    if method == "egp":
        assert res.ensemble_weights is not None and len(res.ensemble_weights) == len(res.model_names)
        assert sum(res.ensemble_weights) == pytest.approx(1.0, abs=1e-6)
        assert any(w is not None for _, w in seen)
    else:
        assert res.ensemble_weights is None
    stopped = plan_views(PlanRequest.of(method, 2, evaluations=12, initial_evaluations=8), realizations,
                         callback=lambda d, t, b, w: d < 10)
    assert stopped.stopped and stopped.evaluations == 10 and stopped.trace.shape == (10,)


def test_bad_inputs(realizations: np.ndarray) -> None:
    assert set(METHODS) == {"egp", "gp", "circle", "arc", "sa", "random", "cmaes", "lawnmower"}
    with pytest.raises(InvalidNumCamerasError):
        plan_views(PlanRequest.of("random", 1), realizations)
    with pytest.raises(UnknownMethodError, match="unknown method"):
        plan_views(PlanRequest.of("nelder-mead", 3), realizations)
    with pytest.raises(InvalidBudgetError):
        plan_views(PlanRequest.of("random", 3, evaluations=0), realizations)
    with pytest.raises(InvalidBudgetError):
        plan_views(PlanRequest.of("egp", 3, evaluations=20, initial_evaluations=30), realizations)
    with pytest.raises(InvalidSceneError):
        plan_views(PlanRequest.of("random", 3), np.zeros((3, 0, 3)))
    bad = realizations.copy()
    bad[1, 5, 2] = np.inf
    with pytest.raises(InvalidSceneError):
        plan_views(PlanRequest.of("circle", 3), bad)
    for err in (InvalidNumCamerasError, UnknownMethodError, InvalidBudgetError, InvalidSceneError):
        assert issubclass(err, ValueError)
    for method in ("random", "sa"):
        with pytest.raises(NoFeasiblePlanError, match="feasible"):
            plan_views(PlanRequest.of(method, 4, evaluations=5, min_separation=100.0), realizations)
    # a ring can always widen: its plan keeps the separation (at a poor reward)
    wide = plan_views(PlanRequest.of("circle", 4, evaluations=4, min_separation=5.0), realizations)
    c = wide.cameras[:, :3]
    d = np.linalg.norm(c[:, None] - c[None], axis=-1)[np.triu_indices(4, 1)]
    assert d.min() >= 5.0 - 1e-9


def test_camera_count_is_bounded() -> None:
    """There was no upper bound on N."""
    PlanRequest.of("circle", MAX_CAMERAS, evaluations=10, initial_evaluations=5)
    for n in (MAX_CAMERAS + 1, 500, 1000):
        with pytest.raises(InvalidNumCamerasError, match=f"from 2 to {MAX_CAMERAS}"):
            PlanRequest.of("circle", n, evaluations=10, initial_evaluations=5)


def test_memory_check_refuses_before_allocating() -> None:
    assert estimate_memory(100, 5, 20000, "paper") < 200 * 2**20  # chunked: no N^2 x P block
    check_memory(4, (5, 20000), "coverage", available=8 * 2**30)
    with pytest.raises(InvalidNumCamerasError, match="GiB"):
        check_memory(100, (500, 20000), "coverage", available=8 * 2**30)


def test_feasible_plan_search_honours_should_stop(realizations: np.ndarray) -> None:
    """The random initial design of 64 cameras (min_separation 0.5) searches
    for minutes without finding a feasible plan; a stop request ends it at once."""
    t0 = time.monotonic()
    res = plan_views(PlanRequest.of("egp", 64, evaluations=60, initial_evaluations=50), realizations,
                     should_stop=lambda: time.monotonic() - t0 > 0.5)
    assert time.monotonic() - t0 < 10.0
    assert res.stopped and res.evaluations == 0 and res.cameras.shape == (0, 6)
    calls = []
    res = plan_views(PlanRequest.of("random", 3, evaluations=40), realizations,
                     should_stop=lambda: calls.append(1) or len(calls) > 2)
    assert res.stopped and 0 < res.evaluations < 40


def test_evaluation_budget_is_bounded_before_anything_is_allocated(realizations: np.ndarray) -> None:
    """A budget of 4e9 evaluations was accepted and grew the planner to 20 GB
    (circle, sa and random had no bound; egp asked torch for 192 GB). Each method has a
    documented bound, and a run the memory cannot hold is refused too, both before the space
    or any record is allocated."""
    from vp_planner.methods import MAX_EVALUATIONS
    from vp_planner.request import BudgetTooLargeError, check_budget_memory, estimate_run_memory

    assert set(MAX_EVALUATIONS) == set(METHODS)
    assert MAX_EVALUATIONS["egp"] == MAX_EVALUATIONS["gp"] == 1000
    assert all(MAX_EVALUATIONS[m] == 100_000 for m in ("circle", "arc", "sa", "random", "cmaes", "lawnmower"))
    for method, evals in (("circle", 4_000_000_000), ("sa", 100_001), ("random", 10**9), ("egp", 1001)):
        with pytest.raises(BudgetTooLargeError, match=f"above the bound of {MAX_EVALUATIONS[method]}"):
            plan_views(PlanRequest.of(method, 4, evaluations=evals, initial_evaluations=10), realizations)
    assert issubclass(BudgetTooLargeError, InvalidBudgetError)
    # the memory estimate: records grow with N, the GPs with n^2
    assert estimate_run_memory("circle", 100, 100_000) > 1.4e9
    assert estimate_run_memory("egp", 4, 1000) > 192e6 > estimate_run_memory("circle", 4, 1000)
    with pytest.raises(BudgetTooLargeError, match="GiB are available"):
        check_budget_memory("circle", 100, 100_000, available=2**30)
    check_budget_memory("circle", 4, 100, available=2**30)
    # at the bound, a run still plans (and within its budget)
    ok = plan_views(PlanRequest.of("circle", 3, evaluations=MAX_EVALUATIONS["circle"] // 1000), realizations)
    assert ok.evaluations == 100


def test_egp_names_the_range_it_serves_when_no_feasible_plan_exists(realizations: np.ndarray) -> None:
    """egp found no feasible plan for N = 100 on one_plant while circle does,
    although 2-100 cameras are allowed. egp's shell holds random feasible plans up to a few dozen
    cameras a plant; beyond, its refusal says so and names the methods that serve the rest."""
    with pytest.raises(NoFeasiblePlanError, match="egp/gp plan up to about 40 cameras a plant .*circle"):
        plan_views(PlanRequest.of("egp", 100, evaluations=3, initial_evaluations=2, structured_init=0), realizations)
    assert plan_views(PlanRequest.of("circle", 100, evaluations=1), realizations).cameras.shape == (100, 6)
