"""The benchmarks' scenes and plans: the scenarios, the planner variants, cached planning runs and
the reconstruction records of a plan (one wind realization at a time, failures recorded)."""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import numpy as np

from bench import cpu_capability
from bench.cache import cached
from vp_planner.methods import BY_NAME

ROOT = Path(__file__).resolve().parent.parent
#: The paper's scenarios and their camera counts (Sec. V).
SCENARIOS = {'one_plant': 4, 'three_row': 6, 'six_rect': 6}
CORN50 = ROOT.parent / 'shared' / 'data' / 'corn50'


def default_models() -> str:
    """``../shared/data/corn50`` when present (the paper's kind of plants), else '' (procedural)."""
    return str(CORN50) if CORN50.is_dir() else ''


_SCENES: dict = {}


def scene(scenario: str, models: str = ''):
    """(NoisyScene, plant models) of a scenario, scene seed 0 (built once per process)."""
    from vp_scene.build import build_noisy_scene

    key = (scenario, models)
    if key not in _SCENES:
        _SCENES[key] = build_noisy_scene(scenario=scenario, models=models or None, seed=0)
    return _SCENES[key]


def models_tag(models: str) -> str:
    return Path(models).name if models else 'procedural'


@dataclass(frozen=True)
class Variant:
    """A planner variant of the benchmarks: its ``request`` fields (flat names of
    :data:`vp_planner.request.FLAT`: the method and its settings; a benchmark cell adds cameras,
    budget, seed and reward) and the ``benchmarks`` that run it by default."""

    request: dict
    benchmarks: tuple[str, ...] = ()

    @property
    def baseline(self) -> bool:
        """A baseline of the paired differences against egp: what a drone operator flies anyway and
        the paper's SA (every method that is not Bayesian optimization, from the registry)."""
        return not BY_NAME[self.request['method']].bayesian


#: The planner variants of the benchmarks, the one table they all read: name (the reports' label
#: and part of every cache name) -> :class:`Variant`. Benchmarks: ``planners`` (bench_planners),
#: ``fields`` (bench_fields), ``sorties`` (bench_sorties: egp's cases, the baselines' c-cases),
#: ``cheap`` (bench_cheap_stage: egp's wall time given to the others); table1's rows name a variant
#: and a reward model each.
VARIANTS = {
    'egp': Variant({'method': 'egp'}, ('planners', 'fields', 'sorties', 'cheap')),  # the default planner
    'egp-random-init': Variant({'method': 'egp', 'structured_init': 0}, ('planners',)),  # the paper's random design
    'egp-paper-config': Variant({'method': 'egp', 'structured_init': 0, 'bo_mode': 'global', 'sim_flights': 0}),  # the paper's BO
    'egp-cheap': Variant({'method': 'egp', 'sim_flights': 0}),                  # egp without its simulated flights
    'egp-one-space': Variant({'method': 'egp', 'parts': 1}, ('fields',)),       # a field in one 6N-dim space
    # by parts under coverage-graph: the parts' chains weighed by the view graph (issue 42)
    'egp-graph': Variant({'method': 'egp', 'reward': 'coverage-graph'}, ('fields',)),
    'gp': Variant({'method': 'gp'}),
    'circle': Variant({'method': 'circle'}, ('planners', 'fields', 'sorties')),
    'arc': Variant({'method': 'arc'}, ('planners', 'fields', 'sorties')),
    'sa': Variant({'method': 'sa'}, ('planners', 'fields', 'cheap')),
    'random': Variant({'method': 'random'}, ('planners', 'cheap')),
    'cmaes': Variant({'method': 'cmaes'}, ('cheap',)),
    'lawnmower': Variant({'method': 'lawnmower'}, ('fields',)),                 # nadir, 70 % overlap
    'lawnmower-oblique': Variant({'method': 'lawnmower', 'lawnmower_tilt': math.radians(30.0)}, ('fields',)),
}


def variants_of(benchmark: str) -> tuple[str, ...]:
    """The variants ``benchmark`` runs by default, in the table's order."""
    return tuple(name for name, v in VARIANTS.items() if benchmark in v.benchmarks)


