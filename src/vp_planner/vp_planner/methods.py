"""The registry of the planning methods (one home): names, what each does, how each plans, their
budget bounds.

Everything that lists the methods follows from :data:`REGISTRY`: the planner's dispatch
(:func:`vp_planner.optimizers.plan_views` calls the entry's :meth:`Method.plan`, no test of names),
the CLI's and the entry script's choices, the benchmarks' variants, the PlanViews action's
documentation and the README's method table (tests keep the last two equal to it). Plain data,
no torch: the entry script and the dispatcher import it cheaply (a planner is imported on use).

Budget bounds: egp and gp fit Gaussian processes on every evaluation made,
O(n^3) time and O(n^2) memory (four GPs for egp), so 1000 evaluations are already hours; the
other methods record each evaluation (a few hundred bytes plus about 150 bytes a camera) and
are bounded at 100000.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any, Optional

__all__ = ["Method", "REGISTRY", "METHODS", "CANDIDATE_METHODS", "BY_NAME", "DEFAULT_METHOD", "BAYESIAN", "MAX_EVALUATIONS",
           "method_table"]


@dataclass(frozen=True)
class Method:
    """One planning method: its ``name`` (the goal's and the CLI's), a one-line ``summary``, the
    ``planner`` that plans it (``"module:function"``, imported on first use so that this module
    stays torch-free), whether it is Bayesian optimization (``bayesian``: initial design, planning
    by parts, the GP budget bound) and with an ensemble of GPs (``ensemble``: the result carries
    its weights and models), its ``max_evaluations``, the ``evaluations`` a run makes whatever its
    budget (None: the budget), the ``settings`` group of the request it reads besides the
    common fields (:class:`vp_planner.request.PlanRequest`'s ``bo``, ``arc``, ``lawnmower``), the
    function of its ``candidates`` mode: N of the request's candidate poses
    (:mod:`vp_planner.candidates`; None: the method has none), and the simulated ``flights`` that
    check its plans by default (:mod:`vp_planner.flight_planning`; a request's ``sim_flights``
    overrides it).

    The planner is called as ``plan(space, objective, request, rng, parts) -> dict``: it spends
    the budget on the :class:`~vp_planner.objective.Objective` of the
    :class:`~vp_planner.space.ViewSpace` (``parts``: the parts a field is planned by, 1 for one
    space) and returns what the run adds to its result (weights, models, steps, initial_best, parts).
    The candidates mode is called as ``plan(space, objective, request, rng)`` on a
    :class:`~vp_planner.candidates.CandidateSpace`.
    """

    name: str
    summary: str
    planner: str
    bayesian: bool = False
    ensemble: bool = False
    max_evaluations: int = 100_000
    evaluations: Optional[int] = None
    settings: Optional[str] = None
    candidates: Optional[str] = None
    flights: int = 0

    def plan(self, space: Any, objective: Any, request: Any, rng: Any, parts: int) -> dict:
        """Plan ``request`` with this method (its :attr:`planner`); the run's extra results."""
        return _function(self.planner)(space, objective, request, rng, parts) or {}

    def plan_candidates(self, space: Any, objective: Any, request: Any, rng: Any) -> dict:
        """Plan ``request`` among its candidates (:attr:`candidates`); the run's extra results."""
        if self.candidates is None:
            raise ValueError(f"method {self.name} has no candidates mode")
        return _function(self.candidates)(space, objective, request, rng) or {}


def _function(name: str) -> Any:
    """The function ``"module:function"`` (imported on first use: this module stays torch-free)."""
    module, _, function = name.partition(":")
    return getattr(importlib.import_module(module), function)


_BO = "vp_planner.bo_planning:run_bo"
_C = "vp_planner.candidates:"
REGISTRY: tuple[Method, ...] = (
    Method("egp", "EGP-VP: BO, an ensemble of 4 GPs, adaptive EI (the paper's); plans checked by simulated flights",
           _BO, True, True, 1000, settings="bo", candidates=_C + "run_bo", flights=12),
    Method("gp", "BO with one GP (RBF-ARD) and EI", _BO, True, False, 1000, settings="bo", candidates=_C + "run_bo"),
    Method("circle", "the tuned circle: N cameras on a ring, radius and height by grid search",
           "vp_planner.baselines:run_circle", candidates=_C + "run_circle"),
    Method("arc", "the tuned circle's ring, cameras 30 degrees apart on an arc facing the scene",
           "vp_planner.baselines:run_arc", settings="arc", candidates=_C + "run_arc"),
    Method("sa", "simulated annealing over a grid of candidate viewpoints (the paper's baseline)",
           "vp_planner.baselines:run_sa", candidates=_C + "run_sa"),
    Method("random", "uniformly random feasible plans", "vp_planner.baselines:run_random",
           candidates=_C + "run_random"),
    Method("cmaes", "CMA-ES (the cma package, IPOP restarts) in the unit cube, from the best structured plan",
           "vp_planner.cmaes:run_cmaes"),
    Method("lawnmower", "the grid survey farmers fly: flight lines with a set overlap, one evaluation",
           "vp_planner.baselines:run_lawnmower", evaluations=1, settings="lawnmower"),
)

#: The method names, in the registry's order.
METHODS: tuple[str, ...] = tuple(m.name for m in REGISTRY)
#: The methods that plan among candidate poses (:mod:`vp_planner.candidates`).
CANDIDATE_METHODS: tuple[str, ...] = tuple(m.name for m in REGISTRY if m.candidates)
#: The registry's entries by name.
BY_NAME: dict[str, Method] = {m.name: m for m in REGISTRY}
#: The method of a goal, a CLI run or the entry script that names none.
DEFAULT_METHOD: str = "egp"
#: The Bayesian-optimization methods.
BAYESIAN: tuple[str, ...] = tuple(m.name for m in REGISTRY if m.bayesian)
#: The largest evaluation budget of a plan, by method.
MAX_EVALUATIONS: dict[str, int] = {m.name: m.max_evaluations for m in REGISTRY}


def method_table() -> str:
    """The README's method table (markdown), from the registry."""
    rows = ["| method | what it does | evaluations |", "|---|---|---|"]
    rows += [f"| `{m.name}` | {m.summary} | 1 to {m.max_evaluations} |" for m in REGISTRY]
    return "\n".join(rows)
