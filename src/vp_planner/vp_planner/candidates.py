"""Choosing among candidate views: a plan is N of M given poses.

A rig's stops, a gantry's positions or the images of an earlier flight are poses a camera can
hold (or did); planning among them is a discrete choice of N of the M candidates, scored by the
same reward models on the same prior (the planning cloud) as a plan in free space.

:class:`CandidateSpace` is the search space every method's candidates mode works in: an encoded
plan U is its N candidate indices (sorted, as floats), :meth:`CandidateSpace.decode` gives the
cameras, and every subset is feasible: the stand-off, altitude and separation rules of
:mod:`vp_planner.feasibility` are not applied, since the candidates are where the rig or the
drone was (or can be). The reward is the request's reward model on the cameras [c, v]: a
candidate's roll about its optical axis is not scored (a camera of the suite is level,
:mod:`vp_scene.camera`; the ``coverage`` reward's W x H footprint is that of the level camera on
the same axis; a rig's few degrees of roll move its corners by a few pixels).

The methods' candidates modes (each :class:`vp_planner.methods.Method` names its function; the
candidates are ordered by azimuth about the prior's centre):

* ``egp``, ``gp``: Bayesian optimization over subsets (:func:`plan_bo_subsets`): the initial
  design (evenly spaced and neighbouring subsets, then random ones), then at each step the
  ensemble of 4 GPs (egp; one GP for gp) is fitted on the subsets' encoding
  (:meth:`CandidateSpace.features`, the candidates each subset covers, smoothed over
  neighbouring candidates), a model is drawn by the evidence weights (eqs. 16-17) and its
  expected improvement is maximized over a pool of unevaluated subsets (every single swap of the
  best subsets, and random ones) with BoTorch's ``optimize_acqf_discrete``.
* ``circle``: the N most evenly spaced candidates (:func:`evenly_spaced`): N azimuths 2 pi / N
  apart, each taken by the nearest unused candidate, at every phase given by a candidate's
  azimuth (up to the budget); the best reward among them.
* ``arc``: N neighbouring candidates (N consecutive in azimuth), the best window.
* ``sa``: simulated annealing over the subsets (:func:`vp_planner.baselines.anneal_subsets`).
* ``random``: random subsets, the best.
* ``lawnmower`` has no candidates mode (it flies its own lines), nor ``cmaes`` (a search in the
  continuous space).

Few views can fail where more work (the dev scan: 10 views 36 degrees apart registered 2 of 10,
20 views every 18 degrees all): the ``coverage`` reward's matching window (full weight up to 25
degrees between a pair's rays, none beyond 45) scores wide gaps low, and ``coverage-graph``
scores a plan whose view graph falls apart 0 (README "Reward models").
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray

from vp_scene.camera import IMAGE_SIZE, CameraModel

from .feasibility import check_realizations
from .reward import DEFAULT_FOV, DEFAULT_THETA_MATCH
from .request import MAX_CANDIDATES, BOSpec, InvalidCandidatesError, check_candidates
from .reward_models import DEFAULT_REWARD_MODEL, check_fixed_cameras
from .space import PlanReward

__all__ = ["CandidateSpace", "evenly_spaced",
           "neighbours", "evaluate_subsets", "plan_bo_subsets", "run_bo", "run_circle", "run_arc", "run_sa",
           "run_random"]


class CandidateSpace(PlanReward):
    """N of the M candidate cameras (module docstring): the space of a candidates-mode plan.

    It offers what :class:`vp_planner.objective.Objective` uses of a
    :class:`~vp_planner.space.ViewSpace` (``dim``, ``num_cameras``, ``realizations``, ``decode``,
    ``_feasible_cameras``, and the reward of :class:`~vp_planner.space.PlanReward`), so the run's
    records, progress and cancel are the same.

    Args:
        candidates: (M, 6) cameras [c, v] (:func:`check_candidates`).
        num_cameras: N, 2 <= N <= M.
        realizations: (K, P, 3) the prior (the planning cloud; a reconstruction is K = 1).
        fov, theta_match, reward_model, image_size, fixed_cameras, point_weights: as ViewSpace.
    """

    def __init__(self, candidates: Any, num_cameras: int, realizations: Any, fov: float = DEFAULT_FOV,
                 theta_match: float = DEFAULT_THETA_MATCH, reward_model: Any = DEFAULT_REWARD_MODEL,
                 image_size: tuple[int, int] = IMAGE_SIZE, fixed_cameras: Any = None, point_weights: Any = None
                 ) -> None:
        self.candidates = check_candidates(candidates)
        M = len(self.candidates)
        if int(num_cameras) != num_cameras or not 2 <= num_cameras <= M:
            raise InvalidCandidatesError(f"{num_cameras} cameras cannot be chosen among {M} candidates")
        self.num_cameras = self.dim = int(num_cameras)
        self.realizations = check_realizations(realizations)
        self.fov, self.theta_match = float(fov), float(theta_match)
        self.reward_model = reward_model
        self.image = CameraModel(int(image_size[0]), int(image_size[1]), self.fov)
        self.fixed_cameras = check_fixed_cameras(fixed_cameras)
        self.point_weights = None if point_weights is None else np.asarray(point_weights, dtype=np.float64)
        #: the prior's centre, the median of its points (a first reconstruction has outliers)
        self.centre = np.median(self.realizations.reshape(-1, 3), axis=0)
        rel = self.candidates[:, :3] - self.centre
        #: azimuth (rad, [0, 2 pi)) of every candidate about the vertical through the prior's centre
        self.azimuths = np.mod(np.arctan2(rel[:, 1], rel[:, 0]), 2 * math.pi)
        #: the candidates in azimuth order
        self.order = np.argsort(self.azimuths, kind="stable")
        # the encoding's smoothing: the angle between the directions of neighbouring candidates
        d = rel / np.maximum(np.linalg.norm(rel, axis=1, keepdims=True), 1e-12)
        self._angles = np.arccos(np.clip(d @ d.T, -1.0, 1.0))
        off = self._angles + np.diag(np.full(M, np.inf))
        self.spacing = float(max(np.median(off.min(axis=1)), 1e-3))
        self._rewards: dict = {}

    @property
    def num_candidates(self) -> int:
        return len(self.candidates)

    def encode(self, subsets: Any) -> NDArray[np.float64]:
        """U (B, N): each subset's indices, sorted, as floats (one (N,) subset gives (N,))."""
        S = np.sort(np.asarray(subsets, dtype=np.int64), axis=-1)
        return S.astype(np.float64)

    def indices(self, U: Any) -> NDArray[np.int64]:
        """The subsets (B, N) of encoded plans U (B, N) (or one (N,))."""
        return np.rint(np.asarray(U, dtype=np.float64)).astype(np.int64)

    def decode(self, U: Any) -> NDArray[np.float64]:
        """The cameras (B, N, 6) of encoded plans U (B, N) (a (N,) plan gives (N, 6))."""
        X = np.asarray(U.detach().cpu() if isinstance(U, torch.Tensor) else U, dtype=np.float64)
        idx = self.indices(X)
        if idx.shape[-1] != self.dim or idx.min() < 0 or idx.max() >= self.num_candidates:
            raise ValueError(f"U must hold {self.dim} candidate indices in [0, {self.num_candidates}), got {X.shape}")
        return self.candidates[idx]

    def features(self, subsets: Any) -> NDArray[np.float64]:
        """The BO encoding (B, M) of subsets (B, N): for every candidate m, how well the subset
        covers it, max over the subset's j of exp(-angle(m, j)^2 / (2 s^2)), with s the median
        angle between a candidate's direction from the prior's centre and its nearest
        neighbour's (a subset holds its own candidates at 1, their neighbours near 0.6)."""
        S = np.asarray(subsets, dtype=np.int64).reshape(-1, self.dim)
        a = self._angles[S]                                   # (B, N, M)
        return np.exp(-0.5 * (a / self.spacing) ** 2).max(axis=1)

    def feasible(self, x: Any) -> Any:
        """Every subset is feasible (module docstring)."""
        n = 1 if np.ndim(x) == 1 else len(x)
        return np.ones(n, dtype=bool)

    def _feasible_cameras(self, cams: NDArray[np.float64]) -> NDArray[np.bool_]:
        return np.ones(len(cams), dtype=bool)

    def random_subsets(self, n: int, rng: np.random.Generator) -> NDArray[np.int64]:
        """n random subsets (n, N) (sorted)."""
        return np.sort(np.stack([rng.choice(self.num_candidates, self.dim, replace=False) for _ in range(n)]),
                       axis=1) if n > 0 else np.zeros((0, self.dim), np.int64)


