#!/usr/bin/env python3
"""The paper's experiment: Table I (Chamfer x100 per method and scenario) and Fig. SR.

Rows (:data:`ROWS`): the baselines a drone operator flies anyway (circle, arc) and the paper's
(sa), each tuned with the default reward model; the default planner (egp); and EGP-VP exactly as
the paper configures it (the paper's reward, EI over the whole space, a random initial design);
and egp under ``coverage-graph`` (coverage times the view graph's connectivity, the candidate the
realistic plan-quality study supports: README "Reward models").
For each scenario (one_plant with 4 cameras, three_row and six_rect with 6) every row plans with
``--seeds`` seeds (100 evaluations; egp: 50 initial + 50 BO), keeps the simple regret
SR(t) = 1 - best-so-far (paper eq. SR, optimum 1) of every run, and reconstructs the seed-0 plan
in every wind realization (render, COLMAP on the CPU, CPU dense stereo, Chamfer). Writes
``results/table1.md``, ``results/table1.json`` and ``results/simple_regret.png``.

Every finished cell (one plan, one reconstruction) is cached as JSON under ``results/cache/``;
a re-run resumes instead of recomputing. Uses Corn50 plants from ``../shared/data/corn50`` when
present (``--models`` to choose), else procedural plants.
"""
from __future__ import annotations

import argparse
import json
import sys
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

if not __package__:  # python bench/table1.py: as python -m bench.table1 (bench/_script.py)
    import _script  # noqa: F401
from bench.cache import cached  # noqa: E402
from bench.cluster import Task, cluster_client, run_tasks  # noqa: E402
from bench.common import (SCENARIOS, VARIANTS, capture_of, capture_tag, known_realizations, models_tag,  # noqa: E402
                          plan_cell, plan_path, reconstruct_record, scene)
from bench.options import parser  # noqa: E402
from bench.publish import machine, publish  # noqa: E402
from bench.stats import describe, describe_difference, paired_difference, rank, realization_units, summary  # noqa: E402

#: Table rows: label -> (planner variant of common.VARIANTS, reward model).
ROWS = {
    'circle': ('circle', 'coverage'),
    'arc': ('arc', 'coverage'),
    'sa': ('sa', 'coverage'),
    'egp': ('egp', 'coverage'),
    'egp (paper configuration)': ('egp-paper-config', 'paper'),
    'egp (coverage-graph)': ('egp', 'coverage-graph'),
}
#: The baseline rows (what a drone operator flies anyway, and the paper's SA): those of a baseline variant.
BASELINES = tuple(row for row, (variant, _) in ROWS.items() if VARIANTS[variant].baseline)
PAPER = {  # Table I of the paper, Chamfer x100 (mean, std)
    'one_plant': {'circle': (4.127, 0.194), 'sa': (3.844, 0.224), 'egp (paper configuration)': (3.256, 0.245)},
    'three_row': {'circle': (2.817, 0.079), 'sa': (2.43, 0.192), 'egp (paper configuration)': (1.614, 0.166)},
    'six_rect': {'circle': (2.717, 0.072), 'sa': (3.905, 0.184), 'egp (paper configuration)': (2.54, 0.578)},
}


def parse_args(argv=None) -> argparse.Namespace:
    ap = parser(__doc__, 'models', 'images', 'threads', 'capture', 'cluster', 'out')
    ap.add_argument('--scenarios', nargs='+', default=list(SCENARIOS), choices=list(SCENARIOS))
    ap.add_argument('--rows', nargs='+', default=list(ROWS), choices=list(ROWS))
    ap.add_argument('--seeds', type=int, default=5, help='planning seeds for the regret figure')
    ap.add_argument('--evals', type=int, default=100)
    ap.add_argument('--init', type=int, default=50)
    ap.add_argument('--realizations', type=int, default=0,
                    help='reconstruct the first n wind realizations of each plan (0: all K)')
    ap.add_argument('--recon-seeds', type=int, default=1,
                    help='reconstruct the plans of the first n seeds (statistics over seed x realization)')
    ap.add_argument('--recon-first', type=int, default=0,
                    help='skip the seeds below this one (a slice of more seeds beside a table that has them; '
                         'python -m bench.table1_combine joins the slices)')
    return ap.parse_args(argv)


