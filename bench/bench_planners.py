#!/usr/bin/env python3
"""Planner quality and speed: final reward of every method, 5 seeds, 100 evaluations, both rewards.

For each scenario (one_plant N=4, three_row N=6, six_rect N=6), reward model (the default
``coverage`` and the paper's) and planner variant (:data:`common.VARIANTS`: egp, egp with the
paper's purely random initial design, egp in the paper's configuration, gp, circle, arc, sa,
random) it plans with seeds 0..S-1 (100 evaluations; egp/gp: 50 initial + 50 BO) and reports

* the final reward, mean +- std over seeds;
* for egp/gp: in how many seeds the final plan beats the best plan of the initial design (the
  BO phase did the work), and by how much;
* wall time per plan (one torch thread, as the planner node and CLI run).

Runs are cached under ``results/cache/plans`` (shared with table1.py), so a re-run resumes.
Writes ``results/bench_planners.json`` and ``results/bench_planners.md``.

    python bench/bench_planners.py [--seeds 5] [--rewards coverage paper] [--variants ...]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

if not __package__:  # python bench/bench_planners.py: as python -m bench.bench_planners (bench/_script.py)
    import _script  # noqa: F401
from bench.cluster import Task, add_cluster_args, cluster_client, run_tasks  # noqa: E402
from bench.common import (ROOT, SCENARIOS, VARIANTS, baselines, default_models, machine, models_tag,  # noqa: E402
                          plan_cell, plan_path, variants_of, write_report)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--models', default=default_models(), help="PLY folder ('' for procedural plants)")
    ap.add_argument('--scenarios', nargs='+', default=list(SCENARIOS), choices=list(SCENARIOS))
    ap.add_argument('--variants', nargs='+', default=list(variants_of('planners')), choices=list(VARIANTS))
    ap.add_argument('--rewards', nargs='+', default=['coverage', 'paper'], choices=['coverage', 'paper'])
    ap.add_argument('--seeds', type=int, default=5)
    ap.add_argument('--evals', type=int, default=100)
    ap.add_argument('--init', type=int, default=50)
    ap.add_argument('--out', default=str(ROOT / 'results'))
    add_cluster_args(ap)
    args = ap.parse_args(argv)

    out = Path(args.out)
    cache = out / 'cache'
    tasks = []
    for reward in args.rewards:
        for scenario in args.scenarios:
            for variant in args.variants:
                for seed in range(args.seeds):
                    a = (cache, scenario, variant, seed, args.evals, args.init, args.models, None, reward)
                    tasks.append(Task((scenario, reward, variant, seed), plan_cell, a, plan_path(*a),
                                      f'{scenario} {reward} {variant} seed {seed}'))
    t0 = time.time()
    with cluster_client(args) as client:
        runs = run_tasks(client, tasks, 'planning')
    failed = {k: r for k, r in runs.items() if 'error' in r}
    for k, r in failed.items():
        print(f'FAILED {k}: {r["error"]}: {r["error_msg"]}', file=sys.stderr)
    if failed:  # the report below averages over seeds: name the failures and stop, never drop them
        raise SystemExit(f'{len(failed)} of {len(runs)} planning runs failed (listed above)')
    report = {'machine': machine(), 'date': time.strftime('%Y-%m-%d'), 'models': models_tag(args.models),
              'evaluations': args.evals, 'initial_evaluations': args.init, 'seeds': args.seeds, 'cells': {}}
    lines = [f'# Planner benchmark ({report["date"]}, {report["machine"]}, plants: {report["models"]})', '',
             f'Final reward after {args.evals} evaluations, mean +- std over {args.seeds} seeds (one torch '
             'thread). "BO did the work": seeds whose final plan beats the best plan of the initial design, '
             'and the mean gain.', '']
    for reward in args.rewards:
        lines += [f'## reward model: {reward}', '',
                  '| scenario (N) | ' + ' | '.join(args.variants) + ' |', '|---|' + '---|' * len(args.variants)]
        bo_lines = ['', '| scenario | variant | BO beat its initial design | mean gain | seconds per plan |',
                    '|---|---|---|---|---|']
        for scenario in args.scenarios:
            cells = []
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
                    bo_lines.append(f'| {scenario} | {variant} | {entry["bo_improved_seeds"]} of {args.seeds} | '
                                    f'{entry["bo_gain_mean"]:+.4f} | {secs.mean():.1f} |')
                report['cells'][f'{reward}/{scenario}/{variant}'] = entry
                cells.append(f'{finals.mean():.4f} +- {finals.std():.4f}')
            lines.append(f'| {scenario} ({SCENARIOS[scenario]}) | ' + ' | '.join(cells) + ' |')
        lines += bo_lines + ['']
        if 'egp' in args.variants:
            verdict = []
            for scenario in args.scenarios:
                e = report['cells'][f'{reward}/{scenario}/egp']['final_mean']
                beaten = [b for b in baselines(args.variants)
                          if report['cells'][f'{reward}/{scenario}/{b}']['final_mean'] >= e]
                verdict.append(f'{scenario}: egp {"above every baseline" if not beaten else "not above " + ", ".join(beaten)}')
            lines += [f'Acceptance (egp mean above {", ".join(baselines(args.variants))}): ' + '; '.join(verdict), '']
    out.mkdir(parents=True, exist_ok=True)
    write_report(out / 'bench_planners.json', report)
    (out / 'bench_planners.md').write_text('\n'.join(lines) + '\n')
    print('\n'.join(lines))
    print(f'({time.time() - t0:.0f} s) wrote {out / "bench_planners.json"}, {out / "bench_planners.md"}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
