#!/usr/bin/env python3
"""The planner's wall time as a user meets it: ``python -m vp_planner.cli`` with egp's defaults
(its simulated flights on a local Dask cluster of the cores), R runs one after the other, nothing
else should be running: results/bench_plan_time.{json,md}.

Each run is the CLI in a process of its own (seed 0, the realistic default); the record holds
the planning seconds plan.json reports (``seconds``: from the request to the chosen plan, the
cheap stage and every flight), the process's wall time (imports, the scene, the cluster's start
and its end included), how the plan was chosen and each flight's seconds. A run that fails is
recorded with its exit status and its last line, never dropped; the median and maximum are over
the runs that planned, and the failures are counted beside them.

    python -m bench.bench_plan_time [--scenario one_plant] [--cameras 4] [--models ../shared/data/corn50] [--repeats 3]
        [--domain-id 78]
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

if not __package__:  # python bench/bench_plan_time.py: as python -m bench.bench_plan_time (bench/_script.py)
    import _script  # noqa: F401
from bench.common import ROOT, models_tag  # noqa: E402
from bench.options import parser  # noqa: E402
from bench.publish import machine, num, publish, table  # noqa: E402


def run_once(scenario: str, cameras: int, models: str, timeout: float, domain: int) -> dict:
    """One planning run of the CLI: its record (module docstring). The CLI starts no DDS participant;
    the run stays on this machine under a domain of its own all the same."""
    env = {**os.environ, 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST', 'ROS_DOMAIN_ID': str(domain),
           'OMP_NUM_THREADS': '1'}
    with tempfile.TemporaryDirectory(prefix='bench_plan_time_') as tmp:
        out = Path(tmp) / 'plan'
        cmd = [sys.executable, '-m', 'vp_planner.cli', '--scenario', scenario, '--method', 'egp', '--cameras',
               str(cameras), '--seed', '0', '--out', str(out), '--no-progress'] + (['--models', models] if models else [])
        t = time.perf_counter()
        try:
            proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=timeout)
            rc, tail = proc.returncode, (proc.stdout + proc.stderr).strip().splitlines()[-1:]
        except subprocess.TimeoutExpired:
            rc, tail = None, [f'timed out after {timeout:.0f} s']
        wall = time.perf_counter() - t
        if rc != 0 or not (out / 'plan.json').is_file():
            return {'wall': wall, 'returncode': rc, 'error': tail}
        plan = json.loads((out / 'plan.json').read_text())
    flights = plan.get('flights') or []
    return {'wall': wall, 'returncode': rc, 'seconds': plan['seconds'], 'chosen_by': plan['chosen_by'],
            'flight_score': plan.get('flight_score'), 'sim_flights': plan.get('sim_flights'),
            'flights_failed': sum(bool(f.get('failed')) for f in flights),
            'flight_seconds': [f.get('seconds') for f in flights], 'reward': plan['reward'],
            'load_average_1min': os.getloadavg()[0]}


def markdown(result: dict) -> str:
    runs = result['runs']
    rows = []
    for i, r in enumerate(runs):
        if r.get('seconds') is None:
            rows.append([str(i + 1), '-', f"{r['wall']:.1f}", f"failed (exit {r['returncode']})", '-', '-', '-'])
            continue
        fs = [s for s in r['flight_seconds'] if s is not None]
        rows.append([str(i + 1), f"{r['seconds']:.1f}", f"{r['wall']:.1f}", r['chosen_by'],
                     f"{len(fs)} ({r['flights_failed']} failed), {min(fs):.1f}-{max(fs):.1f} s" if fs else '-',
                     num(None if r['flight_score'] is None else 100 * r['flight_score'], 3),
                     f"{r['load_average_1min']:.1f}"])
    s = result['summary']
    lines = ['# Planning time: the CLI with egp\'s simulated flights', '',
             f"{result['machine']}; {result['date']}; `python -m vp_planner.cli --scenario {result['scenario']} "
             f"--method egp --cameras {result['cameras']}` ({result['models']}, seed 0), {len(runs)} runs one after the "
             "other. Planning s: plan.json's `seconds` (the cheap stage and the flights); wall s: the process; load: "
             "the 1-minute load average as the run ended.", '',
             *table(['run', 'planning s', 'wall s', 'chosen by', 'flights', 'flight score x100', 'load'], rows), '',
             f"Planning: median {num(s['seconds_median'], 1)} s, max {num(s['seconds_max'], 1)} s over "
             f"{s['planned']} runs; {s['failed']} failed."]
    return '\n'.join(lines) + '\n'


def main(argv=None) -> int:
    ap = parser(__doc__, 'models', 'out')
    ap.add_argument('--scenario', default='one_plant')
    ap.add_argument('--cameras', type=int, default=4)
    ap.add_argument('--repeats', type=int, default=3)
    ap.add_argument('--timeout', type=float, default=900.0, help='seconds a run may take')
    ap.add_argument('--domain-id', type=int, default=78, help='ROS_DOMAIN_ID of the runs')
    args = ap.parse_args(argv)
    if args.repeats < 1:
        ap.error(f'--repeats must be >= 1, got {args.repeats}')
    runs = []
    for i in range(args.repeats):
        runs.append(run_once(args.scenario, args.cameras, args.models, args.timeout, args.domain_id))
        r = runs[-1]
        print(f"run {i + 1}/{args.repeats}: " + (f"planning {r['seconds']:.1f} s, wall {r['wall']:.1f} s"
                                                 if r.get('seconds') is not None else f"failed: {r['error']}"),
              flush=True)
    planned = [r['seconds'] for r in runs if r.get('seconds') is not None]
    summary = {'planned': len(planned), 'failed': len(runs) - len(planned),
               'seconds_median': float(np.median(planned)) if planned else None,
               'seconds_max': max(planned) if planned else None}
    result = {'machine': machine(), 'date': time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime()),
              'scenario': args.scenario, 'cameras': args.cameras,
              'models': models_tag(args.models), 'runs': runs, 'summary': summary}
    publish(args.out, 'bench_plan_time', result, markdown(result))
    return 0


if __name__ == '__main__':
    sys.exit(main())
