#!/usr/bin/env python3
"""Candidate reward terms against the plan-quality study (issue 42): which one ranks the flights as
their reconstruction does, on the check half no tuning used?

Reads the study's reconstructions (``bench.plan_quality``'s cache of the main variant: realistic
capture, the anchored model, ground markers) and scores every plan of the design and check halves
with each candidate; reports per scenario Spearman's rho against -Chamfer (the mean over the
realizations recorded; a failed plan ranks last, ``plan_chamfer``) and the ROC AUC of the plans
that failed (``roc_auc``). Candidates:

``coverage``, ``coverage-graph``, ``paper``
    the reward models as the planner has them (``vp_planner.reward_models``);
``coverage-graph scale s``
    coverage x min(1, lambda_2 / s) for s over 1e-4 ... 1e-2 (the view graph SfM can chain), the
    planner's own (``make_reward`` with ``CoverageParams(view_graph=True, graph_scale=s)``);
    lambda_2 alone (``vp_planner.reward_models.view_graph``) is a feature of the surrogates;
``coverage window/resolution (design-best)``
    coverage's matching window (cutoff 45-90 degrees, flat to 25 or 35) and full resolution
    (250-1000 px/m) chosen by the design half's mean rho over both scenarios;
``registration dop``
    minus the dilution of precision of placing the model from the reported poses (issue 42,
    direction 1), closed form: the similarity (t, omega, s) fitted to N centres (sigma_p 0.02 m)
    and N attitudes (sigma_a 0.5 degree) has information
    I = sum_i J_i^T J_i / sigma_p^2 + N diag(0, I_3 / sigma_a^2, 0), J_i = [I_3, -[a_i]x, a_i],
    a_i = c_i - mean(c); a plant point b = x - mean(c) moves by G(b) = [I_3, -[b]x, b] times
    the error, so its RMS displacement is sqrt(mean_b tr(G I^-1 G^T)) (satellite navigation's
    DOP; every evaluation can afford it);
``linear (design fit)``, ``GP (design fit)``
    a learned surrogate of -log Chamfer (a failed plan: 1.5 x the scenario's worst) from
    coverage, paper, log10 lambda_2 and the DOP, fitted on the design half of both scenarios:
    least squares, and BoTorch's SingleTaskGP (fit_gpytorch_mll) as direction 4 names it.

Writes ``results/rerun/issue42_reward_candidates/reward_candidates.{json,md}``. Minutes: the
coverage grid is 24 settings x the study's plans.
"""
from __future__ import annotations

import argparse
import itertools
import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

if not __package__:  # python bench/reward_candidates.py: as python -m bench.reward_candidates (bench/_script.py)
    import _script  # noqa: F401
from bench.common import ROOT, default_models, machine, scene, write_report  # noqa: E402
from bench.plan_quality import load_study, plan_chamfer, roc_auc, split_halves  # noqa: E402
from bench.stats import spearman  # noqa: E402

SCENARIOS = ('one_plant', 'three_row')
VARIANT = '2000x1500-realistic-anchored'
#: the reported poses' accuracy the DOP assumes (the realistic capture's: RTK-like centres, gimbal attitudes)
SIGMA_POSITION, SIGMA_ATTITUDE = 0.02, math.radians(0.5)
GRAPH_SCALES = (1e-4, 1e-3, 1e-2)
WINDOW_GRID = list(itertools.product((45.0, 60.0, 75.0, 90.0), (25.0, 35.0), (250.0, 500.0, 1000.0)))


