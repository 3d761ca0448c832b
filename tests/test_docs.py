"""The documents: docs/results.md and docs/history_results.md are generated from the files under
results/ (``make docs`` gives the committed files byte for byte, so they are never edited by hand),
every table names its file, commit and command, a table whose plans no longer reproduce is marked
stale, and no results file holds a NaN or Infinity literal (JSON has none; the benchmarks write null).
The README is a short guide (words and line length counted); its generated blocks and docs/'s are
what the code gives (``tools/doc_tables.py``), and every link between the documents lands on a heading."""
from __future__ import annotations

import json
import math
import re
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


def test_every_benchmark_result_names_a_commit_of_this_repository():
    """A result file written by a benchmark (its command ``python -m bench...``) names the commit it
    was measured at, one this repository holds (``-dirty``: tracked files differed then); files
    without a command predate the writer and say where they were committed in docs/results.md."""
    commits = {}
    for path in RESULTS:
        data = _strict(path.read_text())
        if isinstance(data, dict) and data.get("command", [])[:2] == ["python", "-m"]:
            commits[str(path.relative_to(ROOT))] = data.get("commit")
    assert commits
    malformed = {p: c for p, c in commits.items() if not re.fullmatch(r"[0-9a-f]{12}(-dirty)?", str(c))}
    assert not malformed, malformed
    shallow = subprocess.run(["git", "rev-parse", "--is-shallow-repository"], cwd=ROOT, capture_output=True,
                             text=True, timeout=30).stdout.strip()
    if shallow != "false":
        pytest.skip("a shallow clone holds only its newest commits")
    heads = sorted({c.split("-")[0] for c in commits.values()})
    asked = "".join(f"{h}^{{commit}}\n" for h in heads)
    found = subprocess.run(["git", "cat-file", "--batch-check"], cwd=ROOT, input=asked, capture_output=True,
                           text=True, timeout=60).stdout.splitlines()
    unknown = {h for h, line in zip(heads, found) if line.endswith("missing")}
    assert not unknown, {p: c for p, c in commits.items() if c.split("-")[0] in unknown}


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


#: The README is read in about a quarter of an hour, its lines in any editor.
README_WORDS, README_LINE = 3000, 120
DOCUMENTS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def test_the_readme_is_a_short_guide():
    """At most 3,000 words (the README was 9,411 words in 700 lines, some of them 1,430 characters
    long: a line count passed it), every line under 120 characters."""
    readme = (ROOT / "README.md").read_text()
    words = len(readme.split())
    assert words <= README_WORDS, f"README.md has {words} words, at most {README_WORDS}: move details to docs/"
    long = [(n, len(line)) for n, line in enumerate(readme.splitlines(), 1) if len(line) >= README_LINE]
    assert not long, f"README.md lines of {README_LINE} characters or more (line, length): {long}"


def test_the_generated_blocks_are_what_the_code_gives():
    """The method table, the nodes' parameters and the interfaces' fields in README.md and docs/
    are rewritten from the code; a parameter or field added, removed or changed fails here until
    ``python tools/doc_tables.py`` (``make docs``) is run."""
    import doc_tables  # tools/, on the path through conftest

    stale = doc_tables.stale()
    names = [str(p.relative_to(ROOT)) for p in stale]
    assert not stale, f"generated blocks differ from the code in {names}: run python tools/doc_tables.py"
    text = (ROOT / "README.md").read_text()
    for what in ("methods", "action-names PlanViews"):
        assert f"<!-- generated: {what} -->" in text, what
    nodes = (ROOT / "docs" / "nodes.md").read_text()
    for module in ("vp_scene.scene_node:SPECS", "vp_planner.planner_node", "vp_recon.recon_node",
                   "vp_planner.dispatcher_node", "vp_scene.sim_drone_node", "vp_recon.recorder_node",
                   "vp_recon.viewer_node"):
        assert f"<!-- generated: params {module} -->" in nodes, module


def test_a_generated_block_follows_the_code(monkeypatch):
    """A parameter the code gains appears in its block; an edited block is put back."""
    import doc_tables
    from vp_scene import node_runtime, sim_drone_node

    monkeypatch.setitem(sim_drone_node.PARAMS, "battery", node_runtime.Param(0.5, "state of charge", (0.0, 1.0)))
    text = "a\n<!-- generated: params vp_scene.sim_drone_node -->\nedited\n<!-- end generated -->\nb\n"
    out = doc_tables.render(text)
    assert "| `battery` | 0.5 | [0, 1] |  | state of charge |" in out and "edited" not in out
    assert out.startswith("a\n<!-- generated: params vp_scene.sim_drone_node -->\n| parameter |")
    assert out.endswith("<!-- end generated -->\nb\n") and doc_tables.render(out) == out


def _anchor(heading: str) -> str:
    """GitHub's anchor of a markdown heading."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def test_links_between_the_documents_land_on_a_heading():
    """Every relative link of README.md and docs/*.md names a file that exists, and its #anchor a
    heading of that file; links into docs/results.md land on a table (the README's sections moved
    to docs/: a reference to one that is not there fails here)."""
    tables = {docs.anchor(t) for t, *_ in docs.CURRENT + docs.IDEAL}
    bad, into_results = [], 0
    for doc in DOCUMENTS:
        for target, anchor in re.findall(r"\]\(([^)#\s]*)(?:#([^)\s]*))?\)", doc.read_text()):
            if target.startswith(("http://", "https://", "mailto:")):
                continue
            path = (doc.parent / target).resolve() if target else doc
            if not path.exists():
                bad.append((doc.name, target))
                continue
            if not anchor or path.suffix != ".md":
                continue
            if path == docs.OUT / docs.RESULTS_MD:
                into_results += 1
                if anchor not in tables:
                    bad.append((doc.name, f"{target}#{anchor}"))
                continue
            headings = {_anchor(h) for h in re.findall(r"^#+ (.+)$", path.read_text(), re.M)}
            if anchor not in headings:
                bad.append((doc.name, f"{target}#{anchor}"))
    assert into_results and not bad, bad
