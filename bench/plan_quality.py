#!/usr/bin/env python3
"""The plan-quality study: how well does each reward model rank plans the way the reconstruction does?

For each scenario (Corn50 plants from ../shared, scene seed 0, as Table I) it builds at least 60
*feasible* plans from diverse families (structured caps, full circles over a grid of radius and
height, arcs 15-90 degrees apart, plans at several distances, SA, random feasible plans, BO
outputs, the tuned circle), reconstructs each with the project's own pipeline (render, COLMAP on
the CPU, SGBM dense stereo, Chamfer) on the chosen wind realizations, and records what explains
the result: accuracy, completeness, sparse and dense points, verified SIFT matches per camera
pair, the pairs the dense step used, each camera's elevation and distance.

Then every reward model of :data:`vp_planner.reward_models.REWARD_MODELS` (and the ingredient
ablations of ``study_models``, :mod:`bench.reward_ablations`) scores every plan, and Spearman's rho between the reward and
-Chamfer is reported over all plans and over the plans that reconstructed at all.

Phases (``--phase``): ``plans`` (generate, cached), ``recon`` (reconstruct, one cached JSON per
plan and realization: resumable), ``flights`` (one simulated flight of every plan as the planner
flies it, ``--flight-*`` its setting: :func:`flight_cell`; the analysis then ranks by each setting's
flights beside the reward models, ``flight-<setting>``), ``analyze`` (models, Spearman, ``results/plan_quality.json``
and ``results/plan_quality.png``), ``all``. ``--phase analyze --records REPORT`` scores the plans
under today's reward models against the per-plan records a committed report keeps (every score of
every realization, failures with their reasons) instead of the cache: a reward changed, the
reconstruction did not, and its hours are not spent again. Variants: ``--ground`` / ``--no-ground`` choose the
background (default: by the capture, soil for a flight, as ``vp_recon.cli``); each variant is analyzed against
three scores of the same reconstructions (:data:`CLOUDS`): the dense cloud's Chamfer in map (the
main one), the sparse cloud's, and the dense cloud's shape after ICP (``chamfer_shape``).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
import numpy as np

if not __package__:  # python bench/plan_quality.py: as python -m bench.plan_quality (bench/_script.py)
    import _script  # noqa: F401
from bench.cache import cached  # noqa: E402
from bench.cluster import Task, cluster_client, run_tasks  # noqa: E402
from bench.common import ROOT, SCENARIOS, capture_of, capture_tag, models_tag, scene, variant_request  # noqa: E402
from bench.options import parser  # noqa: E402
from bench.publish import machine, num, publish, table  # noqa: E402
from bench.stats import spearman  # noqa: E402

CACHE = ROOT / 'results' / 'cache' / 'plan_quality'
#: what a variant's Spearman ranks against: the dense cloud's Chamfer in map (the main figure),
#: COLMAP's sparse cloud alone, and the dense cloud's shape after a rigid ICP onto the truth
#: (``chamfer_shape``: registration error taken out; kept from 2026-11-26 on)
CLOUDS = {'dense': 'chamfer', 'sparse': 'sparse_chamfer', 'shape': 'chamfer_shape'}
#: seed of the design/check split (issue 18: tune on the design half, report the check half)
SPLIT_SEED = 0


def parse_args(argv=None) -> argparse.Namespace:
    ap = parser(__doc__, 'models', 'images', 'threads', 'capture', 'cluster', 'out')
    ap.add_argument('--scenarios', nargs='+', default=['one_plant', 'three_row'], choices=list(SCENARIOS))
    ap.add_argument('--realizations', default='0,1', help='wind realizations to reconstruct (comma-separated)')
    ap.add_argument('--ground', action=argparse.BooleanOptionalAction, default=None,
                    help='render a textured soil plane under the plants (default: by the capture, as vp_recon.cli)')
    ap.add_argument('--phase', default='all', choices=['plans', 'recon', 'flights', 'analyze', 'all', 'check'],
                    help="check: the design/check split and the check half's Spearman from the per-plan "
                         "records already in --out's plan_quality.json (no cache needed)")
    ap.add_argument('--split-seed', type=int, default=SPLIT_SEED,
                    help='seed of the design/check split of the plans (stratified by family)')
    ap.add_argument('--variants', nargs='+', default=None,
                    help='analyze: variants to report (default: every one found in the cache)')
    ap.add_argument('--records', default=None,
                    help="analyze: score the plans under today's reward models against the per-plan records of "
                         "this plan_quality.json instead of the cache (a study whose reconstructions are "
                         "committed but whose cache is gone; the reconstruction is not run again)")
    from vp_scene.flights import FlightSettings

    fs = FlightSettings()
    ap.add_argument('--flight-width', type=int, default=fs.width, help="flights: the simulated flights' image width")
    ap.add_argument('--flight-height', type=int, default=fs.height, help="flights: their image height")
    ap.add_argument('--flight-sift-octave', type=int, default=fs.sift_first_octave, choices=(-1, 0),
                    help="flights: their SIFT first octave")
    ap.add_argument('--flight-dense-scale', type=float, default=fs.dense_scale, help="flights: their dense scale")
    ap.add_argument('--flight-draws-from', type=int, default=0,
                    help="flights: plan j flies the planner's draw j + this (0: the planner's first draws; another "
                         "value flies every plan again under new draws, and the analysis ranks by the mean of a "
                         "setting's flights beside each one alone)")
    ap.add_argument('--limit', type=int, default=0, help='reconstruct only the first n plans (0: all)')
    ap.add_argument('--ids', nargs='+', default=None,
                    help='reconstruct only these plan ids, in this order (e.g. to do the rarer families first)')
    ap.add_argument('--stride', type=int, default=1,
                    help='reconstruct every n-th plan (a subset that keeps every family, for the '
                         'ground and held-out checks)')
    return ap.parse_args(argv)


# ----------------------------------------------------------------------------- plan families
def _space(scenario: str, models: str):
    from vp_planner.space import ViewSpace

    noisy, _ = scene(scenario, models)
    return noisy, ViewSpace(noisy.points, SCENARIOS[scenario])


def plan_families(scenario: str, models: str) -> list[dict]:
    """The study's plans: [{id, family, params, cameras}], feasible only, deterministic."""
    from vp_planner.designs import random_plans, structured_plans
    from vp_planner.optimizers import plan_views
    from vp_planner.patterns import arc, cap, ring

    noisy, space = _space(scenario, models)
    N = SCENARIOS[scenario]
    R = noisy.points
    ext = space.extent
    centre = ext.centre
    target = centre.copy()
    plans: list[dict] = []

    def add(family: str, params: dict, cams: np.ndarray) -> None:
        cams = np.asarray(cams, dtype=np.float64)
        if cams.shape == (N, 6) and bool(space.feasible(cams)):
            plans.append({'id': f'{family}-{len(plans):03d}', 'family': family, 'params': params,
                          'cameras': cams.tolist()})

    # structured caps: the planner's own initial plans, then caps over elevation x spread x distance
    for i, U in enumerate(structured_plans(space, max_plans=8)):
        add('structured', {'index': i}, space.decode(U))
    half = float(np.max(ext.half))
    rng = np.random.default_rng(11)
    for el in (10, 30, 50, 70):
        for spread in (0.5, 1.0):
            for dist in (1.6, 2.4):
                az = float(rng.uniform(0, 360))
                add('cap', {'elevation': el, 'half_angle_deg': 22.5 * spread, 'distance': dist + half, 'azimuth': az},
                    cap(centre, target, dist + half, N, math.radians(az), math.radians(el),
                        math.radians(22.5 * spread)))
    # full circles over a grid of radius and height (the paper's circle family)
    for r in (1.2, 1.8, 2.6):
        for h in (1.0, 2.2, 3.4):
            add('circle', {'radius': r + half, 'height': h}, ring(centre[:2], target, [r + half], [h], N)[0])
    # arcs 15-90 degrees apart at two (radius, height) pairs, facing the row broadside and along it
    for (r, h, az) in ((1.6, 2.4, 90.0), (2.2, 1.2, 0.0)):
        for spacing in (15, 20, 30, 40, 50, 60, 75, 90):
            if spacing * (N - 1) >= 360:
                continue
            add('arc', {'radius': r + half, 'height': h, 'spacing_deg': spacing, 'azimuth': az},
                arc(centre[:2], target, r + half, h, N, math.radians(spacing), math.radians(az)))
    # a 30-degree arc at several distances (elevation 35 degrees)
    for d in (1.2, 1.6, 2.0, 2.6, 3.3, 4.2):
        dd = d + half
        el = math.radians(35.0)
        add('distance', {'distance': dd, 'spacing_deg': 30},
            arc(centre[:2], target, dd * math.cos(el), centre[2] + dd * math.sin(el), N, math.radians(30.0),
                math.radians(200.0)))
    # random feasible plans of the planner's space
    for U in random_plans(space, 14, np.random.default_rng(5)):
        add('random', {}, space.decode(U))
    # optimizer outputs (100 evaluations) of variants of common.VARIANTS: the paper reward's, then plans
    # optimized for coverage (a reward that can be gamed would show up here as high reward, poor reconstruction)
    for variant, seeds, reward in (('circle', (0,), 'paper'), ('sa', (0, 1, 2, 3), 'paper'),
                                   ('egp', (0, 1, 2), 'paper'), ('gp', (0,), 'paper'), ('egp', (0, 1, 2), 'coverage'),
                                   ('arc', (0,), 'coverage')):
        for seed in seeds:
            res = plan_views(variant_request(variant, num_cameras=N, evaluations=100, initial_evaluations=50, seed=seed,
                                             reward=reward), R)
            add(variant if reward == 'paper' else f'{variant}-{reward}', {'seed': seed, 'reward_model': reward},
                res.cameras)
    return plans