def parse_args(argv=None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--models', default=default_models())
    ap.add_argument('--variant', default=VARIANT, help="the study's cache variant")
    ap.add_argument('--out', default=str(ROOT / 'results' / 'rerun' / 'issue42_reward_candidates'))
    return ap.parse_args(argv)


def registration_dop(cameras: np.ndarray, points: np.ndarray, sigma_position: float = SIGMA_POSITION,
                     sigma_attitude: float = SIGMA_ATTITUDE) -> float:
    """RMS displacement (m) of ``points`` (P, 3) when a model is placed by the similarity fitted to
    the cameras' (N, 6+) reported centres and attitudes (module docstring): the planner's own
    ``vp_planner.reward_models.placement_error`` with all cameras in one part. Degenerate: a single
    camera (or coincident ones) leaves the scale unknown: inf."""
    import torch

    from vp_planner.reward_models import placement_error

    c = torch.as_tensor(np.asarray(cameras, dtype=np.float64)[None, :, :3])
    same = torch.ones(1, c.shape[1], c.shape[1], dtype=torch.bool)
    var = placement_error(c, same, torch.as_tensor(np.asarray(points, dtype=np.float64)), sigma_position,
                          math.degrees(sigma_attitude))[0, 0]
    return float(torch.sqrt(var.mean()))


def _rewards(spec, R: np.ndarray, cams: np.ndarray) -> np.ndarray:
    from vp_planner.reward_models import make_reward

    fn = make_reward(spec, R)
    return np.concatenate([np.asarray(fn(cams[i:i + 16])).reshape(-1) for i in range(0, len(cams), 16)])


def scenario_data(scenario: str, models: str, variant: str) -> dict:
    """The study's recorded plans of a scenario with their scores, half and base features."""
    from vp_planner.reward_models import view_graph

    noisy, _ = scene(scenario, models)
    every = load_study(scenario, models, variant)
    half = split_halves(every)
    plans = [p for p in every if p['recon']]
    cams = np.array([p['cameras'] for p in plans])
    R = noisy.points
    lam2 = []
    for c in cams:
        E = view_graph(c, R)
        lam2.append(float(np.linalg.eigvalsh(np.diag(E.sum(1)) - E)[1]))
    pts = R.reshape(-1, 3)[::7]
    return {'ids': [p['id'] for p in plans], 'half': np.array([half[p['id']] for p in plans]),
            'chamfer': np.array([plan_chamfer(p) for p in plans]), 'R': R, 'cams': cams,
            'coverage': _rewards('coverage', R, cams), 'paper': _rewards('paper', R, cams),
            'lambda2': np.array(lam2), 'dop': np.array([registration_dop(c, pts) for c in cams]),
            'realizations': sorted({k for p in plans for k in p['recon']})}


def score(data: dict, values: dict) -> dict:
    """{scenario: {half: {'rho', 'auc'}}} of one candidate's values per scenario."""
    out = {}
    for s, d in data.items():
        v, ch = np.asarray(values[s], dtype=float), d['chamfer']
        out[s] = {}
        for h in ('design', 'check'):
            m = d['half'] == h
            out[s][h] = {'rho': spearman(list(v[m]), list(-np.where(np.isfinite(ch[m]), ch[m], 1e9))),
                         'auc': roc_auc(v[m], np.isinf(ch[m])), 'plans': int(m.sum()),
                         'failed': int(np.isinf(ch[m]).sum())}
    return out


def features(d: dict) -> np.ndarray:
    return np.stack([d['coverage'], d['paper'], np.log10(np.maximum(d['lambda2'], 0.0) + 1e-4),
                     np.log10(d['dop'])], 1)


def surrogate_values(data: dict, kind: str) -> dict:
    """A surrogate of -log Chamfer fitted on the design half of every scenario, applied to all."""
    X = np.concatenate([features(d) for d in data.values()])
    ys = []
    for d in data.values():
        ch = d['chamfer']
        worst = np.max(ch[np.isfinite(ch)]) if np.isfinite(ch).any() else 1.0
        ys.append(-np.log(np.where(np.isfinite(ch), ch, 1.5 * worst)))
    y = np.concatenate(ys)
    train = np.concatenate([d['half'] == 'design' for d in data.values()])
    mu, sd = X[train].mean(0), X[train].std(0) + 1e-12
    Xn = (X - mu) / sd
    if kind == 'linear':
        A = np.c_[Xn, np.ones(len(Xn))]
        w, *_ = np.linalg.lstsq(A[train], y[train], rcond=None)
        pred = A @ w
    else:  # BoTorch's GP (fit_gpytorch_mll), the surrogate the planner's BO already uses
        import torch
        from botorch.fit import fit_gpytorch_mll
        from botorch.models import SingleTaskGP
        from botorch.models.transforms import Standardize
        from gpytorch.mlls import ExactMarginalLogLikelihood

        tx = torch.as_tensor(Xn, dtype=torch.float64)
        ty = torch.as_tensor(y, dtype=torch.float64)[:, None]
        gp = SingleTaskGP(tx[train], ty[train], outcome_transform=Standardize(m=1))
        fit_gpytorch_mll(ExactMarginalLogLikelihood(gp.likelihood, gp))
        with torch.no_grad():
            pred = gp.posterior(tx).mean.squeeze(-1).numpy()
    out, i = {}, 0
    for s, d in data.items():
        out[s] = pred[i:i + len(d['ids'])]
        i += len(d['ids'])
    return out


def run(args) -> dict:
    from vp_planner.reward_models import CoverageParams

    data = {s: scenario_data(s, args.models, args.variant) for s in SCENARIOS}
    cands: dict = {}
    for name in ('coverage', 'paper'):
        cands[name] = {s: d[name] for s, d in data.items()}
    for scale in GRAPH_SCALES:  # the planner's own coverage-graph (make_reward), at each scale
        p = replace(CoverageParams(), view_graph=True, graph_scale=scale)
        cands[f'coverage-graph scale {scale:g}'] = {s: _rewards(('coverage', p), d['R'], d['cams'])
                                                    for s, d in data.items()}
    cands['registration dop'] = {s: -d['dop'] for s, d in data.items()}
    grid = []
    for cutoff, high, ppm in WINDOW_GRID:
        p = replace(CoverageParams(), window_cutoff=cutoff, window_high=high, ppm_full=ppm)
        vals = {s: _rewards(('coverage', p), d['R'], d['cams']) for s, d in data.items()}
        sc = score(data, vals)
        design = np.mean([sc[s]['design']['rho'] for s in SCENARIOS])
        grid.append({'window_cutoff': cutoff, 'window_high': high, 'ppm_full': ppm, 'design_rho': float(design),
                     'scores': sc})
        print(f'  window {cutoff:.0f}/{high:.0f} ppm {ppm:.0f}: design rho {design:+.3f}', flush=True)
    best = max(grid, key=lambda g: g['design_rho'])
    for kind in ('linear', 'gp'):
        cands[f'{"linear" if kind == "linear" else "GP"} (design fit)'] = surrogate_values(data, kind)
    result = {'date': __import__('time').strftime('%Y-%m-%d'), 'machine': machine(), 'variant': args.variant,
              'realizations': {s: d['realizations'] for s, d in data.items()},
              'plans': {s: len(d['ids']) for s, d in data.items()},
              'failed': {s: int(np.isinf(d['chamfer']).sum()) for s, d in data.items()},
              'candidates': {name: score(data, vals) for name, vals in cands.items()},
              'window_grid': grid, 'window_best': {k: best[k] for k in ('window_cutoff', 'window_high', 'ppm_full')}}
    result['candidates']['coverage window/resolution (design-best)'] = best['scores']
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_report(out / 'reward_candidates.json', result)
    (out / 'reward_candidates.md').write_text(markdown(result))
    print(markdown(result))
    return result


def _num(x) -> str:
    return '-' if x is None or (isinstance(x, float) and not math.isfinite(x)) else f'{x:+.3f}'


def markdown(result: dict) -> str:
    scen = list(result['plans'])
    b = result['window_best']
    lines = ['# Reward candidates against the plan-quality study', '',
             f"{result['machine']}; {result['date']}; study variant `{result['variant']}`, realizations "
             + '; '.join(f"{s} {result['realizations'][s]}" for s in scen) + '; plans (failed): '
             + ', '.join(f"{s} {result['plans'][s]} ({result['failed'][s]})" for s in scen)
             + f". The design-best window: cutoff {b['window_cutoff']:.0f}, flat to {b['window_high']:.0f} degrees, "
             f"{b['ppm_full']:.0f} px/m. Spearman rho of the candidate against -Chamfer and ROC AUC of the failed "
             "plans (- where a half has none failed); the bar (issue 42): check rho >= 0.8, AUC >= 0.9.", '',
             '| candidate | ' + ' | '.join(f'{s} rho check (design) | {s} AUC check (design)' for s in scen) + ' |',
             '|---|' + '---|---|' * len(scen)]
    for name, sc in result['candidates'].items():
        cells = []
        for s in scen:
            c, d = sc[s]['check'], sc[s]['design']
            cells += [f"{_num(c['rho'])} ({_num(d['rho'])})", f"{_num(c['auc'])} ({_num(d['auc'])})"]
        lines.append(f'| {name} | ' + ' | '.join(cells) + ' |')
    return '\n'.join(lines) + '\n'


def main(argv=None) -> int:
    run(parse_args(argv))
    return 0


if __name__ == '__main__':
    sys.exit(main())
