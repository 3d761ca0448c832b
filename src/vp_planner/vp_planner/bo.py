r"""Bayesian optimization on the unit cube: single-GP EI (paper Sec. IV-A) and EGP-EI (Sec. IV-B).

Plain, ROS-free library code. The search space is :math:`\mathcal Z = [0, 1]^d` (callers map
their own parameterization onto the unit cube); the objective :math:`\tilde r` is a black box
that is *maximized*.

Surrogates (eqs. 8-11)
----------------------
Every surrogate is a BoTorch :class:`~botorch.models.SingleTaskGP`: a GP with a constant mean
(about 0 after standardization, the paper's zero-mean prior), a kernel :math:`\kappa^m`, white
Gaussian noise :math:`\sigma_n^2`, trained on the outputs standardized to zero mean and unit
variance (``Standardize`` outcome transform). Its posterior at :math:`\mathbf z` is Gaussian with

.. math::
    \mu_t(\mathbf z) = \mathbf k_t^\top(\mathbf z)(\mathbf K_t + \sigma_n^2 \mathbf I_t)^{-1}\mathbf y_t,
    \qquad
    \sigma_t^2(\mathbf z) = \kappa(\mathbf z, \mathbf z)
        - \mathbf k_t^\top(\mathbf z)(\mathbf K_t + \sigma_n^2\mathbf I_t)^{-1}\mathbf k_t(\mathbf z)
    \qquad \text{(eqs. 10a, 10b)}

(reported on the original scale of :math:`\tilde r`). The ensemble's :data:`MODEL_NAMES`
(paper Sec. V) are ``ScaleKernel(base)`` with base

* ``RBF``: isotropic RBF, :math:`\exp(-\lVert \mathbf z - \mathbf z'\rVert^2 / 2\ell^2)`;
* ``RBF-ARD``: RBF with one lengthscale per input dimension (automatic relevance determination);
* ``Matern-2.5`` and ``Matern-1.5``: isotropic Matern kernels with :math:`\nu = 5/2, 3/2`
  (the paper lists ARD only for the RBF).

All use the same hyperpriors, so that no model is favoured by its prior: lengthscales
:math:`\ell \sim \mathrm{LogNormal}(\sqrt2 + \tfrac12\log d, \sqrt3)` (the dimension-scaled prior
of Hvarfner et al. 2024, BoTorch's default; :math:`\ell \ge 0.025`), outputscale
:math:`\sim \mathrm{LogNormal}(0, 1)` (the data are standardized), noise
:math:`\sigma_n^2 \sim \mathrm{LogNormal}(-4, 1)`, :math:`\sigma_n^2 \ge 10^{-4}` (BoTorch's default).
The single-GP method (``ensemble=False``) uses ``Matern-2.5-ARD``: ``ScaleKernel(Matern`` with
:math:`\nu = 5/2` and ARD) with the same priors. This is the *classic* BoTorch default kernel; note
that BoTorch >= 0.12 changed the default of ``SingleTaskGP`` to an ARD RBF kernel without an
outputscale (``make_model("BoTorch-default", ...)`` builds that one).

Fitting (paper Sec. V: "maximizing the marginal log-likelihood via GPyTorch and BoTorch")
---------------------------------------------------------------------------------------
Hyperparameters :math:`\theta^m` are fitted by L-BFGS-B (BoTorch's ``fit_gpytorch_mll_scipy``)
on GPyTorch's ``ExactMarginalLogLikelihood`` (which includes the log hyperprior densities, i.e.
a MAP fit, as in BoTorch). To keep 50 BO steps x 4 models within budget the fit is *warm-started*
from the previous step's hyperparameters of the same model and capped at
:attr:`BOSettings.fit_maxiter` iterations (:attr:`BOSettings.fit_maxiter_initial` for the first
fit of a run, which starts at the prior modes). A failed fit (e.g. a non-PSD matrix) is caught:
the model falls back to the previous hyperparameters (or the prior modes) with a
``RuntimeWarning``.

Ensemble weights (eq. 16) and model draw (eq. 17)
--------------------------------------------------
The evidence of model :math:`m` is the exact log marginal likelihood of the standardized data
under its fitted hyperparameters, *without* hyperprior terms,

.. math::
    \log p(\mathcal D_t \mid m) = \log \mathcal N(\mathbf y_t; \mu^m \mathbf 1,
        \mathbf K_t^m + (\sigma_n^m)^2 \mathbf I_t)
    = -\tfrac12 \mathbf r^\top \mathbf C^{-1}\mathbf r - \tfrac12\log\lvert\mathbf C\rvert
      - \tfrac t2 \log 2\pi

(GPyTorch's ``ExactMarginalLogLikelihood`` returns this divided by :math:`t` plus prior terms;
we evaluate ``likelihood(model(X)).log_prob(y)`` directly, i.e. the sum). Standardizing the
outputs multiplies every model's likelihood by the same Jacobian, which cancels in the weights

.. math::
    w_t^m = \frac{p(\mathcal D_t\mid m)\, w_0^m}{\sum_{m'} p(\mathcal D_t\mid m')\, w_0^{m'}}
    \qquad \text{(eq. 16)},

computed in log space with ``logsumexp`` (:func:`ensemble_weights`), :math:`w_0` uniform. Then
:math:`m_t \sim \mathrm{Cat}(\mathcal M, \mathbf w_t)` is drawn with the run's seeded generator,
and the next query maximizes the expected improvement of model :math:`m_t` (eq. 17; eq. 14 for the
single GP)

.. math::
    \mathbf z_{t+1} = \arg\max_{\mathbf z \in [0,1]^d}
        \Delta_t(\mathbf z)\,\Phi\!\left(\frac{\Delta_t(\mathbf z)}{\sigma_t(\mathbf z)}\right)
        + \sigma_t(\mathbf z)\,\phi\!\left(\frac{\Delta_t(\mathbf z)}{\sigma_t(\mathbf z)}\right),
    \qquad \Delta_t(\mathbf z) = \mu_t(\mathbf z) - \max_{\tau \le t} y_\tau .

We maximize BoTorch's analytic ``LogExpectedImprovement``: the logarithm of the same EI, which
has the same maximizer but does not underflow to 0 (and keeps useful gradients) far from the
incumbent.

Acquisition optimization and feasibility
-----------------------------------------
A pool of ``raw_samples`` scrambled Sobol points plus perturbations of the best observed points
is scored; ``num_restarts`` starting points are taken from it (half the best, half by Boltzmann
sampling on the scores, with the run's generator) and refined by L-BFGS-B within
:math:`[0, 1]^d` (BoTorch's ``gen_candidates_scipy``, the engine of ``optimize_acqf``). With a
``feasible`` predicate the candidate is chosen in this order:

1. the best *feasible* refined restart (by acquisition value);
2. else the best feasible point of the scored pool (checked in acquisition order, in chunks);
3. else a projection: the point closest to the best restart on the segment from the nearest
   feasible observed point to it (32 points of the segment checked at once);
4. else a random feasible point (rejection sampling, as for the initial design), or, if none is
   found, the best valid observation again.

So every point queried after the initial design is feasible; the initial random design is drawn
by rejection from scrambled Sobol points. Points of a user's ``initial_design`` are evaluated as
given; infeasible ones are never reported as the best.

Numerical safeguards
--------------------
* A non-finite objective value (NaN, +-inf) is a *failed evaluation*: it is kept as NaN in
  :attr:`BOResult.y`, never counts as the best, and the GP sees it as the worst finite value
  observed so far (0 when none is finite), so the model learns to avoid the region.
* Constant data (all training outputs equal, e.g. all rewards 0): no GP is fitted; the step
  queries a random feasible point, records the prior weights and ``draw = -1``.
* Failed fits fall back to earlier hyperparameters (see above); a model whose evidence cannot be
  computed gets weight 0; if none can, the weights are the prior and the candidate is random.
"""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from typing import Callable, Optional, Sequence

