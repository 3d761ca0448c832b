"""bench/bench_recon_speed.py's tables: a failed realization (or a task that raised) is counted,
never dropped, and the paired difference to the default settings uses only the realizations both
reconstructed."""
from __future__ import annotations


import pytest

from bench import bench_recon_speed as brs


def _record(chamfer, sparse=10.0, dense=20.0):
    if chamfer is None:
        return {"error": "RECONSTRUCTION_FAILED", "chamfer_mean": None,
                "per_realization": [{"realization": 0, "error": "RECONSTRUCTION_FAILED", "chamfer": None}]}
    return {"chamfer_mean": chamfer, "per_realization": [
        {"realization": 0, "chamfer": chamfer, "chamfer_shape": chamfer / 2,
         "seconds": {"mesh": 0.0, "render": 1.0, "sparse": sparse, "dense": dense, "score": 2.0}}]}


def test_failures_are_counted_and_pairs_skip_them() -> None:
    full = brs.summary([_record(2.0), _record(3.0), _record(4.0)])
    fast = brs.summary([_record(2.5, 3.0, 4.0), _record(None), {"error": "KilledWorker", "error_msg": "x"}])
    assert (full["n"], full["failed"]) == (3, 0) and full["chamfer_std"] == pytest.approx(1.0)
    assert (fast["n"], fast["failed"]) == (1, 2) and fast["chamfer_std"] is None
    assert fast["errors"] == ["RECONSTRUCTION_FAILED", "KilledWorker"]
    assert fast["seconds"]["total"] == pytest.approx(10.0) and full["seconds"]["total"] == pytest.approx(33.0)
    d = brs.paired(full["chamfer"], fast["chamfer"])
    assert d == {"n": 1, "mean": pytest.approx(0.5), "ci95": None}
    d = brs.paired([2.0, 3.0, 4.0], [2.5, 3.0, 4.5])
    assert d["n"] == 3 and d["mean"] == pytest.approx(1 / 3) and d["ci95"][0] < 1 / 3 < d["ci95"][1]


def test_markdown_shows_every_cell() -> None:
    cells = {"full": brs.summary([_record(2.0), _record(3.0)]),
             "both": brs.summary([_record(None), _record(None)])}
    result = {"machine": "m", "date": "d", "models": "", "seed": 0, "realizations": 2, "width": 2000,
              "height": 1500, "workers": 2, "threads": 1, "scenarios": {"one_plant": cells}}
    text = brs.markdown(result)
    assert "| one_plant | full | 2.50 +- 0.71 (n=2) | - | 1.25 | - |" in text
    assert "| one_plant | both | failed (2 of 2) |" in text
