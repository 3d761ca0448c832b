"""bench/flights_check.py (issue 40's acceptance figures): every unit counted, a failed plan as
failures of all its realizations, a seed two files hold counted once (the later file's), a far-off
success and the registration share measured, and the bars judged."""
from __future__ import annotations

import json
from pathlib import Path

from bench import flights_check as fc


def _table(path: Path, cells: dict) -> Path:
    path.write_text(json.dumps({"cells": cells}))
    return path


def test_units_failures_far_off_share_and_bars(tmp_path: Path) -> None:
    good = [{"chamfer": 4.0, "chamfer_shape": 1.0}, {"chamfer": 2.0, "chamfer_shape": 1.5}]
    far = [{"chamfer": 12.0, "chamfer_shape": 2.0}, {"chamfer": None, "error": "RECONSTRUCTION_FAILED",
                                                     "error_msg": "no pair"}]
    before = _table(tmp_path / "b.json", {
        "one_plant/egp": {"recon_by_seed": {"0": {"per_realization": good}, "1": {"per_realization": far}}},
        "one_plant/sa": {"recon_by_seed": {"0": {"error": "NO_FEASIBLE_PLAN", "per_realization": []}}},
        "one_plant/egp (paper configuration)": {"recon_by_seed": {"0": {"per_realization": good}}}})
    later = _table(tmp_path / "c.json", {"one_plant/egp": {"recon_by_seed": {"1": {"per_realization": good}}}})
    s = fc.summarize([before, later])
    egp = s["table1/egp"]  # seed 1 from the later file: 4 units, none failed, none far off
    assert (egp["units"], egp["failed"], egp["far_off"]) == (4, 0, 0)
    assert egp["share_median"] == (0.75 + 0.25) / 2 and egp["map"] == 3.0
    sa = s["table1/sa"]  # a failed plan: 5 failed units (the realizations of a table) with its reason
    assert (sa["units"], sa["failed"], sa["n"]) == (5, 5, 0) and "NO_FEASIBLE_PLAN" in next(iter(sa["reasons"]))
    assert "table1/egp (paper configuration)" not in s
    alone = fc.summarize([before])["table1/egp"]
    assert (alone["failed"], alone["far_off"], alone["reasons"]) == (1, 1, {"RECONSTRUCTION_FAILED: no pair": 1})
    after = fc.summarize([_table(tmp_path / "a.json", {"one_plant/egp": {"recon_by_seed": {"0": {
        "per_realization": [{"chamfer": 2.0, "chamfer_shape": 1.8}] * 50}}}})])
    b = fc.bars(fc.summarize([before]), after)["egp"]
    assert b["failed_ok"] and b["far_off_ok"] and b["share_ok"] and b["gain_ok"] and b["cells_ok"]
    assert abs(b["table1_map_gain"] - (1 - 2.0 / 6.0)) < 1e-12   # before: 4, 2, 12 reconstructed: mean 6
    assert "| egp | 0.0 % met |" in fc.markdown({"before": {}, "after": after, "bars": {"egp": b}})
