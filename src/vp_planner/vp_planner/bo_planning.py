"""The BO driver of :func:`vp_planner.optimizers.plan_views`: ``egp`` and ``gp`` (Sec. IV) in a
:class:`~vp_planner.space.ViewSpace`, their initial design, and planning a field by parts
(:mod:`vp_planner.parts`). :func:`vp_planner.bo.optimize` runs the BO loop itself; this module
binds it to a space and its :class:`~vp_planner.objective.Objective` (feasibility, cancel, records).
"""
from __future__ import annotations

import math
from typing import Any, Optional

import numpy as np
import torch
from numpy.typing import NDArray

from .designs import random_plans, structured_plans
from .methods import BY_NAME
from .objective import Objective
from .request import BOSpec, PlanRequest
from .space import Callback, NoFeasiblePlanError, StopCheck, ViewSpace

__all__ = ["initial_design", "plan_bo", "plan_bo_by_parts", "optimize_in", "run_bo"]


def initial_design(space: ViewSpace, n: int, rng: np.random.Generator, structured: int = 20,
                   should_stop: Optional[StopCheck] = None) -> NDArray[np.float64]:
    """n initial plans U (n, 6N): up to ``structured`` structured plans, then random feasible ones
    (PlanningCancelled as soon as ``should_stop()`` is True)."""
    S = structured_plans(space, max_plans=max(0, min(structured, n))) if structured > 0 else np.zeros((0, space.dim))
    S = S[:n]
    try:
        rest = random_plans(space, n - len(S), rng, should_stop=should_stop) if n > len(S) else np.zeros((0, space.dim))
    except NoFeasiblePlanError as exc:
        # The range egp/gp serve (README "Planner node"): their space is a shell about the scene,
        # and random plans in it keep min_separation only up to a few dozen cameras a plant. The
        # ring methods widen their circle instead and serve every N up to 100.
        raise NoFeasiblePlanError(f"{exc}; egp/gp plan up to about 40 cameras a plant (more: circle, arc, sa "
                                  f"or lawnmower, or a field planned by parts)") from None
    return np.concatenate([S, rest], axis=0)


def run_bo(space: ViewSpace, obj: Objective, request: PlanRequest, rng: np.random.Generator, parts: int) -> dict:
    """The registry's planner of egp and gp (:class:`vp_planner.methods.Method`): BO in ``space``,
    or by ``parts`` parts when there are more than 1, with the request's ``bo`` settings; an
    ensemble of GPs where the method's entry says so."""
    ensemble = BY_NAME[request.method].ensemble
    if parts > 1:
        return plan_bo_by_parts(space, obj, request.bo, request.evaluations, request.seed, ensemble, parts)
    return plan_bo(space, obj, request.bo, request.evaluations, request.seed, rng, ensemble)


def plan_bo(space: ViewSpace, obj: Objective, bo: BOSpec, evaluations: int, seed: int, rng: np.random.Generator,
            ensemble: bool) -> dict:
    """BO in one space: the initial design of ``bo`` (its size, the structured plans first), then
    :func:`optimize_in` with the rest of the ``evaluations`` in ``bo.mode``."""
    X0 = initial_design(space, bo.initial_evaluations, rng, bo.structured_init, obj.should_stop)
    return optimize_in(space, obj, X0, evaluations, bo.initial_evaluations, seed, ensemble, bo.mode)


