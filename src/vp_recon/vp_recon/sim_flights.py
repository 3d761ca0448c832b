"""Simulated flights of plans over a prior scene: the reconstruction as the planner's expensive fidelity.

:func:`fly_plan` flies one plan (:mod:`vp_scene.flights` says what a simulated flight is): the
prior's plants displaced by the flight's own wind (``draw.n_wind``, a one-realization
:class:`vp_scene.wind.NoisyScene`), photographed under the capture model seeded by
``draw.capture_seed`` (soil, ground markers, hover and localization errors, sensor noise: what
:func:`vp_recon.pipeline.render_flight` gives every flight), reconstructed by
:func:`vp_recon.pipeline.reconstruct_captured` at the flight's setting and scored against the
displaced prior. A reconstruction that fails is a :class:`~vp_scene.flights.FlightScore` with its
error code and reason, never an exception.

:class:`SceneFlights` is the :class:`vp_scene.flights.FlightSimulator` of a prior scene: its
flights run in this process, one after the other, or on a Dask client (one flight a task,
:func:`vp_scene.cluster.open_client`: the local cluster or a user's scheduler). vp_recon offers
it under the entry point ``reconstruction`` of :data:`vp_scene.flights.ENTRY_POINTS`, which is
how the planner's CLI finds it without importing this package.
"""
from __future__ import annotations

import dataclasses
import time
from typing import Callable, Optional, Sequence

import numpy as np
from numpy.typing import NDArray

from vp_scene.capture import REALISTIC, CaptureModel
from vp_scene.flights import FlightDraw, FlightScore, FlightSettings, OnFlight
from vp_scene.wind import WindConfig, noisy_scene_of

from .config import ReconConfig
from .errors import UNKNOWN, ReconError

__all__ = ["fly_plan", "flight_config", "SceneFlights"]


def flight_config(settings: FlightSettings, capture: CaptureModel, draw: FlightDraw, fov: float,
                  mesh_cache: Optional[str] = None, ground: Optional[bool] = None) -> ReconConfig:
    """The reconstruction's settings of a flight: ``settings``' image size, SIFT octave and dense
    scale, ``capture`` seeded by the flight's draw, one thread (flights run side by side), no
    images kept; ``ground``: soil under the plants or the blue screen (None: by the capture)."""
    return ReconConfig(width=settings.width, height=settings.height, fov=fov,
                       sift_first_octave=settings.sift_first_octave, dense_scale=settings.dense_scale,
                       capture=dataclasses.replace(capture, seed=int(draw.capture_seed)), num_threads=1,
                       keep_images=False, mesh_cache=mesh_cache, ground=ground).validate()


def fly_plan(scene: object, wind: WindConfig, cameras: NDArray[np.float64], draw: FlightDraw,
             settings: FlightSettings = FlightSettings(), capture: CaptureModel = REALISTIC,
             fov: float = np.pi / 2, mesh_cache: Optional[str] = None, ground: Optional[bool] = None) -> FlightScore:
    """One simulated flight of ``cameras`` (N, 6) over ``scene`` (a :class:`vp_scene.scenario.Scene`)
    under ``draw`` (module docstring); its score, or its failure. ``ground``: the world under the
    plants (:class:`vp_recon.config.ReconConfig`: soil for a field, False for a rig's backdrop)."""
    from .pipeline import reconstruct_realization

    t0 = time.perf_counter()
    try:
        noisy = noisy_scene_of(scene, wind, [draw.n_wind], seed=draw.index)
        cfg = flight_config(settings, capture, draw, fov, mesh_cache, ground)
        res = reconstruct_realization(noisy, 0, np.asarray(cameras, dtype=np.float64), cfg)
    except ReconError as exc:
        return FlightScore(draw=draw, failed=True, error_code=int(exc.code), reason=str(exc),
                           seconds=time.perf_counter() - t0)
    except (ValueError, RuntimeError, MemoryError) as exc:  # a scene or plan the pipeline cannot take
        return FlightScore(draw=draw, failed=True, error_code=UNKNOWN, reason=f"{type(exc).__name__}: {exc}",
                           seconds=time.perf_counter() - t0)
    coverage = getattr(res.coverage, "fraction", None)
    return FlightScore(draw=draw, chamfer=float(res.chamfer), chamfer_shape=float(res.chamfer_shape),
                       coverage=None if coverage is None else float(coverage), images=int(res.images),
                       seconds=time.perf_counter() - t0)


@dataclasses.dataclass
class SceneFlights:
    """The :class:`vp_scene.flights.FlightSimulator` of a prior ``scene`` (a
    :class:`vp_scene.scenario.Scene`): ``wind`` gives the levels, variance and direction of the
    flights' winds (their n_wind values come with the draws), ``settings`` and ``capture`` how
    they are flown (``ground``: soil or the blue screen, :func:`fly_plan`); ``client``: a
    ``distributed.Client``, or a callable that gives one as a context manager for each batch (a
    Dask task's ``distributed.worker_client``, so that the task leaves its worker to the flights only
    while it waits for them), or None: in this process. ``workers`` is the number of flights flown at
    once (the cluster's workers, 1 in process)."""

    scene: object
    wind: WindConfig = dataclasses.field(default_factory=WindConfig)
    settings: FlightSettings = dataclasses.field(default_factory=FlightSettings)
    capture: CaptureModel = REALISTIC
    client: object = None
    fov: float = np.pi / 2
    mesh_cache: Optional[str] = None
    ground: Optional[bool] = None

    @property
    def wind_variance(self) -> float:
        return float(self.wind.variance)

    @property
    def workers(self) -> int:
        if self.client is None:
            return 1
        if callable(self.client):
            from distributed import get_client

            return max(1, len(get_client().scheduler_info().get("workers", {})))
        return max(1, len(self.client.scheduler_info().get("workers", {})))

    def fly(self, plans: Sequence[NDArray[np.float64]], draws: Sequence[FlightDraw],
            on_flight: Optional[OnFlight] = None, should_stop: Optional[Callable[[], bool]] = None
            ) -> list[FlightScore]:
        if len(plans) != len(draws):
            raise ValueError(f"{len(plans)} plans and {len(draws)} draws: one draw a plan")
        args = (self.settings, self.capture, self.fov, self.mesh_cache, self.ground)
        scores: list[Optional[FlightScore]] = [None] * len(plans)

        def done(i: int, score: FlightScore) -> None:
            scores[i] = score
            if on_flight is not None:
                on_flight(i, score)

        if self.client is None:
            for i, (cams, draw) in enumerate(zip(plans, draws)):
                if should_stop is not None and should_stop():
                    break
                done(i, fly_plan(self.scene, self.wind, cams, draw, *args))
        else:
            import contextlib

            from distributed import as_completed

            with (self.client() if callable(self.client) else contextlib.nullcontext(self.client)) as client:
                scene = client.scatter(self.scene, broadcast=True)
                futures = {client.submit(fly_plan, scene, self.wind, np.asarray(cams), draw, *args, pure=False): i
                           for i, (cams, draw) in enumerate(zip(plans, draws))}
                try:
                    for fut in as_completed(list(futures)):
                        done(futures[fut], fut.result())
                        if should_stop is not None and should_stop():
                            break
                finally:
                    client.cancel([f for f in futures if not f.done()])
        return [s if s is not None else FlightScore(draw=d, failed=True, error_code=UNKNOWN, reason="cancelled")
                for s, d in zip(scores, draws)]
