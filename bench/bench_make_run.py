#!/usr/bin/env python3
"""``make run``'s wall time and score under reconstruction settings: results/bench_make_run.{json,md}.

Issue 40 asks for ``make run`` (one_plant, egp, 4 cameras, 100 evaluations, 5 wind realizations,
realistic capture, 4 drones, after set-up) within 60 s on 2 cores (issue 18: 120 s) and its 5
realizations' Chamfer std / mean at most 0.3 (sample std). Each variant of
:data:`VARIANTS` runs the whole mission once (``tools/run_suite.py`` as ``make run`` calls it,
real nodes over DDS on this machine), one after the other, nothing else should be running; the
record holds the wall time, the summary's seconds, Chamfer and shape per realization, and the
paired difference per realization to the benchmarks' settings (``benchmarks``, the recon
node's defaults). A run that fails is recorded with its exit status, never dropped. Each run
has its own ROS_DOMAIN_ID and stays on this machine (ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST).

With ``--repeats R`` each variant runs R times (one after the other): the row is the first run's,
with every run's wall time beside it (``walls``, their median and maximum); a failed repeat is
counted in ``failed_repeats``, never dropped.

    python -m bench.bench_make_run [--variants benchmarks sift0 make-run sift0-dense0.5] [--repeats 1] [--out results]
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

if not __package__:  # python bench/bench_make_run.py: as python -m bench.bench_make_run (bench/_script.py)
    import _script  # noqa: F401
from bench.common import ROOT  # noqa: E402
from bench.options import parser  # noqa: E402
from bench.publish import machine, publish  # noqa: E402
from bench.stats import paired_interval  # noqa: E402

#: variant -> tools/run_suite.py reconstruction options
VARIANTS = {
    'benchmarks': ['--sift-first-octave', '-1', '--dense-scale', '1.0'],   # the recon node's defaults
    'sift0': ['--sift-first-octave', '0', '--dense-scale', '1.0'],
    'make-run': ['--sift-first-octave', '0', '--dense-scale', '0.7'],      # make run's defaults
    'sift0-dense0.5': ['--sift-first-octave', '0', '--dense-scale', '0.5'],
}
BASE = 'benchmarks'


def run_variant(name: str, domain: int, timeout: float) -> dict:
    """One ``make run`` mission with the variant's options: its record."""
    env = {**os.environ, 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST', 'ROS_DOMAIN_ID': str(domain)}
    with tempfile.TemporaryDirectory(prefix='bench_make_run_') as tmp:
        out = Path(tmp) / 'run'
        cmd = ['make', '-s', 'run', f'OUT={out}', f'RUN_ARGS={" ".join(VARIANTS[name])}']
        t = time.perf_counter()
        try:
            proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=timeout)
            rc, tail = proc.returncode, (proc.stdout + proc.stderr)[-2000:]
        except subprocess.TimeoutExpired:
            rc, tail = None, f'timed out after {timeout:.0f} s'
        wall = time.perf_counter() - t
        summary_file = out / 'summary.json'
        if rc != 0 or not summary_file.exists():
            return {'options': VARIANTS[name], 'wall': wall, 'returncode': rc, 'error': tail.strip().splitlines()[-1:]}
        s = json.loads(summary_file.read_text())
    per = s.get('per_realization', [])
    ch = [p.get('chamfer') for p in per if p.get('chamfer') is not None]
    return {'options': VARIANTS[name], 'wall': wall, 'returncode': rc, 'seconds': s.get('seconds'),
            'load_average_1min': os.getloadavg()[0],
            'cv': float(np.std(ch, ddof=1) / np.mean(ch)) if len(ch) > 1 else None,
            'recon_settings': s.get('recon_settings'), 'reward': s.get('reward'),
            'chamfer_mean': s.get('chamfer_mean'), 'chamfer_shape_mean': s.get('chamfer_shape_mean'),
            'chamfer': [p.get('chamfer') for p in per], 'chamfer_shape': [p.get('chamfer_shape') for p in per]}