import torch
from torch import Tensor

__all__ = [
    "MODEL_NAMES",
    "SINGLE_MODEL_NAME",
    "BOResult",
    "BOSettings",
    "NoFeasiblePointError",
    "ensemble_weights",
    "make_model",
    "fit_model",
    "map_loss_fn",
    "log_evidence",
    "optimize",
]

#: The ensemble's models (paper Sec. V), in the order of :attr:`BOResult.weights`.
MODEL_NAMES: tuple[str, ...] = ("RBF", "RBF-ARD", "Matern-2.5", "Matern-1.5")
#: The single-GP method's model (Sec. IV-A).
SINGLE_MODEL_NAME: str = "Matern-2.5-ARD"

Objective = Callable[[Tensor], Tensor]
Feasible = Callable[[Tensor], Tensor]
Callback = Callable[[int, int, float, Optional[list]], bool]


class NoFeasiblePointError(ValueError):
    """Rejection sampling found no (or not enough) feasible points."""


@dataclass
class BOSettings:
    """Tuning knobs of :func:`optimize` (the defaults meet the project's time budget).

    Attributes:
        fit_maxiter_initial: L-BFGS-B iterations of a model's first fit (from the prior modes).
        fit_maxiter: L-BFGS-B iterations of a warm-started refit.
        num_restarts: acquisition restarts refined by L-BFGS-B.
        raw_samples: Sobol points scored to pick the restarts.
        acq_maxiter: L-BFGS-B iterations per acquisition restart.
        local_samples: perturbed copies of the best observed points added to the pool.
        max_rejection_draws: cap on points drawn by rejection sampling for one request.
        num_threads: torch intra-op threads during the run (restored after); None leaves them.
    """

    fit_maxiter_initial: int = 150
    fit_maxiter: int = 40
    num_restarts: int = 6
    raw_samples: int = 384
    acq_maxiter: int = 60
    local_samples: int = 128
    max_rejection_draws: int = 1 << 17
    num_threads: Optional[int] = None


