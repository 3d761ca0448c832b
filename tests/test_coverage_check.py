"""bench/coverage_check.py (issue 20, part 4): the coverage of the prior of the recorded clouds,
ranked against their Chamfer; failures counted, the largest realization count of a cell read."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bench import coverage_check
from bench.common import scene


def _record(results: Path, stem: str, clouds: list, chamfers: list) -> None:
    from vp_recon.outputs import write_ply

    folder = results / "recon" / stem
    folder.mkdir(parents=True)
    per = []
    for k, (cloud, ch) in enumerate(zip(clouds, chamfers)):
        if cloud is not None:
            write_ply(folder / f"recon_{k}.ply", cloud, np.zeros((len(cloud), 3), np.uint8))
        per.append({"realization": k, "chamfer": ch, "chamfer_shape": ch})
    (results / "cache" / "recon").mkdir(parents=True, exist_ok=True)
    (results / "cache" / "recon" / f"{stem}.json").write_text(
        json.dumps({"capture": "realistic", "per_realization": per}))


def test_coverage_ranks_clouds_that_cover_less_as_worse(tmp_path: Path) -> None:
    noisy, _ = scene("one_plant", "")
    prior = noisy.points[0]  # realization 0 of the planning cloud: fully covered by itself
    rng = np.random.default_rng(0)
    part = [prior[rng.random(len(prior)) < f] for f in (1.0, 0.6, 0.3, 0.1)]
    _record(tmp_path, "procedural-one_plant-good-k2-realistic-soil", [part[0], None], [1.0, None])
    _record(tmp_path, "procedural-one_plant-mid-k2-realistic-soil", [part[1], part[2]], [2.0, 3.0])
    _record(tmp_path, "procedural-one_plant-bad-k1-realistic-soil", [part[3]], [6.0])
    _record(tmp_path, "procedural-one_plant-good-k1-realistic-soil", [part[3]], [1.0])  # smaller k: not read
    result = coverage_check.run(coverage_check.parse_args(["--models", "", "--results", str(tmp_path)]))
    assert result["counts"]["one_plant"] == {"plans": 3, "units": 4, "failed": 1, "missing_cloud": 0,
                                             "failed_plans": 0}
    good = next(u for u in result["units"] if u["plan"].startswith("procedural-one_plant-good"))
    assert good["coverage"] == pytest.approx(1.0)
    assert result["spearman_units"]["one_plant"] == pytest.approx(1.0)
    assert result["spearman_plans"]["one_plant"] == pytest.approx(1.0)
    coverage_check.write_results(tmp_path, result)
    assert "| one_plant | 3 | 4 | 1 | 0 | 1.000 | 1.000 |" in (tmp_path / "coverage_check.md").read_text()
