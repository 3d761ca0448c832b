#!/usr/bin/env python3
"""How far to trust the coverage of the prior (issue 20, part 4): does it rank reconstructions as
the Chamfer does?

Coverage of the prior (``vp_recon.metrics.coverage_of_prior``, tau 3 cm) needs no ground truth, so
it is what a practitioner can check after a real flight. This reads every reconstruction the
benchmarks recorded with its clouds (``results/cache/recon/*.json`` whose folder under
``results/recon/`` holds ``recon_<k>.ply``: Table I's rows, the second sortie's cases), computes the
coverage of each realization's cloud against the scene's planning cloud (all K realizations, the
best-covered one counts), and reports per scenario Spearman's rho between the coverage and minus the
Chamfer x100 (1: coverage ranks exactly as the Chamfer; the Chamfer reads the truth, the coverage
does not), over (plan, realization) units and over plans (means). A realization that failed has no
cloud: it is counted (``failed``), not ranked. Of the same cell recorded with several realization
counts (``-k3``, ``-k5``) only the largest is read. Writes ``results/coverage_check.{json,md}``.
Seconds: one cKDTree query per cloud.
"""
from __future__ import annotations

import argparse
import json
import sys
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

if not __package__:  # python bench/coverage_check.py: as python -m bench.coverage_check (bench/_script.py)
    import _script  # noqa: F401
from bench.stats import spearman  # noqa: E402
from bench.common import (ROOT, SCENARIOS, default_models, machine, models_tag, scene,  # noqa: E402
                          split_realizations, write_report)


def parse_args(argv=None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--models', default=default_models(),
                    help="folder of PLY plant models (default: ../shared/data/corn50 if present; '' procedural)")
    ap.add_argument('--results', default=str(ROOT / 'results'), help='folder with cache/recon and recon/')
    ap.add_argument('--capture', default='realistic', help="records of this capture only ('realistic', 'ideal')")
    ap.add_argument('--out', default=None, help='output folder (default: --results)')
    return ap.parse_args(argv)


def records(results: Path, models: str, capture: str) -> dict:
    """cell -> (stem, record): the reconstruction records of the models and capture with a folder of
    clouds, the largest realization count of each cell."""
    cells: dict = {}
    for path in sorted((results / 'cache' / 'recon').glob(f'{models_tag(models)}-*.json')):
        rec = json.loads(path.read_text())
        if rec.get('capture', 'ideal') != capture or not (results / 'recon' / path.stem).is_dir():
            continue
        split = split_realizations(path.stem)
        cell, k = (split[0] + split[2], split[1]) if split else (path.stem, 0)
        if cell not in cells or cells[cell][0] < k:
            cells[cell] = (k, path.stem, rec)
    return {cell: (stem, rec) for cell, (_, stem, rec) in cells.items()}


def scenario_of(stem: str) -> str:
    return next(s for s in SCENARIOS if f'-{s}-' in stem)


def run(args) -> dict:
    from vp_recon.metrics import coverage_of_prior
    from vp_recon.results import Prior
    from vp_scene.ply import load_points

    results = Path(args.results)
    priors, units, counts = {}, [], {}
    for cell, (stem, rec) in records(results, args.models, args.capture).items():
        scenario = scenario_of(stem)
        if scenario not in priors:
            priors[scenario] = Prior.of_scene(scene(scenario, args.models)[0])
        prior = priors[scenario]
        c = counts.setdefault(scenario, {'plans': 0, 'units': 0, 'failed': 0, 'missing_cloud': 0, 'failed_plans': 0})
        c['plans'] += 1
        c['failed_plans'] += bool(rec.get('error')) and not rec.get('per_realization')
        for i, p in enumerate(rec.get('per_realization', [])):
            k = p.get('realization', i)
            ply = results / 'recon' / stem / f'recon_{k}.ply'
            if p.get('chamfer') is None:
                c['failed'] += 1
                continue
            if not ply.exists():
                c['missing_cloud'] += 1
                continue
            cov = coverage_of_prior(load_points(ply), prior.points, prior.plant, realizations=prior.realizations)
            units.append({'scenario': scenario, 'plan': cell, 'realization': k, 'chamfer': p['chamfer'],
                          'chamfer_shape': p.get('chamfer_shape'), 'coverage': cov.fraction,
                          'coverage_per_plant': list(cov.per_plant)})
            c['units'] += 1
    out = {'date': datetime.now(timezone.utc).strftime('%Y-%m-%d'), 'machine': machine(),
           'models': models_tag(args.models), 'capture': args.capture, 'tau': 0.03, 'counts': counts,
           'spearman_units': {}, 'spearman_plans': {}, 'units': units}
    for scenario in counts:
        us = [u for u in units if u['scenario'] == scenario]
        out['spearman_units'][scenario] = spearman([u['coverage'] for u in us], [-u['chamfer'] for u in us])
        plans = sorted({u['plan'] for u in us})
        cov = [float(np.mean([u['coverage'] for u in us if u['plan'] == p])) for p in plans]
        ch = [float(np.mean([u['chamfer'] for u in us if u['plan'] == p])) for p in plans]
        out['spearman_plans'][scenario] = spearman(cov, [-x for x in ch])
    return out


def markdown(result: dict) -> str:
    """The check's table (of a result as :func:`run` returns it, or as its JSON holds it)."""
    def rho(x):
        return '-' if x is None else f'{x:.3f}'

    lines = ['# Coverage of the prior against the Chamfer', '',
             f"{result['date']}, {result['machine']}; plants {result['models']}, capture {result['capture']}, "
             f"tau {result['tau']} m. Spearman's rho between coverage and minus Chamfer x100 "
             '(1: the coverage ranks reconstructions as the Chamfer does).', '',
             'A failed realization (no cloud) is counted, not ranked; a plan that failed as a whole counts once.', '',
             '| scenario | plans | units | failed realizations | failed plans | rho over units | rho over plans |',
             '|---|---|---|---|---|---|---|']
    for s, c in result['counts'].items():
        lines.append(f"| {s} | {c['plans']} | {c['units']} | {c['failed'] + c['missing_cloud']} | {c['failed_plans']} | "
                     f"{rho(result['spearman_units'][s])} | {rho(result['spearman_plans'][s])} |")
    return '\n'.join(lines) + '\n'


def write_results(out_dir: Path, result: dict) -> None:
    (out_dir / 'coverage_check.md').write_text(markdown(result))
    write_report(out_dir / 'coverage_check.json', result)


def main(argv=None) -> int:
    args = parse_args(argv)
    result = run(args)
    out_dir = Path(args.out or args.results)
    out_dir.mkdir(parents=True, exist_ok=True)
    write_results(out_dir, result)
    print((out_dir / 'coverage_check.md').read_text(), end='')
    return 0


if __name__ == '__main__':
    sys.exit(main())
