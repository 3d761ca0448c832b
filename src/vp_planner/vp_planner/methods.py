"""The registry of the planning methods (one home): names, what each does, their budget bounds.

Everything that lists the methods follows from :data:`REGISTRY`: the planner's dispatch
(:mod:`vp_planner.optimizers`), the CLI's and the entry script's choices, the PlanViews action's
documentation and the README's method table (tests keep the last two equal to it). Plain data,
no torch: the entry script and the dispatcher import it cheaply.

Budget bounds (issue 19, item 1): egp and gp fit Gaussian processes on every evaluation made,
O(n^3) time and O(n^2) memory (four GPs for egp), so 1000 evaluations are already hours; the
other methods record each evaluation (a few hundred bytes plus about 150 bytes a camera) and
are bounded at 100000.
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Method", "REGISTRY", "METHODS", "BAYESIAN", "MAX_EVALUATIONS", "method_table"]


@dataclass(frozen=True)
class Method:
    """One planning method: its ``name`` (the goal's and the CLI's), a one-line ``summary``,
    whether it is Bayesian optimization (``bayesian``: initial design, planning by parts, the GP
    budget bound) and its ``max_evaluations``."""

    name: str
    summary: str
    bayesian: bool = False
    max_evaluations: int = 100_000


REGISTRY: tuple[Method, ...] = (
    Method("egp", "EGP-VP: BO with an ensemble of 4 GPs and adaptive EI (the paper's method)", True, 1000),
    Method("gp", "BO with one GP (RBF-ARD) and EI", True, 1000),
    Method("circle", "the tuned circle: N cameras on a ring, radius and height by grid search"),
    Method("arc", "the tuned circle's ring, cameras 30 degrees apart on an arc facing the scene"),
    Method("sa", "simulated annealing over a grid of candidate viewpoints (the paper's baseline)"),
    Method("random", "uniformly random feasible plans"),
    Method("lawnmower", "the grid survey farmers fly: flight lines with a set overlap, one evaluation"),
)

#: The method names, in the registry's order.
METHODS: tuple[str, ...] = tuple(m.name for m in REGISTRY)
#: The Bayesian-optimization methods.
BAYESIAN: tuple[str, ...] = tuple(m.name for m in REGISTRY if m.bayesian)
#: The largest evaluation budget of a plan, by method.
MAX_EVALUATIONS: dict[str, int] = {m.name: m.max_evaluations for m in REGISTRY}


def method_table() -> str:
    """The README's method table (markdown), from the registry."""
    rows = ["| method | what it does | evaluations |", "|---|---|---|"]
    rows += [f"| `{m.name}` | {m.summary} | 1 to {m.max_evaluations} |" for m in REGISTRY]
    return "\n".join(rows)