@dataclass
class BOResult:
    """Outcome of :func:`optimize`.

    Attributes:
        X: (E, dim) evaluated points, in evaluation order (E < evaluations when stopped).
        y: (E,) objective values (NaN where the evaluation failed).
        best_x: (dim,) best valid (finite and feasible) point (NaN if none).
        best_y: its value (-inf if none).
        trace: (E,) best-so-far valid value after each evaluation (nondecreasing; -inf before
            the first valid one).
        weights: per BO step, the ensemble weights w_t (length M; ensemble only, else empty).
        draws: per BO step, the drawn model index m_t (eq. 17; -1 when the step queried a random
            point because no model could be used; single GP: always 0).
        model_names: names of the models (MODEL_NAMES, or (SINGLE_MODEL_NAME,)).
        stopped: True when the callback cancelled the run.
        fit_seconds: total time spent fitting GPs.
        acq_seconds: total time spent choosing candidates (acquisition optimization and
            feasibility handling, excluding feasibility of the initial design).
        log_evidences: per BO step, log p(D_t | m) of every model (ensemble only).
        valid: (E,) bool, finite value and feasible point.
        n_initial: evaluations of the initial design.
    """

    X: Tensor
    y: Tensor
    best_x: Tensor
    best_y: float
    trace: Tensor
    weights: list = field(default_factory=list)
    draws: list = field(default_factory=list)
    model_names: list = field(default_factory=list)
    stopped: bool = False
    fit_seconds: float = 0.0
    acq_seconds: float = 0.0
    log_evidences: list = field(default_factory=list)
    valid: Optional[Tensor] = None
    n_initial: int = 0


# ---------------------------------------------------------------------- weights (eq. 16)
def ensemble_weights(log_evidences: Sequence[float] | Tensor,
                     log_prior: Optional[Sequence[float] | Tensor] = None) -> Tensor:
    r"""Posterior model weights :math:`w^m \propto p(\mathcal D\mid m)\, w_0^m` (eq. 16).

    Computed in log space: :math:`w = \exp(\ell + \log w_0 - \mathrm{logsumexp}(\ell + \log w_0))`.

    Args:
        log_evidences: (M,) :math:`\log p(\mathcal D\mid m)`; NaN counts as :math:`-\infty`
            (weight 0).
        log_prior: (M,) :math:`\log w_0^m` (need not be normalized); None = uniform.

    Returns:
        (M,) float64 weights summing to 1. If no model has a finite evidence the (normalized)
        prior is returned.
    """
    le = torch.as_tensor(log_evidences, dtype=torch.float64).reshape(-1).clone()
    if le.numel() == 0:
        raise ValueError("log_evidences is empty")
    if log_prior is None:
        lp = torch.full_like(le, -math.log(le.numel()))
    else:
        lp = torch.as_tensor(log_prior, dtype=torch.float64).reshape(-1)
        if lp.shape != le.shape:
            raise ValueError(f"log_prior has shape {tuple(lp.shape)}, expected {tuple(le.shape)}")
        if torch.isnan(lp).any() or torch.isposinf(lp).any() or torch.isneginf(lp).all():
            raise ValueError("log_prior must be finite or -inf, with some finite entry")
    le = torch.nan_to_num(le, nan=-math.inf)
    if torch.isposinf(le).any():  # an infinite evidence takes all the weight (shared equally)
        le = torch.where(torch.isposinf(le), torch.zeros_like(le), torch.full_like(le, -math.inf))
    s = le + lp
    if not torch.isfinite(s).any():
        s = lp.clone()
    return torch.softmax(s, dim=0)


# ---------------------------------------------------------------------- models
def _covar_module(name: str, dim: int):
    from gpytorch.constraints import GreaterThan
    from gpytorch.kernels import MaternKernel, RBFKernel, ScaleKernel
    from gpytorch.priors import LogNormalPrior

    ls_prior = LogNormalPrior(math.sqrt(2.0) + 0.5 * math.log(dim), math.sqrt(3.0))
    kw = dict(lengthscale_prior=ls_prior,
              lengthscale_constraint=GreaterThan(2.5e-2, transform=None, initial_value=ls_prior.mode))
    if name == "RBF":
        base = RBFKernel(**kw)
    elif name == "RBF-ARD":
        base = RBFKernel(ard_num_dims=dim, **kw)
    elif name == "Matern-2.5":
        base = MaternKernel(nu=2.5, **kw)
    elif name == "Matern-1.5":
        base = MaternKernel(nu=1.5, **kw)
    elif name == "Matern-2.5-ARD":
        base = MaternKernel(nu=2.5, ard_num_dims=dim, **kw)
    else:
        raise ValueError(f"unknown model {name!r}; one of {MODEL_NAMES + (SINGLE_MODEL_NAME, 'BoTorch-default')}")
    os_prior = LogNormalPrior(0.0, 1.0)
    return ScaleKernel(base, outputscale_prior=os_prior,
                       outputscale_constraint=GreaterThan(1e-4, transform=None, initial_value=1.0))


def make_model(name: str, X: Tensor, Y: Tensor):
    """A BoTorch SingleTaskGP named ``name`` on data X (n, d) in [0, 1]^d, Y (n,) or (n, 1).

    ``name`` is one of :data:`MODEL_NAMES`, ``"Matern-2.5-ARD"`` (the single-GP model) or
    ``"BoTorch-default"`` (BoTorch's own default kernel). Outputs are standardized (``Standardize``
    outcome transform); hyperparameters start at the prior modes (see the module docstring).
    """
    from botorch.models import SingleTaskGP
    from botorch.models.transforms.outcome import Standardize

    X = torch.as_tensor(X, dtype=torch.float64)
    Y = torch.as_tensor(Y, dtype=torch.float64).reshape(-1, 1)
    if X.ndim != 2 or X.shape[0] != Y.shape[0]:
        raise ValueError(f"X must be (n, d) and Y (n,), got {tuple(X.shape)} and {tuple(Y.shape)}")
    covar = None if name == "BoTorch-default" else _covar_module(name, X.shape[-1])
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*not standardized.*")
        warnings.filterwarnings("ignore", message=".*not contained to the unit cube.*")
        return SingleTaskGP(X, Y, covar_module=covar, outcome_transform=Standardize(m=1))


