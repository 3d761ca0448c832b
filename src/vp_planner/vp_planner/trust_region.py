"""The trust region of EGP-VP's local phase (TuRBO, Eriksson et al., NeurIPS 2019).

A box of side ``length`` (unit-cube units) centred at the incumbent, stretched per dimension by
the drawn GP's lengthscales (w_i = ell_i / geometric mean(ell), so that the box keeps its
volume), in which the drawn model's EI is maximized. One update rule: ``success_tolerance``
consecutive improvements double the side (up to ``length_max``), ``failure_tolerance``
consecutive failures halve it; below ``length_min`` the region has collapsed and restarts at
``length_init``. The state is a tiny dataclass, easy to log and to test.

The side is in unit-cube units of the search space of :class:`vp_planner.space.ViewSpace`:
0.02 turns a camera by 7 degrees of azimuth, moves its look-at target by 2% of the scene.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import torch
from torch import Tensor

__all__ = ["TrustRegion"]


@dataclass
class TrustRegion:
    """TuRBO's state and update rule (see the module docstring)."""

    length: float = 0.1
    length_init: float = 0.1
    length_min: float = 0.005
    length_max: float = 0.4
    success_tolerance: int = 2
    failure_tolerance: int = 4
    successes: int = 0
    failures: int = 0
    restarts: int = 0

    def update(self, improved: bool) -> None:
        """Record one step: grow after ``success_tolerance`` successes, shrink after
        ``failure_tolerance`` failures, restart when collapsed."""
        if improved:
            self.successes += 1
            self.failures = 0
        else:
            self.failures += 1
            self.successes = 0
        if self.successes >= self.success_tolerance:
            self.length = min(2.0 * self.length, self.length_max)
            self.successes = 0
        elif self.failures >= self.failure_tolerance:
            self.length /= 2.0
            self.failures = 0
        if self.length < self.length_min:
            self.length = self.length_init
            self.restarts += 1

    def bounds(self, center: Tensor, lengthscales: Optional[Tensor] = None,
               periodic: Optional[Tensor] = None) -> Tensor:
        """(2, d) lower and upper bounds of the region about ``center`` (d,).

        Non-periodic dimensions are clipped to [0, 1]; ``periodic`` (bool (d,)) dimensions are
        left unclipped (the caller wraps them).
        """
        d = center.shape[-1]
        w = torch.ones(d, dtype=center.dtype)
        if lengthscales is not None:
            ls = torch.as_tensor(lengthscales, dtype=center.dtype).reshape(-1).expand(d)
            w = ls / ls.log().mean().exp()
            w = w.clamp(0.25, 4.0)          # no dimension frozen or let loose entirely
            w = w / w.log().mean().exp()
        half = 0.5 * self.length * w
        lo, hi = center - half, center + half
        if periodic is None:
            periodic = torch.zeros(d, dtype=torch.bool)
        lo = torch.where(periodic, lo, lo.clamp(0.0, 1.0))
        hi = torch.where(periodic, hi, hi.clamp(0.0, 1.0))
        return torch.stack([lo, hi])
