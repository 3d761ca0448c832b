"""vp_recon.sim_flights: the planner's simulated flights are real flights of the suite's world and
reconstruction, under the flight's own wind and capture draws, and a failure is a score."""
from __future__ import annotations

import math

import numpy as np

from vp_scene.flights import FlightDraw, FlightSettings, flight_draws

from vp_recon.sim_flights import SceneFlights, fly_plan

TARGET = np.array([0.0, 0.0, 0.9])
SMALL = FlightSettings(width=800, height=600, sift_first_octave=-1, dense_scale=1.0)


def arc(n: int, step_deg: float, radius: float = 1.6, height: float = 1.6) -> np.ndarray:
    a = np.deg2rad(step_deg * (np.arange(n) - (n - 1) / 2) - 90.0)
    c = np.stack([radius * np.cos(a), radius * np.sin(a), np.full(n, height)], axis=1)
    return np.concatenate([c, TARGET - c], axis=1)


def test_a_flight_is_scored_under_its_own_draw_and_a_bad_plan_is_a_scored_failure(noisy_scene, monkeypatch):
    """The flight's scene is the prior displaced by the draw's n_wind (not one of the scene's own
    realizations), its capture seeded by the draw; a plan whose cameras see nothing fails with the
    reconstruction's code and reason, no exception."""
    import vp_recon.pipeline as pipeline
    import vp_recon.tasks as tasks

    seen = []
    real = pipeline.reconstruct_realization
    released = []
    real_release = tasks.release_heap
    monkeypatch.setattr(tasks, "release_heap", lambda: released.append(len(seen)) or real_release())

    def spy(noisy, k, cams, cfg, *a, **kw):
        seen.append((np.asarray(noisy.n_wind).copy(), cfg.capture.seed, cfg.width, cfg.sift_first_octave))
        return real(noisy, k, cams, cfg, *a, **kw)

    monkeypatch.setattr(pipeline, "reconstruct_realization", spy)
    draw = flight_draws(5, 1, noisy_scene.config.variance)[0]
    score = fly_plan(noisy_scene.scene, noisy_scene.config, arc(4, 25.0), draw, SMALL)
    assert not score.failed, score.reason
    assert 0 < score.chamfer < 0.05 and 0 < score.chamfer_shape <= score.chamfer * 1.5 and score.images >= 3
    assert 0 < score.coverage <= 1 and score.seconds > 0 and score.draw == draw and score.value == score.chamfer
    (n_wind, capture_seed, width, octave), = seen
    assert list(n_wind) == [draw.n_wind] and draw.n_wind not in set(noisy_scene.n_wind)
    assert capture_seed == draw.capture_seed and (width, octave) == (800, -1)
    away = arc(3, 20.0)
    away[:, 3:] = -away[:, 3:]  # every camera looks away from the plant
    bad = fly_plan(noisy_scene.scene, noisy_scene.config, away, FlightDraw(1, 0.0, 2 ** 31 + 1), SMALL)
    assert bad.failed and bad.error_code == 4 and "plant" in bad.reason and bad.value == math.inf
    assert released == [1, 2]  # after each flight, the failed one too: the heap it freed given back


def test_the_heap_a_reconstruction_freed_goes_back_to_the_system():
    """Freed blocks between blocks still in use stay in the process (glibc keeps them) until
    :func:`vp_recon.tasks.release_heap` returns their pages."""
    from vp_recon.tasks import release_heap

    def rss() -> int:
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[1]) * 4096

    release_heap()
    start = rss()
    blocks = [bytearray(64 * 1024) for _ in range(4000)]  # 262 MB from the heap (below mmap's threshold)
    kept = blocks[::50]  # a block in use every 3 MB: no free run at the heap's top to trim
    del blocks
    held = rss()
    release_heap()
    assert held - start > 200e6 and held - rss() > 150e6, (start, held, rss())
    assert len(kept) == 80


def test_the_simulator_flies_a_batch_in_order_and_stops_when_asked(noisy_scene):
    sim = SceneFlights(noisy_scene.scene, noisy_scene.config, SMALL)
    assert sim.workers == 1 and sim.wind_variance == noisy_scene.config.variance
    draws = flight_draws(0, 2, sim.wind_variance)
    got = []
    scores = sim.fly([arc(3, 25.0), arc(3, 25.0)], draws, on_flight=lambda i, s: got.append(i),
                     should_stop=lambda: len(got) >= 1)
    assert got == [0] and not scores[0].failed and scores[0].draw == draws[0]
    assert scores[1].failed and scores[1].reason == "cancelled" and scores[1].draw == draws[1]


def test_the_workers_are_readied_for_the_flights_one_warm_up_a_worker(noisy_scene):
    """warm_up: one task on every worker of the client, returned at once, which makes the
    renderer's context at the flight's size there (a size no other test renders at); in process,
    nothing."""
    from distributed import Client, LocalCluster

    from vp_scene import render

    odd = FlightSettings(width=336, height=252, sift_first_octave=-1, dense_scale=1.0)
    assert SceneFlights(noisy_scene.scene, noisy_scene.config, odd).warm_up() == []
    assert (336, 252) not in render._CONTEXTS
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        sim = SceneFlights(noisy_scene.scene, noisy_scene.config, odd, client=client)
        tasks = sim.warm_up()
        assert len(tasks) == 2 and all(s > 0 for s in client.gather(tasks))
        ran_on = sorted(w for t in tasks for w in client.who_has(t)[t.key])
        assert ran_on == sorted(client.scheduler_info()["workers"])  # one a worker
    assert (336, 252) in render._CONTEXTS  # the workers are threads of this process here


def test_a_batch_given_flat_is_read_into_plans_and_draws_and_a_bad_one_is_named():
    """The SimulateFlights goal's form: 6 numbers a camera plan after plan, one count, index, wind
    and capture seed a plan; a capture seed an evaluation could have (below 2^31) is refused."""
    import pytest

    from vp_recon.sim_flights import flight_batch

    a, b = arc(3, 25.0), arc(4, 20.0)
    flat = np.concatenate([a.ravel(), b.ravel()])
    plans, draws = flight_batch(flat, [3, 4], [0, 1], [0.01, -0.02], [2 ** 31, 2 ** 32 - 1])
    np.testing.assert_array_equal(plans[0], a)
    np.testing.assert_array_equal(plans[1], b)
    assert draws == [FlightDraw(0, 0.01, 2 ** 31), FlightDraw(1, -0.02, 2 ** 32 - 1)]
    for args, text in [
        ((flat, [], [], [], []), "cameras_per_plan has 0 plans, must have 1 to 200"),
        ((flat, [3, 4], [0], [0.0, 0.0], [2 ** 31] * 2), "flight_indices has 1 values for 2 plans"),
        ((flat, [3, 3], [0, 1], [0.0, 0.0], [2 ** 31] * 2), "cameras has 42 numbers"),
        ((flat, [1, 6], [0, 1], [0.0, 0.0], [2 ** 31] * 2), r"cameras_per_plan\[0\] is 1, must be in \[2, "),
        ((flat, [3, 4], [0, 1], [0.0, 0.0], [2 ** 31, 7]), r"capture_seeds\[1\] is 7, must be in \[2147483648, "),
        ((flat, [3, 4], [0, 1], [0.0, math.nan], [2 ** 31] * 2), r"n_wind\[1\] is nan"),
        ((np.where(np.arange(42) == 5, np.nan, flat), [3, 4], [0, 1], [0.0, 0.0], [2 ** 31] * 2), "non-finite"),
    ]:
        with pytest.raises(ValueError, match=text):
            flight_batch(*args)
