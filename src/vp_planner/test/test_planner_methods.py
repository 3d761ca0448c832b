"""The registry of the planning methods and everything that lists them (issue 19, "the house")."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

from vp_planner.methods import BAYESIAN, MAX_EVALUATIONS, METHODS, REGISTRY, method_table

REPO = Path(__file__).resolve().parents[3]


def test_registry() -> None:
    assert METHODS == ("egp", "gp", "circle", "arc", "sa", "random", "lawnmower")
    assert BAYESIAN == ("egp", "gp") and MAX_EVALUATIONS["egp"] == 1000 and MAX_EVALUATIONS["sa"] == 100_000
    assert len({m.name for m in REGISTRY}) == len(REGISTRY)


def test_the_registry_is_torch_free() -> None:
    code = "import sys, vp_planner.methods; assert 'torch' not in sys.modules, 'torch imported'"
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)


def test_the_planner_and_its_cli_dispatch_the_registry() -> None:
    import pytest

    from vp_planner import optimizers
    from vp_planner.cli import parse_args

    assert optimizers.METHODS is METHODS and optimizers.MAX_EVALUATIONS is MAX_EVALUATIONS
    for name in METHODS:
        assert parse_args(["--method", name, "--out", "x"]).method == name
    with pytest.raises(SystemExit):
        parse_args(["--method", "cmaes", "--out", "x"])


def test_the_action_documents_the_registry() -> None:
    """PlanViews.action's method comment lacked lawnmower; now it must list the registry."""
    text = (REPO / "src" / "vp_interfaces" / "action" / "PlanViews.action").read_text()
    line = next(ln for ln in text.splitlines() if ln.startswith("string method"))
    assert re.split(r"\s*\|\s*", line.split("#", 1)[1].strip()) == list(METHODS), line


def test_the_readme_table_is_the_registry() -> None:
    assert method_table() in (REPO / "README.md").read_text()
