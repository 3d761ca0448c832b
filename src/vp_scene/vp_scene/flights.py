"""Simulated flights: the planner's expensive fidelity, shared by the planner and the reconstruction.

A *simulated flight* of a plan flies it over the planner's prior (the plants it plans on, placed
as the world places them) under one wind realization of its own and the capture model, photographs
it, reconstructs the images with the suite's own reconstruction and scores the result against the
prior displaced by that wind: map and shape Chamfer distance, the coverage of the prior, or the
failure and its reason. The planner uses it to check the plans its cheap reward proposes
(:mod:`vp_planner.flight_planning`); the reconstruction flies it (:mod:`vp_recon.sim_flights`).

This module holds what both sides agree on, so that neither imports the other:

* :class:`FlightSettings`: the reconstruction's setting for a flight (image size, SIFT's first
  octave, the dense step's scale), chosen for speed;
* :class:`FlightDraw` and :func:`flight_draws`: a flight's wind (``n_wind``, paper Sec. V-A) and
  its capture-noise seed, from the planner's own seed on a stream of their own. The evaluation's
  realizations come from the scene seed's wind stream (:func:`vp_scene.wind.draw_n_wind`) and its
  capture seeds are below :data:`FLIGHT_CAPTURE_SEEDS` ``[0]`` (every node and CLI refuses larger
  ones), so no wind realization or capture-noise seed that an evaluation scores reaches a flight;
* :func:`flight_capture`: the capture model a flight is photographed under (the realistic one, with
  the planner's reported-pose errors and ground control);
* :class:`FlightScore`: what a flight returns (plain data);
* :class:`FlightSimulator`: the interface the planner is handed (by the CLI, the benchmarks, or
  the planner node as a client of the recon node's ``/simulate_flights`` action), and
  :func:`load_simulator`, which finds the installed implementation by its entry point
  (group :data:`ENTRY_POINTS`), so that the planner's CLI never imports the reconstruction.

ROS-free: numpy only.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any, Callable, Optional, Protocol, Sequence

import numpy as np
from numpy.typing import NDArray

from .camera import check_image_side

__all__ = ["FlightSettings", "FlightDraw", "FlightScore", "FlightSimulator", "flight_draws", "flight_capture",
           "FLIGHT_STREAM", "MAX_FLIGHTS",
           "FLIGHT_CAPTURE_SEEDS", "ENTRY_POINTS", "load_simulator", "FlightSimulatorMissing"]

#: The seed-sequence entry that marks the flights' draws (the scene's streams are 0-3, :mod:`vp_scene.scenario`).
FLIGHT_STREAM = 0x464C  # "FL"
#: [lo, hi): the capture seeds of simulated flights; an evaluation's capture seed is below lo.
FLIGHT_CAPTURE_SEEDS = (2 ** 31, 2 ** 32)
#: The most simulated flights a planning run (a request's ``sim_flights``) or one batch may ask for
#: (each is a reconstruction: seconds to minutes).
MAX_FLIGHTS: int = 200
#: The entry-point group under which a package offers its :class:`FlightSimulator` class.
ENTRY_POINTS = "vp_scene.flight_simulators"


@dataclass(frozen=True)
class FlightSettings:
    """How a simulated flight is photographed and reconstructed: image size (pixels), SIFT's first
    octave (-1: the image doubled first; 0: at its own resolution, about 4x less work) and the
    dense step's scale (0 < s <= 1; SGM costs about s^3). Validated on construction (ValueError)."""

    width: int = 2000
    height: int = 1500
    sift_first_octave: int = 0
    dense_scale: float = 0.5

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            check_image_side(f"flight image {name}", getattr(self, name))
        if isinstance(self.sift_first_octave, bool) or self.sift_first_octave not in (-1, 0):
            raise ValueError(f"flight sift_first_octave must be -1 or 0, got {self.sift_first_octave!r}")
        s = self.dense_scale
        if isinstance(s, bool) or not isinstance(s, (int, float)) or not (math.isfinite(s) and 0.1 <= s <= 1.0):
            raise ValueError(f"flight dense_scale must be in [0.1, 1], got {s!r}")

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class FlightDraw:
    """One flight's draws: the wind's ``n_wind`` (m a level, paper Sec. V-A) and the capture
    model's ``capture_seed`` (in :data:`FLIGHT_CAPTURE_SEEDS`); ``index`` is the flight's number in
    its planning run."""

    index: int
    n_wind: float
    capture_seed: int

    def to_dict(self) -> dict:
        return asdict(self)


