r"""The GP surrogates of EGP-VP: the four kernels, their fit, the evidence and the ensemble weights.

Surrogates (paper eqs. 8-11)
----------------------------
Every surrogate is a BoTorch :class:`~botorch.models.SingleTaskGP`: a constant mean (about 0
after standardization, the paper's zero-mean prior), a kernel :math:`\kappa^m`, Gaussian noise
:math:`\sigma_n^2`, outputs standardized (``Standardize``). Its posterior is eqs. 10a-10b::

    mu_t(z)      = k_t(z)^T (K_t + sigma_n^2 I)^-1 y_t
    sigma_t^2(z) = kappa(z, z) - k_t(z)^T (K_t + sigma_n^2 I)^-1 k_t(z)

The ensemble's :data:`MODEL_NAMES` (paper Sec. V) are ``ScaleKernel(base)`` with base ``RBF``
(isotropic), ``RBF-ARD`` (one lengthscale per input), ``Matern-2.5`` and ``Matern-1.5``
(isotropic; the paper lists ARD only for the RBF). The single-GP method uses ``Matern-2.5-ARD``.
All share the same hyperpriors, so that no model is favoured by its prior: lengthscales
LogNormal(sqrt(2) + log(d) / 2, sqrt(3)) (the dimension-scaled prior of Hvarfner et al. 2024,
BoTorch's default; ell >= 0.025), outputscale LogNormal(0, 1), noise LogNormal(-4, 1) (>= 1e-4).

Fitting (paper Sec. V: "maximizing the marginal log-likelihood via GPyTorch and BoTorch")
----------------------------------------------------------------------------------------
:func:`fit_model` maximizes GPyTorch's ``ExactMarginalLogLikelihood`` (with the hyperprior
terms: a MAP fit, as BoTorch does) through BoTorch's :func:`~botorch.fit.fit_gpytorch_mll`,
which retries from prior samples when L-BFGS-B fails and reports its warnings; they are
counted in :class:`FitReport`, not silenced. A fit may start from earlier hyperparameters
(warm start), which is how :mod:`vp_planner.bo` refits cheaply between full fits.

Evidence and weights (eqs. 16, 17)
----------------------------------
The evidence of model m is the exact log marginal likelihood of the standardized data at its
fitted hyperparameters, without hyperprior terms,
log p(D_t | m) = log N(y_t; mu 1, K_t^m + sigma_n^2 I) (:func:`log_evidence`; GPyTorch's
``ExactMarginalLogLikelihood`` returns it divided by t plus the priors, so it is taken from
``likelihood(model(X)).log_prob(y)``). Standardizing multiplies every model's likelihood by
the same Jacobian, which cancels in w_t^m = p(D_t | m) w_0^m / sum_m' p(D_t | m') w_0^m'
(:func:`ensemble_weights`, in log space), w_0 uniform; :func:`draw_model` draws
m_t ~ Cat(M, w_t) (eq. 17).
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Optional, Sequence

import torch
from torch import Tensor

__all__ = ["MODEL_NAMES", "SINGLE_MODEL_NAME", "FitReport", "make_model", "fit_model", "log_evidence",
           "ensemble_weights", "draw_model", "lengthscales", "get_hypers", "set_hypers"]

#: The ensemble's models (paper Sec. V), in the order of the weights.
MODEL_NAMES: tuple[str, ...] = ("RBF", "RBF-ARD", "Matern-2.5", "Matern-1.5")
#: The single-GP method's model (Sec. IV-A).
SINGLE_MODEL_NAME: str = "Matern-2.5-ARD"


@dataclass
class FitReport:
    """How a fit went: success, the warnings BoTorch raised (messages), the fit's iterations cap."""

    ok: bool
    warnings: list
    maxiter: int


def _covar_module(name: str, dim: int):
    from gpytorch.constraints import GreaterThan
    from gpytorch.kernels import MaternKernel, RBFKernel, ScaleKernel
    from gpytorch.priors import LogNormalPrior

    ls_prior = LogNormalPrior(math.sqrt(2.0) + 0.5 * math.log(dim), math.sqrt(3.0))
    kw = dict(lengthscale_prior=ls_prior,
              lengthscale_constraint=GreaterThan(2.5e-2, initial_value=ls_prior.mode))
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
        raise ValueError(f"unknown model {name!r}; one of {MODEL_NAMES + (SINGLE_MODEL_NAME,)}")
    return ScaleKernel(base, outputscale_prior=LogNormalPrior(0.0, 1.0),
                       outputscale_constraint=GreaterThan(1e-4, initial_value=1.0))


