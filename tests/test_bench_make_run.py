"""bench/bench_make_run.py's table: a failed run is a row (its exit status), never dropped; the
paired difference uses only the realizations both runs scored."""
from __future__ import annotations


import pytest

from bench import bench_make_run as bmr
from bench.stats import paired_interval


def test_failed_runs_are_rows_and_pairs_skip_missing_realizations() -> None:
    d = paired_interval([2.0, 3.0, None, 4.0], [2.5, 3.0, 1.0, 4.5])
    assert d["n"] == 3 and d["mean"] == pytest.approx(1 / 3)
    ok = {"options": bmr.VARIANTS["benchmarks"], "wall": 190.0, "returncode": 0, "chamfer_mean": 3.0,
          "chamfer_shape_mean": 1.4, "chamfer": [2.0, 4.0], "chamfer_shape": [1.3, 1.5]}
    fast = {**ok, "options": bmr.VARIANTS["make-run"], "wall": 108.0, "chamfer_mean": 3.1,
            "vs_base": paired_interval([2.0, 4.0], [2.1, 4.1]),
            "shape_vs_base": paired_interval([1.3, 1.5], [1.3, 1.5])}
    failed = {"options": bmr.VARIANTS["sift0"], "wall": 12.0, "returncode": 2, "error": ["x"]}
    text = bmr.markdown({"machine": "m", "date": "d", "target_s": 120.0,
                         "variants": {"benchmarks": ok, "make-run": fast, "sift0": failed}})
    assert "| benchmarks | `--sift-first-octave -1 --dense-scale 1.0` | 190.0 | - | 3.00 | - | - | 1.40 | - |" in text
    assert "| make-run | `--sift-first-octave 0 --dense-scale 0.7` | 108.0 | - | 3.10 | - | +0.10" in text
    assert "| sift0 | `--sift-first-octave 0 --dense-scale 1.0` | 12.0 | - | failed (exit 2) |" in text
    # issue 40's bar: the realizations' std / mean, and the load the run saw
    ok2 = {**ok, "cv": 0.11, "load_average_1min": 3.4}
    text = bmr.markdown({"machine": "m", "date": "d", "target_s": 60.0, "variants": {"make-run": ok2}})
    assert "| make-run | `--sift-first-octave -1 --dense-scale 1.0` | 190.0 | 3.4 | 3.00 | 0.11 | - | 1.40 | - |" in text
    assert "Target: 60 s and Chamfer std / mean" in text
    # --repeats: every run's wall time beside the first run's row, a failed repeat counted
    rep = {**ok2, "walls": [56.3, 57.4, 61.0], "wall_median": 57.4, "wall_max": 61.0, "failed_repeats": 1}
    text = bmr.markdown({"machine": "m", "date": "d", "target_s": 60.0, "variants": {"make-run": rep}})
    assert "| 190.0 (runs: 56.3, 57.4, 61.0; median 57.4, max 61.0; 1 failed) | 3.4 |" in text
