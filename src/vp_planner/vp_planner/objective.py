"""The objective the optimizers maximize: a :class:`~vp_planner.space.ViewSpace`'s reward (eq. 7)
on encoded plans U, 0 for infeasible ones, with the run's records (every evaluation, the best
feasible plan, the best-so-far trace), its progress callback and its cancel.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Optional

import numpy as np
import torch
from numpy.typing import NDArray

from .space import Callback, PlanningCancelled, StopCheck, ViewSpace, to_numpy

__all__ = ["Objective"]


@dataclass
class Objective:
    """The reward (eq. 7 averaging) on U for optimizers: 0 for infeasible plans; counts and records.

    Calling it on U (B, 6N) (numpy or torch) decodes, checks feasibility, evaluates
    the space's reward model for the feasible rows and returns rewards (B,) of the input's kind.
    Every row counts as one evaluation; after each one ``callback(done, total, best, weights)``
    is called (``weights`` = :attr:`weights`, the latest ensemble weights an optimizer stored);
    when it returns False the objective records that row and raises :class:`PlanningCancelled`.
    ``should_stop()`` is asked before every batch and by :meth:`check_stop` (which optimizers
    call in their feasible-plan searches); True raises :class:`PlanningCancelled` too.
    Evaluations beyond ``total`` raise RuntimeError.
    """

    space: ViewSpace
    total: int
    callback: Optional[Callback] = None
    dtype: torch.dtype = torch.float64
    weights: Optional[list] = None
    U: list = field(default_factory=list)
    cameras: list = field(default_factory=list)
    values: list = field(default_factory=list)
    feasible_flags: list = field(default_factory=list)
    candidate_flags: list = field(default_factory=list)
    best_value: float = 0.0
    best_index: int = -1
    cancelled: bool = False
    should_stop: Optional[StopCheck] = None

    @property
    def count(self) -> int:
        return len(self.values)

    def check_stop(self) -> None:
        """Raise :class:`PlanningCancelled` (and mark the run cancelled) when ``should_stop()``."""
        if self.cancelled or (self.should_stop is not None and self.should_stop()):
            self.cancelled = True
            raise PlanningCancelled()

    def trace(self) -> NDArray[np.float64]:
        """Best-so-far reward of a feasible candidate plan after each evaluation (0 before the first)."""
        ok = np.asarray(self.feasible_flags, bool) & np.asarray(self.candidate_flags, bool)
        v = np.where(ok, np.asarray(self.values, float), 0.0)
        return np.maximum.accumulate(np.maximum(v, 0.0)) if len(v) else np.zeros(0)

    def evaluate_cameras(self, cams: NDArray[np.float64]) -> NDArray[np.float64]:
        """Reward of camera plans (B, N, 6) without bookkeeping (no feasibility check)."""
        if len(cams) == 0:
            return np.zeros(0)
        r = self.space.reward(np.asarray(cams, dtype=np.float64), self.dtype)
        return np.asarray(r, dtype=np.float64).reshape(-1)

    def __call__(self, U: Any) -> Any:
        X, is_torch = to_numpy(U)
        X = np.atleast_2d(X)
        cams = self.space.decode(X)
        return self.record(X, cams, is_torch)

    def record(self, X: NDArray[np.float64], cams: NDArray[np.float64], as_torch: bool = False,
               feasible: Optional[NDArray[np.bool_]] = None, candidate: bool = True) -> Any:
        """Evaluate plans given by both U rows X (B, dim) (may be NaN when not applicable) and
        cameras (B, N, 6); record them one at a time; return rewards (0 where infeasible).

        ``candidate=False`` marks evaluations a method spends on something it will not return
        (the ``arc`` baseline tuning its circle): they count against the budget but never
        become the best plan."""
        self.check_stop()
        ok = self.space._feasible_cameras(cams) if feasible is None else np.asarray(feasible, bool)
        vals = np.zeros(len(cams))
        if ok.any():
            vals[ok] = self.evaluate_cameras(cams[ok])
        for k in range(len(cams)):
            if self.count >= self.total:
                raise RuntimeError(f"evaluation budget of {self.total} exceeded")
            self.U.append(X[k].copy())
            self.cameras.append(cams[k].copy())
            self.values.append(float(vals[k]))
            self.feasible_flags.append(bool(ok[k]))
            self.candidate_flags.append(bool(candidate))
            if candidate and ok[k] and (self.best_index < 0 or vals[k] > self.best_value):
                self.best_value, self.best_index = float(vals[k]), self.count - 1
            if self.callback is not None and self.callback(self.count, self.total, self.best_value, self.weights) is False:
                self.cancelled = True
                raise PlanningCancelled()
        return torch.from_numpy(vals) if as_torch else vals

    def record_part_evaluation(self) -> bool:
        """Count one evaluation spent on a part of the field (:mod:`vp_planner.parts`), not on a
        plan of this space: it uses the budget and reaches the callback like any evaluation but is
        never a candidate (its trace entry is the best complete plan so far, 0 before the first).
        Returns False when the callback asked to stop (the run is then cancelled)."""
        if self.count >= self.total:
            raise RuntimeError(f"evaluation budget of {self.total} exceeded")
        self.U.append(np.full(self.space.dim, np.nan))
        self.cameras.append(np.full((self.space.num_cameras, 6), np.nan))
        self.values.append(0.0)
        self.feasible_flags.append(False)
        self.candidate_flags.append(False)
        if self.callback is not None and self.callback(self.count, self.total, self.best_value, self.weights) is False:
            self.cancelled = True
        return not self.cancelled

    def best_cameras(self) -> Optional[NDArray[np.float64]]:
        return None if self.best_index < 0 else self.cameras[self.best_index]
