"""Planning with two fidelities: the cheap reward proposes, simulated flights decide.

The cheap reward (eq. 7 of a reward model, milliseconds an evaluation) ranks plans as their
reconstruction does only roughly: on plants the planner has not seen it can rank a plan first that
reconstructs several times worse than a fixed arc. A simulated flight (:mod:`vp_scene.flights`:
the plan flown over the prior under a wind and capture noise of the planner's own, photographed,
reconstructed by the suite's reconstruction and scored by its map Chamfer distance) is the
expensive fidelity that predicts a real flight. After the method's cheap stage has spent its
evaluations, :func:`flight_stage` spends the flight budget F:

1. **The pool.** The structured patterns a drone operator flies, scored by the cheap reward on
   their own budget (:func:`patterns`): the tuned circle and the arc (exactly the ``circle`` and
   ``arc`` baselines' plans of the same budget) and the best of the space's structured caps, rings
   and arcs (:func:`vp_planner.designs.structured_plans`); among candidate views, the evenly spaced
   and the neighbouring subsets (the ``circle`` and ``arc`` candidates modes); then the cheap
   stage's evaluated plans, best
   reward first, each at least :data:`MIN_PLAN_DISTANCE` of the scene's size away from those
   already in the pool (centres matched camera to camera, :func:`plan_distance`), so that the
   flights see different plans, not one plan and its neighbours.
2. **The flights.** The patterns are always flown (the chosen plan is never one the simulator
   scores worse than the best fixed pattern), then the pool in order, one flight a plan (each
   flight its own wind and capture draw), handed to the simulator as one batch: its workers
   each take the next flight as they finish one (batches of the workers' count would wait for
   their slowest flight).
3. **The confirmation.** The last ``confirm`` flights fly the best plans again under new draws
   (one wind realization decides little between close plans, and the best of many single flights
   is the luckiest as much as the best); a plan's score is the mean of its flights' map Chamfer
   distances, a failed flight counting as +inf (:attr:`FlightScore.value`).
4. **The choice.** Among the plans flown most often (the confirmed ones), the plan of the lowest
   score; where none of them reconstructed in every flight, among all plans flown; ties go to the
   higher cheap reward. When every flight failed the cheap reward's best plan is kept and the
   result says so.

Flights run on whatever the :class:`~vp_scene.flights.FlightSimulator` runs them on (a Dask
cluster, the recon node); a cancel is seen between batches and inside a batch.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Optional, Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from vp_scene.flights import FlightDraw, FlightScore, FlightSimulator, flight_draws

from .objective import Objective
from .space import PlanningCancelled, StopCheck

__all__ = ["FlightOutcome", "PoolPlan", "flight_stage", "flight_pool", "patterns", "plan_distance",
           "MIN_PLAN_DISTANCE", "OnFlight"]

#: Pool plans differ by at least this fraction of the scene's size (the mean distance between
#: matched camera centres over the diagonal of the scene's box, at least 1 m).
MIN_PLAN_DISTANCE = 0.1

#: ``on_flight(done, total, score)`` after every flight of the run.
OnFlight = Callable[[int, int, FlightScore], None]


def plan_distance(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    """Mean distance (m) between the camera centres of plans ``a`` and ``b`` (N, 6), cameras matched
    one to one to minimize it (scipy's linear_sum_assignment): a plan is the same whatever the
    order of its cameras."""
    d = np.linalg.norm(a[:, None, :3] - b[None, :, :3], axis=-1)
    rows, cols = linear_sum_assignment(d)
    return float(d[rows, cols].mean())


@dataclass
class PoolPlan:
    """A plan of the pool: its cameras, its encoding in the space (U; NaN where a pattern was built
    as cameras), cheap reward and source, and the flights flown of it."""

    cameras: NDArray[np.float64]
    reward: float
    source: str
    U: Optional[NDArray[np.float64]] = None
    flights: list = field(default_factory=list)

    @property
    def score(self) -> float:
        """Mean map Chamfer of its flights (+inf when one failed or none was flown)."""
        values = [f.value for f in self.flights]
        return float(np.mean(values)) if values and all(math.isfinite(v) for v in values) else math.inf


def patterns(space: Any, obj: Objective, request: Any, evaluations: int, rng: np.random.Generator) -> list[PoolPlan]:
    """The structured patterns of the pool (module docstring), each tuned by the cheap reward on a
    budget of its own (``evaluations``: the run's, as the baselines get), on throw-away objectives
    of the same space: in free space the tuned circle, the arc (``request.arc.spacing``) and the best
    structured plan; among candidates (a :class:`vp_planner.candidates.CandidateSpace`) the
    ``circle`` and ``arc`` candidates modes' subsets."""
    from .candidates import CandidateSpace

    def side(budget: int) -> Objective:
        return Objective(space, budget, dtype=obj.dtype, should_stop=obj.should_stop)

    if isinstance(space, CandidateSpace):
        from .candidates import run_arc, run_circle

        tuned = request.replace(evaluations=evaluations)
        makers = [("circle", evaluations, lambda o: run_circle(space, o, tuned, rng)),
                  ("arc", evaluations, lambda o: run_arc(space, o, tuned, rng))]
    else:
        from .baselines import plan_arc, plan_circle
        from .designs import structured_plans

        U = structured_plans(space)
        makers = [("circle", evaluations, lambda o: plan_circle(space, o, evaluations, rng)),
                  ("arc", evaluations, lambda o: plan_arc(space, o, evaluations, rng, request.arc)),
                  ("structured", len(U), lambda o: o(U) if len(U) else None)]
    out = []
    for source, budget, make in makers:
        o = side(max(1, budget))
        make(o)
        if o.best_index >= 0:
            out.append(PoolPlan(np.asarray(o.best_cameras(), dtype=np.float64), o.best_value, source,
                                np.asarray(o.U[o.best_index], dtype=np.float64)))
    return out


def flight_pool(space: ViewSpace, obj: Objective, patterns: Sequence[PoolPlan], size: int) -> list[PoolPlan]:
    """The patterns, then up to ``size`` plans in all from the cheap stage's feasible evaluations,
    best reward first, each at least :data:`MIN_PLAN_DISTANCE` of the scene's size from the plans
    before it (module docstring)."""
    pts = np.asarray(space.realizations, dtype=np.float64).reshape(-1, 3)
    scale = max(1.0, float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0))))
    pool = list(patterns)
    ok = np.asarray(obj.feasible_flags, bool) & np.asarray(obj.candidate_flags, bool)
    values = np.where(ok, np.asarray(obj.values, float), -np.inf)
    for i in np.argsort(-values, kind="stable"):
        if len(pool) >= size or not np.isfinite(values[i]) or values[i] <= 0:
            break
        cams = obj.cameras[int(i)]
        if all(plan_distance(cams, p.cameras) >= MIN_PLAN_DISTANCE * scale for p in pool):
            pool.append(PoolPlan(np.asarray(cams, dtype=np.float64), float(values[i]), "cheap",
                                 np.asarray(obj.U[int(i)], dtype=np.float64)))
    return pool