def optimize_in(space: Any, obj: Objective, X0: NDArray[np.float64], evaluations: int, initial_evaluations: int,
              seed: int, ensemble: bool, bo_mode: str) -> dict:
    """:func:`vp_planner.bo.optimize` on ``obj`` in ``space`` (a ViewSpace, or the JointSpace of
    planning by parts) from the initial design X0; the run's weights, models, steps and the
    initial design's best."""
    from . import bo  # imported lazily: botorch is heavy

    info: dict = {"weights": None, "model_names": None}

    def objective(U: torch.Tensor) -> torch.Tensor:
        return obj(U).to(U.dtype) if isinstance(U, torch.Tensor) else torch.as_tensor(obj(U))

    def feasible(U: torch.Tensor) -> torch.Tensor:
        # BO's rejection sampling and acquisition ask this for every candidate batch: the place to
        # see a cancel between evaluations (PlanningCancelled leaves bo.optimize)
        obj.check_stop()
        return space.feasible(U)

    def bo_callback(done: int, total: int, best: float, weights: Optional[list]) -> bool:
        if weights is not None:
            obj.weights = info["weights"] = [float(x) for x in weights]
        return not obj.cancelled

    res = bo.optimize(objective, space.dim, evaluations, initial_evaluations, seed, ensemble=ensemble,
                      feasible=feasible, initial_design=torch.as_tensor(X0, dtype=torch.float64),
                      callback=bo_callback, settings=bo.BOSettings(mode=bo_mode),
                      periodic=torch.as_tensor(space.periodic),
                      groups=torch.arange(space.dim) % 6)  # the 6 parameters of a camera
    if ensemble and res.steps:
        info["weights"] = [float(x) for x in res.steps[-1].weights]
    info["model_names"] = list(res.model_names)
    info["steps"] = [st.as_dict(res.model_names) for st in res.steps]
    info["initial_best"] = float(res.best_initial) if math.isfinite(res.best_initial) else None
    return info


