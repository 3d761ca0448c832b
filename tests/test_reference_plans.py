"""The reference plans are bit-identical at this commit (issue 39, item 6): small plans of every
method family (circle, arc, sa, egp, egp as the paper configures it; procedural corn, and Corn50
when ../shared has it) planned again and compared with the cameras pinned in
tests/data/reference_plans.json (``python -m bench.reference_plans --pins`` writes them, on purpose
only). A change that moves a plan fails here, so a result table is never silently left describing
other plans; ``python -m bench.reference_plans`` checks the tables' own plans."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from bench import reference_plans as rp

REPO = rp.ROOT
PINNED = json.loads(rp.PINS_FILE.read_text())["pins"]


def test_every_pin_is_pinned():
    assert sorted(PINNED) == sorted(rp.PINS)
    for name, pin in PINNED.items():
        assert pin["sha256"] == rp.digest(pin["cameras"]), name
        assert pin["torch_cpu_capability"] == "AVX2", name


def test_the_reference_plans_are_bit_identical():
    """Every pin planned again in a process of its own (torch's kernels are chosen at its import:
    AVX2, as the benchmarks plan), its cameras compared bit for bit; about 10 s."""
    env = dict(os.environ, ATEN_CPU_CAPABILITY="avx2", OMP_NUM_THREADS="1")
    res = subprocess.run([sys.executable, "-m", "bench.reference_plans", "--verify-pins"], cwd=REPO, env=env,
                         capture_output=True, text=True, timeout=300)
    lines = [json.loads(x) for x in res.stdout.splitlines() if x.startswith("{")]
    assert [x["name"] for x in lines] == list(rp.PINS), res.stderr[-2000:]
    checked = [x for x in lines if "skipped" not in x]
    if any(x["torch_cpu_capability"] != "AVX2" for x in checked):
        pytest.skip(f"torch has no AVX2 kernels on this CPU: {checked[0]['torch_cpu_capability']}")
    moved = [f"{x['name']}: sha256 {x['sha256_now'][:16]} != {x['sha256_pinned'] and x['sha256_pinned'][:16]}, "
             f"reward {x['reward_now']} != {x['reward_pinned']}" for x in checked if not x["reproduces"]]
    assert not moved, "plans moved (if on purpose: python -m bench.reference_plans --pins, and rerun the " \
        "tables that rest on them): " + "; ".join(moved)
    assert res.returncode == 0, res.stderr[-2000:]
    assert any(x["name"].startswith("one_plant-egp") for x in checked)


def test_a_moved_plan_is_caught():
    """The comparison is bit for bit: one ulp in one coordinate is another plan."""
    cams = np.asarray(PINNED["one_plant-circle"]["cameras"])
    moved = cams.copy()
    moved[0, 0] = np.nextafter(moved[0, 0], np.inf)
    assert rp.compare(cams, cams)["reproduces"] and not rp.compare(cams, moved)["reproduces"]
    assert rp.digest(cams) != rp.digest(moved)


def test_a_table_is_stale_when_a_checked_plan_differs():
    checks = {"tables": {"results/table1.json": {"cells": {
        "one_plant/circle": {"reproduces": True}, "one_plant/egp": {"reproduces": False}}}}}
    assert rp.stale_cells(checks, "results/table1.json") == ["one_plant/egp"]
    assert rp.stale_cells(checks, "results/other.json") == []
