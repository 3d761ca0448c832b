"""bench/common.py's reconstruction record: each wind realization reconstructs on its own (a
failure is recorded beside the others, never hides them, never is dropped), and a rerun asking
for more realizations reuses the cached ones instead of recomputing them."""
from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from bench import common


def _result(k: int) -> SimpleNamespace:
    r = SimpleNamespace(realization=k, chamfer=0.01 * (k + 1), chamfer_shape=0.005 * (k + 1), accuracy=0.004,
                        completeness=0.006, fscore=0.7, points=np.full((5, 3), float(k)),
                        colors=np.zeros((5, 3), np.uint8), images=4, sparse_models=1, source="dense",
                        matching="exhaustive", matched_pairs=6, centre_residual=0.03, sparse_mode="anchored",
                        sparse_fallback="", control=None,
                        seconds={"render": 1.0, "sparse": 2.0}, rendered=[])
    return SimpleNamespace(realizations=[r])


@pytest.fixture
def fake_pipeline(monkeypatch):
    """vp_recon.pipeline.reconstruct_plan replaced by one that fails realizations in ``failing``
    and records which realizations it was asked for."""
    from vp_recon import pipeline
    from vp_recon.errors import RECONSTRUCTION_FAILED, ReconError

    calls, failing = [], set()

    def reconstruct_plan(noisy, cameras, config, folder, realizations):
        (k,) = realizations
        calls.append(k)
        if k in failing:
            raise ReconError(RECONSTRUCTION_FAILED, f"realization {k}: registered 1 of 4 images")
        return _result(k)

    monkeypatch.setattr(pipeline, "reconstruct_plan", reconstruct_plan)
    return calls, failing


def _record(folder: Path, ks, known=None) -> dict:
    from vp_recon.config import ReconConfig

    noisy = SimpleNamespace(points=np.zeros((5, 10, 3)))
    return common.reconstruct_record(noisy, np.zeros((4, 6)), ReconConfig(), folder, ks, known)


def test_a_failed_realization_is_recorded_beside_the_others(tmp_path, fake_pipeline) -> None:
    calls, failing = fake_pipeline
    failing.add(1)
    rec = _record(tmp_path / "cell", range(3))
    assert calls == [0, 1, 2]  # the failure did not stop realization 2
    assert "error" not in rec and rec["failed"] == 1
    assert [p["realization"] for p in rec["per_realization"]] == [0, 1, 2]
    bad = rec["per_realization"][1]
    assert bad["chamfer"] is None and bad["error"] == "RECONSTRUCTION_FAILED" and "1 of 4" in bad["error_msg"]
    assert rec["chamfer_mean"] == pytest.approx((1.0 + 3.0) / 2)  # x100, over the reconstructed ones
    assert common.chamfer_text(rec) == "2.000 +- 1.000 (1 of 3 realizations failed)"
    assert sorted(p.name for p in (tmp_path / "cell").glob("recon_*.ply")) == ["recon_0.ply", "recon_2.ply"]


def test_a_record_fails_only_when_no_realization_reconstructs(tmp_path, fake_pipeline) -> None:
    _, failing = fake_pipeline
    failing.update({0, 1})
    rec = _record(tmp_path / "cell", [0, 1])
    assert rec["error"] == "RECONSTRUCTION_FAILED" and rec["chamfer_mean"] is None and rec["failed"] == 2
    assert common.chamfer_text(rec) == "failed (RECONSTRUCTION_FAILED)"


def test_more_realizations_reuse_the_cached_ones(tmp_path, fake_pipeline) -> None:
    calls, failing = fake_pipeline
    failing.add(1)
    cache, recon = tmp_path / "cache", tmp_path / "recon"
    cache.mkdir()
    old = _record(recon / "cell-x-k2-soil", range(2))  # realization 1 failed there
    (cache / "cell-x-k2-soil.json").write_text(json.dumps(old))
    calls.clear()
    known = common.known_realizations(cache / "cell-x-k4-soil.json", recon / "cell-x-k4-soil")
    assert sorted(known) == [0, 1]
    rec = _record(recon / "cell-x-k4-soil", range(4), known)
    assert calls == [2, 3]  # 0 and 1 come from the k2 record, its failure included
    assert rec["per_realization"][:2] == old["per_realization"]
    assert rec["failed"] == 1 and rec["chamfer_mean"] == pytest.approx((1.0 + 3.0 + 4.0) / 3)
    assert (recon / "cell-x-k4-soil" / "recon_0.ply").exists()  # the reused cloud travels along


def test_records_before_per_realization_failures_are_reused_by_position(tmp_path) -> None:
    """A cached record written before each entry named its realization: entries in order 0..j-1;
    an entry whose cloud is gone is recomputed, not reused."""
    cache, recon = tmp_path / "cache", tmp_path / "recon"
    cache.mkdir()
    (recon / "c-k2").mkdir(parents=True)
    (recon / "c-k2" / "recon_0.ply").write_text("ply")
    (cache / "c-k2.json").write_text(json.dumps({"per_realization": [{"chamfer": 1.5}, {"chamfer": 2.5}]}))
    known = common.known_realizations(cache / "c-k3.json", recon / "c-k3")
    assert known == {0: {"chamfer": 1.5}}
    assert common.known_realizations(cache / "c.json", recon / "c") == {}  # no realization count: nothing to reuse