def _get_hypers(model) -> dict[str, Tensor]:
    return {n: p.detach().clone() for n, p in model.named_parameters()}


def _set_hypers(model, hypers: Optional[dict[str, Tensor]]) -> None:
    if not hypers:
        return
    with torch.no_grad():
        for n, p in model.named_parameters():
            if n in hypers and hypers[n].shape == p.shape:
                p.copy_(hypers[n])


def log_evidence(model) -> float:
    r""":math:`\log p(\mathcal D\mid m)`: exact log marginal likelihood (a sum over the n points, no
    hyperprior terms) of the model's (standardized) training targets under its current
    hyperparameters; -inf if it cannot be computed."""
    was_training = model.training
    model.train()
    try:
        with torch.no_grad():
            X = model.train_inputs[0]
            out = model.likelihood(model(X))
            val = float(out.log_prob(model.train_targets))
    except Exception:  # noqa: BLE001 - any numerical failure means "no evidence"
        val = -math.inf
    finally:
        model.train(was_training)
    return val if math.isfinite(val) else -math.inf


def _cholesky(C: Tensor) -> Tensor:
    """Cholesky factor of C, adding jitter 1e-8 .. 1e-4 (times the mean diagonal) if needed."""
    L, info = torch.linalg.cholesky_ex(C)
    if int(info) == 0:
        return L
    scale = float(C.diagonal().mean().detach())
    eye = torch.eye(C.shape[-1], dtype=C.dtype)
    for jitter in (1e-8, 1e-7, 1e-6, 1e-5, 1e-4):
        L, info = torch.linalg.cholesky_ex(C + jitter * scale * eye)
        if int(info) == 0:
            return L
    raise torch.linalg.LinAlgError("kernel matrix is not positive definite, even with jitter")


def map_loss_fn(model) -> Optional[Callable[[], Tensor]]:
    r"""A plain-torch version of GPyTorch's ``ExactMarginalLogLikelihood`` loss for our models.

    Returns ``loss()`` = :math:`-rac1nig[\log\mathcal N(\mathbf y; c\mathbf 1, s\,\mathbf K_\ell
    + \sigma_n^2\mathbf I) + \sum \log p(	heta)ig]` (the same value as ``-mll(model(X), y)``,
    checked in the tests) computed with one Cholesky factorization, about 3x faster than going
    through GPyTorch's lazy tensors; or None when ``model`` is not a ConstantMean +
    ScaleKernel(RBF | Matern 1.5/2.5) + Gaussian-noise GP with unenforced (identity) constraints,
    in which case the GPyTorch closure is used.
    """
    from gpytorch.kernels import MaternKernel, RBFKernel, ScaleKernel
    from gpytorch.likelihoods import GaussianLikelihood
    from gpytorch.means import ConstantMean
    from gpytorch.priors import LogNormalPrior

    cov, mean, lik = model.covar_module, model.mean_module, model.likelihood
    if not (isinstance(cov, ScaleKernel) and type(mean) is ConstantMean and type(lik) is GaussianLikelihood):
        return None
    base = cov.base_kernel
    if type(base) is RBFKernel:
        kind = "rbf"
    elif type(base) is MaternKernel and float(base.nu) in (1.5, 2.5):
        kind = f"m{float(base.nu)}"
    else:
        return None
    if base.active_dims is not None or getattr(model, "input_transform", None) is not None:
        return None
    cons = [cov.raw_outputscale_constraint, base.raw_lengthscale_constraint,
            lik.noise_covar.raw_noise_constraint]
    if any(c.enforced for c in cons):
        return None
    X = model.train_inputs[0]
    yv = model.train_targets
    n = X.shape[0]
    offdiag = 1.0 - torch.eye(n, dtype=X.dtype)
    eye = torch.eye(n, dtype=X.dtype)
    log2pi = math.log(2.0 * math.pi)
    priors = []  # (prior, closure, module, (mu, sigma) for a LogNormal prior, else None)
    for _, module, prior, closure_, _ in model.named_priors():
        ln = None
        if type(prior) is LogNormalPrior and prior.loc.numel() == 1 and prior.scale.numel() == 1:
            ln = (float(prior.loc), float(prior.scale))
        priors.append((prior, closure_, module, ln))

    def log_prior() -> Tensor:
        total = torch.zeros((), dtype=X.dtype)
        for prior, closure_, module, ln in priors:
            v = closure_(module)
            if ln is None:
                total = total + prior.log_prob(v).sum()
            else:  # log N(log v; mu, sigma^2) - log v, written out (torch.distributions is slow)
                lv = torch.log(v)
                total = total + (-lv - math.log(ln[1]) - 0.5 * log2pi
                                 - 0.5 * ((lv - ln[0]) / ln[1]) ** 2).sum()
        return total

    def loss() -> Tensor:
        Z = X / base.raw_lengthscale.reshape(1, -1)
        Z = Z - Z.mean(0, keepdim=True)
        sq = (Z * Z).sum(-1)
        D2 = (sq[:, None] + sq[None, :] - 2.0 * (Z @ Z.T)).clamp_min(0.0) * offdiag
        if kind == "rbf":
            k = torch.exp(-0.5 * D2)
        else:
            d = D2.clamp_min(1e-30).sqrt()
            if kind == "m2.5":
                k = (1.0 + math.sqrt(5.0) * d + (5.0 / 3.0) * D2) * torch.exp(-math.sqrt(5.0) * d)
            else:
                k = (1.0 + math.sqrt(3.0) * d) * torch.exp(-math.sqrt(3.0) * d)
        C = cov.raw_outputscale * k + lik.noise_covar.raw_noise.reshape(()) * eye
        L = _cholesky(C)
        r = (yv - mean.raw_constant).unsqueeze(-1)
        alpha = torch.cholesky_solve(r, L)
        ll = -0.5 * (r * alpha).sum() - torch.log(torch.diagonal(L)).sum() - 0.5 * n * log2pi
        return -(ll + log_prior()) / n

    return loss


