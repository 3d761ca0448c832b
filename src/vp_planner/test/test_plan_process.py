"""A plan in a process of its own (vp_planner.plan_process): the plan plan_views makes, its progress,
its refusals; a stop ends it at once whatever it is doing (one long evaluation here), and a child
that dies is reported."""
from __future__ import annotations

import multiprocessing
import os
import signal
import time

import numpy as np
import pytest

from vp_planner.optimizers import InvalidSceneError, plan_views
from vp_planner.plan_process import PlanProcessDied, run_plan
from vp_planner.request import PlanRequest


def _plans() -> list:
    return [p for p in multiprocessing.active_children() if p.name == "plan"]


def _ring(m: int) -> np.ndarray:
    a = np.linspace(0.0, 2.0 * np.pi, m, endpoint=False)
    return np.stack([3 * np.cos(a), 3 * np.sin(a), np.full(m, 1.5), -np.cos(a), -np.sin(a), np.zeros(m)], axis=1)


@pytest.fixture(scope="module")
def scene() -> np.ndarray:
    from vp_scene.build import build_noisy_scene

    return build_noisy_scene("one_plant", points_per_plant=600, realizations=2, levels=5, seed=3)[0].points


def test_the_plan_is_plan_views_and_its_progress_comes_back(scene) -> None:
    request = PlanRequest.of("egp", 4, evaluations=12, initial_evaluations=8, seed=1)
    seen: list = []
    got = run_plan(request, scene, progress=lambda *a: seen.append(a))
    here = plan_views(request, scene)
    np.testing.assert_array_equal(got.cameras, here.cameras)
    assert got.reward == here.reward and got.evaluations == 12
    assert [s[0] for s in seen] == list(range(1, 13)) and seen[-1][2] == pytest.approx(got.trace[-1])
    assert not _plans()


def test_a_refusal_comes_back_as_itself(scene) -> None:
    bad = scene.copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(InvalidSceneError, match="non-finite"):
        run_plan(PlanRequest.of("circle", 4, evaluations=3), bad)


def test_a_stop_ends_a_long_evaluation_at_once(scene) -> None:
    """100 cameras with 100 already flown: circle's first batch of evaluations takes seconds to a
    minute in one computation that never asks should_stop; the child is killed when it is asked."""
    request = PlanRequest.of("circle", 100, evaluations=10, fixed_cameras=_ring(100))
    run_plan(PlanRequest.of("circle", 4, evaluations=2), scene)  # the fork server is up
    asked: list = []

    def should_stop() -> bool:
        asked.append(time.monotonic())
        return len(_plans()) > 0 and time.monotonic() - asked[0] > 1.0

    assert run_plan(request, scene, should_stop=should_stop) is None
    assert not _plans()  # killed and reaped before the answer


def test_a_child_killed_from_outside_is_reported(scene) -> None:
    request = PlanRequest.of("circle", 100, evaluations=10, fixed_cameras=_ring(100))

    def kill_it() -> bool:
        for p in _plans():
            os.kill(p.pid, signal.SIGKILL)
        return False

    with pytest.raises(PlanProcessDied, match="killed by SIGKILL"):
        run_plan(request, scene, should_stop=kill_it)