def plan_bo_by_parts(space: ViewSpace, obj: Objective, bo: BOSpec, evaluations: int, seed: int, ensemble: bool,
                     parts: int) -> dict:
    """EGP-EI (GP-EI) by parts (:mod:`vp_planner.parts`): each of the ``parts`` parts gets the budget
    of a plan (``evaluations``, ``bo``'s initial design) on its own points, then the whole field's
    structured plans are scored (up to ``bo.structured_init``, at most half of the
    ``evaluations // 2`` left), and the better start of the union of the part plans and the best
    structured plan (put into the parts' shells) is refined on the whole field's reward with the
    rest, in a trust region.

    ``obj`` is the whole run's objective (the joint space's): it counts the part evaluations too
    (recorded with reward 0 and ``candidate=False``: a part's reward is not a plan's) so that the
    budget, the progress callback and cancelling work as for any method."""
    from .parts import JointSpace, allocate_cameras, partition

    R = space.realizations
    labels = partition(R, parts, seed)
    counts = allocate_cameras(np.bincount(labels, minlength=parts), space.num_cameras)
    fixed = np.zeros((0, 3))
    part_spaces, part_U, records = [], [], []
    for g in range(parts):
        sub = ViewSpace(R[:, labels == g], int(counts[g]), min_standoff=space.min_standoff,
                        min_altitude=space.min_altitude, min_separation=space.min_separation, fov=space.fov,
                        theta_match=space.theta_match, reward_model=space.reward_model,
                        image_size=(space.image.width, space.image.height), obstacles=R, fixed_positions=fixed,
                        fixed_cameras=space.fixed_cameras,
                        point_weights=None if space.point_weights is None else space.point_weights[:, labels == g])
        part_obj = Objective(sub, evaluations, dtype=obj.dtype, should_stop=obj.should_stop,
                             callback=_forward(obj))
        info = plan_bo(sub, part_obj, bo, evaluations, seed + g, np.random.default_rng([seed, g]), ensemble)
        best = part_obj.best_cameras()
        if best is None:
            raise NoFeasiblePlanError(f"no feasible plan for part {g + 1} of {parts} ({counts[g]} cameras)")
        fixed = np.concatenate([fixed, best[:, :3]])
        part_spaces.append(sub)
        part_U.append(part_obj.U[part_obj.best_index])
        records.append({"part": g, "cameras": int(counts[g]), "points": int(sub.realizations.shape[1]),
                        "evaluations": part_obj.count, "reward": float(part_obj.best_value),
                        "initial_best": info.get("initial_best")})
    # The whole field's structured plans (rings, arcs, caps about all the parts) are evaluated too,
    # from the joint budget: part plans each good on their own part can make a model that falls
    # into parts (4 low cameras on each side of a 3 x 3 grid: two parts, each placed on its own
    # reported poses, README "Reward models"), where one ring over the field holds together.
    joint_budget = max(1, evaluations // 2)
    room = min(bo.structured_init, (joint_budget - 2) // 2)      # at most half, and 2 left for the joint start
    S, whole = field_starts(space, room)
    X0 = [np.concatenate(part_U)]
    if len(S):
        values = obj.record(S, whole)
        X0.append(_in_parts(whole[int(np.argmax(values))], part_spaces, labels, R))
    joint = JointSpace(space, part_spaces)
    obj.space = joint
    info = optimize_in(joint, obj, np.stack(X0), joint_budget - len(S), len(X0), seed, ensemble, "trust_region")
    info["parts"] = records
    return info


def field_starts(space: ViewSpace, count: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Up to ``count`` whole-field plans planning by parts scores: (U (M, 6N), cameras (M, N, 6)).

    First the tuned circle's family (:class:`vp_planner.baselines.CircleFamily`, horizontal rings
    round the field facing its centre) on the grid its grid search uses, with about half of
    ``count`` cells (3 x 3 of 20), then the structured plans (:func:`structured_plans`, the
    infeasible ones dropped) for the rest. The structured rings sit at one steep elevation on the
    shell's edge; on a field the circle's lower, nearer rings can score higher than the union of
    the part plans, so egp starts from them too.
    A ring is recorded with its own cameras (U: :meth:`ViewSpace.encode_cameras`, projected where
    the shell cannot hold it: the joint refinement starts in the parts' shells anyway)."""
    from .baselines import CircleFamily

    if count <= 0:
        return np.zeros((0, space.dim)), np.zeros((0, space.num_cameras, 6))
    fam = CircleFamily(space)
    cells = fam.grid(count // 2) if count >= 2 else []
    rings = np.array([fam.plan(a, h) for a, h in cells]).reshape(-1, space.num_cameras, 6)
    S = structured_plans(space, max_plans=count - len(rings))
    if not len(rings):
        return S, space.decode(S)
    return np.concatenate([space.encode_cameras(rings), S]), np.concatenate([rings, space.decode(S)])


def _in_parts(cameras: NDArray[np.float64], part_spaces: list, labels: NDArray[np.int64],
              realizations: NDArray[np.float64]) -> NDArray[np.float64]:
    """A whole-field plan (N, 6) in the joint space's coordinates: each part takes as many of its
    cameras as it has, nearest first (the assignment of cameras to the parts' slots minimizing the
    horizontal distances to the parts' centres: scipy's linear_sum_assignment), each camera
    encoded in its part's shell (projected onto it where the shell cannot hold it)."""
    from scipy.optimize import linear_sum_assignment

    xy = realizations[0, :, :2]
    centres = np.array([xy[labels == g].mean(axis=0) for g in range(len(part_spaces))])
    slots = np.repeat(np.arange(len(part_spaces)), [p.num_cameras for p in part_spaces])
    cost = np.linalg.norm(cameras[:, None, :2] - centres[slots][None], axis=-1)
    rows, cols = linear_sum_assignment(cost)
    part_of = np.empty(len(cameras), dtype=np.int64)
    part_of[rows] = slots[cols]
    return np.concatenate([p.encode_cameras(cameras[part_of == g]) for g, p in enumerate(part_spaces)])


def _forward(obj: Objective) -> Callback:
    """A part objective's callback: count the evaluation in the whole run's objective
    (:meth:`Objective.record_part_evaluation`), whose callback and cancel then see it."""
    def callback(done: int, total: int, best: float, weights: Optional[list]) -> bool:
        if weights is not None:
            obj.weights = weights
        return obj.record_part_evaluation()
    return callback
