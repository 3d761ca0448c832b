"""bench/plan_quality.py: the design/check split (stratified by family, seeded), the study's counts
(a plan without a reconstruction is counted as skipped, never dropped) and Spearman per half."""
from __future__ import annotations

import math

import numpy as np
import pytest

from bench.plan_quality import auc_halves, realization_agreement, roc_auc, spearman_halves, split_halves, \
    study_counts


def _plans() -> list[dict]:
    fams = {"circle": 9, "arc": 6, "egp-coverage": 3, "gp": 1}
    return [{"id": f"{f}-{i:03d}", "family": f, "recon": {0: {}}} for f, n in fams.items() for i in range(n)]


def test_the_split_is_stratified_by_family_seeded_and_complete():
    plans = _plans()
    half = split_halves(plans, seed=0)
    assert set(half) == {p["id"] for p in plans}
    for fam, n in (("circle", 9), ("arc", 6), ("egp-coverage", 3), ("gp", 1)):
        design = [i for i, h in half.items() if i.startswith(fam + "-") and h == "design"]
        assert len(design) == n // 2, fam          # every family in both halves (one-plan families: check)
    assert split_halves(list(reversed(plans)), seed=0) == half   # order of the plan list does not matter
    assert split_halves(plans, seed=1) != half                   # the seed does


def test_counts_name_the_skipped_and_failed_plans():
    plans = _plans()[:5]
    plans[3]["recon"] = {}                                       # never reconstructed
    chamfer = np.array([0.01, math.inf, 0.02, math.nan, 0.03])   # one failed, one skipped
    assert study_counts(plans, chamfer) == {"planned": 5, "reconstructed": 3, "failed": 1, "skipped": 1}


def test_spearman_per_half_ranks_a_failure_last_and_uses_only_its_half():
    ids = [f"p{i}" for i in range(8)]
    half = {i: ("design" if n % 2 else "check") for n, i in enumerate(ids)}
    chamfer = np.array([0.01, 0.05, 0.02, 0.06, 0.03, 0.07, math.inf, 0.08])
    reward = [0.9, 0.1, 0.8, 0.3, 0.7, 0.2, 0.0, 0.4]              # check half: perfect; design half: not
    rho = spearman_halves(ids, {"m": reward}, chamfer, half)
    assert rho["check"]["m"] == pytest.approx(1.0)
    assert rho["design"]["m"] == pytest.approx(-0.8)   # d = (3, 0, 0, -3): 1 - 6 * 18 / 60


def test_auc_separates_the_failed_plans_per_half():
    """ROC AUC (Mann-Whitney U / (n1 n0)): 1 when every reconstructed plan outranks every failed
    one, ties half, NaN when a half has no failed plan (or only failed ones); skipped plans
    (Chamfer NaN) are left out."""
    assert roc_auc([0.9, 0.8, 0.1], [False, False, True]) == 1.0
    assert roc_auc([0.1, 0.8, 0.9], [False, False, True]) == 0.0
    assert roc_auc([0.5, 0.5, 0.9], [False, True, False]) == 0.75         # one tie, one win
    assert math.isnan(roc_auc([0.5, 0.6], [False, False])) and math.isnan(roc_auc([0.5], [True]))
    ids = [f"p{i}" for i in range(6)]
    half = {i: ("design" if n < 3 else "check") for n, i in enumerate(ids)}
    chamfer = np.array([0.01, math.inf, 0.02, 0.03, math.inf, math.nan])
    auc = auc_halves(ids, {"m": [0.9, 0.1, 0.8, 0.2, 0.7, 0.0]}, chamfer, half)
    assert auc["design"]["m"] == 1.0 and auc["check"]["m"] == 0.0          # check: p5 skipped, p4 failed above p3


def _one_plant_plan_set(tmp_path):
    """(the study's arguments writing into tmp_path, the committed one_plant plan set); skipped
    where the plan set is for another plant folder."""
    from bench import plan_quality

    args = plan_quality.parse_args(["--scenarios", "one_plant", "--out", str(tmp_path)])
    if not plan_quality.plans_path("one_plant", args.models).exists():
        pytest.skip("the committed one_plant plan set is for another plant folder")
    return args, plan_quality.plans_of("one_plant", args.models)


