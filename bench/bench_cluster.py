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

import argparse
import json
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
from bench.common import ROOT, machine, write_report  # noqa: E402


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
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--workers', type=int, nargs='+', default=[1, 2])
    ap.add_argument('--out', default=str(ROOT / 'results'))
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
    lines = [f'# Cluster engine: Table I cells on {", ".join(map(str, a.workers))} local worker(s) '
             f'({report["date"]}, {report["machine"]})', '',
             f'table1 arguments: `{" ".join(repr(x) if x == "" else x for x in cell_args)}`', '',
             '| workers | tasks | failed | cluster start s | wall s | sum of task s | speedup |', '|---|---|---|---|---|---|---|']
    for w, r in runs.items():
        lines.append(f'| {w} | {r["tasks"]} | {r["failed"]} | {r["cluster_start_s"]:.1f} | {r["wall_s"]:.1f} | '
                     f'{r["task_seconds"]:.1f} | {report["speedup"][str(w)]:.2f} |')
    lines += ['', f'Overhead per task with {first} worker (wall - sum of task seconds) / tasks: '
              f'{report["overhead_per_task_s"]:.2f} s (scene build and imports on a fresh worker included). '
              f'Same plans on every worker count: {report["same_plans"]}; same reconstruction records: '
              f'{report["same_records"]} (largest Chamfer x100 difference of one realization: '
              f'{report["recon_max_abs_diff_chamfer_x100"]:.2g}; the reconstruction is not bit-reproducible '
              'from one process history to another, also in one process, see the README).']
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    write_report(out / 'bench_cluster.json', report)
    (out / 'bench_cluster.md').write_text('\n'.join(lines) + '\n')
    print('\n'.join(lines))
    return 0 if report['same_plans'] else 1


if __name__ == '__main__':
    sys.exit(main())