def baselines(names) -> tuple[str, ...]:
    """The baseline variants among ``names`` (:attr:`Variant.baseline`), in their order."""
    return tuple(name for name in names if VARIANTS[name].baseline)


def variant_request(variant: str, **cell: Any):
    """The :class:`vp_planner.request.PlanRequest` of ``variant`` in a benchmark cell (flat fields:
    num_cameras, evaluations, initial_evaluations, seed, reward, ...)."""
    from vp_planner.request import PlanRequest

    return PlanRequest.from_dict({**VARIANTS[variant].request, **cell})


def plan_path(cache: Path, scenario: str, variant: str, seed: int, evals: int = 100, init: int = 50,
              models: str = '', num_cameras: Optional[int] = None, reward: Optional[str] = None) -> Path:
    """The cache file of :func:`plan_cell` (same arguments)."""
    from vp_planner.reward_models import DEFAULT_REWARD_MODEL

    n = num_cameras or SCENARIOS[scenario]
    reward = reward or DEFAULT_REWARD_MODEL
    request = variant_request(variant, num_cameras=n, evaluations=evals, initial_evaluations=init, seed=seed,
                              reward=reward)
    return cache / 'plans' / (f'{models_tag(models)}-{scenario}-n{n}-{variant}-{reward}-seed{seed}-e{evals}-i{init}'
                              f'{flight_tag(request)}.json')


def flight_tag(request) -> str:
    """The part of a cached plan's name that says its simulated flights ('' for none)."""
    flights = request.flights.flights_of(request.method)
    return '' if not flights else '-f{}-{width}x{height}o{sift_first_octave}d{dense_scale:g}'.format(
        flights, **request.flights.settings().to_dict())


def plan_cell(cache: Path, scenario: str, variant: str, seed: int, evals: int = 100, init: int = 50,
              models: str = '', num_cameras: Optional[int] = None, reward: Optional[str] = None) -> dict:
    """One planning run (cached): cameras, reward, best-so-far trace, seconds, the initial
    design's best and the BO steps (egp/gp). ``variant`` is a key of :data:`VARIANTS`;
    ``reward`` a reward model (None: the planner's default)."""
    from vp_planner.optimizers import plan_views
    from vp_planner.reward_models import DEFAULT_REWARD_MODEL

    n = num_cameras or SCENARIOS[scenario]
    reward = reward or DEFAULT_REWARD_MODEL
    request = variant_request(variant, num_cameras=n, evaluations=evals, initial_evaluations=init, seed=seed,
                              reward=reward)
    path = plan_path(cache, scenario, variant, seed, evals, init, models, num_cameras, reward)

    def compute() -> dict:
        import torch

        torch.set_num_threads(1)  # as the planner node and CLI
        noisy, _ = scene(scenario, models)
        res = plan_views(request, noisy.points, simulator=flight_simulator(request, noisy))
        return {'cameras': np.asarray(res.cameras).tolist(), 'reward': float(res.reward), 'reward_model': reward,
                'trace': [float(x) for x in res.trace], 'seconds': float(res.seconds),
                'ensemble_weights': res.ensemble_weights, 'initial_best': res.initial_best, 'steps': res.steps,
                'cpu_capability': cpu_capability(), 'chosen_by': res.chosen_by, 'flight_score': res.flight_score,
                'flights_note': res.flights_note, 'flights': res.flights, 'flight_plans': res.flight_plans,
                'flight_settings': request.flights.settings().to_dict()}
    return cached(path, compute)


def flight_simulator(request, noisy):
    """The simulated flights of a benchmark's plan (None when the request makes none): the
    reconstruction's own (:class:`vp_recon.sim_flights.SceneFlights`, handed to the planner from
    here, above both packages) over the scene's plants, under the realistic capture with the
    request's reported-pose errors (:func:`vp_planner.cli.flight_capture`). A plan made on a
    benchmark's Dask worker flies on that cluster (``distributed.worker_client`` for each batch: the
    planning task leaves its worker's slot to the flights while it waits for them), as the planner's
    CLI flies on its own; elsewhere the flights run in this process, one after the other."""
    if not request.flights.flights_of(request.method) or request.candidates.poses is not None:
        return None
    from vp_planner.cli import flight_capture
    from vp_recon.sim_flights import SceneFlights

    try:
        from distributed import get_worker, worker_client

        get_worker()
        client = worker_client
    except (ImportError, ValueError):  # not on a Dask worker
        client = None
    return SceneFlights(noisy.scene, noisy.config, request.flights.settings(), flight_capture(request),
                        client=client, fov=request.cameras.fov)


