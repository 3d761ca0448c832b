#!/usr/bin/env python3
"""The fields benchmark from several runs of ``bench/bench_fields.py``: one table over every planning
seed any of them reconstructed (issue 22: fields with 3 seeds x 5 realizations).

``bench_fields.py`` plans with one ``--seed`` a run, so the seeds run as slices (``--seed 1 --out
results/rerun/fields_seed1``, on whatever cluster is at hand; a deterministic method such as the
lawnmower needs only one seed, ``--methods`` leaves it out of the others). This script joins their
``bench_fields.json`` files as ``table1_combine.py`` joins Table I's: per (field:N, method) the
union of the seeds, each seed's Chamfer per wind realization one unit (seed, realization), a later
file winning a seed both hold, a failed unit counted (a failed plan fails every realization) and
ranking its row last; egp's rows paired with the best baseline per (seed, realization) and over
the per-seed means, with 95 % t-intervals. A method reconstructed for fewer seeds than another
pairs on the seeds both have (the rest counted as ``missing``).

Refuses (one line, exit 1) files that disagree on what was measured: image size, wind
realizations, plant set, evaluations a part, capture model.

Writes ``fields_combined.md`` and ``fields_combined.json`` in ``--out``.
"""
from __future__ import annotations

import sys
from datetime import datetime, timezone
from pathlib import Path
from typing import Optional

if not __package__:  # python bench/fields_combine.py: as python -m bench.fields_combine (bench/_script.py)
    import _script  # noqa: F401
from bench.bench_fields import BASELINES  # noqa: E402
from bench.options import parser  # noqa: E402
from bench.publish import publish  # noqa: E402
from bench.table1_combine import combine, markdown, read_table  # noqa: E402

#: what every joined file must agree on (a different value: a different experiment)
SAME = ('resolution', 'realizations', 'models', 'evaluations_per_part', 'capture')


def _capture(table: dict) -> Optional[str]:
    """The capture model of a bench_fields.json: its reconstruction records' (one kind, or None)."""
    kinds = {c['recon'].get('capture') for c in table['cells'].values() if c.get('recon')} - {None}
    if len(kinds) > 1:
        raise SystemExit(f'fields_combine: one file holds reconstructions of several captures: {sorted(kinds)}')
    return kinds.pop() if kinds else None


def load(paths: list[Path]) -> tuple[dict, dict]:
    """({(field:N, method): {seed: (record, source)}}, the agreed metadata) of the files, in order."""
    meta: Optional[dict] = None
    cells: dict = {}
    for path in paths:
        table = read_table(path, 'fields_combine', 'bench_fields.json', ('cells', 'seed'))
        mine = {**{k: table.get(k) for k in SAME if k != 'capture'}, 'capture': _capture(table)}
        if meta is None:
            meta = mine
        for k in SAME:
            if mine[k] != meta[k] and not (k == 'capture' and None in (mine[k], meta[k])):
                raise SystemExit(f'fields_combine: {path} measured another {k} ({mine[k]!r}, not {meta[k]!r})')
        meta['capture'] = meta['capture'] or mine['capture']
        for name, cell in table['cells'].items():
            if cell.get('recon') is None:  # planned only (--no-recon, --recon-methods)
                continue
            field, method = name.split('/', 1)
            cells.setdefault((field, method), {})[int(table['seed'])] = (cell['recon'], str(path))
    return cells, meta or {}


def main(argv=None) -> int:
    ap = parser(__doc__)
    ap.add_argument('tables', nargs='+', type=Path, help='bench_fields.json files of bench/bench_fields.py runs, '
                                                         'oldest first')
    ap.add_argument('--out', type=Path, required=True, help='folder for fields_combined.{md,json}')
    args = ap.parse_args(argv)
    cells, meta = load(args.tables)
    if not cells:
        raise SystemExit('fields_combine: no reconstruction in the files given')
    table = {'date': datetime.now(timezone.utc).strftime('%Y-%m-%d'), **meta,
             'inputs': [str(p) for p in args.tables], **combine(cells, BASELINES, order=None, realizations=meta['realizations'])}
    setting = (f'Capture {meta["capture"]}, {meta["resolution"][0]} x {meta["resolution"][1]}, '
               f'{meta["realizations"]} wind realizations, egp {meta["evaluations_per_part"]} evaluations a part, '
               f'plants {meta["models"]}; columns FIELD:N.')
    publish(args.out, 'fields_combined', table, markdown(table, meta, args.tables, 'Fields', setting))
    return 0


if __name__ == '__main__':
    sys.exit(main())
