#!/usr/bin/env python3
"""The second sortie (issue 21, README "A second sortie"): Chamfer x100 after two sorties.

Per scenario (:data:`SORTIES`: one_plant 4 + 2, three_row 6 + 3, six_rect 6 + 3, grid_3x3 8 + 4
cameras) sortie 1 is an egp plan of N cameras, reconstructed; then, reconstructing from all
N + M images in the first ``--realizations`` wind realizations:

* ``a``: one sortie of N + M cameras planned with egp (what a single bigger fleet gets: the reference);
* ``b``: sortie 2 = an egp plan of M that ignores sortie 1;
* ``c-circle``, ``c-arc``: sortie 2 = the tuned circle / arc of M;
* ``d``: sortie 2 = egp given sortie 1's cameras (``fixed_cameras``);
* ``e``: sortie 2 = egp given sortie 1's cameras and its reconstruction (the points within tau
  weigh ``reconstructed_weight``).

Target: ``e`` beats ``b`` and ``c`` in every scenario and comes within 5 % of ``a``; the table
says where it does not. Writes ``results/bench_sorties.{md,json}``; every plan and
reconstruction is cached as JSON under ``<out>/cache`` (a re-run resumes). Plants: Corn50 from
``../shared/data/corn50`` when present (``--models``), else procedural.

Plans and reconstructions are tasks on Dask (``--scheduler``, ``--workers``: README "Running the
benchmarks on a cluster"; ``--threads 1`` beside more than one local worker). This runs for hours
on 2 cores at the defaults (8 plans and 7 reconstructions a scenario); a smoke slice:
``--scenarios one_plant --evals 8 --init 6 --realizations 1 --width 800 --height 600 --capture ideal
--out /tmp/sorties``.
"""
from __future__ import annotations

import argparse
import math
import sys
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

if not __package__:  # python bench/bench_sorties.py: as python -m bench.bench_sorties (bench/_script.py)
    import _script  # noqa: F401
from vp_scene.limits import seed_arg  # noqa: E402
from bench.cache import cached  # noqa: E402
from bench.cluster import Task, cluster_client, run_tasks  # noqa: E402
from bench.common import (baselines, capture_of, capture_tag, chamfer_text, models_tag, plan_cell,  # noqa: E402
                          plan_path, reconstruct_record, scene, variant_request, variants_of)
from bench.options import parser  # noqa: E402
from bench.publish import machine, publish  # noqa: E402
from bench.stats import rank_key  # noqa: E402
from vp_planner.reward_models import (DEFAULT_RECONSTRUCTED_WEIGHT, DEFAULT_REWARD_MODEL, DEFAULT_TAU,  # noqa: E402
                                      REWARD_MODELS)
from vp_recon.config import MATCHINGS  # noqa: E402

#: scenario -> (N cameras of sortie 1, M cameras of sortie 2).
SORTIES = {'one_plant': (4, 2), 'three_row': (6, 3), 'six_rect': (6, 3), 'grid_3x3': (8, 4)}
#: The planner variant (common.VARIANTS) of sortie 1 and of cases a, b, d, e.
PLANNER = 'egp'
#: The cases c: sortie 2 = a baseline variant of M (common.VARIANTS: the ``sorties`` baselines).
C_CASES = {f'c-{v}': v for v in baselines(variants_of('sorties'))}
#: The cases after sortie 2, in the table's order (module docstring).
CASES = ('a', 'b', *C_CASES, 'd', 'e')
#: How close to ``a`` (relative Chamfer) ``e`` should come.
TARGET = 0.05