def plans_of(scenario: str, models: str) -> list[dict]:
    """The study's distinct plans of a scenario (:func:`distinct_plans`) from
    ``results/plan_quality/plans_<scenario>.json`` when it exists (the committed plan set, so that
    the study can be repeated on the same plans), else generated by :func:`plan_families` and
    written there."""
    return distinct_plans(cached(plans_path(scenario, models), lambda: plan_families(scenario, models)))[0]


def distinct_plans(plans: list[dict]) -> tuple[list[dict], dict]:
    """(the plans whose cameras no earlier plan has, {dropped id: the id it repeats}): an optimizer
    can return a plan of its initial design (egp's 073-075 and gp's 076 are structured-000's on
    one_plant), and one plan counted several times weighs its rank several times."""
    kept, dropped, seen = [], {}, {}
    for p in plans:
        key = np.asarray(p['cameras'], dtype=np.float64).round(9).tobytes()
        if key in seen:
            dropped[p['id']] = seen[key]
            continue
        seen[key] = p['id']
        kept.append(p)
    return kept, dropped


def plans_path(scenario: str, models: str) -> Path:
    return ROOT / 'results' / 'plan_quality' / f'plans_{models_tag(models)}_{scenario}.json'


def describe_cameras(cams: np.ndarray, centre: np.ndarray) -> dict:
    d = cams[:, :3] - centre
    dist = np.linalg.norm(d, axis=1)
    elev = np.degrees(np.arcsin(np.clip(d[:, 2] / np.maximum(dist, 1e-12), -1, 1)))
    return {'distance': dist.round(3).tolist(), 'elevation_deg': elev.round(1).tolist()}


