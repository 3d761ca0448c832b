"""vp_scene.flights: the simulated flights' settings, draws and scores."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vp_scene.build import build_noisy_scene
from vp_scene.flights import (FLIGHT_CAPTURE_SEEDS, FlightDraw, FlightScore, FlightSettings, flight_draws,
                              load_simulator)
from vp_scene.wind import WindConfig, draw_n_wind, noisy_scene_of


def test_draws_are_reproducible_their_own_and_never_an_evaluations():
    """A run's flights draw from a stream of their own: the same seed gives the same draws, the
    draws of flights j are those of flight j whatever the batch, and no wind of the scene's own
    realizations (the evaluation's, of any seed 0..49) and no capture seed an evaluation may use
    (below 2^31) is among them."""
    a = flight_draws(0, 12, 0.002)
    assert a == flight_draws(0, 12, 0.002) and a[5:] == flight_draws(0, 7, 0.002, start=5)
    assert [d.index for d in a] == list(range(12))
    assert flight_draws(1, 12, 0.002) != a
    winds = np.concatenate([draw_n_wind(WindConfig(realizations=20), s) for s in range(50)])
    for d in a + flight_draws(1, 12, 0.002):
        assert FLIGHT_CAPTURE_SEEDS[0] <= d.capture_seed < FLIGHT_CAPTURE_SEEDS[1]
        assert not np.any(np.isclose(winds, d.n_wind, rtol=0, atol=1e-12))
    sd = np.std([d.n_wind for d in flight_draws(3, 400, 0.002)])
    assert abs(sd - math.sqrt(0.002)) < 0.15 * math.sqrt(0.002)
    assert all(d.n_wind == 0 for d in flight_draws(0, 3, 0.0))
    for bad in ((-1, 3, 0.002), (0, 3, float("nan"))):
        with pytest.raises(ValueError):
            flight_draws(*bad)


def test_settings_are_checked_and_a_score_round_trips():
    FlightSettings(640, 480, -1, 1.0)
    for kw in ({"width": 0}, {"height": 100000}, {"sift_first_octave": 1}, {"dense_scale": 0.0},
               {"dense_scale": float("nan")}, {"width": True}):
        with pytest.raises(ValueError):
            FlightSettings(**kw)
    d = FlightDraw(3, 0.01, 2 ** 31 + 5)
    s = FlightScore(draw=d, chamfer=0.02, chamfer_shape=0.015, coverage=0.8, images=4, seconds=3.0)
    assert s.value == 0.02 and FlightScore.from_dict(s.to_dict()) == s
    failed = FlightScore(draw=d, failed=True, error_code=5, reason="no pair")
    assert failed.value == math.inf and FlightScore.from_dict(failed.to_dict()) == failed


def test_the_installed_simulator_is_found_by_its_entry_point():
    """vp_recon offers its simulator under the entry point; an unknown name is one clear error."""
    from vp_scene.flights import FlightSimulatorMissing

    cls = load_simulator()
    assert cls.__name__ == "SceneFlights" and cls.__module__ == "vp_recon.sim_flights"
    with pytest.raises(FlightSimulatorMissing, match="--sim-flights 0"):
        load_simulator("no-such-simulator")


def test_a_scene_under_given_winds_is_the_scenes_own_displacement():
    noisy, _ = build_noisy_scene("one_plant", seed=0, points_per_plant=500, realizations=3)
    again = noisy_scene_of(noisy.scene, noisy.config, noisy.n_wind, noisy.seed)
    np.testing.assert_array_equal(again.points, noisy.points)
    one = noisy_scene_of(noisy.scene, noisy.config, [0.05], 7)
    assert one.points.shape == (1,) + noisy.points.shape[1:] and one.config.realizations == 1
    with pytest.raises(ValueError):
        noisy_scene_of(noisy.scene, noisy.config, [], 0)
