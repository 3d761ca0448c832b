#!/usr/bin/env python3
"""Table I from several runs of ``bench/table1.py``: one table over every seed any of them reconstructed.

Table I with 3 planning seeds x 5 realizations for every randomized row is about 13 hours of one
worker (issue 22); it is run in slices (some rows, some scenarios, some seeds per run, each into its
own ``--out`` folder, on whatever cluster is at hand), and the cache that would resume a slice is
not kept with the results. This script joins the slices' ``table1.json`` files: for every
(scenario, row) the union of the seeds they reconstructed (``recon_by_seed``), each seed's Chamfer
per wind realization as one unit (seed, realization). Where two files hold the same seed of the
same cell the later file on the command line wins (the sources are listed per cell). A failed
reconstruction stays a failed unit: it is counted and ranks its row last (``stats.rank``).

Refuses (one line, exit 1) files that disagree on what was measured: capture model, image size,
evaluations, plant set, or the plants drawn for a scenario.

Writes ``table1_combined.md`` and ``table1_combined.json`` in ``--out``: per cell mean +- sample std
(n, failed) of the Chamfer x100 in map and of the shape after ICP (``chamfer_shape``), the seeds
and their sources, and per scenario egp's paired difference to the best baseline with its 95 %
t-interval (per (seed, realization) both reconstructed, as ``table1.py``), and over the per-seed
means (seeds both rows have).
"""
from __future__ import annotations

import json
import sys
from datetime import datetime, timezone
from pathlib import Path
from typing import Optional

if not __package__:  # python bench/table1_combine.py: as python -m bench.table1_combine (bench/_script.py)
    import _script  # noqa: F401
from bench.common import SCENARIOS  # noqa: E402
from bench.options import parser  # noqa: E402
from bench.publish import publish  # noqa: E402
from bench.stats import describe, describe_difference, paired_difference, rank, realization_units, summary  # noqa: E402
from bench.table1 import BASELINES  # noqa: E402

#: what every joined file must agree on (a different value: a different experiment)
SAME = ('capture', 'resolution', 'evaluations', 'models')


def read_table(path: Path, tool: str, kind: str, keys: tuple = ('cells',)) -> dict:
    """A benchmark's results JSON, or SystemExit naming ``tool`` and the file (unreadable, or not
    a ``kind``: one of ``keys`` missing)."""
    try:
        table = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise SystemExit(f'{tool}: cannot read {path}: {exc}') from None
    missing = [k for k in keys if k not in table]
    if missing:
        raise SystemExit(f'{tool}: {path} is not a {kind} (no {", ".join(repr(k) for k in missing)})')
    return table


def load(paths: list[Path]) -> tuple[dict, dict]:
    """({(scenario, row): {seed: (record, source)}}, the agreed metadata) of the files, in order."""
    meta: Optional[dict] = None
    plants: dict = {}
    cells: dict = {}
    for path in paths:
        table = read_table(path, 'table1_combine', 'table1.json')
        mine = {k: table.get(k) for k in SAME}
        if meta is None:
            meta = mine
        for k in SAME:
            if mine[k] != meta[k]:
                raise SystemExit(f'table1_combine: {path} measured another {k} ({mine[k]!r}, not {meta[k]!r})')
        for scenario, used in table.get('plants', {}).items():
            if plants.setdefault(scenario, used) != used:
                raise SystemExit(f'table1_combine: {path} drew other plants for {scenario}')
        for name, cell in table['cells'].items():
            scenario, row = name.split('/', 1)
            by_seed = cell.get('recon_by_seed') or {'0': cell['recon']}
            for seed, record in by_seed.items():
                cells.setdefault((scenario, row), {})[int(seed)] = (record, str(path))
    return cells, {**(meta or {}), 'plants': plants}


def seed_means(u: dict) -> dict:
    """seed -> mean over its realizations (None when any failed: a failed unit is not averaged away)."""
    by: dict = {}
    for (seed, _), v in u.items():
        by.setdefault(seed, []).append(v)
    return {s: (None if any(v is None for v in vs) else sum(vs) / len(vs)) for s, vs in by.items()}


