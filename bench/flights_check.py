#!/usr/bin/env python3
"""Issue 40's acceptance figures of a set of Table I and fields runs: do flights reconstruct?

Reads the per-realization records of ``bench.table1`` files (``table1.json``: every cell's
``recon_by_seed``) and ``bench.bench_fields`` files (every cell's ``recon``), one unit per
(scenario or field, method, planning seed, wind realization), and reports per method:

* ``units``, ``failed`` (a realization without a Chamfer, or a plan that failed: every
  realization counts) and the failures' reasons (error name: message, counted);
* ``far_off``: reconstructed units more than :data:`FAR_OFF` (x100) worse in map than in shape
  (a model that registered metres away yet counted as reconstructed);
* ``share``: the registration share (map - shape) / map of each reconstructed unit, its median;
* ``map`` and ``shape``: mean Chamfer x100 over the reconstructed units (and n).

Two sets side by side (``--before`` and ``--after``) give the before/after table and the bars
of issue 40: failures at most 1 in 50 for each method, no far-off success, median registration
share at most 25 %, every method's mean map Chamfer on Table I 30 % or more below the before
set's. Writes ``<out>/flights_check.{json,md}``.

    python -m bench.flights_check --before results/table1.json results/rerun/table1_*/table1.json ...
        --after results/rerun/issue40_table1/table1.json ... --out results/rerun/issue40
"""
from __future__ import annotations

import argparse
import json
import statistics
from collections import Counter
from pathlib import Path
from typing import Iterable, Optional

if not __package__:  # python bench/flights_check.py: as python -m bench.flights_check (bench/_script.py)
    import _script  # noqa: F401
from bench.common import ROOT, write_report  # noqa: E402

#: a reconstructed unit this much worse (Chamfer x100) in map than in shape is "far off"
FAR_OFF = 5.0
#: issue 40's bars
MAX_FAILED = 1 / 50
MAX_SHARE = 0.25
MIN_GAIN = 0.30
#: the methods issue 40 judges (Table I rows and fields labels map onto these)
METHODS = ('circle', 'arc', 'sa', 'egp')


def _method(label: str) -> Optional[str]:
    """A table row or fields label as one of :data:`METHODS` (egp by parts is the fields' egp);
    None for the others (egp-one-space, the paper configuration, lawnmower...)."""
    return label if label in METHODS else None


def units_of(path: Path) -> Iterable[tuple[str, str, str, str, list]]:
    """(kind, place, method, planning seed, realization records) of a results file (a failed plan:
    one failed record per realization)."""
    data = json.loads(path.read_text())
    fields = 'evaluations_per_part' in data or any('/' in k and ':' in k.split('/')[0] for k in data['cells'])
    for key, cell in data['cells'].items():
        place, label = key.split('/', 1)
        method = _method(label)
        if method is None:
            continue
        if fields:
            recs = {str(data.get('seed', 0)): cell.get('recon') or {}}
            kind = 'fields'
        else:
            recs = cell.get('recon_by_seed') or {'0': cell.get('recon') or {}}
            kind = 'table1'
        for seed, rec in recs.items():
            per = rec.get('per_realization') or []
            if not per:  # a plan that failed, or a record with none: one failed unit per realization asked
                k = data['realizations'] if isinstance(data.get('realizations'), int) and data['realizations'] else 5
                per = [{'error': rec.get('error') or 'FAILED', 'error_msg': rec.get('error_msg') or 'no reason recorded'}
                       for _ in range(k)]
            yield kind, place, method, str(seed), per


def summarize(paths: list[Path]) -> dict:
    """``kind/method`` -> the figures of the module docstring (Table I and fields apart, and both)."""
    seen: dict = {}  # (kind, place, method, seed) -> its realizations: a later file wins a seed both hold
    for path in paths:
        for kind, place, method, seed, per in units_of(path):
            seen[(kind, place, method, seed)] = per
    groups: dict = {}
    for (kind, place, method, _seed), per in seen.items():
        keys = (f'{kind}/{method}', f'all/{method}') + ((f'cell:{place}/{method}',) if kind == 'table1' else ())
        for key in keys:
            groups.setdefault(key, []).extend((place, p) for p in per)
    out = {}
    for key, units in sorted(groups.items()):
        ok = [p for _, p in units if p.get('chamfer') is not None]
        bad = [p for _, p in units if p.get('chamfer') is None]
        shares = [(p['chamfer'] - p['chamfer_shape']) / p['chamfer'] for p in ok
                  if p.get('chamfer_shape') is not None and p['chamfer'] > 0]
        reasons = Counter(f"{p.get('error', 'FAILED')}: {(p.get('error_msg') or 'no reason recorded')[:90]}"
                          for p in bad)
        out[key] = {'units': len(units), 'failed': len(bad), 'failed_fraction': len(bad) / len(units),
                    'far_off': sum(1 for p in ok if p.get('chamfer_shape') is not None
                                   and p['chamfer'] - p['chamfer_shape'] > FAR_OFF),
                    'share_median': statistics.median(shares) if shares else None,
                    'map': statistics.fmean(p['chamfer'] for p in ok) if ok else None,
                    'shape': statistics.fmean(p['chamfer_shape'] for p in ok if p.get('chamfer_shape') is not None)
                    if ok else None,
                    'n': len(ok), 'reasons': dict(reasons.most_common())}
    return out


