"""The reference plans reproduce at this commit: small plans of every method family (circle, arc,
sa, egp, egp as the paper configures it; procedural corn, and Corn50 when ../shared has it) planned
again and compared with the cameras pinned in tests/data/reference_plans.json (``python -m
bench.reference_plans --pins`` writes them, on purpose only). A change that moves a plan fails
here, so a result table is never silently left describing other plans; ``python -m
bench.reference_plans`` checks the tables' own plans.

"The same plan" is each camera's centre within 1 um, its viewing direction within 1 urad and the
reward within 1e-9 (``bench.reference_plans.TOLERANCE``), not bit for bit: another CPU model's BLAS
and torch kernels round differently (the same code plans the same cameras to about 1e-10 m there),
while a change of the planner moves cameras by its optimizers' steps, millimetres at least."""
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


def test_the_reference_plans_reproduce():
    """Every pin planned again in a process of its own (torch's kernels are chosen at its import:
    AVX2, as the benchmarks plan), its cameras and reward compared within the tolerance; about 10 s."""
    env = dict(os.environ, ATEN_CPU_CAPABILITY="avx2", OMP_NUM_THREADS="1")
    res = subprocess.run([sys.executable, "-m", "bench.reference_plans", "--verify-pins"], cwd=REPO, env=env,
                         capture_output=True, text=True, timeout=300)
    lines = [json.loads(x) for x in res.stdout.splitlines() if x.startswith("{")]
    assert [x["name"] for x in lines] == list(rp.PINS), res.stderr[-2000:]
    checked = [x for x in lines if "skipped" not in x]
    if any(x["torch_cpu_capability"] != "AVX2" for x in checked):
        pytest.skip(f"torch has no AVX2 kernels on this CPU: {checked[0]['torch_cpu_capability']}")
    moved = [f"{x['name']}: cameras {x.get('max_position_diff_m')} m and {x.get('max_direction_diff_rad')} rad "
             f"away, reward {x['reward_now']} != {x['reward_pinned']}" for x in checked if not x["reproduces"]]
    assert not moved, "plans moved (if on purpose: python -m bench.reference_plans --pins, and rerun the " \
        "tables that rest on them): " + "; ".join(moved)
    assert res.returncode == 0, res.stderr[-2000:]
    assert any(x["name"].startswith("one_plant-egp") for x in checked)


def test_a_moved_plan_is_caught_and_rounding_is_not():
    """Rounding (one ulp, 1e-10 m) is the same plan, not bit-identical; a camera 2 um away, turned
    by 2 urad, a reward 1e-8 away, another camera count or a NaN is another plan."""
    cams = np.asarray(PINNED["one_plant-circle"]["cameras"])
    reward = PINNED["one_plant-circle"]["reward"]

    def moved(i, j, by):
        out = cams.copy()
        out[i, j] += by
        return out

    rounded = moved(0, 0, 1e-10)
    rounded[1, 4] = np.nextafter(rounded[1, 4], np.inf)
    same = rp.compare(cams, rounded, reward, reward + 1e-13)
    assert same["reproduces"] and not same["bit_identical"] and rp.digest(cams) != rp.digest(rounded)
    assert rp.compare(cams, cams)["bit_identical"]
    turned = cams.copy()
    v = cams[2, 3:]
    axis = np.cross(v, [0.0, 0.0, 1.0])
    axis /= np.linalg.norm(axis)
    turned[2, 3:] = v * np.cos(2e-6) + np.cross(axis, v) * np.sin(2e-6)  # v turned by 2 urad about axis
    assert abs(rp.direction_angles(cams, turned)[2] - 2e-6) < 1e-9
    for other in (moved(3, 2, 2e-6), turned, cams[:-1], moved(0, 1, np.nan)):
        assert not rp.compare(cams, other)["reproduces"]
    assert not rp.compare(cams, cams, reward, reward + 1e-8)["reproduces"]


def test_a_table_is_stale_when_a_checked_plan_differs():
    checks = {"tables": {"results/table1.json": {"cells": {
        "one_plant/circle": {"reproduces": True}, "one_plant/egp": {"reproduces": False}}}}}
    assert rp.stale_cells(checks, "results/table1.json") == ["one_plant/egp"]
    assert rp.stale_cells(checks, "results/other.json") == []
