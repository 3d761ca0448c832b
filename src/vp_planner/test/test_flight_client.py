"""The planner node's flight simulator over /simulate_flights (vp_planner.flight_client), against a
stand-in action client (the real recon node: tests/test_flights_nodes.py): what the server answers
becomes one score a plan, every flight handed on once, and nothing it meets is an exception."""
from __future__ import annotations

import math
import threading
import time

import numpy as np
import pytest
from rclpy.task import Future

from vp_interfaces.action import SimulateFlights
from vp_scene.flights import FlightScore, FlightSettings, flight_draws
from vp_scene.messages import flight_msg

from vp_planner.flight_client import ActionFlights

SETTINGS = FlightSettings(width=640, height=480, sift_first_octave=-1, dense_scale=0.5)


def done(value) -> Future:
    f = Future()
    f.set_result(value)
    return f


class Handle:
    def __init__(self, accepted: bool, result: Future) -> None:
        self.accepted, self.result, self.cancelled = accepted, result, False

    def get_result_async(self) -> Future:
        return self.result

    def cancel_goal_async(self) -> Future:
        self.cancelled = True
        return done(None)


class Client:
    """An ActionClient of SimulateFlights whose server answers ``answer(goal) -> (accepted, result,
    feedback)``; ``ready``: server_is_ready(); ``answers``: False loses the goal's acceptance (its
    feedback still comes; the result is asked for by the goal's id, as rclpy's handles do)."""

    def __init__(self, answer, ready=True, answers=True) -> None:
        self.answer, self.ready, self.answers, self.goals, self.handles = answer, ready, answers, [], []
        self.result_requests = 0

    def server_is_ready(self) -> bool:
        return self.ready

    def send_goal_async(self, goal, feedback_callback=None, goal_uuid=None) -> Future:
        self.goals.append(goal)
        accepted, result, feedback = self.answer(goal)
        for fb in feedback:
            msg = SimulateFlights.Impl.FeedbackMessage()
            msg.feedback = fb
            feedback_callback(msg)
        self.handles.append(Handle(accepted, result))
        return done(self.handles[-1]) if self.answers else Future()

    def _get_result_async(self, _handle) -> Future:  # rclpy's ClientGoalHandle.get_result_async
        self.result_requests += 1
        return self.handles[-1].result

    def _cancel_goal_async(self, _handle) -> Future:
        self.handles[-1].cancelled = True
        return done(None)


def sim(client) -> ActionFlights:
    return ActionFlights(client, SETTINGS, 0.02, 0.5, True, math.pi / 2, workers=2, wind_variance=0.002)


def plans(n: int) -> list:
    return [np.full((3, 6), float(i + 1)) for i in range(n)]


def scored(goal, i: int, chamfer: float):
    draws = flight_draws(0, len(goal.cameras_per_plan), 0.002)
    return flight_msg(FlightScore(draw=draws[i], chamfer=chamfer, chamfer_shape=chamfer / 2, images=3), i)


def test_the_goal_carries_the_batch_and_a_flight_comes_once_from_feedback_or_result() -> None:
    """Plan 1's feedback arrives, plan 0's is lost: both are handed on once, from the feedback or
    else from the result, and the scores come back in the plans' order."""
    def answer(goal):
        result = SimulateFlights.Result(flights=[scored(goal, 0, 0.03), scored(goal, 1, 0.02)])
        return True, done(SimulateFlights.Impl.GetResultService.Response(result=result)), [
            SimulateFlights.Feedback(flights_done=1, flights_total=2, last=scored(goal, 1, 0.02))]

    client, got = Client(answer), []
    draws = flight_draws(0, 2, 0.002)
    scores = sim(client).fly(plans(2), draws, on_flight=lambda i, s: got.append((i, s.chamfer)))
    goal = client.goals[0]
    assert list(goal.cameras_per_plan) == [3, 3] and len(goal.cameras) == 36 and goal.cameras[18] == 2.0
    assert list(goal.capture_seeds) == [d.capture_seed for d in draws] and (goal.width, goal.height) == (640, 480)
    assert goal.ground_control and goal.fov == pytest.approx(math.pi / 2) and goal.sift_first_octave == -1
    assert got == [(1, 0.02), (0, 0.03)]
    assert [s.chamfer for s in scores] == [0.03, 0.02] and [s.draw for s in scores] == draws