def combine(cells: dict, baselines=BASELINES, order=SCENARIOS, realizations: Optional[int] = None) -> dict:
    """The combined table (JSON-ready) of cells {(column, row): {seed: (record, source)}}: a column
    is a scenario (or a field, ``bench/fields_combine.py``), in ``order`` (None: as they come);
    the paired differences are of every row not in ``baselines`` to the best of those. Every seed
    counts ``realizations`` units (None: the most any record holds), so a plan that failed (no
    realization) fails them all, even in a cell where no seed planned."""
    if realizations is None:
        realizations = max((len(r.get('per_realization') or []) for seeds in cells.values()
                            for r, _ in seeds.values()), default=0)
    columns = list(dict.fromkeys(c for c, _ in cells))
    scenarios = columns if order is None else [s for s in order if s in columns]
    rows = list(dict.fromkeys(r for _, r in cells))
    out = {'cells': {}, 'paired': {}}
    chamfer = {}
    for (scenario, row), seeds in cells.items():
        records = {seed: record for seed, (record, _) in seeds.items()}
        u = realization_units(records, realizations)
        chamfer[(scenario, row)] = u
        shape = realization_units(records, realizations, 'chamfer_shape')
        out['cells'][f'{scenario}/{row}'] = {
            'chamfer': summary({f'{s}/{k}': v for (s, k), v in u.items()}),
            'chamfer_shape': summary({f'{s}/{k}': v for (s, k), v in shape.items()}),
            'seeds': sorted(seeds), 'sources': {str(s): src for s, (_, src) in sorted(seeds.items())},
            'per_unit': {f'{s}/{k}': v for (s, k), v in u.items()}}
    for scenario in scenarios:
        base = [r for r in rows if r in baselines and (scenario, r) in chamfer]
        if not base:
            continue
        best = rank({r: summary(chamfer[(scenario, r)]) for r in base})[0]
        for row in rows:
            if row in baselines or (scenario, row) not in chamfer:
                continue
            a, b = chamfer[(scenario, row)], chamfer[(scenario, best)]
            sa, sb = seed_means(a), seed_means(b)
            out['paired'][f'{scenario}/{row}'] = {
                'baseline': best, **paired_difference(a, b),
                'over_seed_means': paired_difference(sa, sb)}
    out['scenarios'], out['rows'] = scenarios, rows
    return out


def markdown(table: dict, meta: dict, paths: list[Path], title: str = 'Table I', setting: str = '') -> str:
    """The combined table as markdown; ``setting``: what was measured (default: Table I's metadata)."""
    scen, rows = table['scenarios'], table['rows']
    setting = setting or (f'Capture {meta["capture"]["kind"]}, {meta["resolution"][0]} x {meta["resolution"][1]}, '
                          f'{meta["evaluations"]} evaluations, plants {meta["models"]}.')
    lines = [f'# {title}, combined {table["date"]}', '',
             'Joined from ' + ', '.join(f'`{p}`' for p in paths) + ' (a later file wins a seed both hold). '
             f'{setting} Chamfer x100 in map, mean +- sample std '
             'over (seed, realization) units (n: reconstructed; a failed unit is counted and ranks its row last); '
             'seeds in brackets.', '',
             '| method | ' + ' | '.join(scen) + ' |', '|---|' + '---|' * len(scen)]
    for key, title in (('chamfer', None), ('chamfer_shape', 'Shape alone (Chamfer x100 after a rigid ICP)')):
        if title:
            lines += ['', f'## {title}', '', '| method | ' + ' | '.join(scen) + ' |', '|---|' + '---|' * len(scen)]
        for row in rows:
            cells = []
            for s in scen:
                c = table['cells'].get(f'{s}/{row}')
                cells.append(f'{describe(c[key])} [seeds {",".join(map(str, c["seeds"]))}]' if c else 'not run')
            lines.append(f'| {row} | ' + ' | '.join(cells) + ' |')
    lines += ['', '## Paired differences: row - best baseline (Chamfer x100, negative: the row is better)', '',
              'Per (seed, realization) both reconstructed, mean [95 % t-interval] (n); and over the per-seed '
              'means of the seeds both rows have (the planning seed as the unit).', '',
              '| scenario / row | best baseline | per (seed, realization) | over seed means |', '|---|---|---|---|']
    for name, d in table['paired'].items():
        lines.append(f'| {name} | {d["baseline"]} | {describe_difference(d)} | '
                     f'{describe_difference(d["over_seed_means"])} |')
    return '\n'.join(lines) + '\n'


def main(argv=None) -> int:
    ap = parser(__doc__)
    ap.add_argument('tables', nargs='+', type=Path, help="table1.json files of bench/table1.py runs, oldest first")
    ap.add_argument('--out', type=Path, required=True, help='folder for table1_combined.{md,json}')
    args = ap.parse_args(argv)
    cells, meta = load(args.tables)
    table = {'date': datetime.now(timezone.utc).strftime('%Y-%m-%d'), **meta,
             'inputs': [str(p) for p in args.tables], **combine(cells)}
    publish(args.out, 'table1_combined', table, markdown(table, meta, args.tables))
    return 0


if __name__ == '__main__':
    sys.exit(main())