# ----------------------------------------------------------------------------- reconstruction
def variant_name(args) -> str:
    capture = capture_of(args)
    ground = (not capture.ideal) if args.ground is None else args.ground  # ReconConfig.ground_used
    # the capture's own background is the name's default: '-ground' = soil under an ideal capture,
    # '-sky' = the blue screen under a flight
    background = ('-ground' if ground else '') if capture.ideal else ('' if ground else '-sky')
    return f'{args.width}x{args.height}' + background + capture_tag(capture)


def recon_path(scenario: str, models: str, plan: dict, k: int, args) -> Path:
    return CACHE / models_tag(models) / scenario / variant_name(args) / f'{plan["id"]}-k{k}.json'


def recon_cell(scenario: str, models: str, plan: dict, k: int, args) -> dict:
    from vp_recon.config import ReconConfig
    from vp_recon.errors import ReconError
    from vp_recon.pipeline import reconstruct_realization

    path = recon_path(scenario, models, plan, k, args)

    def compute() -> dict:
        noisy, _ = scene(scenario, models)
        cfg = ReconConfig(width=args.width, height=args.height, ground=args.ground, keep_images=False,
                          num_threads=args.threads, capture=capture_of(args))
        t0 = time.perf_counter()
        try:
            r = reconstruct_realization(noisy, k, np.asarray(plan['cameras']), cfg)
        except ReconError as exc:
            return {'error': exc.name, 'error_msg': str(exc), 'seconds': time.perf_counter() - t0}
        sp = r.sparse_score
        return {
            'chamfer': r.chamfer, 'chamfer_shape': r.chamfer_shape, 'accuracy': r.accuracy,
            'completeness': r.completeness, 'fscore': r.fscore,
            'points': int(len(r.points)), 'source': r.source, 'images': r.images, 'visible_images': r.visible_images,
            'sparse_points': r.sparse_points,
            'sparse_chamfer': sp.chamfer if sp else None, 'sparse_accuracy': sp.accuracy if sp else None,
            'sparse_completeness': sp.completeness if sp else None,
            'sparse_clean_points': sp.num_points if sp else 0,
            'sparse_mode': r.sparse_mode, 'sparse_fallback': r.sparse_fallback or None, 'control': r.control,
            'pair_inliers': [[int(a), int(b), int(n)] for (a, b), n in sorted(r.pair_inliers.items())],
            'dense_pairs': [[int(a), int(b), int(n)] for (a, b), n in zip(r.dense_pairs, r.dense_pair_points)],
            'seconds': {**r.seconds, 'total': time.perf_counter() - t0},
        }
    return cached(path, compute)


# ----------------------------------------------------------------------------- simulated flights
def flight_settings(args):
    from vp_scene.flights import FlightSettings

    return FlightSettings(args.flight_width, args.flight_height, args.flight_sift_octave, args.flight_dense_scale)


def flight_tag(settings, draws_from: int = 0) -> str:
    """The name of a flight setting in the cache and the report (``flight-2000x1500o0d0.5``; flown
    under draws from ``draws_from`` on: ``...-draws1000``)."""
    tag = f'flight-{settings.width}x{settings.height}o{settings.sift_first_octave}d{settings.dense_scale:g}'
    return tag + (f'-draws{draws_from}' if draws_from else '')


def flight_path(scenario: str, models: str, plan: dict, settings, draws_from: int = 0) -> Path:
    return CACHE / models_tag(models) / scenario / flight_tag(settings, draws_from) / f'{plan["id"]}.json'


def flight_cell(scenario: str, models: str, plan: dict, j: int, settings, draws_from: int = 0) -> dict:
    """One simulated flight of a plan (cached under the draw set that starts at ``draws_from``), as
    the planner flies it: over the scene's plants, under the draw of flight ``draws_from + j`` of a
    planning run of seed 0 (the planner's own wind and capture noise, never the study's
    realizations), the realistic capture with ground markers."""
    from vp_recon.sim_flights import fly_plan
    from vp_scene.capture import REALISTIC
    from vp_scene.flights import flight_draws

    def compute() -> dict:
        noisy, _ = scene(scenario, models)
        draw = flight_draws(0, 1, noisy.config.variance, start=draws_from + j)[0]
        return fly_plan(noisy.scene, noisy.config, np.asarray(plan['cameras']), draw, settings, REALISTIC).to_dict()
    return cached(flight_path(scenario, models, plan, settings, draws_from), compute)