def recon_tag(scenario: str, row: str, args, seed: int = 0) -> str:
    """The cache name of :func:`recon_cell`."""
    variant, reward = ROWS[row]
    tag = (f'{models_tag(args.models)}-{scenario}-{variant}-{reward}-seed{seed}-e{args.evals}-{args.width}x{args.height}'
           + capture_tag(capture_of(args)))
    return tag + (f'-k{args.realizations}' if args.realizations else '')


def recon_cell(cache: Path, out: Path, scenario: str, row: str, plan: dict, args, seed: int = 0) -> dict:
    """Reconstruct one plan in every wind realization (cached); Chamfer etc. x100 as Table I."""
    from vp_recon.config import ReconConfig

    tag = recon_tag(scenario, row, args, seed)

    def compute() -> dict:
        noisy, _ = scene(scenario, args.models)
        cfg = ReconConfig(width=args.width, height=args.height, num_threads=args.threads,
                          capture=capture_of(args))
        ks = range(min(args.realizations, len(noisy.points))) if args.realizations else None
        return reconstruct_record(noisy, plan['cameras'], cfg, out / 'recon' / tag, ks,
                                  known_realizations(cache / 'recon' / f'{tag}.json', out / 'recon' / tag))
    return cached(cache / 'recon' / f'{tag}.json', compute)


def plan_tasks(cache: Path, args) -> list[Task]:
    """Every planning run of the table: (scenario, row, seed)."""
    tasks = []
    for scenario in args.scenarios:
        for row in args.rows:
            variant, reward = ROWS[row]
            for seed in range(args.seeds):
                a = (cache, scenario, variant, seed, args.evals, args.init, args.models, None, reward)
                tasks.append(Task((scenario, row, seed), plan_cell, a, plan_path(*a), f'{scenario} {row} seed {seed}'))
    return tasks


def recon_seeds(args) -> range:
    """The seeds whose plans are reconstructed: --recon-first up to --recon-seeds (and --seeds)."""
    seeds = range(max(0, args.recon_first), min(max(1, args.recon_seeds), args.seeds))
    if not seeds:
        raise SystemExit(f'table1: no seed to reconstruct (--recon-first {args.recon_first}, --recon-seeds '
                         f'{args.recon_seeds}, --seeds {args.seeds})')
    return seeds


def recon_tasks(cache: Path, out: Path, plans: dict, args) -> list[Task]:
    """One reconstruction per (scenario, row, seed < --recon-seeds): the plan in every wind
    realization (a plan that failed has no task: :func:`run` records its failure)."""
    return [Task((s, row, seed), recon_cell, (cache, out, s, row, plans[(s, row, seed)], args, seed),
                 cache / 'recon' / f'{recon_tag(s, row, args, seed)}.json', f'{s} {row} seed {seed}')
            for s in args.scenarios for row in args.rows for seed in recon_seeds(args)
            if 'error' not in plans[(s, row, seed)]]


def failed_recon(plan: dict) -> dict:
    """The record of a plan that failed: its reconstruction failed too (counted, ranked last)."""
    return {'error': plan['error'], 'error_msg': f'planning failed: {plan.get("error_msg", "")}',
            'chamfer_mean': None, 'chamfer_std': None, 'per_realization': []}


def run(args, client) -> tuple[dict, dict]:
    """(plans, recons) of the table through the cluster ``client``."""
    out = Path(args.out)
    cache = out / 'cache'
    plans = run_tasks(client, plan_tasks(cache, args), 'planning')
    recons = run_tasks(client, recon_tasks(cache, out, plans, args), 'reconstructing')
    for key, plan in plans.items():
        if key[2] in recon_seeds(args) and 'error' in plan:
            recons[key] = failed_recon(plan)
    return plans, recons


def main(argv=None) -> int:
    args = parse_args(argv)
    recon_seeds(args)  # a slice with no seed fails before any work
    with cluster_client(args) as client:
        plans, recons = run(args, client)
    write_results(args, Path(args.out), plans, recons)
    return 0


def chamfer_units(recons: dict, scenario: str, row: str, args) -> dict:
    """(seed, realization) -> Chamfer x100 of a row, None where the reconstruction failed (each
    realization reconstructs on its own: ``common.reconstruct_record``; a failed plan fails in all)."""
    K = len(scene(scenario, args.models)[0].points)
    ks = min(args.realizations, K) if args.realizations else K
    return realization_units({seed: recons[(scenario, row, seed)] for seed in recon_seeds(args)}, ks)


