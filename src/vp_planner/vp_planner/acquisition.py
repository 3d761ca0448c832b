r"""Choosing the next plan: maximize the drawn model's expected improvement over the feasible set.

EI of model m_t (paper eqs. 14, 17)::

    z_{t+1} = argmax_z  Delta(z) Phi(Delta(z) / sigma(z)) + sigma(z) phi(Delta(z) / sigma(z)),
    Delta(z) = mu_t^{m_t}(z) - max_tau y_tau

maximized through its logarithm (BoTorch's ``LogExpectedImprovement``: same maximizer, no
underflow far from the incumbent) over the *feasible* plans of a box (the trust region, or the
whole cube in the paper's global mode):

1. a pool of ``raw_samples`` candidates in the box: in a trust region, TuRBO's perturbations
   (each candidate changes a random subset of about ``perturb_dims`` coordinates of the
   incumbent to scrambled-Sobol values in the box, so that one camera can move alone) and
   coherent moves (one kind of coordinate of every camera shifted together: the whole plan up,
   out, or turned), else scrambled-Sobol points of the cube plus perturbations of the best
   observed plans;
2. infeasible candidates are dropped (the feasibility rules of the plan are the constraints
   of the acquisition optimization, applied to every candidate before it is scored);
3. the best ``num_restarts`` feasible candidates by LogEI start BoTorch's ``optimize_acqf``
   (L-BFGS-B inside the box);
4. the best refined candidate that is still feasible wins; if none is, the best feasible pool
   candidate. ``None`` when the box holds no feasible candidate at all.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Callable, Optional

import torch
from torch import Tensor

__all__ = ["AcquisitionSettings", "propose", "feasible_mask"]

Feasible = Callable[[Tensor], Tensor]


@dataclass
class AcquisitionSettings:
    """Budgets of one acquisition maximization.

    Attributes:
        raw_samples: candidates scored to pick the restarts.
        num_restarts: candidates refined by L-BFGS-B (optimize_acqf).
        maxiter: L-BFGS-B iterations per restart.
        perturb_dims: expected number of coordinates a trust-region candidate changes.
    """

    raw_samples: int = 1024
    num_restarts: int = 8
    maxiter: int = 50
    perturb_dims: float = 6.0


def feasible_mask(feasible: Optional[Feasible], U: Tensor) -> Tensor:
    """Bool (B,) of ``feasible(U)`` (all True without a predicate)."""
    if feasible is None:
        return torch.ones(U.shape[0], dtype=torch.bool)
    if U.shape[0] == 0:
        return torch.zeros(0, dtype=torch.bool)
    ok = torch.as_tensor(feasible(U)).reshape(-1).to(torch.bool)
    if ok.shape[0] != U.shape[0]:
        raise ValueError(f"feasible returned {ok.shape[0]} flags for {U.shape[0]} points")
    return ok


def _sobol(n: int, bounds: Tensor, gen: torch.Generator) -> Tensor:
    from torch.quasirandom import SobolEngine

    seed = int(torch.randint(0, 2**31 - 1, (1,), generator=gen))
    u = SobolEngine(bounds.shape[1], scramble=True, seed=seed).draw(n, dtype=torch.float64)
    return bounds[0] + (bounds[1] - bounds[0]) * u


def _coherent(center: Tensor, bounds: Tensor, groups: Tensor, n: int, gen: torch.Generator) -> Tensor:
    """n candidates that move every coordinate of one group by the same offset (within the box):
    e.g. all cameras up, all out, the whole plan turned in azimuth."""
    kinds = torch.unique(groups)
    pick = kinds[torch.randint(0, kinds.numel(), (n,), generator=gen)]
    sel = groups[None, :] == pick[:, None]                                  # (n, d)
    half = 0.5 * (bounds[1] - bounds[0])
    step = (2 * torch.rand(n, 1, generator=gen, dtype=torch.float64) - 1) * half[None, :]
    return torch.where(sel, center[None, :] + step, center[None, :]).clamp(bounds[0], bounds[1])


def _pool(bounds: Tensor, center: Optional[Tensor], X: Tensor, y: Tensor, valid: Tensor,
          s: AcquisitionSettings, gen: torch.Generator, groups: Optional[Tensor] = None) -> Tensor:
    d = bounds.shape[1]
    raw = _sobol(s.raw_samples, bounds, gen)
    if center is not None:  # trust region: perturb a random subset of the incumbent's coordinates
        prob = min(1.0, s.perturb_dims / d)
        mask = torch.rand(raw.shape, generator=gen, dtype=torch.float64) < prob
        mask[torch.arange(raw.shape[0]), torch.randint(0, d, (raw.shape[0],), generator=gen)] = True
        local = torch.where(mask, raw, center.expand_as(raw))
        if groups is None:
            return local
        return torch.cat([local, _coherent(center, bounds, groups, s.raw_samples // 4, gen)])
    if not valid.any():
        return raw
    order = torch.nonzero(valid).reshape(-1)
    order = order[torch.argsort(y[order], descending=True)][:5]
    reps = X[order][torch.arange(s.raw_samples // 4) % order.numel()]
    noise = 0.02 * torch.randn(reps.shape, generator=gen, dtype=torch.float64)
    local = (reps + noise).clamp(bounds[0], bounds[1])
    return torch.cat([raw, local])


def propose(model, best_f: float, bounds: Tensor, X: Tensor, y: Tensor, valid: Tensor,
            feasible: Optional[Feasible], gen: torch.Generator, settings: AcquisitionSettings,
            center: Optional[Tensor] = None, groups: Optional[Tensor] = None) -> Optional[Tensor]:
    """The next point (d,) by the module's recipe, or None when no feasible candidate exists.

    Args:
        model: the drawn GP (its posterior is on the original scale of y).
        best_f: the incumbent value max y over valid points.
        bounds: (2, d) the box (a trust region, or the unit cube).
        X, y, valid: the observations so far (valid: finite value and feasible point).
        center: the incumbent (trust-region mode: candidates perturb it); None for global mode.
        groups: (d,) int kind of every coordinate (e.g. which camera parameter it is): a quarter
            more trust-region candidates move all coordinates of one kind together.
    """
    from botorch.acquisition.analytic import LogExpectedImprovement
    from botorch.optim import optimize_acqf

    acq = LogExpectedImprovement(model, best_f=best_f)
    pool = _pool(bounds, center, X, y, valid, settings, gen, groups)
    pool = pool[feasible_mask(feasible, pool)]
    if pool.shape[0] == 0:
        return None
    with torch.no_grad():
        vals = torch.cat([acq(c.unsqueeze(1)) for c in pool.split(1024)])
    vals = torch.nan_to_num(vals, nan=-math.inf)
    order = torch.argsort(vals, descending=True)
    starts = pool[order[: settings.num_restarts]].unsqueeze(1)
    best_pool = pool[order[0]]
    try:
        with warnings.catch_warnings():
            # L-BFGS-B stopping at maxiter is the budget, not a failure
            warnings.filterwarnings("ignore", message=".*Optimization failed.*")
            cands, cvals = optimize_acqf(acq, bounds=bounds, q=1, num_restarts=starts.shape[0],
                                         batch_initial_conditions=starts, return_best_only=False,
                                         options={"maxiter": int(settings.maxiter)})
    except Exception as exc:  # noqa: BLE001 - keep the best pool candidate
        warnings.warn(f"acquisition optimization failed ({type(exc).__name__}: {exc}); using the best "
                      "pool candidate", RuntimeWarning, stacklevel=2)
        return best_pool
    cands = cands.detach().reshape(-1, bounds.shape[1])
    cvals = torch.nan_to_num(cvals.detach().reshape(-1), nan=-math.inf)
    ok = feasible_mask(feasible, cands)
    if ok.any() and float(cvals[ok].max()) >= float(vals[order[0]]):
        return cands[ok][torch.argmax(cvals[ok])]
    return best_pool