def run_flights(args, client, study: dict) -> dict:
    """One simulated flight of every plan of the study (cached): the plan set's j-th plan flies the
    draw ``--flight-draws-from`` + j."""
    settings, first = flight_settings(args), args.flight_draws_from
    tasks = [Task((s, p['id']), flight_cell, (s, args.models, p, j, settings, first),
                  flight_path(s, args.models, p, settings, first), f'{s} {p["id"]} flight')
             for s in args.scenarios for j, p in enumerate(study[s])]
    return run_tasks(client, tasks, f'flying ({flight_tag(settings, first)})')


def flight_predictors(scenario: str, models: str, plans: list[dict]) -> dict:
    """The simulated flights found in the cache, as predictors beside the reward models:
    {flight tag: {'reward': minus each plan's map Chamfer (-inf for a failed flight), ...}}, for
    the settings that flew every plan of ``plans``; a setting flown under several draw sets also as
    ``<setting>-mean<k>``, minus the mean of a plan's k flights (-inf when one failed), as the
    planner scores a plan it flew k times (:attr:`vp_planner.flight_planning.PoolPlan.score`)."""
    out, by_setting = {}, {}
    for folder in sorted((CACHE / models_tag(models) / scenario).glob('flight-*')):
        recs = [folder / f'{p["id"]}.json' for p in plans]
        if not all(f.is_file() for f in recs):
            continue
        scores = [json.loads(f.read_text()) for f in recs]
        vals = [-math.inf if r['failed'] or r['chamfer'] is None else -float(r['chamfer']) for r in scores]
        out[folder.name] = {'reward': vals, 'ms_per_plan': 1000 * float(np.mean([r['seconds'] for r in scores])),
                            'failed': int(sum(r['failed'] for r in scores))}
        by_setting.setdefault(folder.name.split('-draws')[0], []).append(out[folder.name])
    for setting, sets in by_setting.items():
        if len(sets) > 1:
            vals = np.mean([r['reward'] for r in sets], axis=0)  # -inf where any flight failed
            out[f'{setting}-mean{len(sets)}'] = {
                'reward': vals.tolist(), 'ms_per_plan': float(sum(r['ms_per_plan'] for r in sets)),
                'failed': int(np.sum(~np.isfinite(vals)))}
    return out


def run_plans(args, client) -> dict:
    """Each scenario's plan set (one task per scenario) -> {scenario: plans}."""
    tasks = [Task(s, plans_of, (s, args.models), plans_path(s, args.models), s) for s in args.scenarios]
    study = run_tasks(client, tasks, 'plan sets')
    for s, plans in study.items():
        if isinstance(plans, dict):  # a failed task: its named error
            raise SystemExit(f'{s}: the plan set failed: {plans["error"]}: {plans["error_msg"]}')
        # the task's cached file is the whole plan set: its repeats are not reconstructed twice
        study[s], dropped = distinct_plans(plans)
        print(f'{s}: {len(study[s])} distinct feasible plans ({len(dropped)} repeats left out: '
              f'{", ".join(f"{a} = {b}" for a, b in dropped.items()) or "none"})')
    return study


def run_recon(args, client, study: dict) -> dict:
    """Reconstruct the chosen plans in the chosen realizations on the cluster (cached)."""
    ks = [int(x) for x in args.realizations.split(',')]
    tasks = []
    for s in args.scenarios:
        plans = study[s]
        if args.ids:
            by_id = {p['id']: p for p in plans}
            plans = [by_id[i] for i in args.ids if i in by_id]
        plans = plans[:: max(1, args.stride)]
        if args.limit:
            plans = plans[: args.limit]
        tasks += [Task((s, p['id'], k), recon_cell, (s, args.models, p, k, args),
                       recon_path(s, args.models, p, k, args), f'{s} {p["id"]} k{k}') for p in plans for k in ks]
    return run_tasks(client, tasks, f'reconstructing ({variant_name(args)})')


def load_study(scenario: str, models: str, variant: str) -> list[dict]:
    """Every plan of the plan set with its reconstructions (realizations found in the cache) of one
    variant; a plan without any record has ``recon == {}`` and is counted as skipped, never dropped."""
    folder = CACHE / models_tag(models) / scenario / variant
    out = []
    for p in plans_of(scenario, models):
        recs = {}
        for f in sorted(folder.glob(f'{p["id"]}-k*.json')):
            recs[int(f.stem.rsplit('-k', 1)[1])] = json.loads(f.read_text())
        out.append({**p, 'recon': recs})
    return out


def load_records(report: dict, scenario: str, models: str, variant: str) -> list[dict]:
    """As :func:`load_study`, from the per-plan records a report keeps of its dense variant
    (``plan_record``: every score of every realization x 100, or the failure and its reason) rather
    than from the cache: every plan of the plan set, ``recon == {}`` when the report has no record of
    it (skipped, counted). The ranks and the split read the same; Chamfer is in centimetres."""
    by_id = {r['id']: r for r in report['variants'].get(f'{variant}/dense', {}).get('per_plan', {}).get(scenario, [])}
    return [{**p, 'recon': by_id[p['id']]['realizations'] if p['id'] in by_id else {}, 'record': by_id.get(p['id'])}
            for p in plans_of(scenario, models)]