def paired_lines(args, units: dict, table: dict) -> list[str]:
    """Markdown (and ``table['paired']``) of egp - best baseline, paired per (seed, realization),
    for every egp row against the best-ranked baseline row of each scenario."""
    baselines = [r for r in args.rows if r in BASELINES]
    egps = [r for r in args.rows if r not in BASELINES]
    if not baselines or not egps:
        return []
    lines = ['', '## Paired differences: egp - best baseline (Chamfer x100, negative: egp better)', '',
             'Per (scenario, seed, realization) where both reconstructed; mean [95 % t-interval] (n); '
             'the best baseline is the best-ranked of ' + ', '.join(baselines) + ' in the scenario.', '',
             '| scenario | best baseline | ' + ' | '.join(egps) + ' |', '|---|---|' + '---|' * len(egps)]
    table['paired'] = {}
    for scenario in args.scenarios:
        best = rank({r: summary(units[(scenario, r)]) for r in baselines})[0]
        cells = [scenario, best]
        for row in egps:
            d = paired_difference(units[(scenario, row)], units[(scenario, best)])
            table['paired'][f'{scenario}/{row}'] = {'baseline': best, **d}
            cells.append(describe_difference(d))
        lines.append('| ' + ' | '.join(cells) + ' |')
    return lines


def _score(plan: dict, scenario: str, models: str, reward: str) -> float:
    from vp_planner.reward_models import make_reward

    noisy, _ = scene(scenario, models)
    return float(make_reward(reward, noisy.points)(np.asarray(plan['cameras'])[None])[0])


def capture_text(args) -> str:
    """The capture of the reconstructions, in words (README "Capture model")."""
    capture = capture_of(args)
    if capture.ideal:
        return 'ideal (the planned poses flown and known exactly, noise-free renders, blue screen)'
    return (f'{capture.kind}: flown with hover and localization errors and sensor noise '
            f'({json.dumps(capture.to_dict())}), over the textured soil with plant masks from the images alone, '
            'the model anchored on the reported poses (COLMAP triangulation and bundle adjustment, registered on '
            'them)' + (', placed on the ground markers and the reported centres' if capture.gcp_markers else ''))


def shape_lines(args, recons: dict, table: dict) -> list[str]:
    """Markdown of the Chamfer after a rigid ICP refinement (the shape alone, without the
    registration error of a flight) and the images registered, per row and scenario."""
    seeds = recon_seeds(args)
    lines = ['', '## Shape alone and registration', '',
             'Chamfer x100 after a rigid ICP refinement onto the truth (`chamfer_shape`: what the Chamfer would be '
             'with a perfect registration to map), mean +- sample std (n); images registered per reconstruction '
             '(min-max). A failed reconstruction is counted.', '',
             '| method | ' + ' | '.join(args.scenarios) + ' |', '|---|' + '---|' * len(args.scenarios)]
    table['shape'] = {}
    for row in args.rows:
        cells = [row]
        for scenario in args.scenarios:
            per = [p for seed in seeds for p in recons[(scenario, row, seed)].get('per_realization', [])]
            stat = summary({i: p.get('chamfer_shape') for i, p in enumerate(per)})
            failed = sum(1 for seed in seeds if recons[(scenario, row, seed)].get('error'))
            imgs = [p['images'] for p in per if p.get('images') is not None]
            table['shape'][f'{scenario}/{row}'] = {**stat, 'images': imgs, 'failed_plans': failed}
            cells.append((describe(stat) if per else 'failed') + (f', images {min(imgs)}-{max(imgs)}' if imgs else '')
                         + (f', {failed} plan(s) failed' if failed else ''))
        lines.append('| ' + ' | '.join(cells) + ' |')
    return lines