def make_model(name: str, X: Tensor, Y: Tensor):
    """A SingleTaskGP named ``name`` on X (n, d), Y (n,) with standardized outputs and the
    shared hyperpriors; hyperparameters start at the prior modes."""
    from botorch.models import SingleTaskGP
    from botorch.models.transforms.outcome import Standardize
    from gpytorch.likelihoods import GaussianLikelihood
    from gpytorch.constraints import GreaterThan
    from gpytorch.priors import LogNormalPrior

    X = torch.as_tensor(X, dtype=torch.float64)
    Y = torch.as_tensor(Y, dtype=torch.float64).reshape(-1, 1)
    if X.ndim != 2 or X.shape[0] != Y.shape[0]:
        raise ValueError(f"X must be (n, d) and Y (n,), got {tuple(X.shape)} and {tuple(Y.shape)}")
    likelihood = GaussianLikelihood(noise_prior=LogNormalPrior(-4.0, 1.0),
                                    noise_constraint=GreaterThan(1e-4, initial_value=math.exp(-4.0)))
    with warnings.catch_warnings():
        # inputs may leave the unit cube (periodic azimuths): not an error for these kernels
        warnings.filterwarnings("ignore", message=".*not contained to the unit cube.*")
        return SingleTaskGP(X, Y, likelihood=likelihood, covar_module=_covar_module(name, X.shape[-1]),
                            outcome_transform=Standardize(m=1))


def get_hypers(model) -> dict[str, Tensor]:
    """The model's raw hyperparameters (a copy)."""
    return {n: p.detach().clone() for n, p in model.named_parameters()}


def set_hypers(model, hypers: Optional[dict[str, Tensor]]) -> None:
    """Load raw hyperparameters saved by :func:`get_hypers` (names and shapes that match)."""
    if not hypers:
        return
    with torch.no_grad():
        for n, p in model.named_parameters():
            if n in hypers and hypers[n].shape == p.shape:
                p.copy_(hypers[n])


def fit_model(model, maxiter: int = 200, start: Optional[dict[str, Tensor]] = None) -> FitReport:
    """MAP-fit the hyperparameters with BoTorch's ``fit_gpytorch_mll`` (L-BFGS-B, at most
    ``maxiter`` iterations a try, retries from prior samples on failure), from ``start`` if given.

    Never raises for a numerical failure: the model keeps its start values and the report says so.
    The model is left in eval mode.
    """
    from botorch.fit import fit_gpytorch_mll
    from gpytorch.mlls import ExactMarginalLogLikelihood

    set_hypers(model, start)
    backup = get_hypers(model)
    mll = ExactMarginalLogLikelihood(model.likelihood, model)
    ok = True
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            fit_gpytorch_mll(mll, optimizer_kwargs={"options": {"maxiter": int(maxiter)}})
            if not all(torch.isfinite(p).all() for p in model.parameters()):
                raise FloatingPointError("non-finite hyperparameters")
        except Exception as exc:  # noqa: BLE001 - a failed fit keeps the start values
            ok = False
            set_hypers(model, backup)
            caught.append(warnings.WarningMessage(f"{type(exc).__name__}: {exc}", RuntimeWarning, __file__, 0))
    model.eval()
    messages = [str(w.message) for w in caught if not issubclass(w.category, DeprecationWarning)]
    return FitReport(ok=ok, warnings=messages, maxiter=int(maxiter))


def log_evidence(model) -> float:
    """log p(D | m): the exact log marginal likelihood (a sum over the points, no hyperprior
    terms) of the standardized training targets at the current hyperparameters; -inf if it
    cannot be computed."""
    was_training = model.training
    model.train()
    try:
        with torch.no_grad():
            X = model.train_inputs[0]
            val = float(model.likelihood(model(X)).log_prob(model.train_targets))
    except Exception:  # noqa: BLE001 - any numerical failure means "no evidence"
        val = -math.inf
    finally:
        model.train(was_training)
    return val if math.isfinite(val) else -math.inf


def lengthscales(model, dim: int) -> Tensor:
    """The base kernel's lengthscales as a (dim,) tensor (an isotropic one repeated)."""
    ls = model.covar_module.base_kernel.lengthscale.detach().reshape(-1)
    return ls.expand(dim).clone() if ls.numel() == 1 else ls.clone()


def ensemble_weights(log_evidences: Sequence[float] | Tensor,
                     log_prior: Optional[Sequence[float] | Tensor] = None) -> Tensor:
    r"""w^m proportional to p(D | m) w_0^m (eq. 16), in log space with a softmax.

    NaN evidences count as -inf (weight 0); an infinite evidence takes all the weight (shared
    equally); if no model has a finite evidence the (normalized) prior is returned.
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
    if torch.isposinf(le).any():
        le = torch.where(torch.isposinf(le), torch.zeros_like(le), torch.full_like(le, -math.inf))
    s = le + lp
    if not torch.isfinite(s).any():
        s = lp.clone()
    return torch.softmax(s, dim=0)


def draw_model(weights: Tensor, generator: torch.Generator) -> int:
    """m_t ~ Cat(M, w_t) (eq. 17) with the run's seeded generator."""
    return int(torch.multinomial(torch.as_tensor(weights, dtype=torch.float64), 1, generator=generator))
