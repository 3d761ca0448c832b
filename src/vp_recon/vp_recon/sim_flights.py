"""Simulated flights of plans over a prior scene: the reconstruction as the planner's expensive fidelity.

:func:`fly_plan` flies one plan (:mod:`vp_scene.flights` says what a simulated flight is): the
prior's plants displaced by the flight's own wind (``draw.n_wind``, a one-realization
:class:`vp_scene.wind.NoisyScene`), photographed under the capture model seeded by
``draw.capture_seed`` (soil, ground markers, hover and localization errors, sensor noise: what
:func:`vp_recon.pipeline.render_flight` gives every flight), reconstructed by
:func:`vp_recon.pipeline.reconstruct_captured` at the flight's setting and scored against the
displaced prior. A reconstruction that fails is a :class:`~vp_scene.flights.FlightScore` with its
error code and reason, never an exception. The heap a flight freed goes back to the system
(:func:`vp_recon.tasks.release_heap`).

:class:`SceneFlights` is the :class:`vp_scene.flights.FlightSimulator` of a prior scene: its
flights run in this process, one after the other, or on a Dask client (one flight a task,
:func:`vp_scene.cluster.open_client`: the local cluster or a user's scheduler). vp_recon offers
it under the entry point ``reconstruction`` of :data:`vp_scene.flights.ENTRY_POINTS`, which is
how the planner's CLI finds it without importing this package. On a cluster a batch's flights come
back as they finish, ``should_stop`` is looked at every :data:`POLL_S` meanwhile, and a task that
ends in an exception is a scored failure. :func:`flight_batch` reads a batch given flat (the recon
node's ``SimulateFlights`` goal) into plans and draws.
"""
from __future__ import annotations

import contextlib
import dataclasses
import math
import time
from typing import Callable, Optional, Sequence

import numpy as np
from numpy.typing import NDArray

from vp_scene.capture import REALISTIC, CaptureModel
from vp_scene.flights import FLIGHT_CAPTURE_SEEDS, MAX_FLIGHTS, FlightDraw, FlightScore, FlightSettings, OnFlight
from vp_scene.wind import WindConfig, noisy_scene_of

from .config import MAX_CAMERAS, ReconConfig
from .errors import UNKNOWN, ReconError

__all__ = ["fly_plan", "warm_worker", "flight_config", "flight_batch", "SceneFlights", "POLL_S"]

#: s between two looks at ``should_stop`` (and at the flights done) while a batch flies on a cluster.
POLL_S = 0.1


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
    from .tasks import release_heap

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
    finally:  # flights follow each other in one process (a Dask worker's, the planner's)
        release_heap()
    coverage = getattr(res.coverage, "fraction", None)
    return FlightScore(draw=draw, chamfer=float(res.chamfer), chamfer_shape=float(res.chamfer_shape),
                       coverage=None if coverage is None else float(coverage), images=int(res.images),
                       seconds=time.perf_counter() - t0)


def warm_worker(scene: object, wind: WindConfig, settings: FlightSettings = FlightSettings(),
                capture: CaptureModel = REALISTIC, fov: float = np.pi / 2) -> float:
    """Ready this process for the flights of ``scene``: the reconstruction's modules imported and
    the renderer's context at the flight's size set up with the soil under the prior
    (:func:`vp_scene.sim_drone.warm_up`: the windless prior photographed once, nothing kept),
    which a process's first flight would otherwise spend before its own work. The seconds it
    took. A warm-up that fails is ignored: the flights meet and score whatever made it fail."""
    from vp_scene.sim_drone import warm_up

    from . import pipeline  # noqa: F401 - imported for the flights (pycolmap, Open3D, OpenCV)
    from .tasks import release_heap

    t0 = time.perf_counter()
    try:
        warm_up(noisy_scene_of(scene, wind, [0.0], seed=0), capture, settings.width, settings.height, fov)
    except (ValueError, RuntimeError, MemoryError):  # a RenderError is a RuntimeError
        pass
    finally:
        release_heap()
    return time.perf_counter() - t0


