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


class ParentSimulator:
    """A FlightSimulator in the caller's process: scores a plan by its cameras' mean height (m / 100)
    and records the process, the plans and the draws it flew; ``block`` holds a batch until
    should_stop() is true (a flight that takes long)."""

    def __init__(self, block: bool = False) -> None:
        self.workers, self.wind_variance, self.block = 2, 0.002, block
        self.flown: list = []
        self.stopped = False
        self.warmed: list = []

    def warm_up(self):
        self.warmed.append((os.getpid(), len(self.flown)))

    def fly(self, plans, draws, on_flight=None, should_stop=None):
        from vp_scene.flights import FlightScore

        out = []
        for i, (cams, draw) in enumerate(zip(plans, draws)):
            self.flown.append((os.getpid(), np.asarray(cams).copy(), draw))
            while self.block and not should_stop():
                time.sleep(0.01)
            if self.block:
                self.stopped = True
                return out
            out.append(FlightScore(draw=draw, chamfer=float(np.mean(cams[:, 2])) / 100, chamfer_shape=0.01,
                                   images=len(cams), seconds=0.1))
            on_flight(i, out[-1])
        return out


def test_the_flights_are_flown_by_the_callers_simulator_and_their_progress_comes_back(scene) -> None:
    """The child asks, the caller's simulator flies (in the caller's process), each flight goes
    back to the flight stage as it comes and its progress to the caller: the plan is the one
    plan_views makes with the same simulator in process."""
    from vp_scene.flights import FLIGHT_CAPTURE_SEEDS

    request = PlanRequest.of("egp", 4, evaluations=12, initial_evaluations=8, seed=1, sim_flights=5)
    sim, seen = ParentSimulator(), []
    got = run_plan(request, scene, simulator=sim, on_flight=lambda done, total, score: seen.append((done, total, score)))
    here = plan_views(request, scene, simulator=ParentSimulator())
    assert got.chosen_by == "flights" == here.chosen_by and len(got.flights) == 5
    np.testing.assert_array_equal(got.cameras, here.cameras)
    assert got.flight_score == pytest.approx(here.flight_score)
    assert {pid for pid, _, _ in sim.flown} == {os.getpid()} and len(sim.flown) == 5
    assert sim.warmed == [(os.getpid(), 0)]  # the child's warm-up readied the caller's simulator, before any flight
    assert [(d, t) for d, t, _ in seen] == [(i, 5) for i in range(1, 6)]
    assert all(FLIGHT_CAPTURE_SEEDS[0] <= draw.capture_seed for _, _, draw in sim.flown)
    assert [s.draw for _, _, s in seen] == [draw for _, _, draw in sim.flown]
    assert not _plans()


def test_a_stop_during_the_flights_ends_the_plan_and_the_batch_at_once(scene) -> None:
    request = PlanRequest.of("egp", 4, evaluations=10, initial_evaluations=8, seed=1, sim_flights=4)
    sim = ParentSimulator(block=True)
    asked: list = []

    def should_stop() -> bool:
        if sim.flown and not asked:
            asked.append(time.monotonic())
        return bool(asked) and time.monotonic() - asked[0] > 0.5

    assert run_plan(request, scene, should_stop=should_stop, simulator=sim) is None
    took = time.monotonic() - asked[0]
    assert not _plans()
    deadline = time.monotonic() + 10.0  # the batch's thread sees the stop by itself
    while not sim.stopped and time.monotonic() < deadline:
        time.sleep(0.01)
    assert sim.stopped and took < 5.0, took
