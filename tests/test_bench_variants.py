"""The benchmarks' planner variants (issue 39, item 2): one table, bench/common.py's VARIANTS, that
every benchmark reads (bench_planners, bench_fields, table1, bench_sorties, plan_quality kept six
more method/variant tables); each variant is a valid plan request, and which ones are baselines
follows the methods' registry."""
from __future__ import annotations

import re
from pathlib import Path

from bench import common

BENCH = Path(__file__).resolve().parents[1] / "bench"


def test_every_variant_is_a_request_and_the_registry_says_which_are_baselines() -> None:
    from vp_planner.methods import BY_NAME
    from vp_planner.request import PlanRequest

    for name, variant in common.VARIANTS.items():
        request = common.variant_request(name, num_cameras=4, evaluations=20, initial_evaluations=10)
        assert request == PlanRequest.from_dict({**variant.request, "num_cameras": 4, "evaluations": 20,
                                                 "initial_evaluations": 10})
        assert variant.baseline == (not BY_NAME[request.method].bayesian), name
    assert common.variants_of("planners") == ("egp", "egp-random-init", "circle", "arc", "sa", "random")
    assert common.baselines(common.variants_of("planners")) == ("circle", "arc", "sa", "random")


def test_the_benchmarks_read_the_one_table() -> None:
    from bench import bench_fields, bench_planners, bench_sorties, table1

    assert bench_fields.METHODS == ("egp", "egp-one-space", "egp-graph", "circle", "arc", "sa", "lawnmower",
                                    "lawnmower-oblique")
    assert bench_fields.BASELINES == ("circle", "arc", "sa", "lawnmower", "lawnmower-oblique")
    assert bench_fields.by_parts("egp") and bench_fields.by_parts("egp-graph") and not bench_fields.by_parts("egp-one-space")
    assert common.variant_request("egp-graph", num_cameras=8).reward.name == "coverage-graph"
    assert common.variant_request("lawnmower-oblique", num_cameras=8).lawnmower.tilt > 0
    assert table1.BASELINES == ("circle", "arc", "sa") and all(v in common.VARIANTS for v, _ in table1.ROWS.values())
    assert bench_sorties.CASES == ("a", "b", "c-circle", "c-arc", "d", "e")
    assert bench_planners.variants_of is common.variants_of
    # no benchmark spells a table of its own: no dict of method fields, no tuple of baseline names
    for path in BENCH.glob("*.py"):
        text = path.read_text()
        if path.name in ("common.py", "docs.py"):  # the table itself; the docs generator's command mapping
            continue
        assert not re.search(r"""["']method["']\s*:\s*["']""", text), path.name
        assert not re.search(r"""^(BASELINES|DEFAULT_VARIANTS)\s*=\s*\(""", text, re.M), path.name
