r"""Bayesian optimization of a black box on the unit cube: EGP-EI (paper Sec. IV-B) and GP-EI (IV-A).

The objective :math:`\tilde r` is *maximized* over [0, 1]^d (callers map their parameterization
onto the cube; coordinates flagged ``periodic`` may leave it, the caller wraps them). One run:

1. an initial design of ``initial_evaluations`` points (given points first, then scrambled-Sobol
   points, feasible ones by rejection);
2. each BO step t:

   * fit the GP(s) on all data (:mod:`vp_planner.gp`): the 4-kernel ensemble for EGP, the
     Matern-2.5-ARD GP for GP-EI. A full MAP fit (``fit_gpytorch_mll``) every ``refit_every``
     steps; in between, the previous hyperparameters are kept (warm) and only the data change,
     which is what makes 100 evaluations in 36-72 D fit the time budget;
   * ensemble weights w_t from the evidence (eq. 16) and a model m_t ~ Cat(w_t) (eq. 17);
   * the next point maximizes m_t's EI (eqs. 14 / 17) over the feasible points of a box
     (:mod:`vp_planner.acquisition`): in ``trust_region`` mode, a TuRBO trust region about the
     incumbent (:mod:`vp_planner.trust_region`) that grows on success and shrinks on failure;
     in ``global`` mode (the paper's configuration), the whole cube.

Every step is recorded (:class:`StepRecord`: model drawn, weights, whether it improved the
incumbent, trust-region side, fit warnings, seconds). Numerical safeguards: a non-finite
objective value is a failed evaluation (never the best; the GP sees the worst finite value);
constant data (e.g. all rewards 0) skips the fit and queries a random feasible point; a model
that cannot be fitted or evaluated gets weight 0.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, Optional

import torch
from torch import Tensor

from .acquisition import AcquisitionSettings, feasible_mask, propose
from .gp import (MODEL_NAMES, SINGLE_MODEL_NAME, draw_model, ensemble_weights, fit_model, get_hypers,
                 lengthscales, log_evidence, make_model, set_hypers)
from .trust_region import TrustRegion

__all__ = ["MODES", "BOSettings", "BOResult", "StepRecord", "NoFeasiblePointError", "optimize"]

Objective = Callable[[Tensor], Tensor]
Feasible = Callable[[Tensor], Tensor]
Callback = Callable[[int, int, float, Optional[list]], bool]

#: Where EI is maximized: in a trust region about the incumbent, or over the whole cube (paper).
MODES: tuple[str, ...] = ("trust_region", "global")


class NoFeasiblePointError(ValueError):
    """Rejection sampling found no (or not enough) feasible points."""


@dataclass
class BOSettings:
    """Knobs of :func:`optimize` (the defaults are what ``bench/bench_planners.py`` supports).

    Attributes:
        mode: ``'trust_region'`` or ``'global'`` (the paper's: EI over the whole cube).
        refit_every: full hyperparameter fit every this many BO steps (1: every step).
        fit_maxiter: L-BFGS-B iterations of a fit.
        acquisition: the acquisition maximization's budgets.
        trust_region: the initial trust-region state (copied per run).
        max_rejection_draws: cap on points drawn by rejection sampling for one request.
    """

    mode: str = "trust_region"
    refit_every: int = 5
    fit_maxiter: int = 150
    acquisition: AcquisitionSettings = field(default_factory=AcquisitionSettings)
    trust_region: TrustRegion = field(default_factory=TrustRegion)
    max_rejection_draws: int = 1 << 17

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f"unknown BO mode {self.mode!r}; one of {', '.join(MODES)}")
        if int(self.refit_every) < 1:
            raise ValueError(f"refit_every must be >= 1, got {self.refit_every}")


@dataclass
class StepRecord:
    """One BO step: evaluation index, model drawn (-1: random point), weights, improvement, the
    trust-region side before the step (None in global mode), refit or not, fit warnings, seconds."""

    evaluation: int
    model: int
    weights: list
    improved: bool
    trust_region: Optional[float]
    refit: bool
    fit_warnings: int
    fit_seconds: float
    acq_seconds: float

    def as_dict(self, names: list) -> dict:
        return {"evaluation": self.evaluation, "model": names[self.model] if self.model >= 0 else None,
                "weights": [round(w, 6) for w in self.weights], "improved": self.improved,
                "trust_region": self.trust_region, "refit": self.refit, "fit_warnings": self.fit_warnings}


@dataclass
class BOResult:
    """Outcome of :func:`optimize`.

    Attributes:
        X: (E, d) evaluated points in evaluation order; y: (E,) values (NaN where failed).
        best_x, best_y: the best valid (finite, feasible) point and value (NaN / -inf if none).
        trace: (E,) best-so-far valid value after each evaluation.
        steps: a :class:`StepRecord` per BO step.
        model_names: the models (MODEL_NAMES, or (SINGLE_MODEL_NAME,)).
        stopped: the callback cancelled the run.
        valid: (E,) finite value and feasible point.
        n_initial: evaluations of the initial design; best_initial: its best valid value.
        fit_seconds, acq_seconds: time spent fitting GPs and choosing candidates.
    """

    X: Tensor
    y: Tensor
    best_x: Tensor
    best_y: float
    trace: Tensor
    steps: list = field(default_factory=list)
    model_names: list = field(default_factory=list)
    stopped: bool = False
    valid: Optional[Tensor] = None
    n_initial: int = 0
    best_initial: float = -math.inf
    fit_seconds: float = 0.0
    acq_seconds: float = 0.0

    @property
    def weights(self) -> list:
        """The ensemble weights of every BO step."""
        return [s.weights for s in self.steps]

    @property
    def draws(self) -> list:
        """The model drawn at every BO step (-1: a random point)."""
        return [s.model for s in self.steps]


class _Sampler:
    """Seeded scrambled-Sobol sampler of [0, 1]^d with rejection by a feasibility predicate."""

    def __init__(self, dim: int, gen: torch.Generator, feasible: Optional[Feasible], max_draws: int):
        from torch.quasirandom import SobolEngine

        seed = int(torch.randint(0, 2**31 - 1, (1,), generator=gen))
        self.engine = SobolEngine(dim, scramble=True, seed=seed)
        self.feasible = feasible
        self.max_draws = int(max_draws)

    def draw(self, n: int) -> Tensor:
        """n feasible points, or NoFeasiblePointError."""
        if n <= 0:
            return torch.zeros(0, self.engine.dimension, dtype=torch.float64)
        got: list[Tensor] = []
        count, drawn, chunk = 0, 0, max(64, 2 * n)
        while count < n and drawn < self.max_draws:
            U = self.engine.draw(chunk, dtype=torch.float64)
            drawn += chunk
            ok = feasible_mask(self.feasible, U)
            got.append(U[ok][: n - count])
            count += int(ok.sum().clamp(max=n - count))
            rate = max(float(ok.double().mean()), 1.0 / chunk)
            chunk = int(min(max(64, 1.2 * (n - count) / rate), 8192, max(self.max_draws - drawn, 1)))
        if count < n:
            raise NoFeasiblePointError(f"only {count} of {n} feasible points in {drawn} random draws")
        return torch.cat(got)[:n]


def _evaluate(objective: Objective, U: Tensor) -> Tensor:
    y = torch.as_tensor(objective(U.clone())).detach().to(dtype=torch.float64, device="cpu").reshape(-1)
    if y.shape[0] != U.shape[0]:
        raise ValueError(f"objective returned {y.shape[0]} values for {U.shape[0]} points")
    return y


def _train_targets(y: Tensor) -> Tensor:
    """Outputs for the GP: failed (non-finite) values replaced by the worst finite value (or 0)."""
    fin = torch.isfinite(y)
    fill = float(y[fin].min()) if fin.any() else 0.0
    return torch.where(fin, y, torch.full_like(y, fill))


def _check_int(name: str, v, lo: int) -> int:
    if isinstance(v, bool) or int(v) != v or v < lo:
        raise ValueError(f"{name} must be an integer >= {lo}, got {v}")
    return int(v)


def optimize(objective: Objective, dim: int, evaluations: int = 100, initial_evaluations: int = 50,
             seed: int = 0, ensemble: bool = True, feasible: Optional[Feasible] = None,
             initial_design: Optional[Tensor] = None, callback: Optional[Callback] = None, *,
             settings: Optional[BOSettings] = None, init_batch: Optional[int] = None,
             periodic: Optional[Tensor] = None, groups: Optional[Tensor] = None) -> BOResult:
    r"""Maximize ``objective`` over [0, 1]^dim with EGP-EI (``ensemble=True``) or GP-EI.

    Args:
        objective: ``objective(U)`` for U (B, dim) float64 -> (B,) values. Called once per BO
            step with B = 1; the initial design in batches of ``init_batch`` (default: all).
        dim: d >= 1. evaluations: total E (initial design included). initial_evaluations: n0.
        seed: seed of the run's own torch generator (same seed and inputs -> same result).
        feasible: ``feasible(U)`` -> bool (B,); None = the whole cube is feasible.
        initial_design: (m, dim) points evaluated first, m <= n0 (the rest random).
        callback: ``callback(done, total, best, weights) -> bool`` after every evaluation
            (weights: the latest ensemble weights, None before the first BO step or for one GP);
            False stops the run at once (``stopped=True``).
        settings: :class:`BOSettings`. init_batch: evaluations per objective call in the design.
        periodic: bool (dim,) coordinates that are periodic (the trust region may leave [0, 1]
            along them; ``objective`` and ``feasible`` must wrap them).
        groups: int (dim,) kind of every coordinate (trust-region candidates also move all
            coordinates of one kind together, see :mod:`vp_planner.acquisition`).

    Raises:
        ValueError for bad arguments; :class:`NoFeasiblePointError` when the random initial
        design cannot find enough feasible points.
    """
    s = settings or BOSettings()
    dim = _check_int("dim", dim, 1)
    E = _check_int("evaluations", evaluations, 1)
    n0 = min(_check_int("initial_evaluations", initial_evaluations, 1), E)
    D0 = torch.zeros(0, dim, dtype=torch.float64)
    if initial_design is not None:
        D0 = torch.as_tensor(initial_design, dtype=torch.float64).detach().cpu().reshape(-1, dim)
        if D0.shape[0] > int(initial_evaluations):
            raise ValueError(f"initial_design has {D0.shape[0]} points > initial_evaluations = {initial_evaluations}")
        if not torch.isfinite(D0).all():
            raise ValueError("initial_design has non-finite entries")
        D0 = D0[:n0]
    per = torch.zeros(dim, dtype=torch.bool) if periodic is None else torch.as_tensor(periodic).reshape(dim).bool()
    grp = None if groups is None else torch.as_tensor(groups).reshape(dim).long()
    return _Run(objective, dim, E, n0, int(seed), bool(ensemble), feasible, callback, s, per, grp).run(D0, init_batch)


class _Run:
    """The state of one optimization (kept together so that the loop reads as the paper's steps)."""

    def __init__(self, objective, dim, E, n0, seed, ensemble, feasible, callback, s: BOSettings, periodic, groups):
        self.objective, self.dim, self.E, self.n0 = objective, dim, E, n0
        self.feasible, self.callback, self.s, self.periodic, self.groups = feasible, callback, s, periodic, groups
        self.gen = torch.Generator().manual_seed(seed)
        self.sampler = _Sampler(dim, self.gen, feasible, s.max_rejection_draws)
        self.names = list(MODEL_NAMES) if ensemble else [SINGLE_MODEL_NAME]
        self.ensemble = ensemble
        self.X = torch.zeros(E, dim, dtype=torch.float64)
        self.y = torch.full((E,), math.nan, dtype=torch.float64)
        self.valid = torch.zeros(E, dtype=torch.bool)
        self.trace = torch.full((E,), -math.inf, dtype=torch.float64)
        self.n, self.best, self.best_i = 0, -math.inf, -1
        self.weights: Optional[list] = None
        self.stopped = False
        self.steps: list[StepRecord] = []
        self.hypers: list = [None] * len(self.names)
        self.tr = TrustRegion(**{k: getattr(s.trust_region, k) for k in ("length", "length_init", "length_min",
                                 "length_max", "success_tolerance", "failure_tolerance")})
        self.fit_s = self.acq_s = 0.0

    def record(self, U: Tensor, vals: Tensor, ok: Tensor) -> bool:
        for k in range(U.shape[0]):
            i = self.n
            self.X[i], self.y[i] = U[k], vals[k]
            self.valid[i] = bool(ok[k]) and math.isfinite(float(vals[k]))
            if self.valid[i] and float(vals[k]) > self.best:
                self.best, self.best_i = float(vals[k]), i
            self.trace[i] = self.best
            self.n = i + 1
            if self.callback is not None and self.callback(i + 1, self.E, self.best, self.weights) is False:
                self.stopped = True
                return False
        return True

    def fit(self, Xn: Tensor, yt: Tensor, refit: bool) -> tuple[list, list, int]:
        """Models (None where unusable), their log evidences, the number of fit warnings."""
        models: list = [None] * len(self.names)
        le = [-math.inf] * len(self.names)
        n_warn = 0
        for m, name in enumerate(self.names):
            model = make_model(name, Xn, yt)
            if refit or self.hypers[m] is None:
                rep = fit_model(model, self.s.fit_maxiter, start=self.hypers[m])
                n_warn += len(rep.warnings)
            else:
                set_hypers(model, self.hypers[m])
                model.eval()
            le[m] = log_evidence(model)
            if math.isfinite(le[m]):
                self.hypers[m] = get_hypers(model)
                models[m] = model
        return models, le, n_warn

    def step(self) -> bool:
        n = self.n
        Xn, yn, vn = self.X[:n], self.y[:n], self.valid[:n]
        yt = _train_targets(yn)
        t0 = time.perf_counter()
        constant = not bool((yt.max() - yt.min()) > 1e-12 * max(1.0, float(yt.abs().max())))
        k = len(self.steps)
        refit = k % self.s.refit_every == 0
        models, le, n_warn = ([None] * len(self.names), [-math.inf] * len(self.names), 0) if constant \
            else self.fit(Xn, yt, refit)
        t1 = time.perf_counter()
        M = len(self.names)
        w = ensemble_weights(le) if not constant else torch.full((M,), 1.0 / M, dtype=torch.float64)
        usable = any(mm is not None for mm in models)
        m_t = (draw_model(w, self.gen) if self.ensemble else 0) if usable else -1
        if m_t >= 0 and models[m_t] is None:
            m_t = -1
        if self.ensemble:
            self.weights = [float(v) for v in w]
        tr_len = self.tr.length if self.s.mode == "trust_region" else None
        x = None
        if m_t >= 0:
            best_f = float(yt[vn].max()) if vn.any() else float(yt.max())
            if self.s.mode == "trust_region" and self.best_i >= 0:
                center = self.X[self.best_i]
                bounds = self.tr.bounds(center, lengthscales(models[m_t], self.dim), self.periodic)
            else:
                center = None
                bounds = torch.stack([torch.zeros(self.dim), torch.ones(self.dim)]).to(torch.float64)
            x = propose(models[m_t], best_f, bounds, Xn, yt, vn, self.feasible, self.gen, self.s.acquisition, center,
                        self.groups)
        if x is None:
            x = self._random_point()
            m_t = -1
        t2 = time.perf_counter()
        self.fit_s += t1 - t0
        self.acq_s += t2 - t1
        before = self.best
        U = x.reshape(1, self.dim).clone()
        go_on = self.record(U, _evaluate(self.objective, U), feasible_mask(self.feasible, U))
        improved = self.best > before + 1e-3 * abs(before) if math.isfinite(before) else self.best > before
        if self.s.mode == "trust_region":
            self.tr.update(improved)
        self.steps.append(StepRecord(evaluation=self.n, model=m_t, weights=[float(v) for v in w],
                                     improved=bool(improved), trust_region=tr_len, refit=bool(refit and not constant),
                                     fit_warnings=n_warn, fit_seconds=t1 - t0, acq_seconds=t2 - t1))
        return go_on

    def _random_point(self) -> Tensor:
        try:
            return self.sampler.draw(1)[0]
        except NoFeasiblePointError:
            if self.valid[: self.n].any():
                return self.X[self.best_i].clone()
            raise

    def run(self, D0: Tensor, init_batch: Optional[int]) -> BOResult:
        n_rand = self.n0 - D0.shape[0]
        R = self.sampler.draw(n_rand) if n_rand > 0 else D0[:0]
        ok0 = torch.cat([feasible_mask(self.feasible, D0), torch.ones(R.shape[0], dtype=torch.bool)])
        U0 = torch.cat([D0, R])
        bs = U0.shape[0] if not init_batch else max(1, int(init_batch))
        running = True
        for a in range(0, U0.shape[0], bs):
            if not self.record(U0[a:a + bs], _evaluate(self.objective, U0[a:a + bs]), ok0[a:a + bs]):
                running = False
                break
        best_initial = self.best
        while running and self.n < self.E:
            running = self.step()
        n, bi = self.n, self.best_i
        return BOResult(
            X=self.X[:n].clone(), y=self.y[:n].clone(),
            best_x=self.X[bi].clone() if bi >= 0 else torch.full((self.dim,), math.nan, dtype=torch.float64),
            best_y=float(self.best), trace=self.trace[:n].clone(), steps=self.steps, model_names=self.names,
            stopped=self.stopped, valid=self.valid[:n].clone(), n_initial=min(n, self.n0),
            best_initial=float(best_initial), fit_seconds=self.fit_s, acq_seconds=self.acq_s)