def parse_args(argv=None) -> argparse.Namespace:
    ap = parser(__doc__, 'models', 'images', 'threads', 'capture', 'cluster', 'out')
    ap.add_argument('--scenarios', nargs='+', default=list(SORTIES), choices=list(SORTIES))
    ap.add_argument('--evals', type=int, default=100)
    ap.add_argument('--init', type=int, default=50)
    ap.add_argument('--seed', type=seed_arg, default=0)
    ap.add_argument('--realizations', type=int, default=2, help='wind realizations reconstructed')
    ap.add_argument('--tau', type=float, default=DEFAULT_TAU)
    ap.add_argument('--reconstructed-weight', type=float, default=DEFAULT_RECONSTRUCTED_WEIGHT)
    ap.add_argument('--matching', default='auto', choices=MATCHINGS,
                    help="image pairs SIFT compares (vp_recon.config.matching_method; 'auto': the pose-chosen "
                         "pairs from 8 images up, 'exhaustive': all of them)")
    ap.add_argument('--reward', default=DEFAULT_REWARD_MODEL, choices=sorted(REWARD_MODELS),
                    help='reward model of every plan (default: the planner\'s, %(default)s); a non-default one '
                         'is part of every cache name')
    return ap.parse_args(argv)


def sortie2_cell(cache: Path, scenario: str, first: dict, m: int, args, reconstruction=None) -> dict:
    """An egp plan of M cameras given sortie 1's cameras (d), and its reconstruction (e); cached."""
    from vp_planner.optimizers import plan_views

    def compute() -> dict:
        import torch

        torch.set_num_threads(1)  # as the planner node and CLI
        noisy, _ = scene(scenario, args.models)
        request = variant_request(PLANNER, num_cameras=m, evaluations=args.evals, initial_evaluations=args.init,
                                  seed=args.seed, fixed_cameras=first['cameras'], reconstruction=reconstruction,
                                  tau=args.tau, reconstructed_weight=args.reconstructed_weight, reward=args.reward)
        res = plan_views(request, noisy.points)
        return {'cameras': np.asarray(res.cameras).tolist(), 'reward': float(res.reward), 'seconds': float(res.seconds),
                'reconstructed_fraction': res.reconstructed_fraction}
    return cached(sortie2_path(cache, scenario, m, args, reconstruction is not None), compute)


def sortie2_path(cache: Path, scenario: str, m: int, args, with_reconstruction: bool) -> Path:
    """The cache file of :func:`sortie2_cell` (case e: ``with_reconstruction``)."""
    case = 'e' if with_reconstruction else 'd'
    tag = (f'{models_tag(args.models)}-{scenario}-sortie2-{case}-m{m}-seed{args.seed}-e{args.evals}-i{args.init}'
           + reward_tag(args)
           + (f'-tau{args.tau:g}-w{args.reconstructed_weight:g}-{args.width}x{args.height}'
              f'{capture_tag(capture_of(args))}-k{args.realizations}' if with_reconstruction else ''))
    return cache / 'plans' / f'{tag}.json'


def recon_cell(cache: Path, out: Path, scenario: str, name: str, cameras, args) -> dict:
    """Reconstruct cameras (all of both sorties) in the first ``--realizations`` realizations; cached."""
    from vp_recon.config import ReconConfig

    tag = recon_tag(scenario, name, args)

    def compute() -> dict:
        noisy, _ = scene(scenario, args.models)
        cfg = ReconConfig(width=args.width, height=args.height, num_threads=args.threads, capture=capture_of(args),
                          matching=args.matching)
        record = reconstruct_record(noisy, np.asarray(cameras), cfg, out / 'recon' / tag,
                                    range(min(args.realizations, len(noisy.points))))
        record['folder'] = str(out / 'recon' / tag)
        return record
    return cached(cache / 'recon' / f'{tag}.json', compute)


def recon_tag(scenario: str, name: str, args) -> str:
    """The cache name of :func:`recon_cell`."""
    return (f'{models_tag(args.models)}-{scenario}-{name}-seed{args.seed}-e{args.evals}-{args.width}x{args.height}'
            f'{capture_tag(capture_of(args))}-k{args.realizations}'
            + ('' if args.matching == 'auto' else f'-{args.matching}') + reward_tag(args))


def reward_tag(args) -> str:
    """The part of a cache name that names a non-default ``--reward`` ('' for the default, so
    the caches written before the option keep their names)."""
    return '' if args.reward == DEFAULT_REWARD_MODEL else f'-{args.reward}'


