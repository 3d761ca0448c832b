#!/usr/bin/env python3
"""The cluster engine measured: the same small Table I cell set on 1 and on 2 local workers.

For each worker count a fresh results folder (nothing cached), a LocalCluster started (its start
time reported apart), then table1's plan and reconstruction tasks through ``bench/cluster.py``.
Reports the wall time, the tasks' own seconds (as each task measured itself), the speedup
wall(1) / wall(2) and the overhead per task  (wall(1) - sum of task seconds) / tasks  of one
worker, and checks that the records are the same on both (same seeds, same numbers).
Writes ``results/bench_cluster.json`` and ``.md``. Slow-ish (a few minutes on 2 cores).
"""
from __future__ import annotations

import json
import shlex
import shutil
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

if not __package__:  # python bench/bench_cluster.py: as python -m bench.bench_cluster (bench/_script.py)
    import _script  # noqa: F401
from bench import table1  # noqa: E402
from bench.cluster import open_client  # noqa: E402
from bench.options import parser  # noqa: E402
from bench.publish import machine, num, publish, table  # noqa: E402


def task_seconds(plans: dict, recons: dict) -> float:
    plan_s = sum(p.get('seconds', 0.0) for p in plans.values())
    recon_s = sum(r['seconds']['total'] for r in recons.values() if isinstance(r.get('seconds'), dict))
    return plan_s + recon_s


def strip_times(x):
    """Records without their wall-clock fields (they differ run to run, the numbers must not)."""
    if isinstance(x, dict):
        return {str(k): strip_times(v) for k, v in x.items() if k != 'seconds'}
    if isinstance(x, (list, tuple)):
        return [strip_times(v) for v in x]
    return x


def numbers_text(records) -> str:
    """Records as JSON text without wall-clock fields: equal iff the numbers are (as text, so that
    a NaN of a failed reconstruction compares equal to itself)."""
    return json.dumps(strip_times(records), sort_keys=True)


def recon_max_diff(runs: list) -> float:
    """Largest |Chamfer x100| difference of one (cell, realization) between the runs (0: identical)."""
    worst = 0.0
    for plans, recons in runs[1:]:
        for key, r in recons.items():
            a = runs[0][1][key].get('per_realization', [])
            b = r.get('per_realization', [])
            worst = max([worst] + [abs(x['chamfer'] - y['chamfer']) for x, y in zip(a, b)])
    return worst


def main(argv=None) -> int:
    ap = parser(__doc__, 'out')
    ap.add_argument('--workers', type=int, nargs='+', default=[1, 2])
    a, rest = ap.parse_known_args(argv)
    cell_args = rest or ['--models', '', '--scenarios', 'one_plant', 'three_row', '--rows', 'circle', 'arc', 'egp',
                         '--seeds', '1', '--evals', '20', '--init', '10', '--width', '1000', '--height', '750',
                         '--realizations', '2', '--threads', '1']
    runs, records = {}, {}
    for w in a.workers:
        tmp = Path(tempfile.mkdtemp(prefix=f'bench_cluster_w{w}_'))
        try:
            args = table1.parse_args(cell_args + ['--out', str(tmp), '--workers', str(w), '--scheduler', 'local'])
            t0 = time.perf_counter()
            with open_client('local', w) as client:
                t1 = time.perf_counter()
                plans, recons = table1.run(args, client)
                t2 = time.perf_counter()
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        n = len(plans) + len(recons)
        busy = task_seconds(plans, recons)
        runs[w] = {'workers': w, 'tasks': n, 'cluster_start_s': t1 - t0, 'wall_s': t2 - t1, 'task_seconds': busy,
                   'failed': sum('error' in r for r in list(plans.values()) + list(recons.values()))}
        records[w] = (plans, recons)
        print(f'{w} worker(s): {runs[w]}', flush=True)
    first = a.workers[0]
    one = runs[first]
    report = {'date': datetime.now(timezone.utc).strftime('%Y-%m-%d'), 'machine': machine(),
              'table1_arguments': cell_args, 'runs': list(runs.values()),
              'same_plans': len({numbers_text(r[0]) for r in records.values()}) == 1,
              'same_records': len({numbers_text(r) for r in records.values()}) == 1,
              'recon_max_abs_diff_chamfer_x100': recon_max_diff(list(records.values())),
              'overhead_per_task_s': (one['wall_s'] - one['task_seconds']) / one['tasks'],
              'speedup': {str(w): one['wall_s'] / r['wall_s'] for w, r in runs.items()}}
    publish(a.out, 'bench_cluster', report, markdown(report))
    return 0 if report['same_plans'] else 1


def markdown(data: dict) -> str:
    """Wall time, speedup and overhead per worker count, and whether the records agree."""
    body = [[str(r['workers']), str(r['tasks']), num(r['cluster_start_s'], 1), num(r['wall_s'], 1),
             num(r['task_seconds'], 1), str(r['failed']), num(data['speedup'].get(str(r['workers'])))]
            for r in data['runs']]
    lines = ['# The benchmarks on a Dask cluster', '', 'A small Table I slice (`python -m bench.table1 '
             + shlex.join(data['table1_arguments']) + '`) on 1 and 2 local workers.', '']
    lines += table(['workers', 'tasks', 'cluster start s', 'wall s', 'task s (sum)', 'failed', 'speedup'], body)
    lines += ['', f'Same plans on every worker count: {data["same_plans"]}; same reconstruction records: '
              f'{data["same_records"]} (largest Chamfer x100 difference {data["recon_max_abs_diff_chamfer_x100"]:.1e}); '
              f'overhead per task {data["overhead_per_task_s"]:.2f} s.']
    return '\n'.join(lines) + '\n'


if __name__ == '__main__':
    sys.exit(main())