@dataclass
class FlightOutcome:
    """What the flight stage chose: ``cameras`` and their cheap ``reward``, its ``source`` in the
    pool (circle, arc, structured, cheap), ``score`` (mean map Chamfer of its flights, m; inf
    when none reconstructed: the cheap reward's best was kept), every flight flown as a record
    (``flights``: plan index in ``plans``, its draw, score, reason, seconds), the plans flown
    (``plans``: cameras, reward, source, score), the stage's seconds and the chosen plan's
    encoding ``U`` (among candidates: its indices)."""

    cameras: NDArray[np.float64]
    reward: float
    source: str
    score: float
    flights: list
    plans: list
    seconds: float
    chosen: int
    U: Optional[NDArray[np.float64]] = None


def flight_stage(space: Any, obj: Objective, simulator: FlightSimulator, flights: int, seed: int,
                 structured: Sequence[PoolPlan], wind_variance: float, confirm: Optional[int] = None,
                 on_flight: Optional[OnFlight] = None, should_stop: Optional[StopCheck] = None) -> FlightOutcome:
    """Spend ``flights`` simulated flights on the cheap stage's plans (module docstring) and choose.

    Args:
        obj: the cheap stage's objective (its records are the candidates).
        simulator: flies plans (:class:`~vp_scene.flights.FlightSimulator`).
        flights: F >= 1, the flights in all (confirmation included).
        seed: the planning run's seed: the flights' draws (:func:`vp_scene.flights.flight_draws`).
        structured: the structured patterns, always flown first (:func:`patterns`).
        wind_variance: the variance of the flights' n_wind (the scene's wind model).
        confirm: flights re-flying the best plans at the end (default: the simulator's workers,
            at least 2, when F leaves room for them after the patterns and one more plan).

    Raises:
        PlanningCancelled: ``should_stop()`` became True.
    """
    t0 = time.perf_counter()
    stop = should_stop or (lambda: False)
    q = max(1, int(getattr(simulator, "workers", 1)))
    if confirm is None:
        confirm = max(2, q) if flights >= len(structured) + 1 + max(2, q) else 0
    confirm = max(0, min(int(confirm), flights - 1))
    pool = flight_pool(space, obj, structured, max(len(structured), flights - confirm))
    draws = iter(flight_draws(seed, flights, wind_variance))
    records: list[dict] = []

    def fly(indices: list[int]) -> None:
        batch = [(i, next(draws)) for i in indices]

        def one(j: int, score: FlightScore) -> None:
            i = batch[j][0]
            pool[i].flights.append(score)
            records.append({"plan": i, "source": pool[i].source, **score.to_dict()})
            if on_flight is not None:
                on_flight(len(records), flights, score)

        simulator.fly([pool[i].cameras for i, _ in batch], [d for _, d in batch], on_flight=one, should_stop=stop)
        if stop():
            raise PlanningCancelled()

    fly(list(range(min(len(pool), flights - confirm))))  # one batch: a worker takes the next flight when free
    while len(records) < flights:  # confirmation: the best plans flown again, one more flight each
        ranked = sorted(range(len(pool)), key=lambda i: (pool[i].score, -pool[i].reward))
        ranked = [i for i in ranked if pool[i].flights and math.isfinite(pool[i].score)] or ranked[:1]
        fly(ranked[:min(q, flights - len(records))])
    most = max(len(p.flights) for p in pool)
    confirmed = [i for i in range(len(pool)) if len(pool[i].flights) == most and math.isfinite(pool[i].score)]
    chosen = min(confirmed or range(len(pool)), key=lambda i: (pool[i].score, -pool[i].reward))
    if not math.isfinite(pool[chosen].score):  # nothing reconstructed: the cheap reward decides
        chosen = max(range(len(pool)), key=lambda i: pool[i].reward)
    best = pool[chosen]
    return FlightOutcome(cameras=best.cameras, reward=float(best.reward), source=best.source, score=best.score,
                         flights=records, chosen=int(chosen), U=best.U,
                         plans=[{"cameras": p.cameras.tolist(), "reward": p.reward, "source": p.source,
                                 "score": p.score if math.isfinite(p.score) else None,
                                 "flights": len(p.flights)} for p in pool],
                         seconds=time.perf_counter() - t0)
