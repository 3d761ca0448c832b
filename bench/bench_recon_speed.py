#!/usr/bin/env python3
"""Faster reconstruction settings against the default: Chamfer and seconds per realization.

Issue 18 asks for ``make run`` within 120 s on 2 cores; a realization's reconstruction is about
47 s of one core, of which semi-global matching (the dense step) 25 s and COLMAP's SIFT 15 s
(README, "Speed of a flight's reconstruction"). This benchmark measures what the two cheaper
settings cost in quality, per variant of :data:`VARIANTS`:

* ``sift_first_octave=0``: SIFT starts at the image's own resolution instead of doubling it first
  (COLMAP's default -1), about 4x fewer pixels to filter;
* ``dense_scale=0.5`` (or 0.7): the stereo pairs are matched on half-size views (SGM's cost about
  1/8; at 0.7 about 1/3).

Plans: egp (the default planner, seed 0, 100 evaluations, as ``make run``) of each scenario,
shared with the other benchmarks' plan cache; every (scenario, variant, realization) is one
task on the Dask cluster (``bench/cluster.py``), cached under ``<out>/cache/recon_speed``. The
realistic capture (the default), Corn50 when present. Seconds are per realization on a worker
of ``--threads`` threads, with ``--workers`` tasks running at once (as ``make run``'s recon
node: 2 one-thread workers); a failed realization is counted, never dropped.

    python bench/bench_recon_speed.py [--scenarios one_plant three_row] [--realizations 5]
        [--variants full sift-octave0 dense-half both both-0.7] [--workers 2 --threads 1] [--out results]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

if not __package__:  # python bench/bench_recon_speed.py: as python -m bench.bench_recon_speed (bench/_script.py)
    import _script  # noqa: F401
from vp_scene.limits import seed_arg  # noqa: E402
from bench.stats import paired_interval  # noqa: E402
from bench.common import (ROOT, SCENARIOS, cached, default_models, machine, models_tag, plan_cell,  # noqa: E402
                          write_report)
from bench.cluster import Task, add_cluster_args, cluster_client, run_tasks  # noqa: E402

#: variant -> ReconConfig fields that differ from the default (``full``).
VARIANTS = {
    'full': {},
    'sift-octave0': {'sift_first_octave': 0},
    'dense-half': {'dense_scale': 0.5},
    'both': {'sift_first_octave': 0, 'dense_scale': 0.5},
    'both-0.7': {'sift_first_octave': 0, 'dense_scale': 0.7},   # make run's settings
}
STAGES = ('mesh', 'render', 'sparse', 'dense', 'score')


def recon_path(cache: Path, scenario: str, variant: str, k: int, args) -> Path:
    """The cache file of :func:`recon_cell` (its stem also names the folder of its clouds)."""
    tag = f'{models_tag(args.models)}-{scenario}-egp-seed{args.seed}-{variant}-{args.width}x{args.height}-r{k}'
    return cache / 'recon_speed' / f'{tag}.json'


def recon_cell(cache: Path, out: Path, scenario: str, variant: str, k: int, cameras: list, args) -> dict:
    """Realization ``k`` of ``scenario`` seen by ``cameras``, reconstructed under ``variant``; cached."""
    from bench.common import reconstruct_record, scene
    from vp_recon.config import ReconConfig

    path = recon_path(cache, scenario, variant, k, args)

    def compute() -> dict:
        noisy, _ = scene(scenario, args.models)
        config = ReconConfig(width=args.width, height=args.height, keep_images=False, num_threads=args.threads,
                             **VARIANTS[variant]).validate()
        t = time.perf_counter()
        record = reconstruct_record(noisy, cameras, config, out / 'recon' / 'speed' / path.stem, realizations=[k])
        record['wall'] = time.perf_counter() - t
        return record
    return cached(path, compute)


def summary(records: list[dict]) -> dict:
    """Chamfer (mean, sample std, n), shape, failures and mean seconds per stage of one cell."""
    per = [r['per_realization'][0] if r.get('per_realization') else {'chamfer': None, 'error': r.get('error')}
           for r in records]
    ok = [p for p in per if p.get('chamfer') is not None]
    ch = np.array([p['chamfer'] for p in ok])
    seconds = {s: float(np.mean([p['seconds'].get(s, 0.0) for p in ok])) for s in STAGES} if ok else {}
    if ok:
        seconds['total'] = float(sum(seconds.values()))
    return {'n': len(ok), 'failed': len(per) - len(ok),
            'chamfer_mean': float(ch.mean()) if len(ch) else None,
            'chamfer_std': float(ch.std(ddof=1)) if len(ch) > 1 else None,
            'chamfer_shape_mean': float(np.mean([p['chamfer_shape'] for p in ok])) if ok else None,
            'chamfer': [p.get('chamfer') for p in per], 'chamfer_shape': [p.get('chamfer_shape') for p in per],
            'seconds': seconds,
            'errors': [p.get('error') for p in per if p.get('chamfer') is None]}


def paired(base: list, other: list) -> dict:
    """other - base per realization (both reconstructed): mean, 95 % t interval, n."""
    return paired_interval(base, other)


def _interval(d) -> str:
    return '-' if not d or d['ci95'] is None else f"{d['mean']:+.2f} [{d['ci95'][0]:+.2f}, {d['ci95'][1]:+.2f}]"


def markdown(result: dict) -> str:
    lines = ['# Faster reconstruction settings: Chamfer x100 and seconds per realization', '',
             f"{result['machine']}; {result['date']}; plants {models_tag(result['models'])}; egp plans "
             f"(seed {result['seed']}, 100 evaluations); realizations 0-{result['realizations'] - 1}, "
             f"{result['width']} x {result['height']}, capture realistic; {result['workers']} worker(s) of "
             f"{result['threads']} thread(s) at once.", '',
             'Chamfer (in map) and shape (after ICP): mean +- sample std (n); vs full: paired difference per '
             'realization, mean [95 % t interval]. Seconds: mean per reconstructed realization.', '',
             '| scenario | variant | Chamfer x100 | vs full | shape x100 | vs full | sparse s | dense s | total s |',
             '|---|---|---|---|---|---|---|---|---|']
    for scen, cells in result['scenarios'].items():
        for variant, c in cells.items():
            if c['chamfer_mean'] is None:
                ch = f"failed ({c['failed']} of {c['failed'] + c['n']})"
            else:
                std = f"{c['chamfer_std']:.2f}" if c['chamfer_std'] is not None else '-'
                ch = f"{c['chamfer_mean']:.2f} +- {std} (n={c['n']}" + \
                    (f", {c['failed']} failed)" if c['failed'] else ')')
            vs, vs_shape = (_interval(c.get(key)) for key in ('vs_full', 'shape_vs_full'))
            sh = '-' if c['chamfer_shape_mean'] is None else f"{c['chamfer_shape_mean']:.2f}"
            s = c['seconds']
            lines.append(f"| {scen} | {variant} | {ch} | {vs} | {sh} | {vs_shape} | " +
                         ' | '.join(f"{s[k]:.1f}" if k in s else '-' for k in ('sparse', 'dense', 'total')) + ' |')
    return '\n'.join(lines) + '\n'


def main() -> int:
    from vp_scene.camera import IMAGE_SIZE

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--models', default=default_models(), help="PLY plant folder ('' = procedural)")
    ap.add_argument('--scenarios', nargs='+', default=['one_plant', 'three_row'], choices=sorted(SCENARIOS))
    ap.add_argument('--variants', nargs='+', default=list(VARIANTS), choices=list(VARIANTS))
    ap.add_argument('--realizations', type=int, default=5)
    ap.add_argument('--seed', type=seed_arg, default=0, help='planning seed of the egp plans')
    ap.add_argument('--width', type=int, default=IMAGE_SIZE[0])
    ap.add_argument('--height', type=int, default=IMAGE_SIZE[1])
    ap.add_argument('--threads', type=int, default=1, help='threads of each reconstruction (default 1)')
    ap.add_argument('--out', default=str(ROOT / 'results'))
    add_cluster_args(ap)
    args = ap.parse_args()
    if args.realizations < 1:
        ap.error('--realizations must be >= 1')
    out = Path(args.out)
    cache = out / 'cache'
    with cluster_client(args) as client:
        plans = run_tasks(client, [Task(s, plan_cell, (cache, s, 'egp', args.seed, 100, 50, args.models), None,
                                        f'{s} plan egp') for s in args.scenarios], desc='planning')
        tasks = []
        for s in args.scenarios:
            if plans[s].get('error'):
                continue
            for v in args.variants:
                for k in range(args.realizations):
                    tasks.append(Task((s, v, k), recon_cell, (cache, out, s, v, k, plans[s]['cameras'], args),
                                      recon_path(cache, s, v, k, args), f'{s} {v} r{k}'))
        records = run_tasks(client, tasks, desc='reconstructing')
    result = {'machine': machine(), 'date': time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime()),
              'models': args.models, 'seed': args.seed, 'realizations': args.realizations, 'width': args.width,
              'height': args.height, 'threads': args.threads, 'workers': args.workers,
              'variants': {v: VARIANTS[v] for v in args.variants}, 'scenarios': {}}
    for s in args.scenarios:
        # a scenario whose plan failed has no reconstruction task: its error counts in every realization
        cells = {v: summary([records.get((s, v, k), plans[s]) for k in range(args.realizations)])
                 for v in args.variants}
        if 'full' in cells:
            for v, c in cells.items():
                if v != 'full':
                    c['vs_full'] = paired(cells['full']['chamfer'], c['chamfer'])
                    c['shape_vs_full'] = paired(cells['full']['chamfer_shape'], c['chamfer_shape'])
        result['scenarios'][s] = cells
    write_report(out / 'bench_recon_speed.json', result)
    text = markdown(result)
    (out / 'bench_recon_speed.md').write_text(text)
    print(text)
    return 0


if __name__ == '__main__':
    sys.exit(main())
