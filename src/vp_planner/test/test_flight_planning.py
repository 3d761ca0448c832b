"""Planning with two fidelities (vp_planner.flight_planning): the cheap reward proposes, simulated
flights choose. A fake simulator stands in for the reconstruction here (its score a known function
of the plan); the real one is tested in vp_recon's test_sim_flights."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vp_scene.build import build_noisy_scene
from vp_scene.flights import FLIGHT_CAPTURE_SEEDS, FlightScore
from vp_scene.wind import draw_n_wind

from vp_planner.flight_planning import plan_distance
from vp_planner.optimizers import plan_views
from vp_planner.request import InvalidRequestError, PlanRequest


class FakeSimulator:
    """Scores a plan by the mean height of its cameras (lower is better here), fails plans whose
    first camera is south of the plant; records every plan and draw it was asked to fly."""

    def __init__(self, workers: int = 2, fail_all: bool = False, stop_after: int = 0) -> None:
        self.workers, self.wind_variance = workers, 0.002
        self.flown, self.fail_all, self.stop_after = [], fail_all, stop_after
        self.batches, self.warmed = [], []

    def warm_up(self):
        self.warmed.append(len(self.flown))

    def fly(self, plans, draws, on_flight=None, should_stop=None):
        self.batches.append(len(plans))
        out = []
        for i, (cams, draw) in enumerate(zip(plans, draws)):
            self.flown.append((np.asarray(cams).copy(), draw))
            if self.fail_all:
                s = FlightScore(draw=draw, failed=True, error_code=5, reason="nothing matched")
            else:
                s = FlightScore(draw=draw, chamfer=float(np.mean(cams[:, 2])) / 100, chamfer_shape=0.01, images=len(cams))
            out.append(s)
            if on_flight is not None:
                on_flight(i, s)
        return out


@pytest.fixture(scope="module")
def noisy():
    return build_noisy_scene("one_plant", seed=0, points_per_plant=800, realizations=3)[0]


def request(**kw):
    return PlanRequest.of("egp", 3, evaluations=16, initial_evaluations=8, seed=1, **kw)


def test_the_flights_choose_the_patterns_are_always_flown_and_the_draws_are_the_planners(noisy):
    sim = FakeSimulator()
    seen = []
    res = plan_views(request(sim_flights=7), noisy.points, simulator=sim,
                     on_flight=lambda done, total, score: seen.append((done, total)))
    assert res.chosen_by == "flights" and len(res.flights) == 7 == len(sim.flown)
    assert seen == [(i, 7) for i in range(1, 8)]
    sources = [r["source"] for r in res.flights]
    assert sources[:3] == ["circle", "arc", "structured"]  # the patterns first, always
    assert sim.warmed == [0]  # readied once, before any flight (while the cheap stage computed)
    assert sim.batches == [5, 2]  # the pool in one batch (no worker waits for the other's flight), then the confirmation
    flown = {i: [r for r in res.flights if r["plan"] == i] for i in {r["plan"] for r in res.flights}}
    most = max(len(rs) for rs in flown.values())
    scores = {i: np.mean([r["chamfer"] for r in rs]) for i, rs in flown.items()}
    best = min((i for i in scores if len(flown[i]) == most), key=scores.get)  # the best confirmed plan
    single = [r["chamfer"] for r in res.flights[:-2]]  # the first pass: one flight a plan
    assert sorted(r["plan"] for r in res.flights[-2:]) == sorted(np.argsort(single)[:2])  # its two best re-flown
    np.testing.assert_array_equal(res.cameras, np.asarray(res.flight_plans[best]["cameras"]))
    assert math.isclose(res.flight_score, scores[best]) and res.reward == res.flight_plans[best]["reward"]
    assert any(len(rs) > 1 for rs in flown.values())  # the confirmation flew the best plans again
    # every draw is the planner's own: its capture seeds above any evaluation's, its winds not the scene's
    for _cams, draw in sim.flown:
        assert FLIGHT_CAPTURE_SEEDS[0] <= draw.capture_seed < FLIGHT_CAPTURE_SEEDS[1]
        assert draw.n_wind not in set(noisy.n_wind) and draw.n_wind not in set(draw_n_wind(noisy.config, 0))
    assert len({d.index for _c, d in sim.flown}) == 7
    # the pool's plans differ (cameras matched one to one)
    plans = [np.asarray(p["cameras"]) for p in res.flight_plans]
    assert all(plan_distance(a, b) > 0 for k, a in enumerate(plans) for b in plans[k + 1:])


def test_without_a_simulator_or_flights_the_cheap_reward_chooses_as_before(noisy):
    """No simulator: the cheap reward's plan, bit for bit the plan of sim_flights 0, and a note."""
    base = plan_views(request(sim_flights=0), noisy.points)
    alone = plan_views(request(), noisy.points)
    assert alone.flights_note.startswith("no flight simulator") and base.flights_note == ""
    np.testing.assert_array_equal(base.cameras, alone.cameras)
    assert base.chosen_by == alone.chosen_by == "reward" and base.flights is None