def split_halves(plans: list[dict], seed: int = SPLIT_SEED) -> dict[str, str]:
    """plan id -> 'design' | 'check': within each family the ids are shuffled (seeded) and the
    first floor(n / 2) design, the rest check (a family of one plan is checked only), so both
    halves hold every kind of plan. Tune reward models on the design half only."""
    rng = np.random.default_rng(seed)
    by_family: dict[str, list[str]] = {}
    for p in plans:
        by_family.setdefault(p['family'], []).append(p['id'])
    half = {}
    for family in sorted(by_family):
        ids = sorted(by_family[family])
        order = rng.permutation(len(ids))
        for rank, i in enumerate(order):
            half[ids[i]] = 'design' if rank < len(ids) // 2 else 'check'
    return half


def study_counts(plans: list[dict], chamfer: np.ndarray) -> dict:
    """planned / reconstructed / failed / skipped of one scenario (skipped: no record at all)."""
    recorded = np.array([bool(p['recon']) for p in plans], dtype=bool)
    ok = np.isfinite(chamfer) & recorded
    return {'planned': len(plans), 'reconstructed': int(ok.sum()), 'failed': int((recorded & ~ok).sum()),
            'skipped': int((~recorded).sum())}


def spearman_halves(ids: list[str], rewards: dict, chamfer: np.ndarray, half: dict[str, str]) -> dict:
    """{'design': {model: rho}, 'check': {model: rho}} over the recorded plans of each half; a
    failed reconstruction ranks last (Chamfer inf), a skipped plan is left out (and counted)."""
    out = {}
    for name in ('design', 'check'):
        sel = np.array([half.get(i) == name for i in ids], dtype=bool) & ~np.isnan(chamfer)
        out[name] = {m: spearman(np.asarray(r)[sel], -chamfer[sel]) for m, r in rewards.items()}
    return out


def auc_halves(ids: list[str], rewards: dict, chamfer: np.ndarray, half: dict[str, str]) -> dict:
    """{'design': {model: AUC}, 'check': {model: AUC}}: how well each reward separates the plans
    that failed (Chamfer inf) from those that reconstructed (:func:`roc_auc`), over the recorded
    plans of each half (issue 42's bar: 0.9 on the check half)."""
    out = {}
    for name in ('design', 'check'):
        sel = np.array([half.get(i) == name for i in ids], dtype=bool) & ~np.isnan(chamfer)
        out[name] = {m: roc_auc(np.asarray(r)[sel], np.isinf(chamfer[sel])) for m, r in rewards.items()}
    return out


def roc_auc(reward, failed) -> float:
    """ROC AUC of ``reward`` as a score of reconstructing: the probability that a plan that
    reconstructed has a higher reward than one that failed, ties counted half, i.e. Mann-Whitney's
    U / (n_reconstructed n_failed) (scipy); NaN when either group is empty."""
    from scipy.stats import mannwhitneyu

    r, f = np.asarray(reward, dtype=float), np.asarray(failed, dtype=bool)
    if f.all() or not f.any():
        return float('nan')
    return float(mannwhitneyu(r[~f], r[f]).statistic / ((~f).sum() * f.sum()))


def realization_chamfer(record: dict, key: str = 'chamfer') -> float:
    """``key`` of one realization's record; inf when it failed (an error or no value)."""
    v = record.get(key)
    return math.inf if record.get('error') or v is None else float(v)


def plan_chamfer(plan: dict, key: str = 'chamfer') -> float:
    """Mean Chamfer (metres) over the reconstructed realizations; inf when any failed; NaN when
    the plan has no record (skipped)."""
    if not plan['recon']:
        return math.nan
    return float(np.mean([realization_chamfer(r, key) for r in plan['recon'].values()]))


def realization_agreement(plans: list[dict], key: str = 'chamfer') -> dict | None:
    """Test-retest reliability of the score itself: Spearman's rho between the plans' Chamfer in
    two wind realizations (the first two that every plan has; a failed one ranks last). How well
    one realization ranks the plans of another bounds how well any reward model can; this is the
    noise ceiling of the study's rho. ``ceiling_mean``: the Spearman-Brown estimate
    sqrt(2 r / (1 + r)) of the highest rho a perfect predictor reaches against the mean of the
    two (a Pearson-model approximation for ranks; NaN for r <= 0). None unless every plan has two
    realizations (a partial second realization would rank a subset)."""
    common = sorted(set.intersection(*[set(p['recon']) for p in plans]) if plans else set())
    if len(common) < 2:
        return None
    a, b = common[:2]
    x = np.array([realization_chamfer(p['recon'][a], key) for p in plans])
    y = np.array([realization_chamfer(p['recon'][b], key) for p in plans])
    rho = spearman(-x, -y)
    ceiling = math.sqrt(2 * rho / (1 + rho)) if rho > 0 else float('nan')
    return {'realizations': [a, b], 'n': len(plans), 'rho_between': rho, 'ceiling_mean': ceiling,
            'failed_in_one_only': int((np.isinf(x) != np.isinf(y)).sum())}


def score_models(scenario: str, models: str, plans: list[dict], model_specs: dict) -> dict:
    """Reward of every plan under every model: {model: [reward per plan]} (eq. 7 averaging)."""
    from vp_planner.reward_models import make_reward

    noisy, _ = scene(scenario, models)
    cams = np.array([p['cameras'] for p in plans])
    out = {}
    for name, spec in model_specs.items():
        fn = make_reward(spec, noisy.points)
        t0 = time.perf_counter()
        vals = np.concatenate([np.asarray(fn(cams[i:i + 16])).reshape(-1) for i in range(0, len(cams), 16)])
        out[name] = {'reward': vals.tolist(), 'ms_per_plan': 1000 * (time.perf_counter() - t0) / max(1, len(cams))}
    return out


