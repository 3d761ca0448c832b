#!/usr/bin/env python3
"""What a drone's RTK and gimbal buy: Chamfer (map and shape) against the reported-pose errors.

Issue 40, direction 5. A flight's model is placed in ``map`` on the poses the drones report (and,
when the field has them, on ground markers). This benchmark flies Table I's seed-0 plans (the
cameras recorded in ``results/table1.json``: the same plans as the table) under the realistic
capture with the reported position sigma at 0.01 / 0.02 / 0.05 m (attitude 0.5 degree) and the
reported attitude sigma at 0.2 / 0.5 / 1 degree (position 0.02 m), each with the realistic
capture's 4 ground markers and without any (``gcp_markers`` 0: the reports alone), and
reconstructs every wind realization: map Chamfer (registration included), shape Chamfer (after a
rigid ICP: the shape alone) and their difference, x100 as Table I. Every (plan, setting,
realization) is one task on the Dask cluster (``bench/cluster.py``), cached under
``<out>/cache/pose_errors``; a failed realization is counted, never dropped.

    python -m bench.bench_pose_errors [--scenarios one_plant] [--methods egp arc] [--realizations 5]
        [--workers 2 --threads 1] [--out results]
"""
from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

if not __package__:  # python bench/bench_pose_errors.py: as python -m bench.bench_pose_errors (bench/_script.py)
    import _script  # noqa: F401
from bench.cluster import Task, add_cluster_args, cluster_client, run_tasks  # noqa: E402
from bench.common import ROOT, cached, default_models, machine, models_tag, reconstruct_record, scene, \
    write_report  # noqa: E402
from bench.stats import summary  # noqa: E402

#: (reported position sigma m, reported attitude sigma deg): position swept at 0.5 deg, attitude at 0.02 m.
SETTINGS = ((0.01, 0.5), (0.02, 0.5), (0.05, 0.5), (0.02, 0.2), (0.02, 1.0))
#: ground markers: the realistic capture's 4, or none (the reports alone).
MARKERS = (4, 0)
TABLE = ROOT / 'results' / 'table1.json'