def test_failed_flights_are_scored_failures_and_every_failure_leaves_the_cheap_choice(noisy):
    res = plan_views(request(sim_flights=4), noisy.points, simulator=FakeSimulator(fail_all=True))
    assert len(res.flights) == 4 and all(r["failed"] and r["reason"] == "nothing matched" for r in res.flights)
    assert res.chosen_by == "reward" and res.flight_score is None and "every simulated flight failed" in res.flights_note
    assert res.reward == max(p["reward"] for p in res.flight_plans)


def test_a_cancel_during_the_flights_stops_the_run(noisy):
    calls = []

    def stop() -> bool:
        return len(calls) >= 2

    res = plan_views(request(sim_flights=8), noisy.points, should_stop=stop, simulator=FakeSimulator(),
                     on_flight=lambda *a: calls.append(a))
    assert res.stopped and res.chosen_by == "reward" and res.flights is None


def test_the_flight_fields_are_checked_and_round_trip():
    r = request(sim_flights=5, flight_width=800, flight_height=600, flight_sift_octave=-1, flight_dense_scale=0.7)
    assert PlanRequest.from_dict(r.as_dict()) == r and r.flights.settings().width == 800
    assert PlanRequest.of("egp", 3).flights.flights_of("egp") == 12
    assert PlanRequest.of("arc", 3).flights.flights_of("arc") == 0
    for bad in ({"sim_flights": -2}, {"sim_flights": 10 ** 6}, {"flight_width": 0}, {"flight_dense_scale": 2.0},
                {"flight_sift_octave": 2}):
        with pytest.raises(InvalidRequestError):
            request(**bad)


def test_among_candidates_the_flights_choose_a_subset_and_name_it(noisy):
    """Among candidate views the patterns are the evenly spaced and the neighbouring subsets; the
    flights' choice comes back as its candidates' indices, its cameras in their order."""
    a = np.deg2rad(np.arange(0, 360, 20.0))
    c = np.stack([1.6 * np.cos(a), 1.6 * np.sin(a), 1.0 + 0.4 * (np.arange(len(a)) % 3)], axis=1)
    cands = np.concatenate([c, np.array([0.0, 0.0, 0.9]) - c], axis=1)
    sim = FakeSimulator()
    res = plan_views(PlanRequest.of("egp", 4, evaluations=16, initial_evaluations=8, seed=1, candidates=cands,
                                    sim_flights=6), noisy.points, simulator=sim)
    assert res.chosen_by == "flights" and [r["source"] for r in res.flights[:2]] == ["circle", "arc"]
    assert len(res.selected) == 4 and len(set(res.selected)) == 4
    np.testing.assert_allclose(res.cameras, cands[res.selected])
    chosen = [p for p in res.flight_plans if sorted(map(tuple, np.round(p["cameras"], 9))) ==
              sorted(map(tuple, np.round(res.cameras, 9)))]
    assert chosen and chosen[0]["score"] == res.flight_score