def markdown(result: dict) -> str:
    def iv(d):
        return '-' if not d or d.get('ci95') is None else \
            f"{d['mean']:+.2f} [{d['ci95'][0]:+.2f}, {d['ci95'][1]:+.2f}]"

    lines = ['# make run: wall time and score per reconstruction setting', '',
             f"{result['machine']}; {result['date']}; `make run` (one_plant, procedural plant, egp, 4 cameras, "
             "5 wind realizations, realistic capture, 4 drones), one run per row, one after the other. "
             f"Target: {result['target_s']:.0f} s and Chamfer std / mean (sample std over the realizations) at most "
             f"{result.get('target_cv', 0.3)}; load: the machine's 1-minute load average as each run ended (2 cores).",
             '', '| variant | options | wall s | load | Chamfer x100 | std / mean | vs benchmarks | shape x100 | '
             'vs benchmarks |', '|---|---|---|---|---|---|---|---|---|']
    for name, r in result['variants'].items():
        if r.get('chamfer_mean') is None:
            lines.append(f"| {name} | `{' '.join(r['options'])}` | {r['wall']:.1f} | - | failed (exit "
                         f"{r['returncode']}) | - | - | - | - |")
            continue
        load = '-' if r.get('load_average_1min') is None else f"{r['load_average_1min']:.1f}"
        cv = '-' if r.get('cv') is None else f"{r['cv']:.2f}"
        wall = f"{r['wall']:.1f}"
        if len(r.get('walls', [])) > 1:
            wall += (f" (runs: {', '.join(f'{w:.1f}' for w in r['walls'])}; median {r['wall_median']:.1f}, max "
                     f"{r['wall_max']:.1f}{'; ' + str(r['failed_repeats']) + ' failed' if r.get('failed_repeats') else ''})")
        lines.append(f"| {name} | `{' '.join(r['options'])}` | {wall} | {load} | {r['chamfer_mean']:.2f} | "
                     f"{cv} | {iv(r.get('vs_base'))} | {r['chamfer_shape_mean']:.2f} | {iv(r.get('shape_vs_base'))} |")
    return '\n'.join(lines) + '\n'


def main(argv=None) -> int:
    ap = parser(__doc__, 'out')
    ap.add_argument('--variants', nargs='+', default=list(VARIANTS), choices=list(VARIANTS))
    ap.add_argument('--timeout', type=float, default=900.0, help='seconds a run may take')
    ap.add_argument('--domain-id', type=int, default=77, help='ROS_DOMAIN_ID of the first run (then +1 each)')
    ap.add_argument('--repeats', type=int, default=1, help='runs of each variant (module docstring)')
    args = ap.parse_args(argv)
    if args.repeats < 1:
        ap.error(f'--repeats must be >= 1, got {args.repeats}')
    runs = {}
    domain = args.domain_id
    for name in args.variants:
        print(f'make run, {name}: {" ".join(VARIANTS[name])}', flush=True)
        repeats = []
        for _ in range(args.repeats):
            repeats.append(run_variant(name, domain, args.timeout))
            domain += 1
            print(f"  {repeats[-1]['wall']:.1f} s, Chamfer x100 {repeats[-1].get('chamfer_mean')}", flush=True)
        runs[name] = repeats[0]
        if args.repeats > 1:
            walls = [r['wall'] for r in repeats]
            runs[name].update(walls=walls, wall_median=float(np.median(walls)), wall_max=max(walls),
                              failed_repeats=sum(r.get('chamfer_mean') is None for r in repeats),
                              chamfer_means=[r.get('chamfer_mean') for r in repeats])
    if BASE in runs and runs[BASE].get('chamfer'):
        for name, r in runs.items():
            if name != BASE and r.get('chamfer'):
                r['vs_base'] = paired_interval(runs[BASE]['chamfer'], r['chamfer'])
                r['shape_vs_base'] = paired_interval(runs[BASE]['chamfer_shape'], r['chamfer_shape'])
    result = {'machine': machine(), 'date': time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime()), 'target_s': 60.0,
              'target_cv': 0.3, 'variants': runs}
    publish(args.out, 'bench_make_run', result, markdown(result))
    return 0


if __name__ == '__main__':
    sys.exit(main())
