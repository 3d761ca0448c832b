"""Shared pieces of the benchmarks: scenarios, the resumable JSON cache, cached planning runs."""
from __future__ import annotations

import json
import os
import platform
import threading
from pathlib import Path
from typing import Any, Callable, Optional

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
#: The paper's scenarios and their camera counts (Sec. V).
SCENARIOS = {'one_plant': 4, 'three_row': 6, 'six_rect': 6}
CORN50 = ROOT.parent / 'shared' / 'data' / 'corn50'


def default_models() -> str:
    """``../shared/data/corn50`` when present (the paper's kind of plants), else '' (procedural)."""
    return str(CORN50) if CORN50.is_dir() else ''


def machine() -> str:
    return f'{platform.machine()}, {os.cpu_count()} CPU cores, Python {platform.python_version()}'


def cached(path: Path, compute: Callable[[], Any]) -> Any:
    """The JSON cached at ``path``, or compute, store (atomically) and return it."""
    if path.exists():
        try:
            return json.loads(path.read_text())
        except json.JSONDecodeError:
            path.unlink()  # a torn write from an interrupted run: recompute
    value = compute()
    write_json(path, value)
    return value


def write_json(path: Path, value: Any) -> None:
    """Write ``value`` to ``path`` atomically (a temporary file per writer, then ``os.replace``:
    several cluster workers and the client write the cache concurrently)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f'.{path.name}.{os.getpid()}.{threading.get_ident()}.tmp')
    tmp.write_text(json.dumps(value))
    os.replace(tmp, path)


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


#: Planner variants of the benchmarks: name -> PlanRequest fields (:mod:`vp_planner.request`).
VARIANTS = {
    'egp': {'method': 'egp'},                                           # the default planner
    'egp-random-init': {'method': 'egp', 'structured_init': 0},          # the paper's random design
    'egp-paper-config': {'method': 'egp', 'structured_init': 0, 'bo_mode': 'global'},  # the paper's BO
    'gp': {'method': 'gp'},
    'circle': {'method': 'circle'},
    'arc': {'method': 'arc'},
    'sa': {'method': 'sa'},
    'random': {'method': 'random'},
}


def plan_path(cache: Path, scenario: str, variant: str, seed: int, evals: int = 100, init: int = 50,
              models: str = '', num_cameras: Optional[int] = None, reward: Optional[str] = None) -> Path:
    """The cache file of :func:`plan_cell` (same arguments)."""
    from vp_planner.reward_models import DEFAULT_REWARD_MODEL

    n = num_cameras or SCENARIOS[scenario]
    reward = reward or DEFAULT_REWARD_MODEL
    return cache / 'plans' / f'{models_tag(models)}-{scenario}-n{n}-{variant}-{reward}-seed{seed}-e{evals}-i{init}.json'


def plan_cell(cache: Path, scenario: str, variant: str, seed: int, evals: int = 100, init: int = 50,
              models: str = '', num_cameras: Optional[int] = None, reward: Optional[str] = None) -> dict:
    """One planning run (cached): cameras, reward, best-so-far trace, seconds, the initial
    design's best and the BO steps (egp/gp). ``variant`` is a key of :data:`VARIANTS`;
    ``reward`` a reward model (None: the planner's default)."""
    from vp_planner.optimizers import PlanRequest, plan_views
    from vp_planner.reward_models import DEFAULT_REWARD_MODEL

    n = num_cameras or SCENARIOS[scenario]
    reward = reward or DEFAULT_REWARD_MODEL
    request = PlanRequest(**VARIANTS[variant], num_cameras=n, evaluations=evals, initial_evaluations=init, seed=seed,
                          reward=reward)
    path = plan_path(cache, scenario, variant, seed, evals, init, models, num_cameras, reward)

    def compute() -> dict:
        import torch

        torch.set_num_threads(1)  # as the planner node and CLI
        noisy, _ = scene(scenario, models)
        res = plan_views(request, noisy.points)
        return {'cameras': np.asarray(res.cameras).tolist(), 'reward': float(res.reward), 'reward_model': reward,
                'trace': [float(x) for x in res.trace], 'seconds': float(res.seconds),
                'ensemble_weights': res.ensemble_weights, 'initial_best': res.initial_best, 'steps': res.steps}
    return cached(path, compute)


def add_capture(ap) -> None:
    """The capture flags of the reconstruction CLI (default: realistic; README 'Capture model')."""
    from vp_recon.cli import add_capture_arguments

    add_capture_arguments(ap)


def capture_of(args):
    """The CaptureModel of a benchmark's flags."""
    from vp_recon.cli import capture_from_args

    return capture_from_args(args)


def capture_tag(capture) -> str:
    """Cache-name suffix of a capture: '' for the ideal one (the records before the capture model
    were ideal and keep their names), '-realistic-soil' (+ a digest of non-default figures) else:
    a flight is reconstructed over the textured ground with masks from its images alone (the
    records of the blue-screen flights before that were '-realistic' and are not reused)."""
    import hashlib

    from vp_scene.capture import REALISTIC

    if capture.ideal:
        return ''
    if capture == REALISTIC:
        return '-realistic-soil'
    return '-realistic-soil-' + hashlib.sha1(json.dumps(capture.to_dict(), sort_keys=True).encode()).hexdigest()[:8]


def chamfer_text(record: dict) -> str:
    """'mean +- std' of a reconstruction record, or 'failed (ERROR)': a failure is a result."""
    if record.get('error') or record.get('chamfer_mean') is None:
        return f"failed ({record.get('error', 'no result')})"
    return f"{record['chamfer_mean']:.3f} +- {record['chamfer_std']:.3f}"


def reconstruct_record(noisy, cameras, config, folder: Path, realizations=None) -> dict:
    """Reconstruct a plan (``vp_recon.pipeline.reconstruct_plan``), write its clouds and contact
    sheet into ``folder``, and return the benchmarks' JSON record (Chamfer etc. x100 as Table I;
    a plan that does not reconstruct is a result too: its error)."""
    from vp_recon.outputs import TABLE_SCALE, contact_sheet, write_image, write_ply
    from vp_recon.pipeline import ReconError, reconstruct_plan

    capture = {'capture': config.capture.kind, 'capture_params': config.capture.to_dict(),
               'sparse_mode': config.sparse_mode_used}
    try:
        res = reconstruct_plan(noisy, np.asarray(cameras), config, folder, realizations=realizations)
    except ReconError as exc:  # a failure: chamfer null, counted and ranked last by every benchmark
        return {'error': exc.name, 'error_msg': str(exc), 'chamfer_mean': None,
                'chamfer_std': None, 'per_realization': [], **capture}
    for r in res.realizations:
        write_ply(folder / f'recon_{r.realization}.ply', r.points, r.colors)
    if res.realizations and res.realizations[0].rendered:
        write_image(folder / 'views.png', contact_sheet(res.realizations[0].rendered))
    return {'chamfer_mean': TABLE_SCALE * res.chamfer_mean, 'chamfer_std': TABLE_SCALE * res.chamfer_std,
            'chamfer_shape_mean': TABLE_SCALE * res.chamfer_shape_mean, 'seconds': res.seconds, **capture,
            'per_realization': [{'chamfer': TABLE_SCALE * r.chamfer, 'chamfer_shape': TABLE_SCALE * r.chamfer_shape,
                                 'accuracy': TABLE_SCALE * r.accuracy,
                                 'completeness': TABLE_SCALE * r.completeness, 'fscore': r.fscore,
                                 'points': int(len(r.points)), 'images': r.images, 'source': r.source,
                                 'matching': r.matching, 'matched_pairs': r.matched_pairs,
                                 'seconds': r.seconds} for r in res.realizations]}