def fit_model(model, maxiter: int, start: Optional[dict[str, Tensor]] = None) -> bool:
    """Fit ``model``'s hyperparameters by L-BFGS-B on GPyTorch's exact MLL (MAP with the priors).

    Uses BoTorch's ``fit_gpytorch_mll_scipy`` (one run, at most ``maxiter`` iterations, no
    random restarts) with the fast closure of :func:`map_loss_fn` when it applies.
    ``start``: hyperparameters to warm-start from (None: the model's current ones). On failure
    (exception or non-finite parameters) the start values are restored, a RuntimeWarning is
    issued and False is returned. The model is left in eval mode.
    """
    from botorch.exceptions.warnings import OptimizationWarning
    from botorch.optim.fit import fit_gpytorch_mll_scipy
    from botorch.optim.utils import get_parameters_and_bounds
    from gpytorch.mlls import ExactMarginalLogLikelihood

    _set_hypers(model, start)
    backup = _get_hypers(model)
    mll = ExactMarginalLogLikelihood(model.likelihood, model)
    ok = True
    try:
        mll.train()
        params = {k: p for k, p in get_parameters_and_bounds(mll)[0].items() if p.requires_grad}
        loss_fn = map_loss_fn(model)
        closure = None
        if loss_fn is not None:
            plist = list(params.values())

            def closure() -> tuple[Tensor, Sequence[Optional[Tensor]]]:
                with torch.enable_grad():
                    val = loss_fn()
                    grads = torch.autograd.grad(val, plist, allow_unused=True)
                return val.detach(), [torch.zeros_like(p) if g is None else g for p, g in zip(plist, grads)]

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", OptimizationWarning)
            fit_gpytorch_mll_scipy(mll, parameters=params, closure=closure,
                                   options={"maxiter": int(maxiter)})
        if not all(torch.isfinite(p).all() for p in model.parameters()):
            raise FloatingPointError("non-finite hyperparameters")
    except Exception as exc:  # noqa: BLE001 - fall back rather than crash the planner
        ok = False
        _set_hypers(model, backup)
        warnings.warn(f"GP fit failed ({type(exc).__name__}: {exc}); keeping the previous "
                      "hyperparameters", RuntimeWarning, stacklevel=2)
    model.eval()
    return ok


# ---------------------------------------------------------------------- helpers
class _Sampler:
    """Seeded scrambled-Sobol sampler of [0, 1]^d with rejection by a feasibility predicate."""

    def __init__(self, dim: int, gen: torch.Generator, feasible: Optional[Feasible], max_draws: int):
        from torch.quasirandom import SobolEngine

        seed = int(torch.randint(0, 2**31 - 1, (1,), generator=gen))
        self.engine = SobolEngine(dim, scramble=True, seed=seed)
        self.feasible = feasible
        self.max_draws = int(max_draws)

    def draw(self, n: int, min_ok: Optional[int] = None) -> Tensor:
        """n feasible points (fewer, but at least ``min_ok`` (default n), or raise)."""
        min_ok = n if min_ok is None else min_ok
        if n <= 0:
            return torch.zeros(0, self.engine.dimension, dtype=torch.float64)
        if self.feasible is None:
            return self.engine.draw(n, dtype=torch.float64)
        got: list[Tensor] = []
        count, drawn, chunk = 0, 0, max(64, 2 * n)
        while count < n and drawn < self.max_draws:
            U = self.engine.draw(chunk, dtype=torch.float64)
            drawn += chunk
            ok = _feasible_mask(self.feasible, U)
            got.append(U[ok][: n - count])
            count += int(ok.sum().clamp(max=n - count))
            rate = max(float(ok.double().mean()), 1.0 / chunk)
            chunk = int(min(max(64, 1.2 * (n - count) / rate), 8192, max(self.max_draws - drawn, 1)))
        if count < min_ok:
            raise NoFeasiblePointError(
                f"only {count} of {n} feasible points in {drawn} random draws")
        return torch.cat(got)[:n] if got else torch.zeros(0, self.engine.dimension, dtype=torch.float64)


def _feasible_mask(feasible: Optional[Feasible], U: Tensor) -> Tensor:
    if feasible is None:
        return torch.ones(U.shape[0], dtype=torch.bool)
    if U.shape[0] == 0:
        return torch.zeros(0, dtype=torch.bool)
    ok = torch.as_tensor(feasible(U)).reshape(-1).to(torch.bool)
    if ok.shape[0] != U.shape[0]:
        raise ValueError(f"feasible returned {ok.shape[0]} flags for {U.shape[0]} points")
    return ok