def test_check_reads_the_main_variant_of_the_capture(tmp_path):
    """The check half of a study is read from the variant of the capture asked for: a flight's
    (realistic, soil) by default, the ideal one with --capture ideal; another is a named error."""
    import json

    from bench import plan_quality

    args, plans = _one_plant_plan_set(tmp_path)
    rng = np.random.default_rng(0)
    records = []
    for i, p in enumerate(plans):
        chamfer = float(rng.uniform(1, 5))
        records.append({"id": p["id"], "family": p["family"],
                        "reward": {"coverage": -chamfer, "paper": float(rng.uniform())},
                        "realizations": {"0": {"error": "RECONSTRUCTION_FAILED"} if i == 0 else {"chamfer": chamfer}}})
    variant = f"{plan_quality.variant_name(args)}/dense"
    assert variant == "2000x1500-realistic-anchored/dense"
    study = {"variants": {variant: {"per_plan": {"one_plant": records}}}}
    (tmp_path / "plan_quality.json").write_text(json.dumps(study))
    result = plan_quality.check_from_records(args)
    assert result["counts"]["one_plant"] == {"planned": len(plans), "reconstructed": len(plans) - 1,
                                             "failed": 1, "skipped": 0}
    assert result["spearman_check"]["one_plant"]["coverage"] > 0.9   # -Chamfer itself, the failed plan last
    with pytest.raises(SystemExit, match="no variant 2000x1500/dense"):
        plan_quality.check_from_records(plan_quality.parse_args(["--scenarios", "one_plant", "--out", str(tmp_path),
                                                                 "--capture", "ideal"]))


def _two_realizations(first: list, second: list) -> list[dict]:
    def rec(v):
        return {"error": "RECONSTRUCTION_FAILED"} if v is None else {"chamfer": v}
    return [{"id": f"p{i}", "recon": {"0": rec(a), "1": rec(b)}} for i, (a, b) in enumerate(zip(first, second))]


def test_realization_agreement_is_the_noise_ceiling_of_the_score():
    same = _two_realizations([0.01, 0.02, 0.03, None], [0.011, 0.025, 0.031, None])
    rel = realization_agreement(same)
    assert rel["realizations"] == ["0", "1"] and rel["n"] == 4
    assert rel["rho_between"] == pytest.approx(1.0) and rel["ceiling_mean"] == pytest.approx(1.0)
    assert rel["failed_in_one_only"] == 0
    # the second realization ranks the plans the other way round, and one fails only there
    flipped = realization_agreement(_two_realizations([0.01, 0.02, 0.03, 0.04], [None, 0.03, 0.02, 0.01]))
    assert flipped["rho_between"] == pytest.approx(-1.0) and math.isnan(flipped["ceiling_mean"])
    assert flipped["failed_in_one_only"] == 1
    # a middling agreement: Spearman-Brown sqrt(2 r / (1 + r)) lies between r and 1
    mid = realization_agreement(_two_realizations([0.01, 0.02, 0.03, 0.04, 0.05], [0.02, 0.01, 0.03, 0.05, 0.04]))
    assert 0 < mid["rho_between"] < mid["ceiling_mean"] < 1
    # a plan reconstructed in one realization only: no pair of realizations every plan has
    partial = _two_realizations([0.01, 0.02, 0.03], [0.01, 0.02, 0.03])
    del partial[1]["recon"]["1"]
    assert realization_agreement(partial) is None


def test_the_study_counts_each_distinct_plan_once() -> None:
    """Issue 42: egp-073/074/075 and gp-076 returned structured-000's plan on one_plant (an optimizer
    can return a plan of its initial design); a plan counted four times weighs its rank four times.
    The study keeps the first of equal plans and names the ones it drops."""
    from bench import plan_quality

    plans = [{"id": "structured-000", "cameras": [[0.0, 1.0, 2.0, 0.0, -1.0, -1.0]] * 2},
             {"id": "egp-073", "cameras": [[0.0, 1.0, 2.0, 0.0, -1.0, -1.0]] * 2},
             {"id": "arc-001", "cameras": [[1.0, 1.0, 2.0, 0.0, -1.0, -1.0]] * 2}]
    kept, dropped = plan_quality.distinct_plans(plans)
    assert [p["id"] for p in kept] == ["structured-000", "arc-001"] and dropped == {"egp-073": "structured-000"}