def test_without_clouds_an_entry_whose_cloud_is_gone_is_reused(tmp_path) -> None:
    """The fields benchmark reads numbers alone (clouds=False): a record resumed from a report,
    whose clouds never travelled, still counts; Table I's default keeps recomputing it."""
    cache, recon = tmp_path / "cache", tmp_path / "recon"
    cache.mkdir()
    (cache / "c-k2.json").write_text(json.dumps({"per_realization": [{"realization": 0, "chamfer": 1.5},
                                                                     {"realization": 1, "chamfer": 2.5}]}))
    assert common.known_realizations(cache / "c-k3.json", recon / "c-k3") == {}
    known = common.known_realizations(cache / "c-k3.json", recon / "c-k3", clouds=False)
    assert {k: p["chamfer"] for k, p in known.items()} == {0: 1.5, 1: 2.5}


def _fields_report(args, capture: dict) -> dict:
    """A bench_fields.json of one realization: grid_3x3 N=8 with a good egp, a failed circle plan
    (and its stand-in reconstruction record), and an arc reconstructed under another capture."""
    from bench import bench_fields

    plan = {"cameras": [[0.0, 2.0, 1.5, 0.0, 0.0, 0.0]] * 8, "reward": 0.5, "reward_model": "coverage",
            "evaluations": 100, "seconds": 1.0, "parts": 2, "initial_best": 0.4}
    entry = {"realization": 0, "chamfer": 2.0, "chamfer_shape": 1.0, "accuracy": 1.0, "completeness": 1.0,
             "seconds": {"render": 1.0}}
    recon = {"chamfer_mean": 2.0, "chamfer_std": 0.0, "failed": 0, "capture": capture["kind"],
             "capture_params": capture, "per_realization": [entry]}
    return {"models": "procedural", "seed": args.seed, "resolution": [args.width, args.height], "realizations": 1,
            "evaluations_per_part": bench_fields.EVALS_PER_PART,
            "cells": {"grid_3x3:8/egp": {"plan": plan, "recon": recon},
                      "grid_3x3:8/circle": {"plan": {"error": "RuntimeError", "error_msg": "x"},
                                            "recon": {"error": "RuntimeError", "error_msg": "planning failed: x",
                                                      "per_realization": []}},
                      "grid_3x3:8/arc": {"plan": plan, "recon": {**recon, "capture_params": {**capture, "seed": 7}}}},
            "subsampling": {"grid_3x3:8": {"plans": 3, "sizes": {}}}}


def test_a_fields_run_on_a_fresh_clone_resumes_from_the_committed_report(tmp_path, fake_pipeline) -> None:
    """The cache is git-ignored; bench_fields.json is committed. A run into the report's folder with
    one more realization writes the report's records where that run cached them and reconstructs
    only the new realization; failures, other captures and other settings are not carried over."""
    from bench import bench_fields

    calls, _ = fake_pipeline
    out = tmp_path / "fields_seed1"
    out.mkdir()
    args = bench_fields.parse_args(["--models", "", "--fields", "grid_3x3:8", "--seed", "1", "--realizations", "2",
                                    "--out", str(out)])
    capture = common.capture_of(args).to_dict()
    report = _fields_report(args, capture)
    (out / "bench_fields.json").write_text(json.dumps(report))
    cache = out / "cache" / "fields"
    # another planning seed: the whole report is left alone
    other = bench_fields.parse_args(["--models", "", "--seed", "2", "--out", str(out)])
    assert bench_fields.resume_from_report(out, cache, other) == 0 and not cache.exists()

    # egp's plan and recon, arc's plan (its reconstruction flew another capture), the subsampling
    assert bench_fields.resume_from_report(out, cache, args) == 4
    egp_plan = bench_fields.plan_path(cache, "grid_3x3", 8, "egp", args)[0]
    assert json.loads(egp_plan.read_text()) == report["cells"]["grid_3x3:8/egp"]["plan"]
    assert not bench_fields.plan_path(cache, "grid_3x3", 8, "circle", args)[0].exists()  # failures run again
    assert sorted(p.name for p in (cache / "recon").iterdir()) == [
        bench_fields.recon_tag("grid_3x3", 8, "egp", bench_fields.parse_args(
            ["--models", "", "--seed", "1", "--realizations", "1"])) + ".json"]
    assert bench_fields.resume_from_report(out, cache, args) == 0  # nothing written over the cache

    rec = bench_fields.recon_cell(cache, out, "grid_3x3", 8, "egp", report["cells"]["grid_3x3:8/egp"]["plan"], args)
    assert calls == [1]  # realization 0 came from the report
    assert [p["chamfer"] for p in rec["per_realization"]] == [2.0, 2.0]  # the fake's realization 1: 0.02 x100

    (out / "bench_fields.json").write_text("{torn")
    with pytest.raises(SystemExit, match="is not JSON"):
        bench_fields.resume_from_report(out, cache, args)