def write_results(args, out: Path, plans, recons) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    stamp = datetime.now(timezone.utc).strftime('%Y-%m-%d')
    host = machine()
    table = {'date': stamp, 'machine': host, 'models': models_tag(args.models), 'rows': ROWS,
             'capture': capture_of(args).to_dict(),
             'evaluations': args.evals, 'resolution': [args.width, args.height], 'cells': {}}
    seeds = recon_seeds(args)
    lines = [f'# Table I, measured {stamp} ({host})', '',
             f'Plants: {args.models or "built-in procedural corn"}. Chamfer distance x 100, mean +- sample std '
             f'(ddof 1) over the plans of seeds {seeds[0]}..{seeds[-1]} x {args.realizations or "all"} wind realizations '
             'of K = 5 (n: the successful reconstructions; a failed one is counted and ranks its row last), lower is '
             'better; the paper\'s value in brackets. Rewards of the seed-0 plan under both models (coverage / paper).', '',
             f'Capture: {capture_text(args)}', '',
             '| method | ' + ' | '.join(f'{s} (N={SCENARIOS[s]})' for s in args.scenarios) + ' |',
             '|---|' + '---|' * len(args.scenarios)]
    units = {(s, row): chamfer_units(recons, s, row, args) for s in args.scenarios for row in args.rows}
    for row in args.rows:
        cells = [row]
        for scenario in args.scenarios:
            recs = {seed: recons[(scenario, row, seed)] for seed in seeds}
            plan = plans[(scenario, row, 0)]
            paper = PAPER[scenario].get(row)
            stat = summary({f'{seed}/{k}': v for (seed, k), v in units[(scenario, row)].items()})
            errors = sorted({r['error'] for r in recs.values() if r.get('error')})
            cell = {'recon': recs[seeds[0]], 'recon_by_seed': {str(k): v for k, v in recs.items()}, 'chamfer': stat,
                    'paper': paper}
            ref = f' [{paper[0]:.3f} +- {paper[1]:.3f}]' if paper else ''
            text = describe(stat) + (f' ({", ".join(errors)})' if errors else '') + ref
            if 'error' not in plan:
                rewards = {m: _score(plan, scenario, args.models, m) for m in ('coverage', 'paper')}
                cell.update(reward=plan['reward'], rewards=rewards, cameras=plan['cameras'])
                text += f', reward {rewards["coverage"]:.3f} / {rewards["paper"]:.3f}'
            table['cells'][f'{scenario}/{row}'] = cell
            cells.append(text)
        lines.append('| ' + ' | '.join(cells) + ' |')
    lines += paired_lines(args, units, table)
    lines += shape_lines(args, recons, table)
    lines += ['', 'Plants used (scene seed 0; name, yaw deg, scale):', '']
    for scenario in args.scenarios:
        noisy, _ = scene(scenario, args.models)
        used = [(p.model_name, round(float(np.degrees(p.yaw)), 1), round(float(p.scale), 3))
                for p in noisy.scene.plants]
        table.setdefault('plants', {})[scenario] = used
        lines.append(f'- {scenario}: ' + ', '.join(f'{n} ({y}, {sc})' for n, y, sc in used))
    lines += ['', '## Final reward of each row\'s own reward model (mean +- sample std over seeds, n)', '',
              '| method | ' + ' | '.join(args.scenarios) + ' |', '|---|' + '---|' * len(args.scenarios)]
    regret = {}
    for row in args.rows:
        cells = [row]
        for scenario in args.scenarios:
            runs = [plans[(scenario, row, s)] for s in range(args.seeds)]
            ok = [p for p in runs if 'error' not in p]
            traces = np.array([p['trace'] for p in ok]).reshape(len(ok), -1)
            stat = summary({s: (p['trace'][-1] if 'error' not in p else None) for s, p in enumerate(runs)})
            cells.append(describe(stat, digits=4, note=ROWS[row][1]))
            regret[(scenario, row)] = 1.0 - traces  # paper eq. SR with optimum 1
            table['cells'][f'{scenario}/{row}']['final_reward'] = {
                **stat, 'model': ROWS[row][1],
                'failures': {str(s): f'{p["error"]}: {p["error_msg"]}' for s, p in enumerate(runs) if 'error' in p},
                'seconds_mean': float(np.mean([p['seconds'] for p in ok])) if ok else float('nan')}
        lines.append('| ' + ' | '.join(cells) + ' |')
    publish(out, 'table1', table, '\n'.join(lines) + '\n')

    fig, axes = plt.subplots(1, len(args.scenarios), figsize=(5 * len(args.scenarios), 4), squeeze=False)
    for ax, scenario in zip(axes[0], args.scenarios):
        for row in args.rows:
            sr = regret[(scenario, row)]
            if not len(sr):  # every seed failed: named in the table above
                continue
            t = np.arange(1, sr.shape[1] + 1)
            ax.plot(t, sr.mean(0), label=f'{row} ({ROWS[row][1]})')
            ax.fill_between(t, sr.mean(0) - sr.std(0), sr.mean(0) + sr.std(0), alpha=0.15)
        ax.set_title(f'{scenario} (N={SCENARIOS[scenario]})')
        ax.set_xlabel('evaluation t')
        ax.set_ylabel('simple regret 1 - max reward')
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / 'simple_regret.png', dpi=120)
    print(f'wrote {out / "simple_regret.png"}')


if __name__ == '__main__':
    sys.exit(main())