def study_models() -> dict:
    """The reward models and ingredient ablations the study compares: name -> spec."""
    from bench.reward_ablations import ablations
    from vp_planner.reward_models import REWARD_MODELS

    specs = {name: name for name in REWARD_MODELS}
    specs.update(ablations())
    return specs


def analyze(args) -> dict:
    source = json.loads(Path(args.records).read_text()) if args.records else None
    if source is not None:  # the rewards of today against a committed study's reconstructions
        found = sorted({k.rsplit('/', 1)[0] for k, v in source.get('variants', {}).items() if v.get('per_plan')})
        if not found:
            raise SystemExit(f'{args.records}: no per-plan records to score')
        variants = args.variants or found
    else:
        variants = args.variants or sorted({d.name for s in args.scenarios
                                            for d in (CACHE / models_tag(args.models) / s).glob('*') if d.is_dir()})
    specs = study_models()
    from vp_planner.reward_models import DEFAULT_REWARD_MODEL

    result: dict = {'default': DEFAULT_REWARD_MODEL, 'date': time.strftime('%Y-%m-%d'), 'machine': machine(),
                    'models_folder': models_tag(args.models), 'plans': {}, 'spearman': {},
                    'spearman_reconstructed': {}, 'variants': {}, 'ms_per_plan': {}, 'failed': {}}
    if source is not None:
        result['records'] = {'file': str(args.records), 'commit': source.get('commit'), 'date': source.get('date')}
    per_plan: dict = {}
    scored: dict = {}
    for variant in variants:
        for cloud, key in CLOUDS.items():
            vname = f'{variant}/{cloud}'
            vres: dict = {'plans': {}, 'spearman': {}, 'spearman_reconstructed': {}, 'failed': {}}
            for s in args.scenarios:
                every = (load_records(source, s, args.models, variant) if source is not None
                         else load_study(s, args.models, variant))
                if cloud == 'shape':  # records from before chamfer_shape was kept do not count
                    if not any(key in r for p in every for r in p['recon'].values()):
                        continue  # no record of this scenario has it: no shape study (not 'all failed')
                    every = [{**p, 'recon': {k: r for k, r in p['recon'].items() if key in r or r.get('error')}}
                             for p in every]
                half = split_halves(every, args.split_seed)
                plans = [p for p in every if p['recon']]  # the skipped ones are counted, below
                if not plans:
                    continue
                plan_set = (s, tuple(p['id'] for p in plans))  # a variant's clouds share the plans: score once
                if plan_set not in scored:
                    scored[plan_set] = {**score_models(s, args.models, plans, specs),
                                        **flight_predictors(s, args.models, plans)}
                rewards = scored[plan_set]
                ch = np.array([plan_chamfer(p, key) for p in plans])
                ok = np.isfinite(ch)
                vres['plans'][s] = len(plans)
                vres['failed'][s] = int((~ok).sum())
                vres.setdefault('counts', {})[s] = study_counts(every, np.array([plan_chamfer(p, key) for p in every]))
                halves = spearman_halves([p['id'] for p in plans], {m: r['reward'] for m, r in rewards.items()},
                                         ch, half)
                vres.setdefault('spearman_design', {})[s] = halves['design']
                vres.setdefault('spearman_check', {})[s] = halves['check']
                aucs = auc_halves([p['id'] for p in plans], {m: r['reward'] for m, r in rewards.items()}, ch, half)
                vres.setdefault('auc_design', {})[s] = aucs['design']
                vres.setdefault('auc_check', {})[s] = aucs['check']
                vres.setdefault('split', {})[s] = half
                vres['spearman'][s] = {m: spearman(r['reward'], -ch) for m, r in rewards.items()}
                vres.setdefault('reliability', {})[s] = realization_agreement(plans, key)
                vres.setdefault('realizations', {})[s] = sorted({k for p in plans for k in p['recon']})
                vres['spearman_reconstructed'][s] = {m: spearman(np.asarray(r['reward'])[ok], -ch[ok])
                                                     for m, r in rewards.items()}
                result['ms_per_plan'][s] = {m: r['ms_per_plan'] for m, r in rewards.items()}
                per_plan[(vname, s)] = (plans, ch, rewards)
                if cloud == 'dense' and source is not None:  # the committed record, today's rewards
                    vres.setdefault('per_plan', {})[s] = [
                        {**p['record'], 'reward': {m: round(float(r['reward'][i]), 5) for m, r in rewards.items()}}
                        for i, p in enumerate(plans)]
                    vres.setdefault('recon_hours', {})[s] = (
                        source['variants'][f'{variant}/dense'].get('recon_hours', {}).get(s))
                elif cloud == 'dense':
                    vres.setdefault('per_plan', {})[s] = [plan_record(p, {m: r['reward'][i] for m, r in rewards.items()},
                                                                      s, args.models)
                                                          for i, p in enumerate(plans)]
                    vres.setdefault('recon_hours', {})[s] = sum(
                        r.get('seconds', {}).get('total', 0.0) if isinstance(r.get('seconds'), dict) else r.get('seconds', 0.0)
                        for p in plans for r in p['recon'].values()) / 3600.0
            result['variants'][vname] = vres
    main_v = f'{variant_name(args)}/dense'
    if main_v in result['variants']:
        mv = result['variants'][main_v]
        result['plans'], result['spearman'] = mv['plans'], mv['spearman']
        result['spearman_reconstructed'], result['failed'] = mv['spearman_reconstructed'], mv['failed']
        for key in ('counts', 'spearman_design', 'spearman_check', 'auc_design', 'auc_check', 'split', 'reliability',
                    'realizations'):
            result[key] = mv.get(key, {})
        result['split_seed'] = args.split_seed
    out = Path(args.out)
    publish(out, 'plan_quality', result, markdown(result))
    plot(out / 'plan_quality.png', per_plan, main_v, specs)
    return result


