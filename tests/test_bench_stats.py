"""bench/stats.py: sample std with n, failures counted and ranked last, paired t-intervals, Spearman."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats as sps

from bench.stats import paired_difference, rank, summary


def test_summary_is_sample_std_with_n_and_counts_failures():
    s = summary({0: 1.0, 1: 2.0, 2: 4.0, 3: None, 4: float("nan")})
    assert s["n"] == 3 and s["failed"] == 2
    assert s["mean"] == pytest.approx(7 / 3)
    assert s["std"] == pytest.approx(np.std([1.0, 2.0, 4.0], ddof=1))
    one = summary({0: 1.0})
    assert one["n"] == 1 and math.isnan(one["std"])


def test_a_row_with_a_failure_ranks_last_whatever_its_mean():
    rows = {"good": summary({0: 3.0, 1: 3.2}), "failed_once": summary({0: 0.1, 1: None}),
            "better": summary({0: 1.0, 1: 1.1}), "all_failed": summary({0: None, 1: None})}
    assert rank(rows) == ["better", "good", "failed_once", "all_failed"]


def test_paired_difference_t_interval_matches_scipy_and_counts_failures():
    rng = np.random.default_rng(3)
    a = {(s, k): float(x) for (s, k), x in zip([(s, k) for s in range(3) for k in range(5)], rng.normal(2, 0.3, 15))}
    b = {u: v + float(rng.normal(0.4, 0.2)) for u, v in a.items()}
    b[(0, 0)] = None  # baseline failed there
    a[(1, 1)] = float("nan")  # egp failed there
    d = paired_difference(a, b)
    diffs = np.array([a[u] - b[u] for u in a if u not in ((0, 0), (1, 1))])
    lo, hi = sps.t.interval(0.95, len(diffs) - 1, loc=diffs.mean(), scale=sps.sem(diffs))
    assert d["n"] == 13 and d["only_a_failed"] == 1 and d["only_b_failed"] == 1 and d["both_failed"] == 0
    assert d["mean"] == pytest.approx(diffs.mean())
    assert (d["low"], d["high"]) == pytest.approx((lo, hi))
    assert d["high"] < 0  # a is better by ~0.4, clearly


def test_table1_shape_table_counts_a_failed_plan() -> None:
    """Table I's shape/registration table: sample statistics of chamfer_shape over the
    realizations, the images registered, and a failed plan counted (never dropped)."""
    from bench import table1

    args = table1.parse_args(["--models", "", "--scenarios", "one_plant", "--rows", "circle", "egp", "--seeds", "1",
                              "--realizations", "2"])
    recons = {("one_plant", "circle", 0): {"per_realization": [{"chamfer_shape": 1.0, "images": 4},
                                                               {"chamfer_shape": 1.2, "images": 3}]},
              ("one_plant", "egp", 0): {"error": "RECONSTRUCTION_FAILED", "per_realization": []}}
    table: dict = {}
    lines = table1.shape_lines(args, recons, table)
    assert "| circle | 1.100 +- 0.141 (n=2), images 3-4 |" in lines
    assert "| egp | failed, 1 plan(s) failed |" in lines
    assert table["shape"]["one_plant/egp"]["failed_plans"] == 1


def test_table1_reconstructs_a_slice_of_seeds(tmp_path) -> None:
    """--recon-first skips the seeds a table already has: only seeds 1 and 2 get a reconstruction
    task; a slice with no seed is refused before any work."""
    from bench import table1

    base = ["--models", "", "--scenarios", "one_plant", "--rows", "arc", "--seeds", "3", "--recon-seeds", "3"]
    args = table1.parse_args(base + ["--recon-first", "1"])
    assert list(table1.recon_seeds(args)) == [1, 2]
    plans = {("one_plant", "arc", s): {"cameras": []} for s in range(3)}
    assert [t.key for t in table1.recon_tasks(tmp_path, tmp_path, plans, args)] == [("one_plant", "arc", 1),
                                                                                ("one_plant", "arc", 2)]
    with pytest.raises(SystemExit, match="no seed to reconstruct"):
        table1.main(base + ["--recon-first", "3", "--out", str(tmp_path)])


def test_a_row_with_no_success_reads_failed_not_nan():
    from bench.stats import describe, describe_difference

    assert describe(summary({0: None, 1: None})) == "failed (n=0, 2 failed)"
    # one value has no sample std: no '+- nan'
    assert describe(summary({0: 0.5, 1: None}), digits=4, note="paper") == "0.5000 (n=1, 1 failed; paper)"
    assert describe(summary({0: 1.0, 1: 2.0})) == "1.500 +- 0.707 (n=2)"
    assert describe_difference(paired_difference({0: None}, {0: 1.0})) == "no pair (n=0, 1 only a failed)"
    assert describe_difference(paired_difference({0: 1.0, 1: 2.0}, {0: 3.0, 1: None})) == "-2.000 (n=1, 1 only b failed)"


def test_one_spearman_ranks_a_failure_last_and_is_nan_where_undefined():
    """The one Spearman of the benchmarks (plan quality, real scans): -inf (a failure) ranks at its
    end; fewer than 3 pairs or a side of one value has no rho: NaN (null in a result file)."""
    from bench.stats import spearman

    assert spearman([0.9, 0.8, 0.7, 0.1], [-1.0, -2.0, -3.0, -math.inf]) == 1.0
    assert spearman([3, 1, 2, 5], [1, 2, 3, 4]) == pytest.approx(sps.spearmanr([3, 1, 2, 5], [1, 2, 3, 4]).statistic)
    assert math.isnan(spearman([1.0, 2.0], [1.0, 2.0]))
    assert math.isnan(spearman([1.0, 1.0, 1.0], [1.0, 2.0, 3.0]))
    assert math.isnan(spearman([1.0, 2.0, 3.0], [-math.inf] * 3))
