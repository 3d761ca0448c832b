"""The registry of the planning methods and everything that lists them."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from vp_planner.methods import BAYESIAN, MAX_EVALUATIONS, METHODS, REGISTRY, method_table

REPO = Path(__file__).resolve().parents[3]


def test_registry() -> None:
    assert METHODS == ("egp", "gp", "circle", "arc", "sa", "random", "cmaes", "lawnmower")
    assert BAYESIAN == ("egp", "gp") and MAX_EVALUATIONS["egp"] == 1000 and MAX_EVALUATIONS["sa"] == 100_000
    assert len({m.name for m in REGISTRY}) == len(REGISTRY)


def test_the_registry_is_torch_free() -> None:
    code = "import sys, vp_planner.methods; assert 'torch' not in sys.modules, 'torch imported'"
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)


def test_the_planner_and_its_cli_dispatch_the_registry() -> None:
    from vp_planner.cli import parse_args

    for name in METHODS:
        assert parse_args(["--method", name, "--out", "x"]).method == name
    with pytest.raises(SystemExit):
        parse_args(["--method", "nelder-mead", "--out", "x"])


def test_the_action_documents_the_registry() -> None:
    """PlanViews.action's method comment lacked lawnmower; now it must list the registry."""
    text = (REPO / "src" / "vp_interfaces" / "action" / "PlanViews.action").read_text()
    line = next(ln for ln in text.splitlines() if ln.startswith("string method"))
    assert re.split(r"\s*\|\s*", line.split("#", 1)[1].strip()) == list(METHODS), line


def test_the_readme_table_is_the_registry() -> None:
    assert method_table() in (REPO / "README.md").read_text()


# ---------------------------------------------------------------- a registry that dispatches
def plan_spiral(space, objective, request, rng, parts) -> dict:
    """A method that is not in the suite: the registry entry below plans with it."""
    from vp_planner.baselines import evaluate_plans
    from vp_planner.patterns import ring

    centre = space.extent.centre
    cams = [ring(centre[:2], centre, [2.0 + 0.1 * k], [1.0 + 0.1 * k], space.num_cameras)[0]
            for k in range(request.evaluations)]
    evaluate_plans(objective, np.asarray(cams))
    return {"steps": ["spiral"]}


def test_a_method_is_one_entry_that_knows_how_to_plan(monkeypatch, realizations) -> None:
    """plan_views dispatched on an if/elif of names: a new method took edits in optimizers.py. Now
    one registry entry (its planner a "module:function") is all plan_views needs, the request and
    the budget checks included."""
    from vp_planner import methods
    from vp_planner.optimizers import plan_views
    from vp_planner.request import PlanRequest

    spiral = methods.Method("spiral", "rings growing outwards", f"{__name__}:plan_spiral", max_evaluations=50)
    monkeypatch.setitem(methods.BY_NAME, "spiral", spiral)
    res = plan_views(PlanRequest.of("spiral", 3, evaluations=5), realizations)
    assert res.method == "spiral" and res.evaluations == 5 and res.steps == ["spiral"] and res.cameras.shape == (3, 6)
    assert res.ensemble_weights is None
    with pytest.raises(ValueError, match="above the bound of 50"):
        PlanRequest.of("spiral", 3, evaluations=51)


def test_the_entries_attributes_replace_the_tests_of_names() -> None:
    """``method == "egp"`` (ensemble weights, model names), ``method in ("egp", "gp")`` (the CLI's
    plan.json) and ``method == "lawnmower"`` (one evaluation) are attributes of the entries."""
    import importlib

    from vp_planner.request import total_evaluations

    assert [m.name for m in REGISTRY if m.ensemble] == ["egp"]
    assert [m.name for m in REGISTRY if m.settings == "bo"] == list(BAYESIAN)
    assert total_evaluations("lawnmower", 100, 1) == 1 and total_evaluations("circle", 100, 1) == 100
    for m in REGISTRY:
        module, _, function = m.planner.partition(":")
        assert callable(getattr(importlib.import_module(module), function)), m.planner
    for path in ("optimizers.py", "request.py", "cli.py", "planner_node.py"):
        text = (REPO / "src" / "vp_planner" / "vp_planner" / path).read_text()
        names = "|".join(METHODS)
        assert not re.search(rf"""method\s*(==|!=|\bin)\s*\(?\s*["']({names})["']""", text), path