def plan_record(plan: dict, rewards: dict, scenario: str, models: str) -> dict:
    """What explains one plan's reconstruction: geometry, scores and the pipeline's internals."""
    noisy, _ = scene(scenario, models)
    rec = {'id': plan['id'], 'family': plan['family'], 'params': plan['params'],
           'reward': {m: round(float(v), 5) for m, v in rewards.items()},
           **describe_cameras(np.asarray(plan['cameras']), noisy.points.reshape(-1, 3).mean(axis=0)),
           'realizations': {}}
    for k, r in sorted(plan['recon'].items()):
        if r.get('error'):  # the failure and its reason (a record without one says so)
            rec['realizations'][k] = {'error': r['error'], 'error_msg': r.get('error_msg') or 'no reason recorded'}
            continue
        rec['realizations'][k] = {
            key: (round(100 * r[key], 4) if r.get(key) is not None else None)
            for key in ('chamfer', 'chamfer_shape', 'accuracy', 'completeness', 'sparse_chamfer', 'sparse_accuracy',
                        'sparse_completeness')}
        rec['realizations'][k].update({'dense_points': r['points'], 'sparse_points': r['sparse_points'],
                                       'pair_inliers': r['pair_inliers'], 'dense_pairs': r['dense_pairs']})
    return rec


def plot(path: Path, per_plan: dict, variant: str, specs: dict) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    cells = [(s, v) for (v, s) in per_plan if v == variant]
    if not cells:
        return
    names = list(specs)
    fig, axes = plt.subplots(len(cells), len(names), figsize=(3.2 * len(names), 3.0 * len(cells)), squeeze=False)
    for row, (s, v) in enumerate(cells):
        plans, ch, rewards = per_plan[(v, s)]
        fam = [p['family'] for p in plans]
        fams = sorted(set(fam))
        cmap = plt.get_cmap('tab10')
        cap = np.nanmax(np.where(np.isfinite(ch), ch, np.nan)) * 1.15 if np.isfinite(ch).any() else 1.0
        y = np.where(np.isfinite(ch), ch, cap) * 100
        for col, m in enumerate(names):
            ax = axes[row][col]
            r = np.asarray(rewards[m]['reward'])
            for i, f in enumerate(fams):
                sel = np.array([x == f for x in fam])
                ax.scatter(r[sel], y[sel], s=12, color=cmap(i % 10), label=f)
            ok = np.isfinite(ch)
            ax.set_title(f'{s}: {m}\nrho {spearman(r, -ch):.2f} (reconstructed {spearman(r[ok], -ch[ok]):.2f})',
                         fontsize=8)
            ax.set_xlabel('reward', fontsize=7)
            ax.set_ylabel('Chamfer x100 (top row: failed)', fontsize=7)
            ax.tick_params(labelsize=6)
            if row == 0 and col == 0:
                ax.legend(fontsize=5)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def check_from_records(args) -> dict:
    """The split and the check half's Spearman from the per-plan records of an existing
    ``plan_quality.json`` (its main variant): for a study whose reconstruction cache is gone."""
    path = Path(args.out) / 'plan_quality.json'
    result = json.loads(path.read_text())
    main_v = f'{variant_name(args)}/dense'
    if main_v not in result.get('variants', {}):
        raise SystemExit(f'{path}: no variant {main_v} to split')
    records = result['variants'][main_v]['per_plan']
    result.update(counts={}, spearman_design={}, spearman_check={}, auc_design={}, auc_check={}, split={},
                  split_seed=args.split_seed)
    for s in args.scenarios:
        every = plans_of(s, args.models)
        by_id = {r['id']: r for r in records.get(s, [])}
        half = split_halves(every, args.split_seed)
        # a per-plan record's realizations, as plan_chamfer reads a plan's cached records (x 100 here)
        every = [{**p, 'recon': by_id[p['id']]['realizations'] if p['id'] in by_id else {}} for p in every]
        ch_all = np.array([plan_chamfer(p) for p in every])
        result['counts'][s] = study_counts(every, ch_all)
        has = np.array([bool(p['recon']) for p in every], dtype=bool)
        recorded, ch = [by_id[p['id']] for p in every if p['recon']], ch_all[has]
        rewards = {m: [r['reward'][m] for r in recorded] for m in recorded[0]['reward']} if recorded else {}
        halves = spearman_halves([r['id'] for r in recorded], rewards, ch, half)
        result['spearman_design'][s], result['spearman_check'][s] = halves['design'], halves['check']
        aucs = auc_halves([r['id'] for r in recorded], rewards, ch, half)
        result['auc_design'][s], result['auc_check'][s] = aucs['design'], aucs['check']
        result['split'][s] = half
    publish(path.parent, 'plan_quality', result, markdown(result))
    return result