def _evaluate(objective: Objective, U: Tensor) -> Tensor:
    y = torch.as_tensor(objective(U.clone()))
    y = y.detach().to(dtype=torch.float64, device="cpu").reshape(-1)
    if y.shape[0] != U.shape[0]:
        raise ValueError(f"objective returned {y.shape[0]} values for {U.shape[0]} points")
    return y


def _train_targets(y: Tensor) -> Tensor:
    """Outputs for the GP: failed (non-finite) values replaced by the worst finite value (or 0)."""
    fin = torch.isfinite(y)
    fill = float(y[fin].min()) if fin.any() else 0.0
    return torch.where(fin, y, torch.full_like(y, fill))


def _pool(dim: int, X: Tensor, y_train: Tensor, valid: Tensor, s: BOSettings,
          gen: torch.Generator) -> Tensor:
    """Raw candidates: scrambled Sobol points + perturbations of the best valid observations."""
    from torch.quasirandom import SobolEngine

    seed = int(torch.randint(0, 2**31 - 1, (1,), generator=gen))
    parts = [SobolEngine(dim, scramble=True, seed=seed).draw(s.raw_samples, dtype=torch.float64)]
    if s.local_samples > 0 and valid.any():
        idx = torch.nonzero(valid).reshape(-1)
        order = idx[torch.argsort(y_train[idx], descending=True)][:5]
        centres = X[order]
        reps = centres[torch.arange(s.local_samples) % centres.shape[0]]
        # perturb about min(d, 10) coordinates of each copy (at least one) by N(0, 0.1^2)
        prob = min(1.0, 10.0 / dim)
        mask = torch.rand(reps.shape, generator=gen, dtype=torch.float64) < prob
        force = torch.randint(0, dim, (reps.shape[0],), generator=gen)
        mask[torch.arange(reps.shape[0]), force] = True
        noise = 0.1 * torch.randn(reps.shape, generator=gen, dtype=torch.float64)
        parts.append((reps + mask * noise).clamp(0.0, 1.0))
    return torch.cat(parts)


def _select_starts(values: Tensor, k: int, gen: torch.Generator) -> Tensor:
    """Indices of k starting points: the best half by value, the rest by Boltzmann sampling."""
    n = values.shape[0]
    k = min(k, n)
    order = torch.argsort(values, descending=True)
    n_top = (k + 1) // 2
    chosen = order[:n_top]
    rest = order[n_top:]
    if k > n_top and rest.numel() > 0:
        v = values[rest]
        v = torch.nan_to_num(v, nan=-math.inf, neginf=-math.inf)
        if torch.isfinite(v).any():
            z = (v - v[torch.isfinite(v)].mean()) / (v[torch.isfinite(v)].std().nan_to_num(0.0) + 1e-9)
            p = torch.softmax(torch.nan_to_num(z, neginf=-1e9), dim=0)
        else:
            p = torch.full_like(v, 1.0 / v.numel())
        pick = torch.multinomial(p, min(k - n_top, rest.numel()), replacement=False, generator=gen)
        chosen = torch.cat([chosen, rest[pick]])
    return chosen


def _propose(model, best_f: float, dim: int, X: Tensor, y_train: Tensor, valid: Tensor,
             feasible: Optional[Feasible], sampler: _Sampler, s: BOSettings,
             gen: torch.Generator) -> Tensor:
    """Maximize LogEI of ``model`` over [0, 1]^dim, returning a feasible point (see module doc)."""
    from botorch.acquisition.analytic import LogExpectedImprovement
    from botorch.exceptions.warnings import OptimizationWarning
    from botorch.generation.gen import gen_candidates_scipy

    acq = LogExpectedImprovement(model, best_f=best_f)
    pool = _pool(dim, X, y_train, valid, s, gen)
    with torch.no_grad():
        vals = torch.cat([acq(c.unsqueeze(1)) for c in pool.split(512)])
    vals = torch.nan_to_num(vals, nan=-math.inf)
    starts = pool[_select_starts(vals, s.num_restarts, gen)].unsqueeze(1)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", OptimizationWarning)
            cands, cvals = gen_candidates_scipy(starts, acq, lower_bounds=0.0, upper_bounds=1.0,
                                                options={"maxiter": int(s.acq_maxiter)})
        cands = cands.detach().reshape(-1, dim).clamp(0.0, 1.0)
        cvals = torch.nan_to_num(cvals.detach().reshape(-1), nan=-math.inf)
    except Exception as exc:  # noqa: BLE001 - fall back to the scored pool
        warnings.warn(f"acquisition optimization failed ({type(exc).__name__}: {exc}); "
                      "using the best raw candidate", RuntimeWarning, stacklevel=2)
        cands, cvals = starts.reshape(-1, dim), vals[_select_starts(vals, s.num_restarts, gen)]
    order = torch.argsort(cvals, descending=True)
    cands = cands[order]
    if feasible is None:
        return cands[0]
    # 1. best feasible refined restart
    ok = _feasible_mask(feasible, cands)
    if ok.any():
        return cands[torch.nonzero(ok)[0, 0]]
    # 2. best feasible point of the pool, in acquisition order
    pool_sorted = pool[torch.argsort(vals, descending=True)]
    for chunk in pool_sorted.split(64):
        okc = _feasible_mask(feasible, chunk)
        if okc.any():
            return chunk[torch.nonzero(okc)[0, 0]]
    # 3. projection onto the feasible set along the segment from the nearest feasible observation
    if valid.any():
        Xv = X[valid]
        anchor = Xv[torch.argmin(((Xv - cands[0]) ** 2).sum(-1))]
        t = torch.linspace(1.0, 0.0, 33, dtype=torch.float64)[:-1]  # excludes the anchor itself
        seg = anchor + t.unsqueeze(1) * (cands[0] - anchor)
        oks = _feasible_mask(feasible, seg)
        if oks.any():
            return seg[torch.nonzero(oks)[0, 0]]
    # 4. a random feasible point
    return _random_point(sampler, X, y_train, valid)


