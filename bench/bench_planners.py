#!/usr/bin/env python3
"""Planner quality and speed: final noisy reward of every method, 5 seeds, 100 evaluations.

For each scenario (one_plant N=4, three_row N=6, six_rect N=6) and method (egp, gp, circle, sa,
random) it plans with seeds 0..S-1 and reports mean +- std of the final noisy reward (eq. 7),
beside the best reward found by any run including long runs (sa and random with ``--long``
evaluations): the regret baseline. Also the EGP-EI wall time per 100-evaluation plan in 24-D
(N=4) and 36-D (N=6). Runs are cached under ``results/cache/plans`` (shared with table1.py), so
a re-run resumes. Writes ``results/bench_planners.json`` and prints a markdown table.

    python bench/bench_planners.py [--seeds 5] [--long 2000] [--models DIR] [--scenarios ...]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import ROOT, SCENARIOS, default_models, machine, models_tag, plan_cell  # noqa: E402

METHODS = ('egp', 'gp', 'circle', 'sa', 'random')


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--models', default=default_models(), help="PLY folder ('' for procedural plants)")
    ap.add_argument('--scenarios', nargs='+', default=list(SCENARIOS), choices=list(SCENARIOS))
    ap.add_argument('--methods', nargs='+', default=list(METHODS), choices=list(METHODS))
    ap.add_argument('--seeds', type=int, default=5)
    ap.add_argument('--evals', type=int, default=100)
    ap.add_argument('--init', type=int, default=50)
    ap.add_argument('--long', type=int, default=2000, help='evaluations of the long sa/random runs')
    ap.add_argument('--out', default=str(ROOT / 'results'))
    args = ap.parse_args(argv)
    from tqdm import tqdm

    out = Path(args.out)
    cache = out / 'cache'
    jobs = [(s, m, seed, args.evals) for s in args.scenarios for m in args.methods for seed in range(args.seeds)]
    jobs += [(s, m, 0, args.long) for s in args.scenarios for m in ('sa', 'random') if args.long > 0]
    runs = {}
    bar = tqdm(jobs, desc='planning', unit='run', file=sys.stdout)
    t0 = time.time()
    for scenario, method, seed, evals in bar:
        bar.set_postfix_str(f'{scenario} {method} seed {seed} ({evals} evals)')
        runs[(scenario, method, seed, evals)] = plan_cell(cache, scenario, method, seed, evals, args.init,
                                                          args.models)
    report = {'machine': machine(), 'date': time.strftime('%Y-%m-%d'), 'models': models_tag(args.models),
              'evaluations': args.evals, 'initial_evaluations': args.init, 'seeds': args.seeds,
              'long_evaluations': args.long, 'scenarios': {}}
    lines = [f'# Planner benchmark ({report["date"]}, {report["machine"]}, plants: {report["models"]})', '',
             f'Final noisy reward after {args.evals} evaluations, mean +- std over {args.seeds} seeds; '
             f'best known = best of every run incl. {args.long}-evaluation sa/random runs.', '',
             '| scenario (N) | best known | ' + ' | '.join(args.methods) + ' |',
             '|---|---|' + '---|' * len(args.methods)]
    for scenario in args.scenarios:
        best = max(r['reward'] for (s, *_), r in runs.items() if s == scenario)
        entry = {'best_known': best, 'methods': {}}
        cells = []
        for method in args.methods:
            rs = [runs[(scenario, method, seed, args.evals)] for seed in range(args.seeds)]
            finals = np.array([r['reward'] for r in rs])
            secs = np.array([r['seconds'] for r in rs])
            entry['methods'][method] = {'final_mean': float(finals.mean()), 'final_std': float(finals.std()),
                                        'finals': finals.tolist(), 'seconds_mean': float(secs.mean()),
                                        'simple_regret_vs_best_known': float(best - finals.mean())}
            cells.append(f'{finals.mean():.4f} +- {finals.std():.4f}')
        report['scenarios'][scenario] = entry
        lines.append(f'| {scenario} ({SCENARIOS[scenario]}) | {best:.4f} | ' + ' | '.join(cells) + ' |')
    lines += ['', '| scenario | dims | egp seconds per plan (mean) | gp | circle | sa | random |', '|---|---|---|---|---|---|---|']
    for scenario in args.scenarios:
        m = report['scenarios'][scenario]['methods']
        lines.append(f'| {scenario} | {6 * SCENARIOS[scenario]} | ' + ' | '.join(
            f'{m[k]["seconds_mean"]:.1f}' if k in m else '-' for k in METHODS) + ' |')
    out.mkdir(parents=True, exist_ok=True)
    (out / 'bench_planners.json').write_text(json.dumps(report, indent=1))
    (out / 'bench_planners.md').write_text('\n'.join(lines) + '\n')
    print('\n'.join(lines))
    print(f'({time.time() - t0:.0f} s) wrote {out / "bench_planners.json"}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
