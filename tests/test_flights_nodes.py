"""The planner's simulated flights through the recon node (real scene, planner and recon processes
over DDS): the planner's planning process asks, the planner node flies the batches on the recon
node's ``/simulate_flights`` (one flight a Dask task on its local cluster), the flights choose.

Small on purpose: one plant of 600 points, egp's cheap stage of 10 evaluations, flights of 640 x
480 views (SIFT's doubled first octave: fewer pixels leave too few keypoints), batches of two flights
on one worker (a worker's first flight pays its start: imports, the renderer's soil textures).
"""
from __future__ import annotations

import math
import time

import pytest

from action_msgs.msg import GoalStatus
from rclpy.action import ActionClient
from vp_interfaces.action import PlanViews, SimulateFlights

from vp_scene.build import build_noisy_scene
from vp_scene.flights import FLIGHT_CAPTURE_SEEDS

from test_planner_node import SCENE, TIMEOUT, send, wait_for_server

#: The flights' setting, as planner parameters: batches of two.
FLIGHTS = {"flight_width": 640, "flight_height": 480, "flight_sift_octave": -1, "flight_dense_scale": 0.5,
           "flight_workers": 2}
#: The recon node: flights on a local cluster of one worker (a batch's second flight is still flying
#: when its first is back); the plan published afterwards is reconstructed cheaply (not tested here).
RECON = {"scheduler": "local", "workers": 1, "width": 320, "height": 240, "dense": False, "max_realizations": 1}


def egp(sim_flights: int, seed: int = 1) -> PlanViews.Goal:
    return PlanViews.Goal(num_cameras=4, method="egp", evaluations=10, initial_evaluations=8, seed=seed,
                          sim_flights=sim_flights)


def test_the_flights_choose_through_the_recon_node_and_a_cancel_stops_them(ros_env, start_node, ros_node,
                                                                           tmp_path) -> None:
    """The plan is chosen by its flights, each flown by the recon node under the planner's own
    draws (capture seeds from 2^31 up, winds that are none of the scene's), with feedback after
    every flight; then a goal cancelled during its flights is answered at once, and the recon
    node's batch is cancelled too."""
    start_node("vp_scene", "scene", SCENE, ros_env)
    recon = start_node("vp_recon", "recon", {**RECON, "output_folder": str(tmp_path / "recon")}, ros_env)
    planner = start_node("vp_planner", "planner", FLIGHTS, ros_env)
    client = ros_node(ros_env)
    action = ActionClient(client.node, PlanViews, "/plan_views")
    flights_server = ActionClient(client.node, SimulateFlights, "/simulate_flights")
    assert client.spin_until(lambda: "scene received" in planner.output(), TIMEOUT), planner.output()
    assert client.spin_until(flights_server.server_is_ready, TIMEOUT), recon.output()
    wait_for_server(client, action, planner)

    feedback: list = []
    _, res = send(client, action, egp(2), feedback)
    r = res.result
    assert r.error_code == PlanViews.Result.NONE, r.error_msg
    assert r.chosen_by == "flights" and r.flights_note == "", (r.chosen_by, r.flights_note, planner.output()[-3000:])
    assert sorted(f.source for f in r.flights) == ["arc", "circle"]  # the patterns first, always
    winds = set(build_noisy_scene(**SCENE)[0].n_wind)
    for f in r.flights:  # the planner's own draws, never an evaluation's
        assert FLIGHT_CAPTURE_SEEDS[0] <= f.capture_seed < FLIGHT_CAPTURE_SEEDS[1] and f.n_wind not in winds
    ok = [f for f in r.flights if not f.failed]
    assert ok and all(0 < f.chamfer < 0.5 and f.images >= 2 and f.seconds > 0 for f in ok)
    assert r.flight_score == pytest.approx(min(f.chamfer for f in ok))  # one flight a plan: the best one's
    flown = [f for f in feedback if f.flights_total]
    assert [f.flights_done for f in flown] == [1, 2] and {f.flights_total for f in flown} == {2}
    assert [f.last_flight_chamfer for f in flown] == pytest.approx(  # in the order they came back
        [math.nan if f.failed else f.chamfer for f in r.flights], nan_ok=True)
    assert flown[0].evaluations_done == 10  # the evaluations first, then the flights
    assert "simulated flight 2/2: map Chamfer" in planner.output()
    assert "flying 2 plans" in recon.output() and "simulated flight 2/2 (plan" in recon.output()
    # the planner asked the recon node to ready its worker as the cheap stage began, before the flights
    out = recon.output()
    assert "readying 1 flight worker(s) for 640x480 flights" in out, out[-3000:]
    assert out.index("readying 1 flight worker(s)") < out.index("flying 2 plans")

    feedback.clear()
    handle = client.spin_future(action.send_goal_async(egp(2, seed=2), feedback_callback=lambda fb: feedback.append(
        fb.feedback)), TIMEOUT)
    assert handle.accepted
    assert client.spin_until(lambda: any(f.flights_done >= 1 for f in feedback), 240.0), planner.output()[-3000:]
    client.spin_future(handle.cancel_goal_async(), TIMEOUT)
    t0 = time.monotonic()
    res = client.spin_future(handle.get_result_async(), 30.0)
    took = time.monotonic() - t0
    assert res.status == GoalStatus.STATUS_CANCELED and res.result.error_code == PlanViews.Result.CANCELED
    assert "simulated flights" in res.result.error_msg and took < 10.0, (took, res.result.error_msg)
    assert client.spin_until(lambda: "simulated flights cancelled" in recon.output(), TIMEOUT), recon.output()[-3000:]
    assert planner.alive() and recon.alive()


def test_without_a_recon_node_the_plan_is_made_without_flights_and_says_so(ros_env, start_node, ros_node) -> None:
    start_node("vp_scene", "scene", SCENE, ros_env)
    planner = start_node("vp_planner", "planner", {"flight_server_timeout": 1.0}, ros_env)
    client = ros_node(ros_env)
    action = ActionClient(client.node, PlanViews, "/plan_views")
    assert client.spin_until(lambda: "scene received" in planner.output(), TIMEOUT), planner.output()
    wait_for_server(client, action, planner)
    _, res = send(client, action, PlanViews.Goal(num_cameras=3, method="circle", evaluations=6, sim_flights=3))
    r = res.result
    assert r.error_code == PlanViews.Result.NONE and len(r.plan.poses) == 3, r.error_msg
    assert r.chosen_by == "reward" and not r.flights and math.isnan(r.flight_score)
    assert "/simulate_flights is not served" in r.flights_note, r.flights_note
    assert "/simulate_flights is not served" in planner.output()