def parse_args(argv=None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--scenarios', nargs='+', default=['one_plant'])
    ap.add_argument('--methods', nargs='+', default=['egp', 'arc'], help="Table I rows whose seed-0 plan is flown")
    ap.add_argument('--models', default=default_models())
    ap.add_argument('--realizations', type=int, default=5)
    ap.add_argument('--threads', type=int, default=1)
    ap.add_argument('--out', default=str(ROOT / 'results'))
    add_cluster_args(ap)
    return ap.parse_args(argv)


def capture_of(position: float, attitude: float, markers: int):
    from vp_scene.capture import REALISTIC

    return replace(REALISTIC, report_position_sigma=position, report_attitude_sigma=attitude,
                   gcp_markers=markers).validate()


def tag(scenario: str, method: str, position: float, attitude: float, markers: int, k: int, args) -> str:
    return f'{models_tag(args.models)}-{scenario}-{method}-p{position:g}-a{attitude:g}-gcp{markers}-k{k}'


def recon_cell(cache: Path, out: Path, scenario: str, method: str, cameras: list, position: float,
               attitude: float, markers: int, k: int, args) -> dict:
    """Realization ``k`` of the plan flown with these reported-pose errors and markers (cached)."""
    from vp_recon.config import ReconConfig

    name = tag(scenario, method, position, attitude, markers, k, args)

    def compute() -> dict:
        noisy, _ = scene(scenario, args.models)
        cfg = ReconConfig(num_threads=args.threads, keep_images=False, capture=capture_of(position, attitude, markers))
        return reconstruct_record(noisy, cameras, cfg, out / 'recon' / 'pose_errors' / name, [k])
    return cached(cache / 'pose_errors' / f'{name}.json', compute)


def tasks(cache: Path, out: Path, args) -> list[Task]:
    table = json.loads(TABLE.read_text())['cells']
    out_tasks = []
    for s in args.scenarios:
        for m in args.methods:
            cameras = table[f'{s}/{m}']['cameras']
            for markers in MARKERS:
                for position, attitude in SETTINGS:
                    for k in range(args.realizations):
                        key = (s, m, markers, position, attitude, k)
                        out_tasks.append(Task(key, recon_cell, (cache, out, s, m, cameras, position, attitude, markers,
                                                                k, args),
                                              cache / 'pose_errors' / f'{tag(s, m, position, attitude, markers, k, args)}.json',
                                              f'{s} {m} p{position:g} a{attitude:g} gcp{markers} k{k}'))
    return out_tasks


def cells_of(records: dict, args) -> dict:
    """``scenario/method/markers/position/attitude`` -> map, shape and map - shape summaries
    (mean, sample std (n-1), n, failed) over the realizations, with each failure's reason."""
    cells = {}
    for s in args.scenarios:
        for m in args.methods:
            for markers in MARKERS:
                for position, attitude in SETTINGS:
                    per = [(records[(s, m, markers, position, attitude, k)].get('per_realization') or [{}])[0]
                           for k in range(args.realizations)]
                    chamfer = {k: p.get('chamfer') for k, p in enumerate(per)}
                    shape = {k: p.get('chamfer_shape') for k, p in enumerate(per)}
                    gap = {k: (chamfer[k] - shape[k]) if chamfer[k] is not None and shape[k] is not None else None
                           for k in chamfer}
                    cells[f'{s}/{m}/{markers}/{position:g}/{attitude:g}'] = {
                        'scenario': s, 'method': m, 'gcp_markers': markers, 'report_position_sigma': position,
                        'report_attitude_sigma': attitude, 'map': summary(chamfer), 'shape': summary(shape),
                        'registration': summary(gap),
                        'failures': [p.get('error_msg') or p.get('error') for p in per if p.get('chamfer') is None]}
    return cells


def markdown(report: dict) -> str:
    lines = ['# Chamfer against the reported-pose errors', '',
             f"{report['machine']}; {report['date']}. Table I's seed-0 plans flown under the realistic capture with "
             'the reported-pose errors below, with the 4 ground markers and without; Chamfer x100, mean +- sample '
             f"std (n-1) over {report['realizations']} wind realizations (n: reconstructed; failures counted).", '',
             '| scenario | method | markers | position sigma m | attitude sigma deg | map | shape | map - shape |',
             '|---|---|---|---|---|---|---|---|']
    for c in report['cells'].values():
        def text(d: dict) -> str:
            failed = f", {d['failed']} failed" if d['failed'] else ''
            if not d['n']:
                return f"failed {d['failed']}"
            spread = f" +- {d['std']:.2f}" if d['n'] > 1 else ''
            return f"{d['mean']:.2f}{spread} (n={d['n']}{failed})"
        lines.append(f"| {c['scenario']} | {c['method']} | {c['gcp_markers']} | {c['report_position_sigma']:g} | "
                     f"{c['report_attitude_sigma']:g} | {text(c['map'])} | {text(c['shape'])} | "
                     f"{text(c['registration'])} |")
    return '\n'.join(lines) + '\n'


def main(argv=None) -> int:
    from datetime import datetime, timezone

    args = parse_args(argv)
    out = Path(args.out)
    cache = out / 'cache'
    with cluster_client(args) as client:
        records = run_tasks(client, tasks(cache, out, args), 'pose errors')
    report = {'machine': machine(), 'date': datetime.now(timezone.utc).strftime('%Y-%m-%d %H:%M UTC'),
              'models': models_tag(args.models), 'realizations': args.realizations, 'plans': str(TABLE.relative_to(ROOT)),
              'settings': [list(s) for s in SETTINGS], 'markers': list(MARKERS), 'cells': cells_of(records, args)}
    out.mkdir(parents=True, exist_ok=True)
    write_report(out / 'bench_pose_errors.json', report)
    (out / 'bench_pose_errors.md').write_text(markdown(report))
    print(markdown(report))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
