#!/usr/bin/env python3
"""The cheap stage at its own speed: egp's evaluations against CMA-ES, SA and random search in egp's wall time.

On the cheap reward (the default ``coverage`` model) of each scenario (one_plant N = 4,
three_row N = 6, row_12 N = 12; Corn50 plants when present, ``--models ''`` procedural) and
planning seed 0..S-1, one after the other in this process (one torch thread, as the planner):

1. ``egp`` plans with its defaults (100 evaluations, 50 of them the initial design; row_12 by
   parts, 100 a part and 50 for the joint refinement): its wall time T is the cell's time;
2. every other variant of ``common.variants_of('cheap')`` (cmaes, sa, random) plans the same
   scenario and seed and is stopped at T after its call (the objective's ``should_stop``, asked
   between evaluation batches). cmaes and random do not depend on their budget and get the
   registry's bound; sa cools over its budget, so it gets the evaluations that fill T at its
   rate on this scene, measured just before by a pilot run of ``--pilot`` evaluations (not counted).
   ``--clock cpu`` gives them egp's CPU time instead (this process's, one thread: what the wall
   time would be on a quiet machine), read on the same egp runs.

Each run records the best reward against seconds (time and evaluation of every improvement,
from the progress callback), hence the reward at 10, 25, 50 and 100 % of T, and at egp's number
of evaluations E (None for a run that made fewer); its evaluations, wall and CPU seconds, and
the machine's 1-minute load before and after (the machine may be shared: wall time is noisy,
the equal-evaluations column and the CPU seconds say how much). A run that raises is recorded
with its error and counted as failed (a cell whose egp failed has no T: its others are missing).
The report: per scenario, mean +- sample std over seeds at each fraction of T, each variant minus
egp paired over seeds at T and at E (mean [95 % t-interval]), and which reaches the highest
reward at T.

Every run is cached under ``<out>/cache/cheap_stage`` (the others' files name egp's T: a re-run
resumes, a new egp time redoes the others). Writes ``<out>/bench_cheap_stage-<plants>[-cpu].json``
(with the command and commit) and ``.md``.

    python -m bench.bench_cheap_stage [--scenarios one_plant three_row row_12] [--seeds 5] [--models DIR]
        [--clock wall|cpu] [--out results]
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path
from typing import Any, Optional

import numpy as np

if not __package__:  # python bench/bench_cheap_stage.py: as python -m bench.bench_cheap_stage (bench/_script.py)
    import _script  # noqa: F401
from bench.cache import cached  # noqa: E402
from bench.common import ROOT, default_models, models_tag, scene, variant_request, variants_of  # noqa: E402
from bench.publish import machine, publish  # noqa: E402
from bench.stats import describe, describe_difference, paired_difference, summary  # noqa: E402

#: scenario -> cameras N.
CELLS = {'one_plant': 4, 'three_row': 6, 'row_12': 12}
#: The variants: the reference (egp) first, then those given its wall time.
VARIANTS = variants_of('cheap')
REFERENCE = VARIANTS[0]
#: Fractions of the reference's wall time at which the best reward is read.
FRACTIONS = (0.1, 0.25, 0.5, 1.0)


#: The clocks a run can be given egp's time on: wall time, or this process's CPU time (what the
#: wall time would be on a quiet machine: one thread).
CLOCKS = {'wall': time.perf_counter, 'cpu': time.process_time}
#: A record's seconds on each clock (in the order of CLOCKS), and the column of an improvement
#: [wall s, CPU s, evaluations, best].
SECONDS = {'wall': 'seconds', 'cpu': 'cpu_seconds'}
COLUMN = {'wall': 0, 'cpu': 1}


def timed_plan(request: Any, points: Any, time_limit: Optional[float] = None, clock: str = 'wall') -> dict:
    """Plan ``request`` (stopped ``time_limit`` seconds of ``clock`` after the call when given): the
    run's record (reward, evaluations, wall and CPU seconds, the improvements as [wall s, CPU s,
    evaluations, best], the load before and after), or its error."""
    from vp_planner.optimizers import plan_views

    improvements: list = []

    def elapsed() -> list:
        return [f() - origin[k] for k, f in CLOCKS.items()]

    def progress(done: int, total: int, best: float, weights: Any) -> bool:
        if not improvements or best > improvements[-1][3]:
            improvements.append([*elapsed(), done, float(best)])
        return True

    def should_stop() -> bool:
        return time_limit is not None and CLOCKS[clock]() - origin[clock] >= time_limit

    load = os.getloadavg()[0]
    origin = {k: f() for k, f in CLOCKS.items()}
    try:
        res = plan_views(request, points, callback=progress, should_stop=should_stop)
    except Exception as exc:  # a failed run is a result: recorded and counted
        return {'error': type(exc).__name__, 'error_msg': str(exc), **dict(zip(SECONDS.values(), elapsed())),
                'load': [load, os.getloadavg()[0]]}
    return {'reward': float(res.reward), 'evaluations': int(res.evaluations), 'budget': int(request.evaluations),
            'stopped': bool(res.stopped), **dict(zip(SECONDS.values(), elapsed())), 'improvements': improvements,
            'load': [load, os.getloadavg()[0]]}


def sa_budget(request_of: Any, points: Any, seconds: float, pilot: int, clock: str) -> tuple[int, dict]:
    """The evaluations sa makes in ``seconds`` of ``clock`` on this scene: a pilot run of ``pilot``
    evaluations gives the time to its first evaluation and its rate after it. Returns (budget, the
    pilot's figures; its error when it failed)."""
    from vp_planner.methods import BY_NAME

    bound = BY_NAME['sa'].max_evaluations
    run = timed_plan(request_of(pilot), points, clock=clock)
    if 'error' in run:
        return 1, {'pilot_error': run['error'], 'pilot_error_msg': run['error_msg']}
    first, last = run['improvements'][0][COLUMN[clock]], run[SECONDS[clock]]
    rate = (run['evaluations'] - 1) / max(last - first, 1e-9)
    budget = int(min(bound, max(1, 1 + rate * (seconds - first))))
    return budget, {'pilot_seconds': last, 'pilot_evaluations': run['evaluations'], 'first_evaluation_s': first,
                    'rate_per_s': rate}


def best_at(run: dict, seconds: Optional[float] = None, evaluations: Optional[int] = None,
            clock: str = 'wall') -> Optional[float]:
    """The best reward a run had reached by ``seconds`` of ``clock`` (or by its ``evaluations``-th
    evaluation): 0 before its first feasible plan; None for a failed run or one that made fewer
    evaluations."""
    if 'error' in run or (evaluations is not None and run['evaluations'] < evaluations):
        return None
    best = 0.0
    for entry in run['improvements']:
        t, done, value = entry[COLUMN[clock]], entry[2], entry[3]
        if (seconds is not None and t > seconds) or (evaluations is not None and done > evaluations):
            break
        best = value
    return best


def cell_runs(cache: Path, scenario: str, seed: int, args) -> dict:
    """variant -> run of one (scenario, seed): egp first, the others in its wall time (cached)."""
    from vp_planner.methods import BY_NAME

    n = CELLS[scenario]
    noisy, _ = scene(scenario, args.models)
    stem = f'{models_tag(args.models)}-{scenario}-n{n}-seed{seed}'

    def request(variant: str, evaluations: int) -> Any:
        return variant_request(variant, num_cameras=n, evaluations=evaluations, seed=seed,
                               initial_evaluations=min(args.initial, evaluations))

    folder = cache / 'cheap_stage'
    ref = cached(folder / f'{stem}-{REFERENCE}-e{args.evaluations}-i{args.initial}.json',
                 lambda: timed_plan(request(REFERENCE, args.evaluations), noisy.points))
    runs = {REFERENCE: ref}
    if 'error' in ref:
        return {**runs, **{v: {'error': 'NO_REFERENCE', 'error_msg': f'{REFERENCE} failed: {ref["error_msg"]}'}
                           for v in args.variants if v != REFERENCE}}
    limit = float(ref[SECONDS[args.clock]])
    tag = '' if args.clock == 'wall' else f'-{args.clock}'
    for v in args.variants:
        if v == REFERENCE:
            continue

        def compute(v: str = v) -> dict:
            method = variant_request(v, num_cameras=n).method
            if method == 'sa':
                budget, how = sa_budget(lambda e: request(v, e), noisy.points, limit, args.pilot, args.clock)
            else:
                budget, how = BY_NAME[method].max_evaluations, {}
            return {**timed_plan(request(v, budget), noisy.points, limit, args.clock), 'time_limit': limit,
                    'clock': args.clock, **how}
        runs[v] = cached(folder / f'{stem}-{v}-t{limit:.3f}{tag}.json', compute)
    return runs


def summarize(runs: dict, variants: tuple, seeds: int, clock: str = 'wall') -> dict:
    """One scenario's table: per variant the reward at each fraction of egp's time and at egp's
    evaluations (:func:`bench.stats.summary` over seeds: failures and missing runs counted), the
    evaluations and seconds; each variant minus egp paired over seeds; the variant highest at T."""
    missing = {'error': 'MISSING', 'error_msg': 'not run'}
    by = {v: {s: runs.get((v, s), missing) for s in range(seeds)} for v in variants}
    ref = by[REFERENCE]
    out: dict = {'variants': {}, 'paired': {}}
    for v in variants:
        at_t = {}
        for f in FRACTIONS:
            at_t[f'{f:g}'] = {s: (None if 'error' in ref[s] else
                                  best_at(r, seconds=f * ref[s][SECONDS[clock]], clock=clock))
                              for s, r in by[v].items()}
        at_e = {s: (best_at(r, evaluations=ref[s]['evaluations']) if 'error' not in ref[s] else None)
                for s, r in by[v].items()}
        out['variants'][v] = {
            'at_fraction': {f: {'values': list(vals.values()), **summary(vals)} for f, vals in at_t.items()},
            'at_reference_evaluations': {'values': list(at_e.values()), **summary(at_e)},
            'evaluations': summary({s: r.get('evaluations') for s, r in by[v].items()}),
            'seconds': summary({s: r.get('seconds') if 'error' not in r else None for s, r in by[v].items()}),
            'cpu_seconds': summary({s: r.get('cpu_seconds') for s, r in by[v].items()}),
            'errors': [r['error'] for r in by[v].values() if 'error' in r]}
        out['variants'][v]['_final'], out['variants'][v]['_at_e'] = at_t['1'], at_e
    for v in variants:
        if v != REFERENCE:
            out['paired'][v] = {'at_T': paired_difference(out['variants'][v]['_final'],
                                                          out['variants'][REFERENCE]['_final']),
                                'at_E': paired_difference(out['variants'][v]['_at_e'],
                                                          out['variants'][REFERENCE]['_at_e'])}
    finals = {v: out['variants'][v]['at_fraction']['1'] for v in variants}
    ranked = sorted(variants, key=lambda v: (finals[v]['failed'], -(finals[v]['mean'] if finals[v]['n'] else -1)))
    out['winner_at_T'] = ranked[0]
    if len(ranked) > 1:
        out['winner_minus_next'] = paired_difference(out['variants'][ranked[0]]['_final'],
                                                     out['variants'][ranked[1]]['_final'])
        out['runner_up'] = ranked[1]
    for v in variants:
        del out['variants'][v]['_final'], out['variants'][v]['_at_e']
    return out


def _seeds(seeds: list) -> str:
    return f'{seeds[0]}-{seeds[-1]}' if len(seeds) > 1 else str(seeds[0])


def markdown(report: dict) -> str:
    load = report['load_1min']
    clock_name = {'wall': 'wall time', 'cpu': 'CPU time'}[report['clock']]
    lines = [f"# The cheap stage at its own speed ({report['date']}, {report['machine']}, plants: {report['models']})",
             '', f"Best `{report['reward']}` reward reached, mean +- sample std over planning seeds "
             f"{_seeds(report['seeds'])}, at 10/25/50/100 % of egp's {clock_name} T on the same scenario and seed "
             f"({REFERENCE}: {report['evaluations']} evaluations, {report['initial']} of them its initial design; "
             "row_12 by parts), and at egp's number of evaluations E. One torch thread; a cell's runs one after "
             "the other.", '',
             f"Machine load (the 1-minute load average before and after each run, this benchmark's own run "
             f"adding about 1; {report['cores']} cores): min {load['min']:.1f}, mean {load['mean']:.1f}, max "
             f"{load['max']:.1f}: "
             + ('a shared, loaded machine, wall time is noisy; the CPU seconds and the reward at E say how much.'
                if load['max'] > report['cores'] else 'wall time is about CPU time.'), '']
    for scen, t in report['scenarios'].items():
        ref = t['variants'][REFERENCE]
        T = ref[SECONDS[report['clock']]]
        lines += [f"## {scen} (N = {CELLS.get(scen, '?')}): T = {T['mean']:.1f} s {clock_name} "
                  f"(egp, mean over seeds), E = {ref['evaluations']['mean']:.0f}", '',
                  '| method | 10 % of T | 25 % | 50 % | 100 % of T | at E evaluations | evaluations in T | wall s | '
                  'CPU s |', '|---|---|---|---|---|---|---|---|---|']
        for v, c in t['variants'].items():
            cells = [describe(c['at_fraction'][f'{f:g}'], 4) for f in FRACTIONS]
            lines.append(f"| {v} | " + ' | '.join(cells) + f" | {describe(c['at_reference_evaluations'], 4)} | "
                         f"{describe(c['evaluations'], 0)} | {describe(c['seconds'], 1)} | "
                         f"{describe(c['cpu_seconds'], 1)} |")
        lines += ['', 'Paired over seeds, method minus egp (mean [95 % t-interval] (n)):', '']
        for v, d in t['paired'].items():
            lines.append(f"- {v} - {REFERENCE}: at T {describe_difference(d['at_T'])}; at E "
                         f"{describe_difference(d['at_E'])}")
        if 'runner_up' in t:
            lines += ['', f"Highest at T: **{t['winner_at_T']}**, {describe_difference(t['winner_minus_next'])} "
                      f"above the next ({t['runner_up']})."]
        lines.append('')
    return '\n'.join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--models', default=default_models(), help="PLY folder ('' for procedural plants)")
    ap.add_argument('--scenarios', nargs='+', default=list(CELLS), choices=list(CELLS))
    ap.add_argument('--variants', nargs='+', default=list(VARIANTS), choices=list(VARIANTS))
    ap.add_argument('--seeds', type=int, default=5, help='planning seeds --seed-from..SEEDS-1')
    ap.add_argument('--seed-from', type=int, default=0,
                    help='the first seed (processes sharing the cache split the seeds)')
    ap.add_argument('--evaluations', type=int, default=100, help="egp's evaluations (a part's, by parts)")
    ap.add_argument('--initial', type=int, default=50, help="egp's initial design")
    ap.add_argument('--pilot', type=int, default=100, help="evaluations of sa's pilot run (its rate)")
    ap.add_argument('--clock', default='wall', choices=list(CLOCKS),
                    help="the others get egp's wall time, or its CPU time (a quiet machine's wall time)")
    ap.add_argument('--out', default=str(ROOT / 'results'))
    args = ap.parse_args(argv)
    if REFERENCE not in args.variants:
        ap.error(f'--variants must include {REFERENCE} (its wall time is the others\')')
    for bad, text in ((not 0 <= args.seed_from < args.seeds,
                       f'--seed-from {args.seed_from} must be in 0..{args.seeds - 1}'),
                      (args.evaluations < 1, f'--evaluations {args.evaluations} must be >= 1'),
                      (not 0 <= args.initial <= args.evaluations,
                       f'--initial {args.initial} must be in 0..{args.evaluations} (--evaluations)'),
                      (args.pilot < 2, f'--pilot {args.pilot} must be >= 2 evaluations')):
        if bad:
            ap.error(text)
    import torch

    torch.set_num_threads(1)  # as the planner node and CLI
    out = Path(args.out)
    cache = out / 'cache'
    warm_up(args)
    seeds = range(args.seed_from, args.seeds)
    t0 = time.time()
    runs: dict = {}
    for scenario in args.scenarios:
        for seed in seeds:
            for v, r in cell_runs(cache, scenario, seed, args).items():
                runs[(scenario, v, seed)] = r
                print(f"{scenario} seed {seed} {v}: " + (f"failed ({r['error']}: {r['error_msg']})" if 'error' in r
                      else f"{r['reward']:.4f} in {r['seconds']:.1f} s, {r['evaluations']} evaluations"), flush=True)
    variants = tuple(v for v in VARIANTS if v in args.variants)
    loads = [x for r in runs.values() for x in r.get('load', [])]
    report = {'machine': machine(), 'date': time.strftime('%Y-%m-%d'), 'models': models_tag(args.models),
              'reward': variant_request(REFERENCE, num_cameras=4).reward.name, 'seeds': list(seeds),
              'evaluations': args.evaluations, 'initial': args.initial, 'variants': list(variants),
              'fractions': list(FRACTIONS), 'torch_threads': 1, 'cores': os.cpu_count(),
              'load_1min': {'min': min(loads, default=math.nan), 'mean': float(np.mean(loads)) if loads else math.nan,
                            'max': max(loads, default=math.nan)},
              'failed': sum(1 for r in runs.values() if 'error' in r), 'runs': len(runs),
              'clock': args.clock,
              'scenarios': {s: summarize({(v, seed - args.seed_from): runs[(s, v, seed)] for v in variants
                                          for seed in seeds}, variants, len(seeds), args.clock)
                            for s in args.scenarios},
              'records': {f'{s}/{v}/seed{seed}': r for (s, v, seed), r in runs.items()}}
    name = f"bench_cheap_stage-{models_tag(args.models)}" + ('' if args.clock == 'wall' else f'-{args.clock}')
    publish(out, name, report, markdown(report))
    print(f'({time.time() - t0:.0f} s)')
    return 0


def warm_up(args) -> None:
    """Plan each variant once with a few evaluations on the first scenario (not timed): imports
    (botorch, cma) and torch's first calls land here, not in the first timed run."""
    noisy, _ = scene(args.scenarios[0], args.models)
    for v in args.variants:
        timed_plan(variant_request(v, num_cameras=CELLS[args.scenarios[0]], evaluations=4, initial_evaluations=2),
                   noisy.points)


if __name__ == '__main__':
    sys.exit(main())
