#!/usr/bin/env python3
"""The paper's experiment: Table I (Chamfer x100 per method and scenario) and Fig. SR.

For each scenario (one_plant with 4 cameras, three_row and six_rect with 6) and each method
(circle, sa, egp; plus random and gp for the regret figure) it plans with ``--seeds`` seeds
(100 evaluations: 50 random + 50 BO for egp), keeps the simple regret SR(t) = 1 - best-so-far
(paper eq. SR, optimum 1) of every run, and reconstructs the seed-0 plan of circle, sa and egp in
every wind realization (render, COLMAP, CPU dense stereo, Chamfer). Writes
``results/table1.md``, ``results/table1.json`` and ``results/simple_regret.png``.

Every finished cell (one plan, one reconstruction) is cached as JSON under
``results/cache/``; a re-run resumes instead of recomputing. Uses Corn50 plants from
``../shared/data/corn50`` when present (``--models`` to choose), else procedural plants.
"""
from __future__ import annotations

import argparse
import json
import sys
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import ROOT, SCENARIOS, VARIANTS, cached, default_models, machine, models_tag, plan_cell, scene  # noqa: E402

TABLE_METHODS = ('circle', 'sa', 'egp')
PAPER = {  # Table I of the paper, Chamfer x100 (mean, std)
    'one_plant': {'circle': (4.127, 0.194), 'sa': (3.844, 0.224), 'egp': (3.256, 0.245)},
    'three_row': {'circle': (2.817, 0.079), 'sa': (2.43, 0.192), 'egp': (1.614, 0.166)},
    'six_rect': {'circle': (2.717, 0.072), 'sa': (3.905, 0.184), 'egp': (2.54, 0.578)},
}


def parse_args(argv=None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--models', default=default_models(),
                    help="folder of PLY plant models (default: ../shared/data/corn50 if present; '' procedural)")
    ap.add_argument('--scenarios', nargs='+', default=list(SCENARIOS), choices=list(SCENARIOS))
    ap.add_argument('--methods', nargs='+', default=['circle', 'sa', 'egp', 'random', 'egp-random-init'],
                    choices=['circle', 'sa', 'egp', 'gp', 'random', *VARIANTS])
    ap.add_argument('--seeds', type=int, default=5, help='planning seeds for the regret figure')
    ap.add_argument('--variant-seeds', type=int, default=3,
                    help='seeds of the (slow) egp-random-init variant, the paper\'s purely random initial design')
    ap.add_argument('--evals', type=int, default=100)
    ap.add_argument('--init', type=int, default=50)
    ap.add_argument('--width', type=int, default=2000)
    ap.add_argument('--height', type=int, default=1500)
    ap.add_argument('--out', default=str(ROOT / 'results'))
    return ap.parse_args(argv)


def seeds_of(method: str, args) -> int:
    return min(args.seeds, args.variant_seeds) if method in VARIANTS else args.seeds


def recon_cell(cache: Path, out: Path, scenario: str, method: str, plan: dict, args) -> dict:
    """Reconstruct one plan in every wind realization (cached); Chamfer etc. x100 as Table I."""
    from vp_recon.outputs import TABLE_SCALE, contact_sheet, write_image, write_ply
    from vp_recon.pipeline import ReconConfig, ReconError, reconstruct_plan

    tag = f'{models_tag(args.models)}-{scenario}-{method}-seed0-e{args.evals}-{args.width}x{args.height}'

    def compute() -> dict:
        noisy, _ = scene(scenario, args.models)
        cfg = ReconConfig(width=args.width, height=args.height)
        folder = out / 'recon' / tag
        try:
            res = reconstruct_plan(noisy, np.asarray(plan['cameras']), cfg, folder)
        except ReconError as exc:  # a plan that does not reconstruct is a result too
            return {'error': exc.name, 'error_msg': str(exc), 'chamfer_mean': float('nan'),
                    'chamfer_std': float('nan'), 'per_realization': []}
        for r in res.realizations:
            write_ply(folder / f'recon_{r.realization}.ply', r.points, r.colors)
        if res.realizations and res.realizations[0].rendered:
            write_image(folder / 'views.png', contact_sheet(res.realizations[0].rendered))
        return {'chamfer_mean': TABLE_SCALE * res.chamfer_mean, 'chamfer_std': TABLE_SCALE * res.chamfer_std,
                'seconds': res.seconds,
                'per_realization': [{'chamfer': TABLE_SCALE * r.chamfer, 'accuracy': TABLE_SCALE * r.accuracy,
                                     'completeness': TABLE_SCALE * r.completeness, 'fscore': r.fscore,
                                     'points': int(len(r.points)), 'images': r.images, 'source': r.source}
                                    for r in res.realizations]}
    return cached(cache / 'recon' / f'{tag}.json', compute)