def test_analyze_scores_todays_rewards_against_a_reports_records(tmp_path):
    """--records: a committed study's reconstructions (per-plan records, failures with their
    reasons) are scored under today's reward models without the cache; the records are kept as
    they were, the rewards are today's, a plan the report never recorded is counted as skipped."""
    import json

    from bench import plan_quality
    from vp_planner.reward_models import make_reward

    args, plans = _one_plant_plan_set(tmp_path)
    rng = np.random.default_rng(0)
    records = []
    for i, p in enumerate(plans[:-1]):                      # the last plan: never reconstructed
        realization = ({"error": "RECONSTRUCTION_FAILED", "error_msg": "no pair"} if i == 0 else
                       {"chamfer": float(rng.uniform(1, 5)), "chamfer_shape": float(rng.uniform(1, 4)),
                        "sparse_chamfer": float(rng.uniform(1, 5))})
        records.append({"id": p["id"], "family": p["family"], "reward": {"coverage": 123.0},
                        "realizations": {"0": realization, "1": realization}})
    variant = f"{plan_quality.variant_name(args)}/dense"
    source = tmp_path / "before" / "plan_quality.json"
    source.parent.mkdir()
    source.write_text(json.dumps({"commit": "abc", "variants": {variant: {"per_plan": {"one_plant": records},
                                                                          "recon_hours": {"one_plant": 1.5}}}}))
    result = plan_quality.analyze(plan_quality.parse_args(["--scenarios", "one_plant", "--out", str(tmp_path),
                                                           "--records", str(source)]))
    assert result["records"]["commit"] == "abc"
    assert result["counts"]["one_plant"] == {"planned": len(plans), "reconstructed": len(plans) - 2,
                                             "failed": 1, "skipped": 1}
    kept = result["variants"][variant]["per_plan"]["one_plant"]
    assert [r["id"] for r in kept] == [r["id"] for r in records]
    assert kept[0]["realizations"]["0"]["error_msg"] == "no pair" and kept[5]["realizations"] == records[5]["realizations"]
    from bench.common import scene
    noisy, _ = scene("one_plant", args.models)
    today = float(make_reward("coverage", noisy.points)(np.array([plans[5]["cameras"]]))[0])
    assert kept[5]["reward"]["coverage"] == pytest.approx(today, abs=1e-5) and today != 123.0
    assert result["variants"][variant]["recon_hours"]["one_plant"] == 1.5
    assert set(result["variants"]) == {variant, variant.replace("/dense", "/sparse"), variant.replace("/dense", "/shape")}
    assert (tmp_path / "plan_quality.json").exists()


def test_flights_under_several_draw_sets_rank_by_their_mean_a_failure_last(tmp_path, monkeypatch):
    import json

    import bench.plan_quality as pq
    from vp_scene.flights import FlightSettings

    monkeypatch.setattr(pq, "CACHE", tmp_path)
    plans = [{"id": f"p-{i}"} for i in range(3)]
    setting = FlightSettings(1000, 750, 0, 0.5)
    chamfers = {0: [0.010, 0.020, 0.030], 1000: [0.030, None, 0.010]}   # p-1 fails under the second draws
    for first, values in chamfers.items():
        for p, c in zip(plans, values):
            path = pq.flight_path("one_plant", "", p, setting, first)
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps({"chamfer": c, "failed": c is None, "seconds": 2.0}))
    got = pq.flight_predictors("one_plant", "", plans)
    assert set(got) == {"flight-1000x750o0d0.5", "flight-1000x750o0d0.5-draws1000", "flight-1000x750o0d0.5-mean2"}
    mean = got["flight-1000x750o0d0.5-mean2"]
    assert mean["reward"][0] == pytest.approx(-0.020) and mean["reward"][2] == pytest.approx(-0.020)
    assert mean["reward"][1] == -math.inf and mean["failed"] == 1
    assert mean["ms_per_plan"] == pytest.approx(4000.0)                 # both flights' cost
    (tmp_path / pq.models_tag("") / "one_plant" / "flight-1000x750o0d0.5-draws1000" / "p-2.json").unlink()
    assert set(pq.flight_predictors("one_plant", "", plans)) == {"flight-1000x750o0d0.5"}  # a set not complete: left out


def test_a_second_draw_set_flies_under_its_own_draws_into_its_own_cache(tmp_path, monkeypatch):
    """run_flights with --flight-draws-from K: plan j's task flies draw K + j and writes under the
    K set's tag, never reading the first set's records."""
    import argparse

    import bench.plan_quality as pq

    import types

    import vp_recon.sim_flights
    import vp_scene.flights

    monkeypatch.setattr(pq, "CACHE", tmp_path)
    flown = {}  # plan id -> (cache path, first draw index asked of flight_draws)

    def fake_cached(path, compute):  # the computation runs with the flight itself stubbed
        flown[path.stem] = (path, compute())
        return flown[path.stem][1]

    noisy = types.SimpleNamespace(scene=None, config=types.SimpleNamespace(variance=0.01))
    monkeypatch.setattr(pq, "cached", fake_cached)
    monkeypatch.setattr(pq, "scene", lambda scenario, models: (noisy, None))
    monkeypatch.setattr(vp_scene.flights, "flight_draws", lambda seed, n, variance, start: [start])
    monkeypatch.setattr(vp_recon.sim_flights, "fly_plan",
                        lambda *a: types.SimpleNamespace(to_dict=lambda: a[3]))  # the draw flown
    monkeypatch.setattr(pq, "run_tasks", lambda client, tasks, desc: {t.key: t.fn(*t.args) for t in tasks})
    args = argparse.Namespace(scenarios=["one_plant"], models="", flight_width=1000, flight_height=750,
                              flight_sift_octave=0, flight_dense_scale=0.5, flight_draws_from=1000)
    pq.run_flights(args, None, {"one_plant": [{"id": "a-0", "cameras": []}, {"id": "b-1", "cameras": []}]})
    (path0, draw0), (path1, draw1) = flown["a-0"], flown["b-1"]
    assert path0.parent.name == path1.parent.name == "flight-1000x750o0d0.5-draws1000"
    assert (draw0, draw1) == (1000, 1001)
