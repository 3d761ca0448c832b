"""bench/bench_sorties.py (issue 21, part 3): the verdict against the issue's target and the
files it writes (the benchmark itself runs for hours; its smoke slice is in the README)."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from bench import bench_sorties


def row(**chamfer) -> dict:
    cases = {c: {"chamfer_mean": chamfer.get(c.replace("-", "_")), "chamfer_std": 0.0} for c in bench_sorties.CASES}
    return {"n": 4, "m": 2, "sortie1": {"reward": 0.5, "chamfer": {"chamfer_mean": 2.0, "chamfer_std": 0.0}},
            "cases": cases}


def test_verdict_against_the_target() -> None:
    good = row(a=1.0, b=1.2, c_circle=1.3, c_arc=1.25, d=1.1, e=1.04)
    assert bench_sorties.verdict(good) == ("e beats b; e beats c-circle; e beats c-arc; +4.0 % of a (within 5 %)")
    bad = row(a=1.0, b=1.05, c_circle=1.3, c_arc=1.25, d=1.1, e=1.08)
    assert bench_sorties.verdict(bad) == ("e does not beat b; e beats c-circle; e beats c-arc; +8.0 % of a (beyond 5 %)")
    assert bench_sorties.verdict(row(a=1.0)) == "e failed"
    # a case that failed in one realization ranks behind e whatever its mean (six_rect's circle)
    one_failed = row(a=1.0, b=1.2, c_circle=0.5, c_arc=1.25, d=1.1, e=1.04)
    one_failed["cases"]["c-circle"]["failed"] = 1
    assert bench_sorties.verdict(one_failed).startswith("e beats b; e beats c-circle; e beats c-arc;")
    e_failed = row(a=1.0, b=1.2, c_circle=1.3, c_arc=1.25, d=1.1, e=0.9)
    e_failed["cases"]["e"]["failed"] = 1
    assert bench_sorties.verdict(e_failed) == ("e does not beat b; e does not beat c-circle; e does not beat c-arc; "
                                               "-10.0 % of a (beyond 5 %; e failed in 1 realization(s))")


def test_results_files(tmp_path: Path) -> None:
    args = bench_sorties.parse_args(["--models", "", "--out", str(tmp_path), "--capture", "ideal"])
    bench_sorties.write_results(args, tmp_path, {"one_plant": row(a=1.0, b=1.2, c_circle=1.3, c_arc=1.25, d=1.1,
                                                                  e=1.04)})
    md = (tmp_path / "bench_sorties.md").read_text()
    assert "| one_plant | 4 + 2 | 2.000 +- 0.000 | 1.000 +- 0.000 |" in md and "within 5 %" in md
    data = json.loads((tmp_path / "bench_sorties.json").read_text())
    assert data["rows"]["one_plant"]["cases"]["e"]["chamfer_mean"] == 1.04


def test_a_slice_runs_on_a_local_cluster_and_a_rerun_reads_the_cache(tmp_path: Path) -> None:
    """The smoke slice (procedural plants, 640x480, ideal capture, egp without its simulated flights:
    tests/test_flights_nodes.py and the planner's tests fly them) through a 1-worker LocalCluster:
    every case of the table has a result or a named error, sortie 2's plan e is made from sortie 1's
    reconstruction, and a rerun runs no task (every plan and reconstruction cached)."""
    argv = ["--models", "", "--scenarios", "one_plant", "--evals", "4", "--init", "3", "--realizations", "1",
            "--width", "640", "--height", "480", "--capture", "ideal", "--out", str(tmp_path), "--workers", "1",
            "--threads", "1", "--planner", "egp-cheap"]
    assert bench_sorties.main(argv) == 0
    rows = json.loads((tmp_path / "bench_sorties.json").read_text())["rows"]
    cases = rows["one_plant"]["cases"]
    assert set(cases) == set(bench_sorties.CASES)
    assert all(c.get("chamfer_mean") is not None or c.get("error") for c in cases.values())
    assert rows["one_plant"]["sortie1"]["chamfer"].get("chamfer_mean") is not None, rows["one_plant"]["sortie1"]["chamfer"]
    assert cases["e"]["chamfer_mean"] is not None  # planned given sortie 1's reconstruction
    # every plan flown is kept in the results, sortie 2's beside sortie 1's (a: all N + M cameras)
    assert len(rows["one_plant"]["sortie1"]["cameras"]) == 4 and len(cases["a"]["cameras"]) == 6
    assert all(len(cases[c]["cameras"]) == 2 for c in ("b", "c-circle", "c-arc", "d", "e"))
    plans = sorted(p.name for p in (tmp_path / "cache" / "plans").glob("*.json"))
    assert len(plans) == 7 and sum("sortie2-e" in p and "-k1" in p for p in plans) == 1
    assert len(list((tmp_path / "cache" / "recon").glob("*.json"))) == 7
    stamps = {p: p.stat().st_mtime_ns for p in (tmp_path / "cache").rglob("*.json")}
    assert bench_sorties.main(argv) == 0
    assert {p: p.stat().st_mtime_ns for p in (tmp_path / "cache").rglob("*.json")} == stamps
    assert json.loads((tmp_path / "bench_sorties.json").read_text())["rows"] == rows


def test_the_matching_is_part_of_a_reconstruction_s_cache_name() -> None:
    """``--matching exhaustive`` reconstructs again (its own cache files); ``auto`` keeps the names
    of the reconstructions made before the flag existed."""
    auto = bench_sorties.parse_args(["--models", ""])
    exhaustive = bench_sorties.parse_args(["--models", "", "--matching", "exhaustive"])
    assert bench_sorties.recon_tag("three_row", "d-n6-m3", auto).endswith("-k2")
    assert bench_sorties.recon_tag("three_row", "d-n6-m3", exhaustive) == (
        bench_sorties.recon_tag("three_row", "d-n6-m3", auto) + "-exhaustive")
    with pytest.raises(SystemExit):
        bench_sorties.parse_args(["--models", "", "--matching", "all"])


def test_a_non_default_reward_is_part_of_every_cache_name(tmp_path: Path) -> None:
    """``--reward coverage-graph`` plans and reconstructs again (its own cache files for the plans
    of sortie 1, a-c, d, e and every reconstruction); the default keeps the names written before
    the option existed, and an unknown model is refused."""
    from bench.common import plan_path

    default = bench_sorties.parse_args(["--models", ""])
    graph = bench_sorties.parse_args(["--models", "", "--reward", "coverage-graph"])
    assert bench_sorties.recon_tag("one_plant", "e-n4-m2", default).endswith("-k2")
    assert bench_sorties.recon_tag("one_plant", "e-n4-m2", graph) == (
        bench_sorties.recon_tag("one_plant", "e-n4-m2", default) + "-coverage-graph")
    for e in (False, True):
        d_path = bench_sorties.sortie2_path(tmp_path, "one_plant", 2, default, e)
        g_path = bench_sorties.sortie2_path(tmp_path, "one_plant", 2, graph, e)
        assert "coverage-graph" not in d_path.name and "coverage-graph" in g_path.name
    assert plan_path(tmp_path, "one_plant", "egp", 0, reward=graph.reward) != plan_path(tmp_path, "one_plant", "egp", 0)
    with pytest.raises(SystemExit):
        bench_sorties.parse_args(["--models", "", "--reward", "no-such-model"])