def _random_point(sampler: _Sampler, X: Tensor, y_train: Tensor, valid: Tensor) -> Tensor:
    """A random feasible point; if rejection sampling finds none, the best valid observation."""
    try:
        return sampler.draw(1)[0]
    except NoFeasiblePointError:
        if valid.any():
            idx = torch.nonzero(valid).reshape(-1)
            return X[idx[torch.argmax(y_train[idx])]].clone()
        raise


# ---------------------------------------------------------------------- main loop
def optimize(
    objective: Objective,
    dim: int,
    evaluations: int = 100,
    initial_evaluations: int = 50,
    seed: int = 0,
    ensemble: bool = True,
    feasible: Optional[Feasible] = None,
    initial_design: Optional[Tensor] = None,
    callback: Optional[Callback] = None,
    *,
    settings: Optional[BOSettings] = None,
    init_batch: Optional[int] = None,
) -> BOResult:
    r"""Maximize ``objective`` over [0, 1]^dim by BO: EGP-EI (``ensemble=True``, paper Sec. IV-B)
    or single-GP EI with a Matern-2.5 ARD kernel (``ensemble=False``, Sec. IV-A).

    The first ``initial_evaluations`` evaluations are ``initial_design`` (if given) followed by
    scrambled-Sobol random points (feasible ones by rejection when ``feasible`` is given); each
    later one is a BO step: fit the GP(s) on all data (weights by eq. 16 and draw
    :math:`m_t` by eq. 17 for the ensemble), maximize (Log)EI (eqs. 14 / 17), evaluate the point.

    Args:
        objective: ``objective(U)`` with U (B, dim) float64 in [0, 1]^dim -> (B,) values to
            maximize. Called once per BO step with B = 1; the initial design is evaluated in
            batches of ``init_batch`` (default: all at once). Exceptions propagate.
        dim: input dimension d >= 1.
        evaluations: total evaluations E (initial design included).
        initial_evaluations: size of the initial design n0 (capped at E), >= 1.
        seed: seed of the run's own torch generator (the global RNG is not used); same seed
            and inputs -> same result.
        ensemble: EGP-EI (True) or single GP-EI (False).
        feasible: ``feasible(U)`` -> bool (B,); None = every point of the cube is feasible.
        initial_design: optional (m, dim) points evaluated first, m <= n0 (the rest random).
        callback: ``callback(done, total, best, weights) -> bool`` after every evaluation
            (done = 1..E, total = E, best = best-so-far valid value, weights = the latest
            ensemble weights as a list, None before the first BO step or for a single GP).
            Returning False stops the run at once: the result holds the ``done`` evaluations
            made so far (rows of an initial batch after that one are dropped), ``stopped=True``.
        settings: :class:`BOSettings` (fit/acquisition budgets, threads).
        init_batch: evaluations per objective call in the initial design (None: all).

    Returns:
        :class:`BOResult`.

    Raises:
        ValueError for bad arguments; :class:`NoFeasiblePointError` (a ValueError) when the
        random initial design cannot find enough feasible points.
    """
    s = settings or BOSettings()
    if isinstance(dim, bool) or int(dim) != dim or dim < 1:
        raise ValueError(f"dim must be a positive integer, got {dim}")
    if isinstance(evaluations, bool) or int(evaluations) != evaluations or evaluations < 1:
        raise ValueError(f"evaluations must be a positive integer, got {evaluations}")
    if int(initial_evaluations) != initial_evaluations or initial_evaluations < 1:
        raise ValueError(f"initial_evaluations must be a positive integer, got {initial_evaluations}")
    dim, E = int(dim), int(evaluations)
    n0 = min(int(initial_evaluations), E)
    D0 = torch.zeros(0, dim, dtype=torch.float64)
    if initial_design is not None:
        D0 = torch.as_tensor(initial_design, dtype=torch.float64).detach().cpu()
        if D0.ndim == 1 and D0.numel() == dim:
            D0 = D0.reshape(1, dim)
        if D0.ndim != 2 or D0.shape[1] != dim:
            raise ValueError(f"initial_design must be (m, {dim}), got {tuple(D0.shape)}")
        if D0.shape[0] > int(initial_evaluations):
            raise ValueError(f"initial_design has {D0.shape[0]} points > initial_evaluations "
                             f"= {initial_evaluations}")
        if not torch.isfinite(D0).all():
            raise ValueError("initial_design has non-finite entries")
        D0 = D0.clamp(0.0, 1.0)[:n0]

    old_threads = torch.get_num_threads()
    if s.num_threads is not None:
        torch.set_num_threads(int(s.num_threads))
    try:
        return _run(objective, dim, E, n0, int(seed), bool(ensemble), feasible, D0, callback, s,
                    init_batch)
    finally:
        if s.num_threads is not None:
            torch.set_num_threads(old_threads)