def reconstruction_points(record: dict) -> np.ndarray:
    """The points of every realization a reconstruction record wrote (its recon_<k>.ply)."""
    from vp_scene.ply import load_points

    clouds = [load_points(p) for p in sorted(Path(record['folder']).glob('recon_*.ply'))]
    return np.concatenate(clouds) if clouds else np.zeros((0, 3))


def run(client, cache: Path, out: Path, args) -> dict:
    """Every scenario's sortie 1 and cases of sortie 2 (plans, rewards, Chamfer x100) as tasks on
    the Dask ``client``, in four waves (each needs the one before): (1) sortie 1 and the plans of
    a, b, c; (2) sortie 1's reconstruction, the plans of d, the reconstructions of a, b, c;
    (3) the plans of e (from sortie 1's reconstruction); (4) the reconstructions of d and e.
    A task that fails is a record with its error (counted, never dropped)."""
    kw = dict(evals=args.evals, init=args.init, models=args.models)
    plan_of = {'a': (PLANNER, 1), 'b': (PLANNER, 0), **{c: (v, 0) for c, v in C_CASES.items()}}

    def plan_task(scenario: str, key: str, variant: str, cameras: int) -> Task:
        a = (cache, scenario, variant, args.seed, args.evals, args.init, args.models, cameras, args.reward)
        return Task((scenario, key), plan_cell, a, plan_path(*a), f'{scenario} plan {key}')

    def recon_task(scenario: str, key: str, name: str, cameras) -> Task:
        return Task((scenario, key), recon_cell, (cache, out, scenario, name, np.asarray(cameras).tolist(), args),
                    cache / 'recon' / f'{recon_tag(scenario, name, args)}.json', f'{scenario} recon {key}')

    def sortie2_task(scenario: str, key: str, first: dict, reconstruction=None) -> Task:
        m = SORTIES[scenario][1]
        return Task((scenario, key), sortie2_cell, (cache, scenario, first, m, args, reconstruction),
                    sortie2_path(cache, scenario, m, args, reconstruction is not None), f'{scenario} plan {key}')

    sizes = {s: SORTIES[s] for s in args.scenarios}
    plans = run_tasks(client, [plan_task(s, 'sortie1', PLANNER, n) for s, (n, m) in sizes.items()]
                      + [plan_task(s, c, v, m + n * extra) for s, (n, m) in sizes.items()
                         for c, (v, extra) in plan_of.items()], 'planning')

    def case_task(s: str, case: str) -> Task:
        """The reconstruction after sortie 2 of ``case``: a's cameras alone, else sortie 1's and the case's."""
        (n, m), first, p = sizes[s], plans[(s, 'sortie1')], plans[(s, case)]
        cams = p['cameras'] if case == 'a' else np.concatenate([first['cameras'], p['cameras']])
        return recon_task(s, case, f'{case}-n{n}-m{m}', cams)

    def planned(s: str, case: str) -> bool:
        return (s, case) in plans and 'error' not in plans[(s, case)]

    ok = [s for s in sizes if planned(s, 'sortie1')]
    recons = run_tasks(client, [recon_task(s, 'sortie1', f'sortie1-{PLANNER}-n{sizes[s][0]}',
                                           plans[(s, 'sortie1')]['cameras'])
                                for s in ok]
                       + [sortie2_task(s, 'd', plans[(s, 'sortie1')]) for s in ok]
                       + [case_task(s, c) for s in ok for c in plan_of if planned(s, c)], 'sortie 1, a-c')
    plans.update({k: recons.pop(k) for k in [k for k in recons if k[1] == 'd']})  # plan d rode along in that wave
    flown = [s for s in ok if recons[(s, 'sortie1')].get('chamfer_mean') is not None]
    plans.update(run_tasks(client, [sortie2_task(s, 'e', plans[(s, 'sortie1')],
                                                 reconstruction_points(recons[(s, 'sortie1')])) for s in flown],
                           'planning e'))
    recons.update(run_tasks(client, [case_task(s, c) for s in ok for c in ('d', 'e') if planned(s, c)], 'd, e'))
    rows = {}
    for s, (n, m) in sizes.items():
        first = plans[(s, 'sortie1')]
        row = {'n': n, 'm': m, 'sortie1': {'reward': first.get('reward'), 'cameras': first.get('cameras'),
                                            'chamfer': recons.get((s, 'sortie1'), first)},
               'cases': {}}
        for case in CASES:
            p = plans.get((s, case))
            if p is None:
                why = 'sortie 1 did not plan' if 'error' in first else 'sortie 1 did not reconstruct'
                row['cases'][case] = {'error': why, 'chamfer_mean': None}
            elif 'error' in p:
                row['cases'][case] = {**p, 'chamfer_mean': None}
            else:
                row['cases'][case] = {'reward': p['reward'], 'plan_seconds': p.get('seconds'),
                                      'cameras': p['cameras'], **recons[(s, case)]}
        rows[s] = row
    return rows


