#!/usr/bin/env python3
"""Planner quality and speed: final reward of every method, 5 seeds, 100 evaluations, both rewards.

For each scenario (one_plant N=4, three_row N=6, six_rect N=6), reward model (the default
``coverage`` and the paper's) and planner variant (:data:`common.VARIANTS`: egp, egp with the
paper's purely random initial design, egp in the paper's configuration, gp, circle, arc, sa,
random) it plans with seeds 0..S-1 (100 evaluations; egp/gp: 50 initial + 50 BO) and reports

* the final reward, mean +- sample std over seeds;
* for egp/gp: in how many seeds the final plan beats the best plan of the initial design (the
  BO phase did the work), and by how much;
* wall time per plan (one torch thread, as the planner node and CLI run).

Runs are cached under ``results/cache/plans`` (shared with table1.py), so a re-run resumes.
Writes ``results/bench_planners.json`` and ``results/bench_planners.md``.

    python -m bench.bench_planners [--seeds 5] [--rewards coverage paper] [--variants ...]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

if not __package__:  # python bench/bench_planners.py: as python -m bench.bench_planners (bench/_script.py)
    import _script  # noqa: F401
from bench.cluster import Task, cluster_client, run_tasks  # noqa: E402
from bench.common import SCENARIOS, VARIANTS, models_tag, plan_cell, plan_path, variants_of  # noqa: E402
from bench.options import parser  # noqa: E402
from bench.publish import machine, publish, table  # noqa: E402
from bench.stats import describe, summary  # noqa: E402


def parse_args(argv=None) -> argparse.Namespace:
    ap = parser(__doc__, 'models', 'cluster', 'out')
    ap.add_argument('--scenarios', nargs='+', default=list(SCENARIOS), choices=list(SCENARIOS))
    ap.add_argument('--variants', nargs='+', default=list(variants_of('planners')), choices=list(VARIANTS))
    ap.add_argument('--rewards', nargs='+', default=['coverage', 'paper'], choices=['coverage', 'paper'])
    ap.add_argument('--seeds', type=int, default=5)
    ap.add_argument('--evals', type=int, default=100)
    ap.add_argument('--init', type=int, default=50)
    return ap.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    cache = Path(args.out) / 'cache'
    tasks = []
    for reward in args.rewards:
        for scenario in args.scenarios:
            for variant in args.variants:
                for seed in range(args.seeds):
                    a = (cache, scenario, variant, seed, args.evals, args.init, args.models, None, reward)
                    tasks.append(Task((scenario, reward, variant, seed), plan_cell, a, plan_path(*a),
                                      f'{scenario} {reward} {variant} seed {seed}'))
    with cluster_client(args) as client:
        runs = run_tasks(client, tasks, 'planning')
    failed = {k: r for k, r in runs.items() if 'error' in r}
    for k, r in failed.items():
        print(f'FAILED {k}: {r["error"]}: {r["error_msg"]}', file=sys.stderr)
    if failed:  # the report averages over seeds: name the failures and stop, never drop them
        raise SystemExit(f'{len(failed)} of {len(runs)} planning runs failed (listed above)')
    report = {'machine': machine(), 'date': time.strftime('%Y-%m-%d'), 'models': models_tag(args.models),
              'evaluations': args.evals, 'initial_evaluations': args.init, 'seeds': args.seeds, 'cells': {}}
    for reward in args.rewards:
        for scenario in args.scenarios:
            for variant in args.variants:
                rs = [runs[(scenario, reward, variant, seed)] for seed in range(args.seeds)]
                finals = np.array([r['reward'] for r in rs])
                secs = np.array([r['seconds'] for r in rs])
                entry = {'final_mean': float(finals.mean()), 'final_std': float(finals.std()),
                         'finals': finals.tolist(), 'seconds_mean': float(secs.mean()), 'seconds': secs.tolist()}
                if rs[0].get('initial_best') is not None:
                    init = np.array([r['initial_best'] for r in rs])
                    entry['initial_best'] = init.tolist()
                    entry['bo_improved_seeds'] = int(np.sum(finals > init + 1e-9))
                    entry['bo_gain_mean'] = float(np.mean(finals - init))
                report['cells'][f'{reward}/{scenario}/{variant}'] = entry
    publish(args.out, 'bench_planners', report, markdown(report))
    return 0


def markdown(data: dict) -> str:
    """Per reward model a table of scenario x variant: the final reward (mean +- sample std over
    the seeds), the seeds whose BO beat its initial design, the seconds a plan."""
    rewards = list(dict.fromkeys(k.split('/')[0] for k in data['cells']))
    lines = ['# Planners: final reward', '', f'Final reward after {data["evaluations"]} evaluations '
             f'({data["initial_evaluations"]} initial for egp), mean +- sample std (n-1) over {data["seeds"]} seeds, '
             f'plants {data["models"]}; "BO beat": seeds whose final plan is better than the best plan of the initial '
             'design.', '']
    for reward in rewards:
        keys = [k for k in data['cells'] if k.startswith(reward + '/')]
        scen = list(dict.fromkeys(k.split('/')[1] for k in keys))
        methods = list(dict.fromkeys(k.split('/')[2] for k in keys))
        body = []
        for s in scen:
            row = [s]
            for m in methods:
                c = data['cells'].get(f'{reward}/{s}/{m}')
                if c is None:
                    row.append('-')
                    continue
                st = summary(dict(enumerate(c['finals'])))
                row.append(describe(st, 4) + (f', BO beat {c["bo_improved_seeds"]} of {len(c["finals"])}'
                                              if 'bo_improved_seeds' in c else '') + f', {c["seconds_mean"]:.1f} s')
            body.append(row)
        lines += [f'Reward `{reward}`:', ''] + table(['scenario'] + methods, body) + ['']
    return '\n'.join(lines)


if __name__ == '__main__':
    sys.exit(main())