def capture_of(args):
    """The CaptureModel of a benchmark's flags."""
    from vp_recon.cli import capture_from_args

    return capture_from_args(args)


def capture_tag(capture) -> str:
    """Cache-name suffix of a capture: '' for the ideal one (the records before the capture model
    were ideal and keep their names), '-realistic-anchored' (+ a digest of non-default figures)
    else: a flight over the textured ground, masks from its images alone, the model anchored on the
    reported poses and placed on the ground markers (issue 40). The records of earlier flights
    ('-realistic': blue screen; '-realistic-soil': incremental SfM, no markers) are not reused."""
    import hashlib

    from vp_scene.capture import REALISTIC

    if capture.ideal:
        return ''
    if capture == REALISTIC:
        return '-realistic-anchored'
    return '-realistic-anchored-' + hashlib.sha1(json.dumps(capture.to_dict(), sort_keys=True).encode()).hexdigest()[:8]


def chamfer_text(record: dict) -> str:
    """'mean +- std' of a reconstruction record, or 'failed (ERROR)': a failure is a result."""
    if record.get('error') or record.get('chamfer_mean') is None:
        return f"failed ({record.get('error', 'no result')})"
    failed = record.get('failed', 0)
    return (f"{record['chamfer_mean']:.3f} +- {record['chamfer_std']:.3f}"
            + (f" ({failed} of {len(record['per_realization'])} realizations failed)" if failed else ''))


def realization_entry(r) -> dict:
    """The ``per_realization`` entry of one reconstructed realization (x100 as Table I)."""
    from vp_recon.outputs import TABLE_SCALE

    return {'realization': int(r.realization), 'chamfer': TABLE_SCALE * r.chamfer,
            'chamfer_shape': TABLE_SCALE * r.chamfer_shape, 'accuracy': TABLE_SCALE * r.accuracy,
            'completeness': TABLE_SCALE * r.completeness, 'fscore': r.fscore, 'points': int(len(r.points)),
            'images': r.images, 'sparse_models': r.sparse_models, 'source': r.source, 'matching': r.matching,
            'matched_pairs': r.matched_pairs, 'centre_residual': float(r.centre_residual)
            if math.isfinite(r.centre_residual) else None, 'sparse_mode': r.sparse_mode,
            'sparse_fallback': r.sparse_fallback or None, 'control': r.control, 'seconds': r.seconds}


def reconstructed(per: list) -> list:
    """The entries of ``per_realization`` that reconstructed (a failed one has ``chamfer`` None)."""
    return [p for p in per if p.get('chamfer') is not None]


