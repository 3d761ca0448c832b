"""bench/fields_combine.py joins runs of bench_fields.py made with different planning seeds: the
union of the seeds per (field, method), a failed plan counted in every realization, egp paired with
the best baseline on the seeds both have, and files that measured something else refused."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from bench import fields_combine

BENCH = Path(__file__).resolve().parents[1] / "bench"


def _recon(chamfers):
    """A reconstruction record as common.reconstruct_record writes it (None: a failed realization)."""
    per = [{"realization": k, "chamfer": c, "chamfer_shape": None if c is None else c / 2}
           for k, c in enumerate(chamfers)]
    return {"capture": "realistic", "per_realization": per}


def _fields(path: Path, seed: int, cells: dict, realizations: int = 2, **meta) -> Path:
    """A bench_fields.json of one seed: cells {"field:N/method": chamfers, or "failed" (the plan
    failed: bench_fields records an error and no realization), or None (planned only)}."""
    out = {}
    for name, c in cells.items():
        if c == "failed":
            out[name] = {"plan": {"error": "PLANNING_FAILED"},
                         "recon": {"error": "PLANNING_FAILED", "chamfer_mean": None, "per_realization": []}}
        else:
            out[name] = {"plan": {"reward": 0.5}, "recon": None if c is None else _recon(c)}
    table = {"seed": seed, "resolution": [2000, 1500], "realizations": realizations, "models": "corn50",
             "evaluations_per_part": 100, "cells": out, **meta}
    path.write_text(json.dumps(table))
    return path


def test_seeds_join_and_egp_pairs_with_the_best_baseline_on_shared_seeds(tmp_path):
    s0 = _fields(tmp_path / "s0.json", 0, {"grid_3x3:8/egp": [2.0, 3.0], "grid_3x3:8/arc": [3.0, 3.5],
                                           "grid_3x3:8/lawnmower": [50.0, 60.0], "grid_3x3:8/sa": None})
    s1 = _fields(tmp_path / "s1.json", 1, {"grid_3x3:8/egp": [2.5, None],
                                           "grid_3x3:8/arc": [3.0, 4.0], "grid_3x3:8/sa": "failed"})
    cells, meta = fields_combine.load([s0, s1])
    assert meta["capture"] == "realistic" and meta["realizations"] == 2
    assert sorted(cells[("grid_3x3:8", "egp")]) == [0, 1] and sorted(cells[("grid_3x3:8", "lawnmower")]) == [0]
    table = fields_combine.combine(cells, fields_combine.BASELINES, order=None, realizations=2)
    egp = table["cells"]["grid_3x3:8/egp"]["chamfer"]
    assert (egp["n"], egp["failed"]) == (3, 1) and egp["mean"] == pytest.approx(2.5)
    sa = table["cells"]["grid_3x3:8/sa"]["chamfer"]
    assert (sa["n"], sa["failed"]) == (0, 2)  # the failed plan fails both realizations; seed 0 planned only
    paired = table["paired"]["grid_3x3:8/egp"]
    assert paired["baseline"] == "arc"  # lawnmower has the higher mean, sa failed
    # units (0,0) (0,1) (1,0) both reconstructed; (1,1) egp failed: counted, not averaged away
    assert paired["n"] == 3 and paired["only_a_failed"] == 1
    assert paired["mean"] == pytest.approx(((2.0 - 3.0) + (3.0 - 3.5) + (2.5 - 3.0)) / 3)
    assert "grid_3x3:8/lawnmower" not in table["paired"] and table["scenarios"] == ["grid_3x3:8"]


def test_cli_writes_the_table_and_refuses_another_experiment(tmp_path, capsys):
    s0 = _fields(tmp_path / "s0.json", 0, {"row_12:12/egp": [2.0, 2.2], "row_12:12/circle": [4.0, 4.4]})
    s1 = _fields(tmp_path / "s1.json", 1, {"row_12:12/egp": [2.1, 2.3], "row_12:12/circle": [4.0, 4.2]})
    assert fields_combine.main([str(s0), str(s1), "--out", str(tmp_path / "out")]) == 0
    md = (tmp_path / "out" / "fields_combined.md").read_text()
    assert md.startswith("# Fields, combined") and "| egp | 2.150 +- 0.129 (n=4) [seeds 0,1] |" in md
    data = json.loads((tmp_path / "out" / "fields_combined.json").read_text())
    assert data["paired"]["row_12:12/egp"]["baseline"] == "circle" and data["paired"]["row_12:12/egp"]["n"] == 4
    five = _fields(tmp_path / "k5.json", 2, {"row_12:12/egp": [2.0] * 5}, realizations=5)
    with pytest.raises(SystemExit, match="another realizations"):
        fields_combine.main([str(s0), str(five), "--out", str(tmp_path / "out")])
    other = _fields(tmp_path / "ideal.json", 2, {"row_12:12/egp": [2.0, 2.0]})
    table = json.loads(other.read_text())
    table["cells"]["row_12:12/egp"]["recon"]["capture"] = "ideal"
    other.write_text(json.dumps(table))
    with pytest.raises(SystemExit, match="another capture"):
        fields_combine.main([str(s0), str(other), "--out", str(tmp_path / "out")])
    (tmp_path / "broken.json").write_text("{")
    with pytest.raises(SystemExit, match="cannot read"):
        fields_combine.main([str(tmp_path / "broken.json"), "--out", str(tmp_path / "out")])
