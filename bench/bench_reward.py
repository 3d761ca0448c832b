#!/usr/bin/env python3
"""The reward models' cost per plan: results/bench_reward.{json,md}.

The paper's noisy reward (eq. 7): one plan (raw points, and points laid out once with
``prepare_points`` as the optimizers do) and a batch of plans (default 1000) of 4 cameras on 10k
points x 5 realizations, in float64 and float32. The ``coverage`` and ``coverage-graph`` models: one plan and a batch,
as :func:`vp_planner.reward_models.make_reward` builds it (its default subsample of the points). Points: a Corn50 plant from ../shared/data/corn50 when present (wind
displacement as the paper's L-level model), else a synthetic cylinder-ish plant.

    python -m bench.bench_reward [--points 10000] [--realizations 5] [--cameras 4] [--batch 1000]
"""
from __future__ import annotations

import platform
import sys
import time

import numpy as np
import torch

if not __package__:  # python bench/bench_reward.py: as python -m bench.bench_reward (bench/_script.py)
    import _script  # noqa: F401
from bench.common import CORN50  # noqa: E402
from bench.options import parser  # noqa: E402
from bench.publish import num, publish, table  # noqa: E402
from vp_planner.designs import random_plans
from vp_planner.reward import noisy_reward, prepare_points
from vp_planner.reward_models import make_reward
from vp_planner.space import ViewSpace
from vp_scene.ply import load_ply


def synthetic_plant(n: int, rng: np.random.Generator) -> np.ndarray:
    z = rng.uniform(0, 2.0, n)
    r = 0.05 + 0.4 * rng.random(n) * np.sin(np.pi * z / 2.0)
    a = rng.uniform(0, 2 * np.pi, n)
    return np.stack([r * np.cos(a), r * np.sin(a), z], axis=1)


def scene(points: int, K: int, seed: int = 0) -> tuple[np.ndarray, str]:
    rng = np.random.default_rng(seed)
    ply = CORN50 / "10.ply"
    if ply.exists():
        P = load_ply(ply).points  # the project's one PLY reader
        P = P[rng.choice(len(P), points, replace=len(P) < points)]
        P[:, 2] -= P[:, 2].min()
        source = str(ply.name)
    else:
        P = synthetic_plant(points, rng)
        source = "synthetic"
    L = 10
    lev = np.clip(np.ceil(P[:, 2] / P[:, 2].max() * L), 1, L)
    out = []
    for _ in range(K):
        Q = P.copy()
        Q[:, 0] += lev * rng.normal(0, np.sqrt(0.002))
        out.append(Q)
    return np.stack(out), source


def best_of(fn, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main(argv=None) -> int:
    ap = parser(__doc__, "out")
    ap.add_argument("--points", type=int, default=10000)
    ap.add_argument("--realizations", type=int, default=5)
    ap.add_argument("--cameras", type=int, default=4)
    ap.add_argument("--batch", type=int, default=1000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int, default=1, help="torch threads (the planner's default: 1)")
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    R, source = scene(args.points, args.realizations)
    space = ViewSpace(R, args.cameras)
    plans = space.decode(random_plans(space, args.batch, np.random.default_rng(1)))
    result = {
        "points": args.points, "realizations": args.realizations, "cameras": args.cameras,
        "batch": args.batch, "source": source, "torch": torch.__version__,
        "threads": torch.get_num_threads(), "machine": platform.processor() or platform.machine(),
        "results": {},
    }
    for name, dt in (("float64", torch.float64), ("float32", torch.float32)):
        noisy_reward(plans[:2], R, dtype=dt)  # warm-up
        prep = prepare_points(R, dt)
        one = best_of(lambda: noisy_reward(plans[0], R, dtype=dt), args.repeats * 3)
        one_prep = best_of(lambda: noisy_reward(plans[0], prep, dtype=dt), args.repeats * 3)
        many = best_of(lambda: noisy_reward(plans, prep, dtype=dt), args.repeats)
        result["results"][name] = {
            "one_plan_ms": round(one * 1e3, 3),
            "one_plan_prepared_points_ms": round(one_prep * 1e3, 3),
            "batch_s": round(many, 4),
            "batch_ms_per_plan": round(many / args.batch * 1e3, 3),
        }
    r64 = noisy_reward(plans[:50], R)
    r32 = noisy_reward(plans[:50], R, dtype=torch.float32)
    result["max_abs_diff_float32"] = float(np.max(np.abs(r64 - r32)))
    for model in ("coverage", "coverage-graph"):
        cov = make_reward(model, R)
        cov(plans[:2])  # warm-up
        one = best_of(lambda: cov(plans[:1]), args.repeats * 3)
        many = best_of(lambda: cov(plans[: min(args.batch, 200)]), args.repeats)
        result["results"][model] = {"one_plan_ms": round(one * 1e3, 3),
                                    "batch_ms_per_plan": round(many / min(args.batch, 200) * 1e3, 3)}
    publish(args.out, "bench_reward", result, markdown(result))
    return 0


def markdown(data: dict) -> str:
    """Milliseconds a plan of every model: one plan, one plan on prepared points, a plan in a batch."""
    body = [[m, num(r.get("one_plan_ms"), 1), num(r.get("one_plan_prepared_points_ms"), 1),
             num(r.get("batch_ms_per_plan"), 1)] for m, r in data["results"].items()]
    lines = ["# Cost of a reward evaluation", "", f"{data['cameras']} cameras, {data['points']} points x "
             f"{data['realizations']} realizations, {data['threads']} torch thread; `float64`/`float32`: the paper "
             "reward. Best of repeats, ms. The paper reward in float32 differs from float64 by at most "
             f"{data['max_abs_diff_float32']:.1e}.", ""]
    lines += table(["model", "one plan", "one plan, points prepared", "per plan in a batch"], body)
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
