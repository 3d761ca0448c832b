"""docs/results.md and docs/history_results.md are generated from the files under results/:
``make docs`` gives the committed files byte for byte (so they are never edited by hand), every
table names its file, commit and command, a table whose plans no longer reproduce is marked stale,
and no results file holds a NaN or Infinity literal (JSON has none; the benchmarks write null)."""
from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest

from bench import docs, reference_plans
from bench.cache import write_json
from bench.common import ROOT
from bench.publish import git_commit, publish

RESULTS = sorted(p for p in (ROOT / "results").rglob("*.json") if "cache" not in p.relative_to(ROOT).parts)


def _strict(text: str):
    def refuse(name):
        raise ValueError(f"{name} literal")
    return json.loads(text, parse_constant=refuse)


def test_the_documents_are_what_the_results_give():
    for name, text in docs.render().items():
        assert (docs.OUT / name).read_text() == text, f"docs/{name} differs from the results: run make docs"


def test_every_table_names_its_file_commit_and_command_and_superseded_runs_stand_apart():
    """docs/results.md holds the current results only; every superseded run is in
    docs/history_results.md, with what superseded it."""
    def sections(text: str) -> dict:
        return {s.split("\n", 1)[0]: s for s in text.split("\n## ")[1:] if not s.startswith("Contents")}
    rendered = docs.render()
    current, superseded = sections(rendered[docs.RESULTS_MD]), sections(rendered[docs.SUPERSEDED_MD])
    assert list(current) == [t for t, *_ in docs.CURRENT + docs.IDEAL]
    assert list(superseded) == [t for t, *_ in docs.SUPERSEDED]
    for (title, *_, by), s in zip(docs.SUPERSEDED, superseded.values()):
        assert s.split("\n\n", 2)[1] == by, title
    for s in [*current.values(), *superseded.values()]:
        assert "Source: [`results/" in s and ("measured at commit `" in s or "committed in `" in s), s[:200]
        assert "command" in s, s[:200]


@pytest.mark.parametrize("path", RESULTS, ids=[str(p.relative_to(ROOT)) for p in RESULTS])
def test_no_results_file_holds_a_nan_literal(path):
    _strict(path.read_text())


def test_a_report_is_strict_json_and_says_where_it_came_from(tmp_path, capsys):
    """publish: the result's JSON (strict, with its command and commit), its markdown beside it, printed."""
    path = publish(tmp_path / "out", "r", {"std": float("nan"), "interval": [float("-inf"), 1.5], "n": 1}, "# R\n")
    data = _strict(path.read_text())
    assert path == tmp_path / "out" / "r.json" and (tmp_path / "out" / "r.md").read_text() == "# R\n"
    assert data["std"] is None and data["interval"] == [None, 1.5] and data["n"] == 1
    assert data["commit"] == git_commit() and data["command"] == sys.argv
    assert capsys.readouterr().out.startswith("# R\nwrote ")
    write_json(tmp_path / "cache.json", {"mean": math.nan})  # cache records too
    assert _strict((tmp_path / "cache.json").read_text()) == {"mean": None}


def test_a_benchmark_records_its_command_as_run(tmp_path):
    """A benchmark run by its path records ``python -m bench.<name> ...`` and the commit."""
    table = tmp_path / "t.json"
    table.write_text(json.dumps({"capture": {"kind": "ideal"}, "resolution": [8, 6], "evaluations": 1, "models": "m",
                                 "cells": {"one_plant/egp": {"recon": {"per_realization": [{"chamfer": 1.0}]}}}}))
    res = subprocess.run([sys.executable, str(ROOT / "bench" / "table1_combine.py"), str(table), "--out", str(tmp_path)],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr[-2000:]
    data = _strict((tmp_path / "table1_combined.json").read_text())
    assert data["command"] == ["python", "-m", "bench.table1_combine", str(table), "--out", str(tmp_path)]
    assert data["commit"] == git_commit()


def test_a_table_whose_plans_differ_is_marked_stale(tmp_path, monkeypatch):
    checks = tmp_path / "reference_plans.json"
    cell = {"commit": "abc", "date": "2026-01-01", "torch_cpu_capability": "AVX2"}
    write_json(checks, {"tables": {"results/table1.json": {"cells": {
        "one_plant/egp": {**cell, "reproduces": False}, "one_plant/arc": {**cell, "reproduces": True}}}}})
    monkeypatch.setattr(reference_plans, "RESULTS", checks)
    seed0 = docs.table1_seed0_section("results/table1.json", "T")
    assert "**STALE: the plans of one_plant/egp no longer come out of the planner**" in seed0
    combined = docs.combined_section("results/rerun/table1_combined/table1_combined.json", "C", "Table I")
    assert "**STALE**: one_plant/egp seed 0" in combined and "one_plant/arc seed 0" not in combined
    write_json(checks, {"tables": {"results/table1.json": {"cells": {"one_plant/egp": {**cell, "reproduces": True}}}}})
    assert "STALE" not in docs.table1_seed0_section("results/table1.json", "T")


def test_make_docs_check_says_when_a_document_is_stale(tmp_path):
    assert docs.main(["--out", str(tmp_path), "--check"]) == 1  # none written yet
    assert docs.main(["--out", str(tmp_path)]) == 0 and docs.main(["--out", str(tmp_path), "--check"]) == 0
    (tmp_path / docs.SUPERSEDED_MD).write_text("edited by hand\n")
    assert docs.main(["--out", str(tmp_path), "--check"]) == 1


def test_the_readme_is_short_and_its_figures_live_in_results_md():
    """At most 700 lines (read in ten minutes); its links into docs/results.md land on a table."""
    import re

    readme = (ROOT / "README.md").read_text()
    assert len(readme.splitlines()) <= 700
    anchors = {docs.anchor(t) for t, *_ in docs.CURRENT + docs.IDEAL}
    links = set(re.findall(r"docs/results\.md#([a-z0-9_-]+)", readme))
    assert links and links <= anchors, links - anchors