def flight_draws(seed: int, count: int, variance: float, start: int = 0) -> list[FlightDraw]:
    """The draws of flights ``start .. start + count - 1`` of a planning run of ``seed``: flight j's
    ``n_wind ~ N(0, variance)`` and its capture seed, both from ``default_rng([seed, FLIGHT_STREAM, j])``
    (module docstring: disjoint from every evaluation's)."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0, got {seed!r}")
    if not (math.isfinite(variance) and variance >= 0):
        raise ValueError(f"wind variance must be finite and >= 0, got {variance!r}")
    out = []
    for j in range(int(start), int(start) + int(count)):
        rng = np.random.default_rng([int(seed), FLIGHT_STREAM, j])
        n_wind = float(rng.normal(0.0, math.sqrt(variance)))
        capture_seed = int(rng.integers(*FLIGHT_CAPTURE_SEEDS))
        out.append(FlightDraw(index=j, n_wind=n_wind, capture_seed=capture_seed))
    return out


def flight_capture(report_position_sigma: float, report_attitude_sigma: float, ground_control: bool) -> Any:
    """The :class:`vp_scene.capture.CaptureModel` a simulated flight is photographed under: the
    realistic one (hover errors, sensor noise) with the errors of the poses the planner's flight
    reports (m, degrees per axis) and, with ``ground_control``, its markers (without: none);
    ValueError naming a bad figure. Its seed is each flight's (:class:`FlightDraw`)."""
    import dataclasses

    from .capture import REALISTIC

    return dataclasses.replace(REALISTIC, report_position_sigma=report_position_sigma,
                               report_attitude_sigma=report_attitude_sigma,
                               gcp_markers=REALISTIC.gcp_markers if ground_control else 0).validate()


@dataclass
class FlightScore:
    """What one simulated flight gives (distances in metres).

    ``chamfer`` (map: registration included) and ``chamfer_shape`` (after a rigid ICP) against the
    prior displaced by the flight's wind, ``coverage`` the fraction of the prior's plant points the
    reconstruction reaches, ``images`` registered; a failed flight has ``failed`` True, the
    reconstruction's ``error_code`` and ``reason`` and no distances. :attr:`value` is what the
    planner minimizes."""

    draw: FlightDraw
    chamfer: Optional[float] = None
    chamfer_shape: Optional[float] = None
    coverage: Optional[float] = None
    images: int = 0
    failed: bool = False
    error_code: int = 0
    reason: str = ""
    seconds: float = 0.0

    @property
    def value(self) -> float:
        """The map Chamfer distance, +inf for a failed flight (a plan that does not reconstruct
        is worse than any that does)."""
        return math.inf if self.failed or self.chamfer is None else float(self.chamfer)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["draw"] = self.draw.to_dict()
        return d

    @classmethod
    def from_dict(cls, data: dict) -> "FlightScore":
        return cls(**{**data, "draw": FlightDraw(**data["draw"])})


#: ``on_flight(i, score)``: called as flight i of a batch comes back (any order).
OnFlight = Callable[[int, FlightScore], None]


class FlightSimulator(Protocol):
    """Flies plans over a prior: ``fly(plans, draws, on_flight, should_stop)`` -> one
    :class:`FlightScore` a plan, in the order given (plans[i] flown with draws[i]). A flight
    that fails is a scored failure, never an exception; ``should_stop()`` True ends the batch early
    (the flights not flown are failures with reason 'cancelled'). ``workers``: how many flights it
    flies at once (the planner's batch size); ``wind_variance``: the variance of n_wind in the
    scene's wind model (the planner draws the flights' winds with it). A simulator may also offer
    ``warm_up()``, which starts readying its workers and returns at once; the planner calls it
    before its cheap stage."""

    workers: int
    wind_variance: float

    def fly(self, plans: Sequence[NDArray[np.float64]], draws: Sequence[FlightDraw],
            on_flight: Optional[OnFlight] = None, should_stop: Optional[Callable[[], bool]] = None
            ) -> list[FlightScore]: ...


class FlightSimulatorMissing(RuntimeError):
    """No package offers a flight simulator (entry-point group :data:`ENTRY_POINTS`)."""


def load_simulator(name: str = "reconstruction") -> Any:
    """The flight simulator class installed under ``name`` in :data:`ENTRY_POINTS` (vp_recon offers
    ``reconstruction``); FlightSimulatorMissing when none is."""
    from importlib.metadata import entry_points

    found = [ep for ep in entry_points(group=ENTRY_POINTS) if ep.name == name]
    if not found:
        raise FlightSimulatorMissing(f"no flight simulator {name!r} is installed (entry points {ENTRY_POINTS}); "
                                     "install vp_recon, or plan with --sim-flights 0")
    return found[0].load()
