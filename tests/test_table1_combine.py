"""bench/table1_combine.py joins slices of Table I: the union of the seeds, a later file wins a seed
both hold, a failed unit is counted (never averaged away), the paired difference is per (seed,
realization), and files that measured something else are refused with one line."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from bench import table1_combine

BENCH = Path(__file__).resolve().parents[1] / "bench"

CAPTURE = {"kind": "realistic", "seed": 0}


def _record(chamfers):
    """A reconstruction record of table1.py: None = a failed realization."""
    per = [{"realization": k, "chamfer": c, "chamfer_shape": None if c is None else c / 2}
           for k, c in enumerate(chamfers)]
    return {"per_realization": per}


def _table(path: Path, cells: dict, capture=CAPTURE) -> Path:
    """A table1.json holding cells {(scenario, row): {seed: chamfers}}."""
    table = {"capture": capture, "resolution": [2000, 1500], "evaluations": 100, "models": "corn50",
             "plants": {"six_rect": [["12", 97.1, 0.908]]},
             "cells": {f"{s}/{r}": {"recon": _record(seeds[min(seeds)]),
                                    "recon_by_seed": {str(k): _record(v) for k, v in seeds.items()}}
                       for (s, r), seeds in cells.items()}}
    path.write_text(json.dumps(table))
    return path


def test_union_of_seeds_later_file_wins_and_failures_count(tmp_path):
    first = _table(tmp_path / "a.json", {("six_rect", "arc"): {0: [3.0, 3.0], 1: [3.0, 3.0], 2: [3.0, 3.0]},
                                          ("six_rect", "egp"): {0: [9.0, 9.0]}})
    second = _table(tmp_path / "b.json", {("six_rect", "sa"): {0: [4.0, None], 1: [4.0, 4.0], 2: [4.0, 4.0]},
                                           ("six_rect", "egp"): {0: [2.0, 2.0], 1: [2.0, 3.0], 2: [1.0, 2.0]}})
    cells, meta = table1_combine.load([first, second])
    table = table1_combine.combine(cells)
    egp = table["cells"]["six_rect/egp"]
    assert egp["seeds"] == [0, 1, 2] and egp["sources"]["0"] == str(second)  # seed 0 from the later file
    assert egp["chamfer"]["n"] == 6 and egp["chamfer"]["mean"] == pytest.approx(2.0)
    sa = table["cells"]["six_rect/sa"]["chamfer"]
    assert (sa["n"], sa["failed"]) == (5, 1)
    paired = table["paired"]["six_rect/egp"]
    assert paired["baseline"] == "arc"  # sa has a failed unit: it ranks below arc
    assert paired["n"] == 6 and paired["mean"] == pytest.approx(2.0 - 3.0)
    assert paired["over_seed_means"]["n"] == 3
    assert "six_rect/arc" not in table["paired"]  # baselines are not compared with themselves


def test_a_failed_plan_fails_every_realization(tmp_path):
    cells = {("six_rect", "arc"): {0: [3.0, 3.0]}, ("six_rect", "egp"): {0: [2.0, 2.0], 1: []}}
    loaded, _ = table1_combine.load([_table(tmp_path / "a.json", cells)])
    egp = table1_combine.combine(loaded)["cells"]["six_rect/egp"]["chamfer"]
    assert (egp["n"], egp["failed"]) == (2, 2)


def test_refuses_another_experiment_in_one_line(tmp_path):
    a = _table(tmp_path / "a.json", {("six_rect", "arc"): {0: [3.0]}})
    b = _table(tmp_path / "b.json", {("six_rect", "egp"): {0: [2.0]}}, capture={"kind": "ideal"})
    out = subprocess.run([sys.executable, str(BENCH / "table1_combine.py"), str(a), str(b), "--out", str(tmp_path)],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 1 and out.stderr.strip().count("\n") == 0
    assert "measured another capture" in out.stderr and str(b) in out.stderr
    missing = subprocess.run([sys.executable, str(BENCH / "table1_combine.py"), str(tmp_path / "none.json"),
                              "--out", str(tmp_path)], capture_output=True, text=True, timeout=60)
    assert missing.returncode == 1 and "cannot read" in missing.stderr


def test_writes_the_table(tmp_path):
    a = _table(tmp_path / "a.json", {("six_rect", "arc"): {0: [3.0, 3.5]}, ("six_rect", "egp"): {0: [2.0, 2.5]}})
    assert table1_combine.main([str(a), "--out", str(tmp_path / "out")]) == 0
    md = (tmp_path / "out" / "table1_combined.md").read_text()
    assert "| egp | 2.250 +- 0.354 (n=2) [seeds 0] |" in md
    assert json.loads((tmp_path / "out" / "table1_combined.json").read_text())["paired"]["six_rect/egp"]["n"] == 2


def test_a_row_whose_every_plan_failed_counts_every_unit_as_failed(tmp_path):
    """A plan that failed has no realization in its record; where every seed of a cell failed so,
    its units still count (the realizations of the other cells), failed, never n = 0 and nothing."""
    only = _table(tmp_path / "a.json", {("six_rect", "arc"): {0: [3.0, 3.0, 3.0]},
                                         ("six_rect", "egp"): {0: [], 1: []}})
    table = table1_combine.combine(table1_combine.load([only])[0])
    egp = table["cells"]["six_rect/egp"]["chamfer"]
    assert (egp["n"], egp["failed"]) == (0, 6)
    assert table["paired"]["six_rect/egp"]["only_a_failed"] == 3