def main(argv=None) -> int:
    args = parse_args(argv)
    from tqdm import tqdm

    out = Path(args.out)
    cache = out / 'cache'
    plans, recons = {}, {}
    jobs = [(s, m, seed) for s in args.scenarios for m in args.methods for seed in range(seeds_of(m, args))]
    bar = tqdm(jobs, desc='planning', unit='plan', file=sys.stdout)
    for scenario, method, seed in bar:
        bar.set_postfix_str(f'{scenario} {method} seed {seed}')
        plans[(scenario, method, seed)] = plan_cell(cache, scenario, method, seed, args.evals, args.init,
                                                    args.models)
    cells = [(s, m) for s in args.scenarios for m in args.methods if m in TABLE_METHODS]
    bar = tqdm(cells, desc='reconstructing', unit='plan', file=sys.stdout)
    for scenario, method in bar:
        bar.set_postfix_str(f'{scenario} {method}')
        recons[(scenario, method)] = recon_cell(cache, out, scenario, method, plans[(scenario, method, 0)], args)
    write_results(args, out, plans, recons)
    return 0


def write_results(args, out: Path, plans, recons) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    stamp = datetime.now(timezone.utc).strftime('%Y-%m-%d')
    host = machine()
    table = {'date': stamp, 'machine': host, 'models': models_tag(args.models),
             'evaluations': args.evals, 'resolution': [args.width, args.height], 'cells': {}}
    lines = [f'# Table I, measured {stamp} ({host})', '',
             f'Plants: {args.models or "built-in procedural corn"}. Chamfer distance x 100 '
             '(mean +- std over the 5 wind realizations), lower is better; the paper\'s value in '
             'brackets. Reward: noisy reward (eq. 7) of the plan.', '',
             '| method | ' + ' | '.join(f'{s} (N={SCENARIOS[s]})' for s in args.scenarios) + ' |',
             '|---|' + '---|' * len(args.scenarios)]
    for method in TABLE_METHODS:
        if method not in args.methods:
            continue
        row = [method]
        for scenario in args.scenarios:
            r = recons.get((scenario, method))
            paper = PAPER[scenario][method]
            plan = plans[(scenario, method, 0)]
            table['cells'][f'{scenario}/{method}'] = {'recon': r, 'reward': plan['reward'],
                                                      'paper': paper}
            failed = f' ({r["error"]})' if r.get('error') else ''
            row.append(f'{r["chamfer_mean"]:.3f} +- {r["chamfer_std"]:.3f}{failed} '
                       f'[{paper[0]:.3f} +- {paper[1]:.3f}], reward {plan["reward"]:.3f}')
        lines.append('| ' + ' | '.join(row) + ' |')
    lines += ['', 'Plants used (scene seed 0; name, yaw deg, scale):', '']
    for scenario in args.scenarios:
        noisy, _ = scene(scenario, args.models)
        used = [(p.model_name, round(float(np.degrees(p.yaw)), 1), round(float(p.scale), 3))
                for p in noisy.scene.plants]
        table.setdefault('plants', {})[scenario] = used
        lines.append(f'- {scenario}: ' + ', '.join(f'{n} ({y}, {sc})' for n, y, sc in used))
    lines += ['', '## Final noisy reward (mean +- std over seeds)', '',
              '| method | ' + ' | '.join(args.scenarios) + ' |', '|---|' + '---|' * len(args.scenarios)]
    regret = {}
    for method in args.methods:
        row = [method]
        for scenario in args.scenarios:
            traces = np.array([plans[(scenario, method, s)]['trace'] for s in range(seeds_of(method, args))])
            finals = traces[:, -1]
            row.append(f'{finals.mean():.4f} +- {finals.std():.4f} ({len(finals)} seeds)')
            regret[(scenario, method)] = 1.0 - traces  # paper eq. SR with optimum 1
            table['cells'].setdefault(f'{scenario}/{method}', {})['final_reward'] = {
                'mean': float(finals.mean()), 'std': float(finals.std()),
                'seconds_mean': float(np.mean([plans[(scenario, method, s)]['seconds']
                                               for s in range(seeds_of(method, args))])),
                'seeds': seeds_of(method, args)}
        lines.append('| ' + ' | '.join(row) + ' |')
    out.mkdir(parents=True, exist_ok=True)
    (out / 'table1.md').write_text('\n'.join(lines) + '\n')
    (out / 'table1.json').write_text(json.dumps(table, indent=2))

    fig, axes = plt.subplots(1, len(args.scenarios), figsize=(5 * len(args.scenarios), 4), squeeze=False)
    for ax, scenario in zip(axes[0], args.scenarios):
        for method in args.methods:
            sr = regret[(scenario, method)]
            t = np.arange(1, sr.shape[1] + 1)
            ax.plot(t, sr.mean(0), label=method)
            ax.fill_between(t, sr.mean(0) - sr.std(0), sr.mean(0) + sr.std(0), alpha=0.15)
        ax.set_title(f'{scenario} (N={SCENARIOS[scenario]})')
        ax.set_xlabel('evaluation t')
        ax.set_ylabel('simple regret 1 - max reward')
        ax.grid(alpha=0.3)
        ax.legend()
    fig.tight_layout()
    fig.savefig(out / 'simple_regret.png', dpi=120)
    print('\n'.join(lines))
    print(f'wrote {out / "table1.md"}, {out / "table1.json"}, {out / "simple_regret.png"}')


if __name__ == '__main__':
    sys.exit(main())