def flight_batch(cameras: Sequence[float], cameras_per_plan: Sequence[int], indices: Sequence[int],
                 n_wind: Sequence[float], capture_seeds: Sequence[int], max_cameras: int = MAX_CAMERAS
                 ) -> tuple[list[NDArray[np.float64]], list[FlightDraw]]:
    """The plans (each (N_i, 6)) and draws of a batch given flat (the ``SimulateFlights`` goal's
    form: 6 numbers a camera, plan after plan, and one count, flight index, n_wind and capture seed
    a plan); ValueError naming the first bad field: 1 to :data:`vp_scene.flights.MAX_FLIGHTS`
    plans, 2..``max_cameras`` finite
    cameras a plan, the counts summing to the cameras, finite winds, capture seeds in
    :data:`vp_scene.flights.FLIGHT_CAPTURE_SEEDS` (never an evaluation's)."""
    flat = np.asarray(cameras, dtype=np.float64).ravel()
    counts = [int(n) for n in cameras_per_plan]
    if not 1 <= len(counts) <= MAX_FLIGHTS:
        raise ValueError(f"cameras_per_plan has {len(counts)} plans, must have 1 to {MAX_FLIGHTS}")
    for name, values in (("flight_indices", indices), ("n_wind", n_wind), ("capture_seeds", capture_seeds)):
        if len(values) != len(counts):
            raise ValueError(f"{name} has {len(values)} values for {len(counts)} plans: one a plan")
    for i, n in enumerate(counts):
        if not 2 <= n <= max_cameras:
            raise ValueError(f"cameras_per_plan[{i}] is {n}, must be in [2, {max_cameras}]")
    if flat.size != 6 * sum(counts):
        raise ValueError(f"cameras has {flat.size} numbers, cameras_per_plan asks for 6 x {sum(counts)}")
    if not np.all(np.isfinite(flat)):
        raise ValueError("cameras has non-finite numbers")
    lo, hi = FLIGHT_CAPTURE_SEEDS
    for i, (seed, wind) in enumerate(zip(capture_seeds, n_wind)):
        if not lo <= int(seed) < hi:
            raise ValueError(f"capture_seeds[{i}] is {int(seed)}, must be in [{lo}, {hi}) (a simulated flight's, "
                             "never an evaluation's)")
        if not math.isfinite(float(wind)):
            raise ValueError(f"n_wind[{i}] is {float(wind)}, must be finite")
    ends = np.cumsum([0] + counts)
    plans = [flat[6 * a:6 * b].reshape(-1, 6) for a, b in zip(ends[:-1], ends[1:])]
    draws = [FlightDraw(index=int(j), n_wind=float(w), capture_seed=int(c))
             for j, w, c in zip(indices, n_wind, capture_seeds)]
    return plans, draws


@dataclasses.dataclass
class SceneFlights:
    """The :class:`vp_scene.flights.FlightSimulator` of a prior ``scene`` (a
    :class:`vp_scene.scenario.Scene`): ``wind`` gives the levels, variance and direction of the
    flights' winds (their n_wind values come with the draws), ``settings`` and ``capture`` how
    they are flown (``ground``: soil or the blue screen, :func:`fly_plan`); ``client``: a
    ``distributed.Client``, or a callable that gives one as a context manager for each batch (a
    Dask task's ``distributed.worker_client``, so that the task leaves its worker to the flights only
    while it waits for them), or None: in this process. ``workers`` is the number of flights flown at
    once (the cluster's workers, 1 in process); :meth:`warm_up` readies them while the planner
    computes."""

    scene: object
    wind: WindConfig = dataclasses.field(default_factory=WindConfig)
    settings: FlightSettings = dataclasses.field(default_factory=FlightSettings)
    capture: CaptureModel = REALISTIC
    client: object = None
    fov: float = np.pi / 2
    mesh_cache: Optional[str] = None
    ground: Optional[bool] = None
    _warming: list = dataclasses.field(default_factory=list, init=False, repr=False)

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

    def warm_up(self) -> list:
        """Start :func:`warm_worker` on every worker of the client, one task each, and return at
        once with their futures (kept here too: the planner calls it before its cheap stage, which
        leaves the workers idle, and never waits); the first flights queue behind them. In
        process, or on a Dask task's client (its worker is the planner's), nothing: []."""
        if self.client is None or callable(self.client):
            return []
        client = self.client
        scene = client.scatter(self.scene, broadcast=True, hash=False)
        args = (self.wind, self.settings, self.capture, self.fov)
        tasks = [client.submit(warm_worker, scene, *args, workers=[w], allow_other_workers=False, pure=False)
                 for w in client.scheduler_info().get("workers", {})]
        self._warming = [scene, *tasks]
        return tasks

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
        else:  # as they come back, looking at should_stop every POLL_S meanwhile
            with (self.client() if callable(self.client) else contextlib.nullcontext(self.client)) as client:
                # a key of this batch's own (hash=False): the same scene scattered by an earlier
                # batch under its content's key would be released with that batch's future
                scene = client.scatter(self.scene, broadcast=True, hash=False)
                pending = {client.submit(fly_plan, scene, self.wind, np.asarray(cams), draw, *args, pure=False): i
                           for i, (cams, draw) in enumerate(zip(plans, draws))}
                try:
                    while pending and not (should_stop is not None and should_stop()):
                        ready = [f for f in pending if f.done()]
                        for fut in ready:
                            i = pending.pop(fut)
                            done(i, _outcome(fut, draws[i]))
                        if not ready:
                            time.sleep(POLL_S)
                finally:  # a flight already running ends on its worker (Dask stops no running task); dropped
                    client.cancel(list(pending))
        return [s if s is not None else FlightScore(draw=d, failed=True, error_code=UNKNOWN, reason="cancelled")
                for s, d in zip(scores, draws)]


def _outcome(future: object, draw: FlightDraw) -> FlightScore:
    """A finished flight's score; a task that ended in an exception (a lost worker, a failure
    :func:`fly_plan` does not catch) is a scored failure naming it."""
    try:
        return future.result()
    except Exception as exc:  # noqa: BLE001 - a flight's failure is its score, never the batch's
        return FlightScore(draw=draw, failed=True, error_code=UNKNOWN, reason=f"{type(exc).__name__}: {exc}")