def reconstruct_record(noisy, cameras, config, folder: Path, realizations=None, known=None) -> dict:
    """Reconstruct a plan (``vp_recon.pipeline.reconstruct_plan``), one wind realization at a time,
    write its clouds and contact sheet into ``folder``, and return the benchmarks' JSON record
    (Chamfer etc. x100 as Table I).

    A realization that does not reconstruct is a result too: its ``per_realization`` entry holds
    its error and ``chamfer: null`` (counted, ranked last) and the other realizations keep theirs;
    ``chamfer_mean`` / ``chamfer_std`` (population) are over the reconstructed ones, ``failed``
    counts the rest, and the record carries ``error`` only when no realization reconstructed.
    ``known``: realization -> entry already computed (a cached record of the same plan with fewer
    realizations, :func:`known_realizations`): reused, not recomputed (a realization's capture is
    seeded by its index alone; COLMAP's run-to-run spread, about 0.5 % of the Chamfer, is all a
    recomputation would change).
    """
    from vp_recon.errors import ReconError
    from vp_recon.outputs import contact_sheet, write_image, write_ply
    from vp_recon.pipeline import reconstruct_plan

    capture = {'capture': config.capture.kind, 'capture_params': config.capture.to_dict(),
               'sparse_mode': config.sparse_mode_used}
    ks = list(range(len(noisy.points))) if realizations is None else [int(k) for k in realizations]
    known = known or {}
    per = []
    for k in ks:
        if k in known:
            per.append({**known[k], 'realization': k})
            continue
        try:
            (r,) = reconstruct_plan(noisy, np.asarray(cameras), config, folder, realizations=[k]).realizations
        except ReconError as exc:  # this realization failed: recorded, the others go on
            per.append({'realization': k, 'error': exc.name, 'error_msg': str(exc), 'chamfer': None,
                        'chamfer_shape': None, 'images': None})
            continue
        folder.mkdir(parents=True, exist_ok=True)
        write_ply(folder / f'recon_{k}.ply', r.points, r.colors)
        if r.rendered and not (folder / 'views.png').exists():
            write_image(folder / 'views.png', contact_sheet(r.rendered))
        per.append(realization_entry(r))
    ok = reconstructed(per)
    seconds = {}
    for p in ok:
        for stage, s in p['seconds'].items():
            seconds[stage] = seconds.get(stage, 0.0) + s
    record = {'failed': len(per) - len(ok), 'seconds': seconds, **capture, 'per_realization': per}
    if not ok:
        first = per[0] if per else {'error': 'NO_SCENE', 'error_msg': 'no realization selected'}
        return {'error': first['error'], 'error_msg': first['error_msg'], 'chamfer_mean': None,
                'chamfer_std': None, **record}
    ch = np.array([p['chamfer'] for p in ok])
    return {'chamfer_mean': float(ch.mean()), 'chamfer_std': float(ch.std()),
            'chamfer_shape_mean': float(np.mean([p['chamfer_shape'] for p in ok])), **record}


def split_realizations(stem: str) -> Optional[tuple[str, int, str]]:
    """(tag, n, rest) of a cache name ``<tag>-k<n><rest>`` (rest: empty or ``-<capture tag>``),
    None when the name has no realization count."""
    import re

    m = re.fullmatch(r'(.*)-k(\d+)((?:-\D.*)?)', stem)
    return (m.group(1), int(m.group(2)), m.group(3)) if m else None


def known_realizations(cache_file: Path, folder: Path, clouds: bool = True) -> dict:
    """realization -> ``per_realization`` entry of the cached records of the same cell with fewer
    realizations (``<tag>-k<j><rest>.json`` beside ``cache_file`` = ``<tag>-k<n><rest>.json``, j < n), their
    clouds copied into ``folder``: what a rerun with more realizations need not recompute.

    ``clouds``: an entry whose cloud is gone is recomputed (Table I's clouds feed coverage_check and
    the second sortie); False for a benchmark that reads the numbers alone (the fields benchmark,
    resumed on a fresh clone from its committed report, which holds no clouds)."""
    import shutil

    split = split_realizations(cache_file.stem)
    if split is None:
        return {}
    base, n, rest = split
    known = {}
    for j in range(n - 1, 0, -1):
        old = cache_file.with_name(f'{base}-k{j}{rest}.json')
        if not old.exists():
            continue
        for i, p in enumerate(json.loads(old.read_text()).get('per_realization', [])):
            k = int(p.get('realization', i))  # records before per-realization failures: in order 0..j-1
            if k in known:
                continue
            cloud = folder.parent / f'{base}-k{j}{rest}' / f'recon_{k}.ply'
            if clouds and p.get('chamfer') is not None and not cloud.exists():
                continue  # its cloud is gone: recompute rather than leave a hole in the folder
            if cloud.exists():
                folder.mkdir(parents=True, exist_ok=True)
                for f in (cloud, cloud.with_name('views.png')):
                    if f.exists() and not (folder / f.name).exists():
                        shutil.copyfile(f, folder / f.name)
            known[k] = p
    return known