def rank(record: dict) -> tuple:
    """:func:`stats.rank_key` of a case's reconstruction record: a case with more failed
    realizations ranks behind one with fewer whatever its mean (a failure is the worst result, as
    in every table here), then the mean Chamfer; a case that failed in every realization (or whose
    task raised: no count) ranks last."""
    mean = record.get('chamfer_mean')
    if mean is None:
        return rank_key({'failed': math.inf, 'mean': math.nan})
    return rank_key({'failed': int(record.get('failed') or 0), 'mean': float(mean)})


def verdict(row: dict) -> str:
    """Whether e beats b and both c and comes within TARGET of a (lower Chamfer is better; a case
    with failed realizations ranks behind one without, :func:`rank`)."""
    cases = row['cases']
    e = cases.get('e', {})
    if e.get('chamfer_mean') is None:
        return 'e failed'
    notes = [f'e {"beats" if rank(e) < rank(cases[k]) else "does not beat"} {k}' for k in ('b', 'c-circle', 'c-arc')]
    a = cases.get('a', {})
    if a.get('chamfer_mean') is not None:
        gap = e['chamfer_mean'] / a['chamfer_mean'] - 1.0
        e_failed = int(e.get('failed') or 0)
        within = gap <= TARGET and e_failed <= int(a.get('failed') or 0)
        notes.append(f'{100 * gap:+.1f} % of a ({"within" if within else "beyond"} {100 * TARGET:.0f} %'
                     + (f'; e failed in {e_failed} realization(s)' if e_failed else '') + ')')
    return '; '.join(notes)


def write_results(args, out: Path, rows: dict) -> None:
    head = '| scenario | N + M | sortie 1 | ' + ' | '.join(CASES) + ' | verdict |'
    lines = ['# The second sortie: Chamfer x100 after sortie 2 (mean +- std over realizations)', '',
             f'{machine()}; {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC; plants {models_tag(args.models)}; '
             f'egp {args.evals} evaluations ({args.init} initial), seed {args.seed}; {args.realizations} wind '
             f'realizations, {args.width} x {args.height} images, capture {capture_of(args).kind}; tau {args.tau} m, '
             f'reconstructed weight {args.reconstructed_weight}; matching {args.matching}; reward '
             f'{args.reward}.', '',
             'a: one sortie of N + M (egp); b: sortie 2 egp ignoring sortie 1; c: circle / arc of M; '
             'd: egp given the flown cameras; e: egp given the flown cameras and their reconstruction.', '',
             head, '|' + '---|' * (len(CASES) + 4)]
    for scenario, row in rows.items():
        cells = [chamfer_text(row['cases'][c]) for c in CASES]
        lines.append(f"| {scenario} | {row['n']} + {row['m']} | {chamfer_text(row['sortie1']['chamfer'])} | "
                     + ' | '.join(cells) + f' | {verdict(row)} |')
    publish(out, 'bench_sorties', {'args': vars(args), 'machine': machine(), 'rows': rows}, '\n'.join(lines) + '\n')


def main(argv=None) -> int:
    args = parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with cluster_client(args) as client:
        rows = run(client, out / 'cache', out, args)
    write_results(args, out, rows)
    return 0


if __name__ == '__main__':
    sys.exit(main())