def bars(before: dict, after: dict) -> dict:
    """Issue 40's bars on the ``after`` set (the 30 % gain against ``before``, Table I only)."""
    out = {}
    for m in METHODS:
        a = after.get(f'all/{m}')
        if a is None:
            continue
        b1, a1 = before.get(f'table1/{m}'), after.get(f'table1/{m}')
        gain = None if not (b1 and a1 and b1['map'] and a1['map'] is not None) else 1.0 - a1['map'] / b1['map']
        cells = {}  # the table's own cells: scenario -> 1 - after / before of the mean map Chamfer
        for key, c in after.items():
            if key.startswith('cell:') and key.endswith(f'/{m}') and before.get(key) and before[key]['map']:
                cells[key[5:].split('/')[0]] = None if c['map'] is None else 1.0 - c['map'] / before[key]['map']
        out[m] = {'table1_cell_gains': cells,
                  'cells_ok': bool(cells) and all(g is not None and g >= MIN_GAIN for g in cells.values()),
                  'failed_fraction': a['failed_fraction'], 'failed_ok': a['failed_fraction'] <= MAX_FAILED,
                  'far_off': a['far_off'], 'far_off_ok': a['far_off'] == 0,
                  'share_median': a['share_median'],
                  'share_ok': a['share_median'] is not None and a['share_median'] <= MAX_SHARE,
                  'table1_map_gain': gain, 'gain_ok': gain is not None and gain >= MIN_GAIN}
    return out


def _f(x, fmt: str = '.2f') -> str:
    return '-' if x is None else format(x, fmt)


def markdown(report: dict) -> str:
    lines = ['# Flights that reconstruct: before and after', '',
             f"Units: (scenario or field, method, planning seed, wind realization). Chamfer x100, mean over the "
             f"reconstructed units; far off: map more than {FAR_OFF:g} worse than shape; share: (map - shape) / map, "
             'median over the reconstructed units.', '',
             '| set | method | units | failed | far off | median share | map | shape |', '|---|---|---|---|---|---|---|---|']
    for name in ('before', 'after'):
        for key, c in report[name].items():
            if key.startswith('cell:'):
                continue
            lines.append(f"| {name} {key.split('/')[0]} | {key.split('/')[1]} | {c['units']} | {c['failed']} | "
                         f"{c['far_off']} | {_f(c['share_median'] and 100 * c['share_median'], '.0f')} % | "
                         f"{_f(c['map'])} (n={c['n']}) | {_f(c['shape'])} |")
    lines += ['', "## Issue 40's bars (after; the map gain on Table I against before)", '',
              '| method | failed <= 1/50 | far off = 0 | median share <= 25 % | Table I map >= 30 % below (pooled) '
              '| each Table I cell >= 30 % below |', '|---|---|---|---|---|---|']
    for m, b in report['bars'].items():
        def mark(ok: bool) -> str:
            return 'met' if ok else '**missed**'
        lines.append(f"| {m} | {100 * b['failed_fraction']:.1f} % {mark(b['failed_ok'])} | {b['far_off']} "
                     f"{mark(b['far_off_ok'])} | {_f(b['share_median'] and 100 * b['share_median'], '.0f')} % "
                     f"{mark(b['share_ok'])} | {_f(b['table1_map_gain'] and 100 * b['table1_map_gain'], '.0f')} % "
                     f"{mark(b['gain_ok'])} | "
                     + ', '.join(f"{s} {_f(g and 100 * g, '.0f')} %" for s, g in b['table1_cell_gains'].items())
                     + f" {mark(b['cells_ok'])} |")
    reasons = {k: c['reasons'] for k, c in report['after'].items() if c['reasons'] and k.startswith('all/')}
    if reasons:
        lines += ['', '## Failures after, with their reasons', '']
        for k, r in reasons.items():
            lines += [f"- {k.split('/')[1]}: " + '; '.join(f'{n} x {why}' for why, n in r.items())]
    return '\n'.join(lines) + '\n'


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--before', nargs='+', required=True, help='table1.json / bench_fields.json files before')
    ap.add_argument('--after', nargs='+', required=True, help='the same after')
    ap.add_argument('--out', default=str(ROOT / 'results'))
    args = ap.parse_args(argv)
    rel = [[str(Path(p)) for p in args.before], [str(Path(p)) for p in args.after]]
    before, after = summarize([Path(p) for p in args.before]), summarize([Path(p) for p in args.after])
    report = {'before_files': rel[0], 'after_files': rel[1], 'before': before, 'after': after,
              'bars': bars(before, after), 'far_off_threshold': FAR_OFF}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_report(out / 'flights_check.json', report)
    (out / 'flights_check.md').write_text(markdown(report))
    print(markdown(report))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