def markdown(data: dict) -> str:
    """The study's report (of a result as :func:`analyze` returns it, or as its JSON holds it):
    per variant Spearman's rho of each reward model against -Chamfer (check and design halves, the
    failures' AUC), the noise ceiling, the failed plans by family."""
    variants = data['variants']
    lines = ['# Plan-quality study', '']
    counts = data.get('counts') or {}
    if data.get('records'):  # rewards scored again against a committed study's reconstructions
        r = data['records']
        lines += [f'The reconstructions are the per-plan records of `{r["file"]}` (measured {r.get("date")} at '
                  f'`{r.get("commit")}`, not run again); the rewards are scored at this report\'s commit.', '']
    if counts:
        lines += ['Plans: ' + '; '.join(f'{s} {c["planned"]} planned, {c["reconstructed"]} reconstructed, '
                                        f'{c["failed"]} failed, {c["skipped"]} skipped' for s, c in counts.items())
                  + f' (a failed plan ranks last; split seed {data.get("split_seed")}).', '']
    for vname, v in variants.items():
        check, design = v.get('spearman_check'), v.get('spearman_design')
        if check:
            models = list(next(iter(check.values())))
            head = ['model'] + [f'{s} check (design)' for s in check]
            body = [[m] + [f'{num(check[s].get(m))} ({num(design[s].get(m))})' for s in check] for m in models]
            caption = f'Spearman rho of reward against -Chamfer, `{vname}`, check half (design half)'
            auc, auc_d = v.get('auc_check'), v.get('auc_design')
            if auc:  # the failures' separation (ROC AUC), beside each scenario's rho
                head += [f'{s} failed: AUC check (design)' for s in auc]
                body = [row + [f'{num(auc[s].get(m))} ({num(auc_d[s].get(m))})' for s in auc]
                        for row, m in zip(body, models)]
                caption += ('; AUC: how well the reward tells the plans that failed from those that reconstructed '
                            '(ROC AUC, 1 perfect, 0.5 chance; - where no plan of the half failed)')
            lines += [caption + ':', '']
        else:
            sp = v.get('spearman') or {}
            models = list(next(iter(sp.values()))) if sp else []
            spr = v.get('spearman_reconstructed') or {}
            head = ['model'] + [f'{s} all (reconstructed)' for s in sp]
            body = [[m] + [f'{num(sp[s].get(m))} ({num(spr.get(s, {}).get(m))})' for s in sp] for m in models]
            lines += [f'Spearman rho of reward against -Chamfer, `{vname}`, all plans (plans that reconstructed):', '']
        lines += table(head, body) + ['']
    main = next(iter(variants), None)
    if data.get('spearman_check') and main and not variants[main].get('spearman_check'):
        check, design = data['spearman_check'], data['spearman_design']
        models = list(next(iter(check.values())))
        lines += [f'Spearman rho on the design/check split (from the per-plan records, `{main}`), check half '
                  '(design half):', '']
        lines += table(['model'] + [f'{s} check (design)' for s in check],
                       [[m] + [f'{num(check[s].get(m))} ({num(design[s].get(m))})' for s in check]
                        for m in models]) + ['']
    rel_ = data.get('reliability') or {}
    for s, r in rel_.items():
        if r:
            lines.append(f'Realizations {r["realizations"][0]} and {r["realizations"][1]} rank the {r["n"]} plans of '
                         f'{s} alike with rho {num(r["rho_between"])} ({r["failed_in_one_only"]} fail in one only); '
                         f'a perfect model would reach about {num(r["ceiling_mean"])} against their mean '
                         '(Spearman-Brown).')
    dense = next((v for k, v in variants.items() if k.endswith('/dense') and v.get('per_plan')), None)
    if dense:
        fams: dict = {}
        for s, plans in dense['per_plan'].items():
            for p in plans:
                failed = not math.isfinite(plan_chamfer({'recon': p['realizations']}))
                f = fams.setdefault(p['family'], {}).setdefault(s, [0, 0, []])
                f[0] += 1
                f[1] += failed
                if failed:
                    f[2].append(float(np.median(p.get('elevation_deg') or [math.nan])))
        lines += ['', 'Plans that failed, by family (failed in any realization reconstructed; in brackets the '
                  'median camera elevation of each failed plan, degrees):', '']
        lines += table(['family'] + list(dense['per_plan']),
                       [[fam] + [f'{v[1]} of {v[0]}' + (' (' + ', '.join(f'{e:.0f}' for e in sorted(v[2])) + ')'
                                                          if v[2] else '') if (v := by.get(s)) else '-'
                                 for s in dense['per_plan']] for fam, by in fams.items()])
    return '\n'.join(lines) + '\n'


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.phase in ('plans', 'all', 'recon', 'flights'):
        with cluster_client(args) as client:
            study = run_plans(args, client)
            if args.phase in ('recon', 'all'):
                run_recon(args, client, study)
            if args.phase == 'flights':
                run_flights(args, client, study)
    if args.phase in ('analyze', 'all'):
        analyze(args)
    if args.phase == 'check':
        check_from_records(args)
    return 0


if __name__ == '__main__':
    sys.exit(main())
