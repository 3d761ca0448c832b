#!/usr/bin/env python3
"""Fields: every method on a 3 x 3 grid (N = 8) and a row of 12 plants (N = 12, and N = 16).

For each field and method: the plan's reward (the default model), the planning seconds (one torch
thread, nothing else running), and its reconstruction on the first ``--realizations`` wind
realizations (default 2) at 2000 x 1500 (render, COLMAP with pose-chosen image pairs from 8
cameras up, CPU dense stereo): Chamfer, accuracy, completeness x100 and seconds per realization.
Methods:

* ``egp``: the default planner; on these fields it plans by parts (``vp_planner.parts``: 100
  evaluations a part, 50 for the joint refinement);
* ``egp-one-space``: EGP-EI in one 6N-dimensional space with the same number of evaluations (the
  measurement behind planning by parts);
* ``circle``, ``arc``, ``sa``: the baselines, with egp's total number of evaluations;
* ``lawnmower`` (nadir) and ``lawnmower-oblique`` (30 degrees), 70% overlap: the survey farmers
  fly (one evaluation, no tuning).

Also measured (``subsampling``): how the ``coverage`` reward's point subsampling (3000 points a
realization by default) changes the reward on these fields: Spearman's rho against the reward on
all points over 80 plans a field, the mean shift, and the cost per plan.

Writes ``results/bench_fields.md`` and ``results/bench_fields.json``; every plan and
reconstruction is cached under ``results/cache/fields`` (a re-run resumes). The cache is not
committed; the report is: a run into a folder whose ``bench_fields.json`` has the same settings
starts from that report's plans and realizations (:func:`resume_from_report`), so a study grown by
``--realizations`` 1, 2, ... goes on from a fresh clone, another machine or another session. Uses the Corn50 plants
of ``../shared/data/corn50`` when present (``--models``), else procedural plants.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

if not __package__:  # python bench/bench_fields.py: as python -m bench.bench_fields (bench/_script.py)
    import _script  # noqa: F401
from vp_scene.limits import seed_arg  # noqa: E402
from bench.cache import cached, write_json  # noqa: E402
from bench.cluster import Task, cluster_client, run_tasks  # noqa: E402
from bench.common import (VARIANTS, baselines, capture_of, capture_tag, chamfer_text, flight_simulator,  # noqa: E402
                          flight_tag, known_realizations, models_tag, reconstruct_record, reconstructed, scene,
                          variant_request, variants_of)
from bench.options import parser  # noqa: E402
from bench.publish import machine, publish  # noqa: E402
from bench.stats import describe, describe_difference, paired_difference, rank, summary  # noqa: E402

#: (field, N) cells: the issue's targets, and N = 16 on the row (planned and reconstructed).
FIELDS = (("grid_3x3", 8), ("row_12", 12), ("row_12", 16))
#: The method labels: the variants of ``common.VARIANTS`` this benchmark runs (``evaluations``
#: filled in per field).
METHODS = variants_of("fields")
#: The baselines of the paired differences (every METHODS row that is not egp).
BASELINES = baselines(METHODS)
EVALS_PER_PART = 100
SUBSAMPLE_SIZES = (1500, 3000, 6000, 12000, 0)


def parse_args(argv=None) -> argparse.Namespace:
    ap = parser(__doc__, "models", "images", "threads", "capture", "cluster", "out")
    ap.add_argument("--fields", nargs="+", default=[f"{f}:{n}" for f, n in FIELDS],
                    help="FIELD:N cells, e.g. grid_3x3:8 row_12:12")
    ap.add_argument("--methods", nargs="+", default=list(METHODS), choices=list(METHODS))
    ap.add_argument("--no-recon", dest="recon", action="store_false", help="plan only")
    ap.add_argument("--recon-methods", nargs="+", default=None, choices=list(METHODS),
                    help="methods to reconstruct (default: all of --methods)")
    ap.add_argument("--realizations", type=int, default=2, help="wind realizations reconstructed per plan")
    ap.add_argument("--seed", type=seed_arg, default=0)
    return ap.parse_args(argv)


def field_budget(field: str, n: int, models: str) -> tuple[int, int]:
    """(parts egp plans by, its total evaluations) on this field."""
    from vp_planner.parts import auto_parts
    from vp_planner.request import total_evaluations

    noisy, _ = scene(field, models)
    parts = auto_parts(noisy.points, n)
    return parts, total_evaluations("egp", EVALS_PER_PART, parts)


def field_cell(spec: str) -> tuple[str, int]:
    """(field, N) of a ``FIELD:N`` cell (``--fields``, the report's keys)."""
    field, _, n = spec.partition(":")
    return field, int(n)


def plan_path(cache: Path, field: str, n: int, label: str, args) -> tuple[Path, int]:
    """(cache file, evaluation budget) of :func:`plan_cell`."""
    parts, total = field_budget(field, n, args.models)
    evals = EVALS_PER_PART if by_parts(label) else total
    tag = flight_tag(variant_request(label, num_cameras=n, evaluations=evals, initial_evaluations=min(50, evals),
                                     seed=args.seed))
    return cache / "plans" / f"{models_tag(args.models)}-{field}-n{n}-{label}-seed{args.seed}-e{evals}{tag}.json", evals


def by_parts(label: str) -> bool:
    """Whether the variant plans a field by parts (egp/gp with automatic parts): it gets
    :data:`EVALS_PER_PART` a part, the others egp's total."""
    variant = VARIANTS[label]
    return not variant.baseline and variant.request.get("parts", 0) != 1


def plan_cell(cache: Path, field: str, n: int, label: str, args) -> dict:
    """One planning run (cached), timed alone with one torch thread."""
    from vp_planner.optimizers import plan_views

    path, evals = plan_path(cache, field, n, label, args)
    request = variant_request(label, num_cameras=n, evaluations=evals, initial_evaluations=min(50, evals),
                              seed=args.seed)

    def compute() -> dict:
        import torch

        torch.set_num_threads(1)
        noisy, _ = scene(field, args.models)
        res = plan_views(request, noisy.points, simulator=flight_simulator(request, noisy))
        return {"cameras": np.asarray(res.cameras).tolist(), "reward": float(res.reward),
                "reward_model": res.reward_model, "evaluations": int(res.evaluations),
                "seconds": float(res.seconds), "parts": res.parts, "initial_best": res.initial_best,
                "chosen_by": res.chosen_by, "flight_score": res.flight_score, "flights_note": res.flights_note,
                "flights": res.flights, "flight_plans": res.flight_plans,
                "flight_settings": request.flights.settings().to_dict()}
    return cached(path, compute)


def recon_tag(field: str, n: int, label: str, args) -> str:
    return (f"{models_tag(args.models)}-{field}-n{n}-{label}-seed{args.seed}-{args.width}x{args.height}"
            f"-k{args.realizations}{capture_tag(capture_of(args))}")


def recon_cell(cache: Path, out: Path, field: str, n: int, label: str, plan: dict, args) -> dict:
    """Reconstruct a plan on the first ``args.realizations`` wind realizations (cached)."""
    from vp_recon.config import ReconConfig

    tag = recon_tag(field, n, label, args)

    def compute() -> dict:
        noisy, _ = scene(field, args.models)
        cfg = ReconConfig(width=args.width, height=args.height, num_threads=args.threads,
                          capture=capture_of(args))
        ks = range(min(args.realizations, len(noisy.points)))
        return reconstruct_record(noisy, plan["cameras"], cfg, out / "recon" / "fields" / tag, ks,
                                  known_realizations(cache / "recon" / f"{tag}.json", out / "recon" / "fields" / tag,
                                                     clouds=False))
    return cached(cache / "recon" / f"{tag}.json", compute)


def resume_from_report(out: Path, cache: Path, args) -> int:
    """Seed the cache with the records of ``out/bench_fields.json`` (an earlier run's report) that
    this run would otherwise recompute; returns how many files it wrote.

    Each record goes where that run cached it: a plan under its plan file, a reconstruction of K
    realizations under the tag with ``-k<K>``, which a run with more realizations reuses entry by
    entry (:func:`common.known_realizations`; the report holds no clouds, and the fields benchmark
    reads none). Nothing is written over an existing cache file, and nothing from a report of other
    settings: another plant set, planning seed, image size or budget (the whole report is left
    alone), or a reconstruction under another capture (that record alone). The subsampling
    measurement goes where :func:`subsampling_cell` caches it. Failed tasks are not
    records (the cache never keeps them; they run again), nor is a failed plan's stand-in record."""
    from argparse import Namespace

    report_file = out / "bench_fields.json"
    if not report_file.exists():
        return 0
    try:
        report = json.loads(report_file.read_text())
    except json.JSONDecodeError as exc:
        raise SystemExit(f"bench_fields: {report_file} is not JSON ({exc}); move it away to start afresh")
    same = (report.get("models") == models_tag(args.models) and report.get("seed") == args.seed
            and report.get("resolution") == [args.width, args.height]
            and report.get("evaluations_per_part") == EVALS_PER_PART)
    if not same:
        print(f"bench_fields: {report_file} has other settings; not resumed from", flush=True)
        return 0
    capture = capture_of(args).to_dict()
    as_run = Namespace(**{**vars(args), "realizations": int(report["realizations"])})
    written = 0
    for key, cell in report.get("cells", {}).items():
        spec, _, label = key.partition("/")
        field, n = field_cell(spec)
        if label not in METHODS:
            continue
        plan, recon = cell.get("plan") or {}, cell.get("recon") or {}
        targets = []
        if "cameras" in plan and "error" not in plan:
            targets.append((plan_path(cache, field, n, label, args)[0], plan))
        if recon.get("per_realization") and recon.get("capture_params") == capture:
            targets.append((cache / "recon" / f"{recon_tag(field, n, label, as_run)}.json", recon))
        for path, record in targets:
            if not path.exists():
                write_json(path, record)
                written += 1
    for spec, record in report.get("subsampling", {}).items():
        path = subsampling_path(cache, *field_cell(spec), args)
        if not path.exists():
            write_json(path, record)
            written += 1
    print(f"bench_fields: resumed from {report_file} ({report['realizations']} realization(s)): "
          f"{written} record(s) into {cache}", flush=True)
    return written


def subsampling_path(cache: Path, field: str, n: int, args) -> Path:
    return cache / "subsampling" / f"{models_tag(args.models)}-{field}-n{n}.json"


def subsampling_cell(cache: Path, field: str, n: int, plans: dict, args) -> dict:
    """The coverage reward at several subsample sizes on 80 plans of this field (cached): 20
    structured, 50 random feasible, and the benchmark's own plans."""
    import torch
    from dataclasses import replace
    from scipy.stats import spearmanr

    from vp_planner.designs import random_plans, structured_plans
    from vp_planner.reward_models import CoverageParams, make_reward
    from vp_planner.space import ViewSpace

    path = subsampling_path(cache, field, n, args)

    def compute() -> dict:
        torch.set_num_threads(1)
        noisy, _ = scene(field, args.models)
        R = noisy.points
        space = ViewSpace(R, n)
        U = np.concatenate([structured_plans(space, 20), random_plans(space, 50, np.random.default_rng(args.seed))])
        planned = np.array([p["cameras"] for p in plans.values() if len(p["cameras"]) == n]).reshape(-1, n, 6)
        cams = np.concatenate([space.decode(U), planned])  # a failed plan has no cameras: not among them
        out = {"plans": int(len(cams)), "points_per_realization": int(R.shape[1]), "sizes": {}}
        ref = None
        for size in reversed(SUBSAMPLE_SIZES):  # all points first: the reference
            f = make_reward(("coverage", replace(CoverageParams(), max_points=size)), R, dtype=torch.float32)
            t0 = time.perf_counter()
            r = np.array([float(f(c[None])[0]) for c in cams])
            ms = 1000 * (time.perf_counter() - t0) / len(cams)
            ref = r if ref is None else ref
            out["sizes"][str(size or R.shape[1])] = {
                "spearman_vs_all": float(spearmanr(ref, r)[0]), "mean_shift": float(np.mean(r - ref)),
                "max_abs_diff": float(np.max(np.abs(r - ref))), "ms_per_plan": ms, "mean_reward": float(r.mean())}
        return out
    return cached(path, compute)


def main(argv=None) -> int:
    args = parse_args(argv)
    out = Path(args.out)
    cache = out / "cache" / "fields"
    resume_from_report(out, cache, args)
    cells = [field_cell(spec) for spec in args.fields]
    with cluster_client(args) as client:
        tasks = [Task((field, n, label), plan_cell, (cache, field, n, label, args),
                      plan_path(cache, field, n, label, args)[0], f"{field} N={n} {label}")
                 for field, n in cells for label in args.methods]
        plans = run_tasks(client, tasks, "planning")
        for (field, n, label), p in plans.items():
            print(f"plan {field} N={n} {label}: " + (f"FAILED {p['error']}: {p['error_msg']}" if "error" in p else
                  f"reward {p['reward']:.4f}, {p['evaluations']} evaluations, {p['seconds']:.1f} s"), flush=True)
        recons: dict = {}
        if args.recon:
            tasks = [Task((field, n, label), recon_cell, (cache, out, field, n, label, plans[(field, n, label)], args),
                          cache / "recon" / f"{recon_tag(field, n, label, args)}.json", f"{field} N={n} {label}")
                     for field, n in cells for label in args.recon_methods or args.methods
                     if label in args.methods and "error" not in plans[(field, n, label)]]
            recons = run_tasks(client, tasks, "reconstructing")
            for key, p in plans.items():  # a failed plan is a failed reconstruction: counted, ranked last
                if "error" in p and (args.recon_methods is None or key[2] in args.recon_methods):
                    recons[key] = {"error": p["error"], "error_msg": f"planning failed: {p['error_msg']}",
                                   "chamfer_mean": None, "chamfer_std": None, "per_realization": []}
            for (field, n, label), r in recons.items():
                print(f"recon {field} N={n} {label}: Chamfer x100 {chamfer_text(r)}", flush=True)
    subsampling = {f"{field}:{n}": subsampling_cell(cache, field, n,
                                                    {k[2]: v for k, v in plans.items()
                                                     if k[:2] == (field, n) and "error" not in v}, args)
                   for field, n in cells}
    write_results(args, out, cells, plans, recons, subsampling)
    return 0


def realization_chamfers(r: dict, args) -> dict:
    """realization -> Chamfer x100 of a reconstruction record, None where it failed (each
    realization on its own: ``common.reconstruct_record``; a failed plan fails in every one)."""
    per = {p.get("realization", i): p.get("chamfer") for i, p in enumerate(r.get("per_realization", []))}
    return {k: per.get(k) for k in range(args.realizations)}


def paired_lines(field: str, n: int, args, recons: dict, result: dict) -> list[str]:
    """egp rows - the best-ranked baseline, paired per wind realization, 95 % t-interval."""
    units = {label: realization_chamfers(recons[(field, n, label)], args)
             for label in args.methods if (field, n, label) in recons}
    baselines = [m for m in units if m in BASELINES]
    egps = [m for m in units if m not in BASELINES]
    if not baselines or not egps:
        return []
    best = rank({m: summary(units[m]) for m in baselines})[0]
    lines = ["", f"Paired per realization, Chamfer x100 minus the best baseline ({best}); mean [95 % t-interval] (n):", ""]
    for m in egps:
        d = paired_difference(units[m], units[best])
        result.setdefault("paired", {})[f"{field}:{n}/{m}"] = {"baseline": best, **d}
        lines.append(f"- {m} - {best}: {describe_difference(d)}")
    return lines


def write_results(args, out: Path, cells, plans, recons, subsampling) -> None:
    stamp = datetime.now(timezone.utc).strftime("%Y-%m-%d")
    host = machine()
    result = {"date": stamp, "machine": host, "models": models_tag(args.models), "seed": args.seed,
              "resolution": [args.width, args.height], "realizations": args.realizations,
              "evaluations_per_part": EVALS_PER_PART, "cells": {}, "subsampling": subsampling}
    lines = [f"# Fields, measured {stamp} ({host})", "",
             f"Plants: {'Corn50 (' + models_tag(args.models) + ')' if args.models else 'built-in procedural corn'} (scene seed 0; planning seed {args.seed}). Reward: the default "
             "model. Chamfer x100 (mean +- sample std (ddof 1, n successful; failures counted) over wind realizations "
             f"0..{args.realizations - 1}, {args.width} x {args.height}), lower is better. Planning seconds alone "
             "(one torch thread); reconstruction seconds per realization.", ""]
    for field, n in cells:
        parts, total = field_budget(field, n, args.models)
        lines += [f"## {field}, N = {n} (egp: {parts} parts, {total} evaluations)", "",
                  "| method | reward | evaluations | planning s | Chamfer x100 | accuracy | completeness | "
                  "recon s / realization | pairs matched per realization |", "|---|---|---|---|---|---|---|---|---|"]
        for label in args.methods:
            p = plans[(field, n, label)]
            r = recons.get((field, n, label))
            cell = {"plan": p, "recon": r}
            result["cells"][f"{field}:{n}/{label}"] = cell
            if r is None:
                rec = ["-"] * 5
            elif r.get("error"):
                rec = [f"{describe(summary(realization_chamfers(r, args)))} ({r['error']})", "-", "-", "-", "-"]
            else:
                per = reconstructed(r["per_realization"])
                rec = [describe(summary(realization_chamfers(r, args))),
                       f"{np.mean([x['accuracy'] for x in per]):.3f}",
                       f"{np.mean([x['completeness'] for x in per]):.3f}",
                       f"{np.mean([sum(x['seconds'].values()) for x in per]):.0f}",
                       "/".join(str(x["matched_pairs"]) for x in per)]
            planned = (f"failed ({p['error']}) | - | -" if "error" in p else
                       f"{p['reward']:.4f} | {p['evaluations']} | {p['seconds']:.1f}")
            lines.append(f"| {label} | {planned} | " + " | ".join(rec) + " |")
        lines += paired_lines(field, n, args, recons, result)
        lines.append("")
    lines += ["## Point subsampling of the coverage reward", "",
              "| field | plans | points a realization | kept | Spearman vs all points | mean shift | max abs diff | ms / plan |",
              "|---|---|---|---|---|---|---|---|"]
    for key, s in subsampling.items():
        for size, v in s["sizes"].items():
            lines.append(f"| {key} | {s['plans']} | {s['points_per_realization']} | {size} | "
                         f"{v['spearman_vs_all']:.4f} | {v['mean_shift']:+.4f} | {v['max_abs_diff']:.4f} | "
                         f"{v['ms_per_plan']:.1f} |")
    publish(out, "bench_fields", result, "\n".join(lines) + "\n")


if __name__ == "__main__":
    sys.exit(main())
