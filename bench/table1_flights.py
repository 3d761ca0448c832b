#!/usr/bin/env python3
"""Table I's plans flown: the seed-0 plans of ``results/ideal/table1.json`` reconstructed under a capture.

Table I (``bench/table1.py``) was measured with the ideal capture (planned poses flown and known
exactly, noise-free renders). This benchmark takes exactly those plans (the cameras stored in
``results/ideal/table1.json``, the same scenes: the same models and scene seed 0) and reconstructs each
in the first ``--realizations`` wind realizations under ``--capture`` (default: realistic, README
"Capture model"), so that the two columns differ only by the capture. A plan that does not
reconstruct is a result: it is counted, shown as failed and ranked last, never dropped.

Writes ``results/table1_flights.json`` and ``.md`` (``--out``). Cached per cell under
``results/cache/table1_flights/`` (a rerun resumes).
"""
from __future__ import annotations

import argparse
import json
import sys
from datetime import datetime, timezone
from pathlib import Path

if not __package__:  # python bench/table1_flights.py: as python -m bench.table1_flights (bench/_script.py)
    import _script  # noqa: F401
from bench.common import (ROOT, add_capture, cached, capture_of, capture_tag, chamfer_text, machine,  # noqa: E402
                          models_tag, reconstruct_record, scene, write_report)


def parse_args(argv=None) -> argparse.Namespace:
    from vp_scene.camera import IMAGE_SIZE

    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--table', default=str(ROOT / 'results' / 'ideal' / 'table1.json'),
                    help='Table I results with the plans (default: the ideal-capture table)')
    ap.add_argument('--models', default=str(ROOT.parent / 'shared' / 'data' / 'corn50'),
                    help="the plants Table I used (its 'models' entry names them)")
    ap.add_argument('--scenarios', nargs='+', default=['one_plant', 'three_row'])
    ap.add_argument('--realizations', type=int, default=2)
    ap.add_argument('--width', type=int, default=IMAGE_SIZE[0])
    ap.add_argument('--height', type=int, default=IMAGE_SIZE[1])
    ap.add_argument('--threads', type=int, default=0)
    ap.add_argument('--out', default=str(ROOT / 'results'))
    add_capture(ap)
    return ap.parse_args(argv)


def main(argv=None) -> int:
    from vp_recon.config import ReconConfig

    args = parse_args(argv)
    table = json.loads(Path(args.table).read_text())
    if table.get('models') != models_tag(args.models):
        raise SystemExit(f"{args.table} was measured on plants {table.get('models')!r}, --models gives "
                         f"{models_tag(args.models)!r}")
    capture = capture_of(args)
    cfg = ReconConfig(width=args.width, height=args.height, num_threads=args.threads, capture=capture)
    cache = ROOT / 'results' / 'cache' / 'table1_flights'
    out = Path(args.out)
    rows = list(table['rows'])  # Table I's row labels, in its order
    cells: dict = {}
    for scenario in args.scenarios:
        noisy, _ = scene(scenario, args.models)
        for row in rows:
            key = f'{scenario}/{row}'
            if key not in table['cells']:
                continue
            plan = table['cells'][key]
            tag = (f"{models_tag(args.models)}-{scenario}-{row.replace(' ', '_')}-{args.width}x{args.height}"
                   f"-k{args.realizations}{capture_tag(capture)}")
            rec = cached(cache / f'{tag}.json', lambda: reconstruct_record(
                noisy, plan['cameras'], cfg, out / 'recon' / 'table1_flights' / tag, range(args.realizations)))
            ideal = plan['recon']
            cells[key] = {'flown': rec, 'ideal': ideal, 'reward': plan['reward'], 'cameras': plan['cameras']}
            print(f'{key}: {capture.kind} {chamfer_text(rec)} | ideal {chamfer_text(ideal)}', flush=True)
    stamp = datetime.now(timezone.utc).strftime('%Y-%m-%d')
    failed = sum(1 for c in cells.values() if c['flown'].get('chamfer_mean') is None)
    lines = [f'# Table I plans flown ({capture.kind} capture), measured {stamp} ({machine()})', '',
             f"Plans: the seed-0 plans of {Path(args.table).name} ({table.get('models')}). Chamfer x100, mean +- "
             f"population std over wind realizations 0..{args.realizations - 1}, {args.width} x {args.height}; "
             f"shape: after a rigid ICP refinement. Failed plans: {failed} of {len(cells)} (counted, ranked last).",
             '', f'Capture: {json.dumps(capture.to_dict())}', '',
             '| scenario | method | flown | flown shape | registered images | ideal (Table I) | rank flown | rank ideal |',
             '|---|---|---|---|---|---|---|---|']
    for scenario in args.scenarios:
        keys = [k for k in cells if k.startswith(scenario + '/')]

        def rank(which: str) -> dict:
            def score(k):
                v = cells[k][which].get('chamfer_mean')
                return float('inf') if v is None or v != v else v  # failures last
            order = sorted(keys, key=score)
            return {k: order.index(k) + 1 for k in keys}
        rf, ri = rank('flown'), rank('ideal')
        for k in keys:
            f = cells[k]['flown']
            shape = f.get('chamfer_shape_mean')
            reg = '/'.join(str(p['images']) for p in f.get('per_realization', [])) or '-'
            lines.append(f"| {scenario} | {k.split('/', 1)[1]} | {chamfer_text(f)} | "
                         f"{'-' if shape is None else f'{shape:.3f}'} | {reg} | {chamfer_text(cells[k]['ideal'])} | "
                         f'{rf[k]} | {ri[k]} |')
    out.mkdir(parents=True, exist_ok=True)
    result = {'date': stamp, 'machine': machine(), 'capture': capture.to_dict(), 'failed': failed,
              'realizations': args.realizations, 'resolution': [args.width, args.height], 'cells': cells}
    write_report(out / 'table1_flights.json', result)
    (out / 'table1_flights.md').write_text('\n'.join(lines) + '\n')
    print('\n'.join(lines))
    return 0


if __name__ == '__main__':
    sys.exit(main())
