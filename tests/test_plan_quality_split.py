"""bench/plan_quality.py: the design/check split (stratified by family, seeded), the study's counts
(a plan without a reconstruction is counted as skipped, never dropped) and Spearman per half."""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from plan_quality import spearman_halves, split_halves, study_counts  # noqa: E402


def _plans() -> list[dict]:
    fams = {"circle": 9, "arc": 6, "egp-coverage": 3, "gp": 1}
    return [{"id": f"{f}-{i:03d}", "family": f, "recon": {0: {}}} for f, n in fams.items() for i in range(n)]


def test_the_split_is_stratified_by_family_seeded_and_complete():
    plans = _plans()
    half = split_halves(plans, seed=0)
    assert set(half) == {p["id"] for p in plans}
    for fam, n in (("circle", 9), ("arc", 6), ("egp-coverage", 3), ("gp", 1)):
        design = [i for i, h in half.items() if i.startswith(fam + "-") and h == "design"]
        assert len(design) == n // 2, fam          # every family in both halves (one-plan families: check)
    assert split_halves(list(reversed(plans)), seed=0) == half   # order of the plan list does not matter
    assert split_halves(plans, seed=1) != half                   # the seed does


def test_counts_name_the_skipped_and_failed_plans():
    plans = _plans()[:5]
    plans[3]["recon"] = {}                                       # never reconstructed
    chamfer = np.array([0.01, math.inf, 0.02, math.nan, 0.03])   # one failed, one skipped
    assert study_counts(plans, chamfer) == {"planned": 5, "reconstructed": 3, "failed": 1, "skipped": 1}


def test_spearman_per_half_ranks_a_failure_last_and_uses_only_its_half():
    ids = [f"p{i}" for i in range(8)]
    half = {i: ("design" if n % 2 else "check") for n, i in enumerate(ids)}
    chamfer = np.array([0.01, 0.05, 0.02, 0.06, 0.03, 0.07, math.inf, 0.08])
    reward = [0.9, 0.1, 0.8, 0.3, 0.7, 0.2, 0.0, 0.4]              # check half: perfect; design half: not
    rho = spearman_halves(ids, {"m": reward}, chamfer, half)
    assert rho["check"]["m"] == pytest.approx(1.0)
    assert rho["design"]["m"] == pytest.approx(-0.8)   # d = (3, 0, 0, -3): 1 - 6 * 18 / 60