def _phases(count: int, budget: int) -> NDArray[np.int64]:
    """Up to ``budget`` of ``count`` positions, evenly spread (all when the budget allows)."""
    if budget >= count:
        return np.arange(count)
    return np.unique(np.floor(np.arange(budget) * count / budget).astype(np.int64))


def evenly_spaced(space: CandidateSpace, budget: int) -> NDArray[np.int64]:
    """``circle``'s subsets (B, N), B <= budget: at each phase (a candidate's azimuth), N target
    azimuths 2 pi / N apart, each taken by the nearest candidate not yet taken (circular
    distance in azimuth); duplicates dropped."""
    N, az = space.dim, space.azimuths
    out = []
    for p in _phases(space.num_candidates, budget):
        start = az[space.order[p]]
        taken: list[int] = []
        for k in range(N):
            target = np.mod(start + 2 * math.pi * k / N, 2 * math.pi)
            d = np.abs(np.angle(np.exp(1j * (az - target))))
            d[taken] = np.inf
            taken.append(int(np.argmin(d)))
        out.append(sorted(taken))
    return np.unique(np.array(out, dtype=np.int64), axis=0)


def neighbours(space: CandidateSpace, budget: int) -> NDArray[np.int64]:
    """``arc``'s subsets (B, N), B <= budget: N candidates consecutive in azimuth, from every
    start (wrapping around)."""
    M, N = space.num_candidates, space.dim
    out = [np.sort(space.order[(s + np.arange(N)) % M]) for s in _phases(M, budget)]
    return np.unique(np.array(out, dtype=np.int64), axis=0)