def test_the_warm_up_sends_the_setting_with_no_plans_and_nothing_without_a_server() -> None:
    """warm_up: one goal with no plans and no cameras at the flights' setting (the recon node
    readies its workers for it), never waited for; with no server, nothing sent."""
    client = Client(lambda goal: (True, Future(), []))
    sim(client).warm_up()
    goal, = client.goals
    assert list(goal.cameras_per_plan) == [] and list(goal.cameras) == [] and list(goal.capture_seeds) == []
    assert (goal.width, goal.height, goal.sift_first_octave) == (640, 480, -1) and goal.ground_control
    assert goal.fov == pytest.approx(math.pi / 2) and client.result_requests == 0
    gone = Client(lambda goal: (True, Future(), []), ready=False)
    sim(gone).warm_up()
    assert gone.goals == []


def test_a_refused_goal_makes_scored_failures_and_the_cheap_reward_chooses(tmp_path) -> None:
    """The recon node flies one batch at a time: a refused batch is a failure a flight, each
    handed to the flight stage, which ends without an exception."""
    from vp_scene.build import build_noisy_scene

    from vp_planner.optimizers import plan_views
    from vp_planner.request import PlanRequest

    client = Client(lambda goal: (False, Future(), []))
    got = []
    scores = sim(client).fly(plans(2), flight_draws(0, 2, 0.002), on_flight=lambda i, s: got.append(i))
    assert sorted(got) == [0, 1] and all(s.failed and "refused" in s.reason for s in scores)
    points = build_noisy_scene("one_plant", points_per_plant=300, realizations=2, seed=0)[0].points
    res = plan_views(PlanRequest.of("circle", 3, evaluations=4, sim_flights=4), points, simulator=sim(client))
    assert res.chosen_by == "reward" and len(res.flights) == 4 and "every simulated flight failed" in res.flights_note


def test_a_stop_cancels_the_goal_and_a_lost_server_fails_the_flights_not_back(monkeypatch) -> None:
    import vp_planner.flight_client as fc

    pending = Future()  # a result that never comes
    client = Client(lambda goal: (True, pending, []))
    stop = threading.Event()
    threading.Timer(0.3, stop.set).start()
    scores = sim(client).fly(plans(2), flight_draws(0, 2, 0.002), should_stop=stop.is_set)
    assert client.handles[0].cancelled and all(s.failed and s.reason == "cancelled" for s in scores)
    assert sim(client).fly(plans(1), flight_draws(0, 1, 0.002), should_stop=lambda: True)[0].reason == "cancelled"
    assert len(client.goals) == 1  # a stop seen first: nothing sent

    monkeypatch.setattr(fc, "LOST_S", 0.2)
    client.ready = False
    t0 = time.monotonic()
    scores = sim(client).fly(plans(2), flight_draws(0, 2, 0.002))
    assert all(s.failed and "went away" in s.reason for s in scores) and time.monotonic() - t0 < 30


def test_a_lost_acceptance_is_known_by_the_feedback_and_a_lost_result_by_every_flight_back(monkeypatch) -> None:
    """The goal's acceptance never comes, its feedback does (the batch's start, then a flight):
    the result is asked for by the goal's id; a result that never comes either is not waited for
    once every flight is back by feedback; a goal with no answer at all is given up."""
    import vp_planner.flight_client as fc

    monkeypatch.setattr(fc, "RESULT_GRACE_S", 0.2)
    monkeypatch.setattr(fc, "RESULT_AGAIN_S", 0.1)
    monkeypatch.setattr(fc, "ANSWER_S", 0.3)

    def answer(goal, result=None):
        fb = [SimulateFlights.Feedback(flights_done=0, flights_total=1),
              SimulateFlights.Feedback(flights_done=1, flights_total=1, last=scored(goal, 0, 0.04))]
        return True, result if result is not None else Future(), fb

    client = Client(lambda goal: answer(goal, done(SimulateFlights.Impl.GetResultService.Response(
        result=SimulateFlights.Result(flights=[scored(goal, 0, 0.04)])))), answers=False)
    got = []
    scores = sim(client).fly(plans(1), flight_draws(0, 1, 0.002), on_flight=lambda i, s: got.append(i))
    assert got == [0] and scores[0].chamfer == 0.04 and client.result_requests == 1
    client = Client(answer, answers=False)  # neither acceptance nor result: the feedback had every flight
    scores = sim(client).fly(plans(1), flight_draws(0, 1, 0.002))
    assert scores[0].chamfer == 0.04 and client.result_requests >= 2  # asked again meanwhile
    client = Client(lambda goal: (True, Future(), []), answers=False)  # nothing at all
    scores = sim(client).fly(plans(1), flight_draws(0, 1, 0.002))
    assert scores[0].failed and "did not answer" in scores[0].reason