def _run(objective: Objective, dim: int, E: int, n0: int, seed: int, ensemble: bool,
         feasible: Optional[Feasible], D0: Tensor, callback: Optional[Callback], s: BOSettings,
         init_batch: Optional[int]) -> BOResult:
    gen = torch.Generator().manual_seed(seed)
    sampler = _Sampler(dim, gen, feasible, s.max_rejection_draws)
    names = list(MODEL_NAMES) if ensemble else [SINGLE_MODEL_NAME]
    M = len(names)

    X = torch.zeros(E, dim, dtype=torch.float64)
    y = torch.full((E,), math.nan, dtype=torch.float64)
    valid = torch.zeros(E, dtype=torch.bool)
    trace = torch.full((E,), -math.inf, dtype=torch.float64)
    state = {"n": 0, "best": -math.inf, "best_i": -1, "weights": None, "stopped": False}
    weights_hist: list[list[float]] = []
    evid_hist: list[list[float]] = []
    draws: list[int] = []
    fit_s = acq_s = 0.0

    def record(U: Tensor, vals: Tensor, ok: Tensor) -> bool:
        """Store evaluations one by one, calling the callback; False when stopped."""
        for k in range(U.shape[0]):
            i = state["n"]
            X[i], y[i] = U[k], vals[k]
            valid[i] = bool(ok[k]) and math.isfinite(float(vals[k]))
            if valid[i] and float(vals[k]) > state["best"]:
                state["best"], state["best_i"] = float(vals[k]), i
            trace[i] = state["best"]
            state["n"] = i + 1
            if callback is not None:
                ret = callback(i + 1, E, state["best"], state["weights"])
                if ret is not None and not ret:
                    state["stopped"] = True
                    return False
        return True

    # ---- initial design: given points, then random feasible ones
    running = True
    n_rand = n0 - D0.shape[0]
    R = sampler.draw(n_rand) if n_rand > 0 else D0[:0]
    ok0 = torch.cat([_feasible_mask(feasible, D0), torch.ones(R.shape[0], dtype=torch.bool)])
    U0 = torch.cat([D0, R])
    bs = U0.shape[0] if not init_batch else max(1, int(init_batch))
    for a in range(0, U0.shape[0], bs):
        if not record(U0[a:a + bs], _evaluate(objective, U0[a:a + bs]), ok0[a:a + bs]):
            running = False
            break

    # ---- BO steps
    hypers: list[Optional[dict[str, Tensor]]] = [None] * M
    while running and state["n"] < E:
        n = state["n"]
        Xn, yn, vn = X[:n], y[:n], valid[:n]
        yt = _train_targets(yn)
        t0 = time.perf_counter()
        models: list = [None] * M
        le = [-math.inf] * M
        constant = not bool((yt.max() - yt.min()) > 1e-12 * max(1.0, float(yt.abs().max())))
        if not constant:
            for m, name in enumerate(names):
                try:
                    model = make_model(name, Xn, yt)
                except Exception as exc:  # noqa: BLE001
                    warnings.warn(f"could not build model {name} ({exc})", RuntimeWarning, stacklevel=2)
                    continue
                maxiter = s.fit_maxiter if hypers[m] is not None else s.fit_maxiter_initial
                fit_model(model, maxiter, start=hypers[m])
                le[m] = log_evidence(model)
                if math.isfinite(le[m]):
                    hypers[m] = _get_hypers(model)
                    models[m] = model
        t1 = time.perf_counter()
        fit_s += t1 - t0
        if ensemble:
            w = ensemble_weights(le) if not constant else torch.full((M,), 1.0 / M, dtype=torch.float64)
            weights_hist.append([float(v) for v in w])
            evid_hist.append([float(v) for v in le])
            state["weights"] = weights_hist[-1]
            m_t = int(torch.multinomial(w, 1, generator=gen)) if any(mm is not None for mm in models) else -1
        else:
            m_t = 0 if models[0] is not None else -1
        draws.append(m_t)
        if m_t >= 0 and models[m_t] is not None:
            best_f = float(yt[vn].max()) if vn.any() else float(yt.max())
            x = _propose(models[m_t], best_f, dim, Xn, yt, vn, feasible, sampler, s, gen)
        else:
            x = _random_point(sampler, Xn, yt, vn)
        acq_s += time.perf_counter() - t1
        U = x.reshape(1, dim).clone()
        if not record(U, _evaluate(objective, U), _feasible_mask(feasible, U)):
            break

    n = state["n"]
    bi = state["best_i"]
    return BOResult(
        X=X[:n].clone(), y=y[:n].clone(),
        best_x=X[bi].clone() if bi >= 0 else torch.full((dim,), math.nan, dtype=torch.float64),
        best_y=float(state["best"]), trace=trace[:n].clone(),
        weights=weights_hist, draws=draws, model_names=names, stopped=bool(state["stopped"]),
        fit_seconds=fit_s, acq_seconds=acq_s, log_evidences=evid_hist, valid=valid[:n].clone(),
        n_initial=min(n, n0),
    )