def evaluate_subsets(space: CandidateSpace, obj: Any, subsets: Any) -> NDArray[np.float64]:
    """Evaluate subsets (B, N) in batches of 16 (one recorded evaluation each), at most the
    objective's budget left; their rewards."""
    from .baselines import batch_size

    S = np.asarray(subsets, dtype=np.int64).reshape(-1, space.dim)[: max(0, obj.total - obj.count)]
    out = []
    step = batch_size(space)
    for b0 in range(0, len(S), step):
        U = space.encode(S[b0:b0 + step])
        out.append(obj.record(U, space.decode(U)))
    return np.concatenate(out) if out else np.zeros(0)


def plan_bo_subsets(space: CandidateSpace, obj: Any, bo: BOSpec, evaluations: int, seed: int, rng: np.random.Generator,
                    ensemble: bool, refit_every: int = 5, pool_random: int = 256) -> dict:
    """BO over subsets (module docstring): the run's weights, model names, steps and initial best.

    The initial design (:class:`vp_planner.request.BOSpec` ``bo``) is up to ``bo.structured_init``
    evenly spaced and neighbouring subsets, then random ones, ``bo.initial_evaluations`` in all;
    then one subset a step, never one evaluated before (a subset that has been scored is known:
    the reward is deterministic)."""
    from botorch.acquisition.analytic import LogExpectedImprovement
    from botorch.optim import optimize_acqf_discrete

    from .bo import StepRecord
    from .gp import (MODEL_NAMES, SINGLE_MODEL_NAME, draw_model, ensemble_weights, fit_model, get_hypers,
                     log_evidence, make_model, set_hypers)

    names = list(MODEL_NAMES) if ensemble else [SINGLE_MODEL_NAME]
    E = int(evaluations)
    n0 = min(int(bo.initial_evaluations), E)
    structured = bo.structured_init
    seen: set = set()
    design: list = []
    if structured > 0:
        half = max(1, structured // 2)
        for S in (evenly_spaced(space, half), neighbours(space, structured - half)):
            design += [tuple(s) for s in S]
    design = [s for s in dict.fromkeys(design)][:n0]
    tries = 0
    while len(design) < n0 and tries < 50 * n0:
        s = tuple(space.random_subsets(1, rng)[0])
        tries += 1
        if s not in design:
            design.append(s)
    sels = [np.array(s, np.int64) for s in design]
    ys = list(evaluate_subsets(space, obj, np.array(design, np.int64).reshape(-1, space.dim)))
    seen.update(design)
    initial_best = max(ys) if ys else None
    gen = torch.Generator().manual_seed(int(seed))
    hypers: list = [None] * len(names)
    steps, weights = [], None
    while obj.count < E:
        obj.check_stop()
        X = torch.as_tensor(space.features(np.array(sels)))
        y = torch.as_tensor(np.array(ys, dtype=np.float64))
        refit = len(steps) % refit_every == 0
        # the pool: every single swap of the three best subsets, and random ones, unevaluated
        pool: dict = {}
        for i in torch.argsort(y, descending=True)[:3].tolist():
            cur = sels[i]
            rest = np.setdiff1d(np.arange(space.num_candidates), cur)
            for slot in range(space.dim):
                for new in rest:
                    s = cur.copy()
                    s[slot] = new
                    pool.setdefault(tuple(np.sort(s)), None)
        for s in space.random_subsets(pool_random, rng):
            pool.setdefault(tuple(s), None)
        cands = [s for s in pool if s not in seen]
        if not cands:
            break
        m_t, le = -1, [-math.inf] * len(names)
        constant = float(y.max() - y.min()) <= 1e-12 * max(1.0, float(y.abs().max()))
        models: list = [None] * len(names)
        if not constant:
            for m, name in enumerate(names):
                model = make_model(name, X, y)
                if refit or hypers[m] is None:
                    fit_model(model, 150, start=hypers[m])
                else:
                    set_hypers(model, hypers[m])
                    model.eval()
                le[m] = log_evidence(model)
                if math.isfinite(le[m]):
                    hypers[m], models[m] = get_hypers(model), model
        w = ensemble_weights(le) if any(mm is not None for mm in models) else \
            torch.full((len(names),), 1.0 / len(names), dtype=torch.float64)
        if any(mm is not None for mm in models):
            m_t = draw_model(w, gen) if ensemble else 0
            if models[m_t] is None:
                m_t = -1
        if m_t >= 0:
            choices = torch.as_tensor(space.features(np.array(cands)))
            acq = LogExpectedImprovement(models[m_t], best_f=float(y.max()))
            with torch.no_grad():
                x, _ = optimize_acqf_discrete(acq, q=1, choices=choices, max_batch_size=1024, unique=True)
            pick = int(torch.nonzero(torch.all(choices == x.reshape(1, -1), dim=1))[0])
        else:  # constant data or no usable model: a random unevaluated subset
            pick = int(rng.integers(len(cands)))
        chosen = np.array(cands[pick], np.int64)
        before = float(y.max())
        value = float(evaluate_subsets(space, obj, chosen[None])[0])
        sels.append(chosen)
        ys.append(value)
        seen.add(cands[pick])
        if ensemble:
            weights = [float(v) for v in w]
            obj.weights = weights
        steps.append(StepRecord(evaluation=obj.count, model=m_t, weights=[float(v) for v in w],
                                improved=value > before + 1e-3 * abs(before), trust_region=None,
                                refit=bool(refit and not constant), fit_warnings=0, fit_seconds=0.0,
                                acq_seconds=0.0).as_dict(names))
    return {"weights": weights, "model_names": names, "steps": steps, "initial_best": initial_best}


# ---------------------------------------------------------------------- the registry's candidates modes
def run_bo(space: CandidateSpace, obj: Any, request: Any, rng: np.random.Generator) -> dict:
    """egp and gp among candidates (an ensemble where the registry's entry says so)."""
    from .methods import BY_NAME

    return plan_bo_subsets(space, obj, request.bo, request.evaluations, request.seed, rng,
                           BY_NAME[request.method].ensemble)


def run_circle(space: CandidateSpace, obj: Any, request: Any, rng: np.random.Generator) -> None:
    evaluate_subsets(space, obj, evenly_spaced(space, request.evaluations))


def run_arc(space: CandidateSpace, obj: Any, request: Any, rng: np.random.Generator) -> None:
    evaluate_subsets(space, obj, neighbours(space, request.evaluations))


def run_random(space: CandidateSpace, obj: Any, request: Any, rng: np.random.Generator) -> None:
    evaluate_subsets(space, obj, space.random_subsets(request.evaluations, rng))


def run_sa(space: CandidateSpace, obj: Any, request: Any, rng: np.random.Generator) -> None:
    from .baselines import anneal_subsets

    anneal_subsets(space.candidates, space.dim, obj, request.evaluations, rng, encode=space.encode)
