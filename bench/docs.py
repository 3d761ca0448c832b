#!/usr/bin/env python3
"""docs/results.md from the results files: ``make docs`` (``python -m bench.docs``).

Every figure of docs/results.md is read from a JSON file under results/ by this script, never
copied by hand (tests/test_docs.py regenerates it and compares it with the committed file), and
every table names the file, the commit and the command it came from: the ``commit`` and
``command`` the benchmark recorded (``bench.common.write_report``), or for a file written before
benchmarks recorded them the commit that committed it and the command from the README of the time
(:data:`LEGACY`, a mapping of this script). A Table I file whose plans were planned again and
found to differ (``python -m bench.reference_plans`` -> results/reference_plans.json) is marked
stale. Spreads are named: "sample std (n-1)" where this script computes them from the records,
"population std" where a file holds one so computed.

``--check``: exit 1 when docs/results.md is not what the results give (nothing written).
"""
from __future__ import annotations

import argparse
import importlib
import json
import math
import shlex
import sys
from pathlib import Path
from typing import Callable, Optional

import numpy as np

if not __package__:  # python bench/docs.py: as python -m bench.docs (bench/_script.py)
    import _script  # noqa: F401
from bench import reference_plans  # noqa: E402
from bench.common import ROOT  # noqa: E402
from bench.stats import describe, describe_difference, summary  # noqa: E402

OUT = ROOT / 'docs' / 'results.md'
STD = 'mean +- sample std (n-1) (n: reconstructed; failures counted, ranked last)'

#: results files written before the benchmarks recorded their command and commit:
#: path -> (the commit that committed the file, the command that made it, as the README gave it)
LEGACY = {
    'results/table1.json': ('ff4baab', 'python bench/table1.py --workers 2 --seeds 1 --recon-seeds 1 --realizations 5 --threads 1'),
    'results/rerun/table1_six_rect_3seeds/table1.json': ('bb81a42', 'python bench/table1.py --scenarios six_rect --rows arc egp --seeds 3 --recon-seeds 3 --threads 1 --workers 2 --out results/rerun/table1_six_rect_3seeds'),
    'results/rerun/table1_six_rect_3seeds_sa/table1.json': ('34a0d6c', 'python bench/table1.py --scenarios six_rect --rows sa --seeds 3 --recon-seeds 3 --threads 1 --workers 2 --out results/rerun/table1_six_rect_3seeds_sa'),
    'results/rerun/table1_one_plant_seeds12/table1.json': ('2647ee2', 'python bench/table1.py --scenarios one_plant --rows arc sa egp --seeds 3 --recon-seeds 3 --recon-first 1 --threads 1 --workers 2 --out results/rerun/table1_one_plant_seeds12'),
    'results/rerun/table1_three_row_seeds12/table1.json': ('437c98b', 'python bench/table1.py --scenarios three_row --rows arc sa egp --seeds 3 --recon-seeds 3 --recon-first 1 --threads 1 --workers 2 --out results/rerun/table1_three_row_seeds12'),
    **{f'results/rerun/table1_paper_{s}_seeds12/table1.json': ('6f2a281', f'python bench/table1.py --scenarios {s} --rows "egp (paper configuration)" --seeds 3 --recon-seeds 3 --recon-first 1 --threads 1 --workers 2 --out results/rerun/table1_paper_{s}_seeds12')
       for s in ('one_plant', 'three_row', 'six_rect')},
    'results/rerun/table1_graph_seed0/table1.json': ('94480db', 'python bench/table1.py --scenarios one_plant three_row six_rect --rows "egp (coverage-graph)" --seeds 1 --recon-seeds 1 --threads 1 --workers 2 --out results/rerun/table1_graph_seed0'),
    'results/rerun/table1_graph_seeds12/table1.json': ('e7625d2', 'python bench/table1.py --scenarios one_plant three_row six_rect --rows "egp (coverage-graph)" --seeds 3 --recon-seeds 3 --recon-first 1 --threads 1 --workers 2 --out results/rerun/table1_graph_seeds12'),
    'results/rerun/table1_combined/table1_combined.json': ('e7625d2', None),  # the command: from its inputs
    'results/rerun/fields_combined/fields_combined.json': ('79996e4', None),
    **{f'results/rerun/fields_seed{s}/bench_fields.json': (c, f'python bench/bench_fields.py --fields grid_3x3:8 row_12:12 --seed {s} --realizations 5 --threads 1{m} --out results/rerun/fields_seed{s}')
       for s, c, m in ((0, 'db2ead4', ''), (1, '79996e4', ' --methods egp egp-one-space circle arc sa'),
                       (2, 'ec23b0a', ' --methods egp egp-one-space circle arc sa'))},
    'results/bench_fields.json': ('96816b0', 'python bench/bench_fields.py --fields grid_3x3:8 row_12:12 --workers 2 --threads 1'),
    'results/rerun/fields_merged_models_grid/bench_fields.json': ('73ee5fc', None),
    'results/rerun/fields_merged_models_row/bench_fields.json': ('73ee5fc', None),
    'results/rerun/plan_quality_before_anchored/plan_quality.json': ('4057b39', 'python bench/plan_quality.py --scenarios one_plant --realizations 0 --phase recon --workers 2 --threads 1 (then --realizations 1; three_row: realization 0), then --phase analyze'),
    'results/bench_sorties.json': ('92813d1', 'python bench/bench_sorties.py --threads 1 --workers 2 --out results'),
    'results/rerun/sorties_merged_models/bench_sorties.json': ('8c71328', 'python bench/bench_sorties.py --scenarios three_row six_rect --threads 1 --workers 2 --out results/rerun/sorties_merged_models'),
    'results/rerun/sorties_exhaustive/bench_sorties.json': ('0deb43b', 'python bench/bench_sorties.py --scenarios six_rect three_row --realizations 2 --workers 2 --threads 1 --matching exhaustive --out results/rerun/sorties_exhaustive'),
    'results/rerun/sorties_graph/bench_sorties.json': ('e5c7e4a', 'python bench/bench_sorties.py --scenarios one_plant --reward coverage-graph --workers 2 --threads 1 --out results/rerun/sorties_graph'),
    'results/rerun/sorties_grid_3x3/bench_sorties.json': ('c460c66', None),
    'results/coverage_check.json': ('ff4baab', 'python bench/coverage_check.py'),
    'results/bench_recon_speed.json': ('405790e', 'python bench/bench_recon_speed.py --workers 2 --threads 1 --realizations 5'),
    'results/bench_make_run.json': ('405790e', 'python bench/bench_make_run.py'),
    'results/bench_recon.json': ('1940e10', 'python bench/bench_recon.py --models ../shared/data/corn50'),
    'results/bench_planners.json': ('ecf1e77', 'python bench/bench_planners.py'),
    'results/rerun/bench_planners_one_plant_coverage.json': ('ff4baab', None),
    'results/bench_reward.json': ('94480db', 'python bench/bench_reward.py'),
    'results/bench_cluster.json': ('54428ea', 'python bench/bench_cluster.py'),
    'results/bench_matching.json': ('de1ad17', 'python bench/bench_matching.py'),
    'results/bench_fleet_transport.json': ('56608a0', 'python bench/bench_fleet_transport.py --mode transport|recon|drones'),
    'results/bench_viewer.json': ('6af8da4', 'python bench/bench_viewer.py'),
    'results/ideal/table1.json': ('6af8da4', 'python bench/table1.py --realizations 2 (before the capture model: the ideal capture, now --capture ideal)'),
    'results/heldout_procedural/table1.json': ('01950b4', "python bench/table1.py --models '' --scenarios one_plant three_row --rows circle arc sa egp --seeds 1 --realizations 2 --out results/heldout_procedural"),
    'results/ideal/bench_fields.json': ('ff4baab', 'python bench/bench_fields.py (before the capture model: the ideal capture)'),
    'results/ideal/plan_quality.json': ('2647ee2', 'python bench/plan_quality.py (before the capture model: the ideal capture)'),
    'results/flights_blue_screen/table1_flights.json': ('3c7ab47', 'python bench/table1_flights.py'),
}


def load(rel: str) -> dict:
    return json.loads((ROOT / rel).read_text())


def num(x, digits: int = 2, sign: bool = False) -> str:
    """A number, '-' for none (null, NaN)."""
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return '-'
    return f'{x:+.{digits}f}' if sign else f'{x:.{digits}f}'


def source(rel: str, data: dict, derived_command: Optional[str] = None) -> str:
    """The line under a table: file, date, commit and command."""
    parts = [f'Source: [`{rel}`](../{rel})'] + ([str(data['date'])] if data.get('date') else [])
    if data.get('commit'):
        parts.append(f'measured at commit `{data["commit"]}`')
    elif rel in LEGACY:
        parts.append(f'committed in `{LEGACY[rel][0]}`')
    legacy = LEGACY.get(rel, (None, None))[1]
    if data.get('command'):
        command = f'command: `{shlex.join(data["command"])}`'
    elif derived_command:
        command = f'command: `{derived_command}`'
    elif legacy:
        command = f'command (as the README gave it; not recorded by the benchmark then): `{legacy}`'
    else:
        command = 'command not recorded'
    return ', '.join(parts) + '; ' + command + '.' + plans_note(rel)


def plans_note(rel: str) -> str:
    """' Plans: ...' for a Table I file whose plans were planned again (results/reference_plans.json)."""
    checks = reference_plans.load(reference_plans.RESULTS)
    cells = checks.get('tables', {}).get(rel, {}).get('cells')
    if not cells:
        return ''
    stale = reference_plans.stale_cells(checks, rel)
    caps = sorted({c.get('torch_cpu_capability') or '?' for c in cells.values()})
    last = max((c.get('commit') or '', c.get('date') or '') for c in cells.values())
    when = f'at commit `{last[0]}` ({last[1]}, torch kernels {"/".join(caps)})'
    if stale:
        return (f' **STALE: the plans of {", ".join(stale)} no longer come out of the planner** (planned again {when}); '
                'the figures of those cells describe other plans than this commit makes.')
    return f' Plans: all {len(cells)} planned again and reproduced (cameras within 1 um and 1 urad) {when}.'


def demote(md: str, by: int = 2) -> str:
    """A markdown text with its headings ``by`` levels down (a benchmark's own report inside a section)."""
    return '\n'.join('#' * by + line if line.startswith('#') else line for line in md.splitlines()).strip() + '\n'


def record_summary(record: Optional[dict], key: str = 'chamfer') -> dict:
    """:func:`bench.stats.summary` (mean, sample std (n-1), n, failed) of a reconstruction record's
    realizations; a record without any (a failed plan) is one failure."""
    per = (record or {}).get('per_realization') or []
    if not per:
        return {'mean': math.nan, 'std': math.nan, 'n': 0, 'failed': 1}
    return summary({i: p.get(key) for i, p in enumerate(per)})


def table(head: list[str], rows: list[list[str]]) -> list[str]:
    return ['| ' + ' | '.join(head) + ' |', '|' + '---|' * len(head)] + ['| ' + ' | '.join(r) + ' |' for r in rows]


def cell_grid(cells: dict, text: Callable[[dict], str], corner: str = 'method') -> list[str]:
    """A markdown table of ``column/row`` cells (a results file's ``cells``): rows down, columns
    across, in the file's order, ``text(cell)`` in each ('not run' where a cell is missing)."""
    columns = list(dict.fromkeys(k.split('/', 1)[0] for k in cells))
    rows = list(dict.fromkeys(k.split('/', 1)[1] for k in cells))
    return table([corner] + columns, [[row] + [text(cells[f'{c}/{row}']) if f'{c}/{row}' in cells else 'not run'
                                               for c in columns] for row in rows])


# ---------------------------------------------------------------- Table I

def combined_section(rel: str, title: str, kind: str) -> str:
    """A table joined by bench/table1_combine.py or bench/fields_combine.py (their own markdown)."""
    from bench.table1_combine import markdown

    data = load(rel)
    meta = {k: data.get(k) for k in ('capture', 'resolution', 'evaluations', 'models')}
    setting = ''
    if kind == 'Fields':
        setting = (f"Capture {data.get('capture')}, {data['resolution'][0]} x {data['resolution'][1]}, "
                   f"{data.get('evaluations_per_part')} evaluations a part, plants {data.get('models')}.")
    md = demote(markdown(data, meta, [Path(p) for p in data['inputs']], kind, setting), 1)
    md = md.split('\n', 1)[1].lstrip()  # its own title: the section has one
    command = ('python bench/table1_combine.py ' if kind == 'Table I' else 'python bench/fields_combine.py ') + \
        ' '.join(data['inputs']) + f' --out {Path(rel).parent}'
    checks = reference_plans.load(reference_plans.RESULTS)
    stale = [f'{cell} seed {seed}' for cell, c in data['cells'].items() for seed, src in c.get('sources', {}).items()
             if cell in reference_plans.stale_cells(checks, src)]
    note = ('\n\n**STALE**: ' + ', '.join(stale) + ': the run these seeds come from made a seed-0 plan of that cell '
            'that no longer comes out of the planner (results/reference_plans.json; the plans of seeds 1 and 2 are '
            'not kept in the files, so the run stands for them).') if stale else ''
    return f'## {title}\n\n{md}\n{source(rel, data, command)}{note}\n'


def table1_seed0_section(rel: str, title: str) -> str:
    """A table1.json run: per cell the Chamfer over its realizations, the shape, the rewards of the seed-0 plan."""
    data = load(rel)

    def text(c: dict) -> str:
        recs = c.get('recon_by_seed') or {'0': c['recon']}
        ch = summary({f'{seed}/{i}': p.get('chamfer') for seed, r in recs.items()
                      for i, p in enumerate(r.get('per_realization') or [None]) if p is not None} or {'0': None})
        shape = summary({f'{seed}/{i}': p.get('chamfer_shape') for seed, r in recs.items()
                         for i, p in enumerate(r.get('per_realization') or [])})
        rw, paper = c.get('rewards') or {}, c.get('paper')
        return (describe(ch, 2) + (f' / shape {num(shape["mean"])}' if shape['n'] else '')
                + (f'; reward {num(rw.get("coverage"), 3)} / {num(rw.get("paper"), 3)}' if rw else '')
                + (f' [paper {paper[0]:.2f} +- {paper[1]:.2f}]' if paper else ''))
    lines = [f'## {title}', '',
             f'Plants {data.get("models")}, capture {capture_kind(data)}, {data["resolution"][0]} x '
             f'{data["resolution"][1]}, {data["evaluations"]} evaluations a plan. Chamfer x100 in map, {STD}, over '
             'the realizations reconstructed; "shape": the mean after a rigid ICP onto the truth; the rewards of '
             'the seed-0 plan under coverage / paper; the paper\'s own Table I value in brackets (PatchMatch '
             'stereo, not comparable in absolute terms).', '']
    lines += cell_grid(data['cells'], text)
    if data.get('paired'):
        lines += ['', 'Paired difference to the best baseline, per (seed, realization) both reconstructed, mean '
                  '[95 % t-interval] (n):', '']
        lines += table(['scenario / row', 'best baseline', 'difference'],
                       [[k, d['baseline'], describe_difference(d)] for k, d in data['paired'].items()])
    return '\n'.join(lines) + '\n\n' + source(rel, data) + '\n'


def capture_kind(data: dict) -> str:
    cap = data.get('capture')
    if isinstance(cap, dict):
        return cap.get('kind', '?')
    return cap or 'ideal (before the capture model)'


# ---------------------------------------------------------------- fields, sorties, plan quality

def fields_section(rel: str, title: str) -> str:
    """A bench_fields.json run: per (field:N, method) the Chamfer over its realizations."""
    data = load(rel)

    def text(c: dict) -> str:
        plan = c.get('plan') or {}
        return describe(record_summary(c.get('recon')), 2) + (
            f'; reward {num(plan.get("reward"), 3)}' if 'reward' in plan else f'; plan failed ({plan.get("error")})')
    lines = [f'## {title}', '', f'Plants {data.get("models")}, planning seed {data.get("seed")}, capture '
             f'{capture_kind(data) if "capture" in data else capture_of_cells(data)}, {data["resolution"][0]} x '
             f'{data["resolution"][1]}, realizations 0-{data["realizations"] - 1}. Chamfer x100 in map, {STD}; '
             'the plan\'s reward (default model).', '']
    lines += cell_grid(data['cells'], text)
    return '\n'.join(lines) + '\n\n' + source(rel, data) + '\n'


def capture_of_cells(data: dict) -> str:
    kinds = sorted({(c.get('recon') or {}).get('capture') or 'ideal' for c in data['cells'].values()})
    return '/'.join(kinds)


def sorties_section(rel: str, title: str) -> str:
    from bench.bench_sorties import CASES, verdict

    data = load(rel)
    a = data.get('args', {})
    body = []
    for scenario, row in data['rows'].items():
        cells = [scenario, f'{row["n"]} + {row["m"]}', describe(record_summary(row['sortie1'].get('chamfer')), 2)]
        cells += [describe(record_summary(row['cases'].get(c)), 2) for c in CASES]
        body.append(cells + [verdict(row)])
    lines = [f'## {title}', '',
             f'Plants {Path(str(a.get("models"))).name or "procedural"}, egp {a.get("evals")} evaluations, seed '
             f'{a.get("seed")}, {a.get("realizations")} realizations, {a.get("width")} x {a.get("height")}, capture '
             f'{a.get("capture")}, matching {a.get("matching")}, reward {a.get("reward") or "coverage (default)"}. '
             f'Chamfer x100 after sortie 2, {STD}. a: one sortie of N + M (egp); b: sortie 2 egp ignoring sortie 1; '
             'c: circle / arc of M; d: egp given the flown cameras; e: egp given the flown cameras and their reconstruction. Verdict: the target '
             'is that e beats b and both c and comes within 5 % of a.', '']
    lines += table(['scenario', 'N + M', 'sortie 1'] + list(CASES) + ['verdict'], body)
    return '\n'.join(lines) + '\n\n' + source(rel, data) + '\n'


def plan_quality_section(rel: str, title: str) -> str:
    from bench.plan_quality import plan_chamfer

    data = load(rel)
    variants = data['variants']
    scen = list(data.get('counts') or data.get('plans'))
    lines = [f'## {title}', '']
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
    return '\n'.join(lines) + '\n\n' + source(rel, data) + '\n'


# ---------------------------------------------------------------- smaller benchmarks

def own_markdown(module: str) -> Callable[[str, str], str]:
    """A section from a benchmark's own ``markdown(data)`` of its JSON (``module``: the benchmark,
    imported when the section is rendered)."""
    def render(rel: str, title: str) -> str:
        data = load(rel)
        md = demote(importlib.import_module(module).markdown(data), 2).split('\n', 1)[1].lstrip()
        return f'## {title}\n\n{md}\n{source(rel, data)}\n'
    return render


def recon_stages_section(rel: str, title: str) -> str:
    data = load(rel)
    body = [[name.replace('_', ' '), s['capture'], '/'.join(map(str, s.get('registered_images') or [])),
             *(num(s['seconds'].get(k), 1) for k in
                                                                    ('render', 'sparse', 'dense', 'score', 'total')),
             num(s.get('chamfer_x100')), num(s.get('chamfer_shape_x100'))]
            for name, s in data['stages_one_plant'].items()]
    lines = [f'## {title}', '', f'One plant ({Path(str(data.get("models"))).name or "procedural"}), '
             f'{data["width"]} x {data["height"]}, a ring of views 30 degrees apart, one realization, seconds per stage '
             'with the reconstruction on the machine\'s cores.', '']
    lines += table(['views', 'capture', 'registered', 'render s', 'sparse s', 'dense s', 'score s', 'total s',
                    'Chamfer x100', 'shape x100'], body)
    return '\n'.join(lines) + '\n\n' + source(rel, data) + '\n'


def planners_section(rel: str, title: str) -> str:
    data = load(rel)
    rewards = list(dict.fromkeys(k.split('/')[0] for k in data['cells']))
    lines = [f'## {title}', '', f'Final reward after {data["evaluations"]} evaluations ({data["initial_evaluations"]} '
             f'initial for egp), {STD.split(" (n:")[0]} over {data["seeds"]} seeds, plants {data["models"]}; '
             '"BO beat": seeds whose final plan is better than the best plan of the initial design.', '']
    for reward in rewards:
        keys = [k for k in data['cells'] if k.startswith(reward + '/')]
        scen = list(dict.fromkeys(k.split('/')[1] for k in keys))
        methods = list(dict.fromkeys(k.split('/')[2] for k in keys))
        body = []
        for s in scen:
            row = [s]
            for m in methods:
                c = data['cells'].get(f'{reward}/{s}/{m}')
                if c is None:
                    row.append('-')
                    continue
                st = summary(dict(enumerate(c['finals'])))
                row.append(describe(st, 4) + (f', BO beat {c["bo_improved_seeds"]} of {len(c["finals"])}'
                                              if 'bo_improved_seeds' in c else '') + f', {c["seconds_mean"]:.1f} s')
            body.append(row)
        lines += [f'Reward `{reward}`:', ''] + table(['scenario'] + methods, body) + ['']
    return '\n'.join(lines) + '\n' + source(rel, data) + '\n'


def reward_cost_section(rel: str, title: str) -> str:
    data = load(rel)
    body = [[m, num(r.get('one_plan_ms'), 1), num(r.get('one_plan_prepared_points_ms'), 1),
             num(r.get('batch_ms_per_plan'), 1)] for m, r in data['results'].items()]
    lines = [f'## {title}', '', f'{data["cameras"]} cameras, {data["points"]} points x {data["realizations"]} '
             f'realizations, {data["threads"]} torch thread; `float64`/`float32`: the paper reward. Best of repeats, '
             f'ms. The paper reward in float32 differs from float64 by at most {data["max_abs_diff_float32"]:.1e}.', '']
    lines += table(['model', 'one plan', 'one plan, points prepared', 'per plan in a batch'], body)
    return '\n'.join(lines) + '\n\n' + source(rel, data) + '\n'


def cluster_section(rel: str, title: str) -> str:
    data = load(rel)
    body = [[str(r['workers']), str(r['tasks']), num(r['cluster_start_s'], 1), num(r['wall_s'], 1),
             num(r['task_seconds'], 1), str(r['failed']), num(data['speedup'].get(str(r['workers'])))]
            for r in data['runs']]
    lines = [f'## {title}', '', 'A small Table I slice (`python -m bench.table1 ' + shlex.join(data['table1_arguments'])
             + '`) on 1 and 2 local workers.', '']
    lines += table(['workers', 'tasks', 'cluster start s', 'wall s', 'task s (sum)', 'failed', 'speedup'], body)
    lines += ['', f'Same plans on every worker count: {data["same_plans"]}; same reconstruction records: '
              f'{data["same_records"]} (largest Chamfer x100 difference {data["recon_max_abs_diff_chamfer_x100"]:.1e}); '
              f'overhead per task {data["overhead_per_task_s"]:.2f} s.']
    return '\n'.join(lines) + '\n\n' + source(rel, data) + '\n'


def matching_section(rel: str, title: str) -> str:
    data = load(rel)
    body = [[r['size'], str(r['cameras']), r['matching'], str(r['pairs_matched']), str(r['pairs_verified']),
             str(r.get('wide_verified')), str(r.get('images')), num(r.get('chamfer_x100')),
             num(r.get('seconds_dense'), 1)]
            for part in ('field', 'threshold') for r in data.get(part) or []]
    lines = [f'## {title}', '', f'Exhaustive against pose-chosen image pairs ({data.get("scene")}; "wide": verified '
             'pairs more than 90 degrees apart).', '']
    lines += table(['size', 'cameras', 'matching', 'pairs matched', 'verified', 'wide verified', 'images',
                    'Chamfer x100', 'dense s'], body)
    return '\n'.join(lines) + '\n\n' + source(rel, data) + '\n'


def fleet_section(rel: str, title: str) -> str:
    data = load(rel)
    lines = [f'## {title}', '',
             f'Transport: {data["drones"]} drones, {data["width"]} x {data["height"]} rgb8 ({data["megabytes_per_set"]:.0f} '
             f'MB a set), one publisher process to one subscriber: ' + ', '.join(num(s['seconds']) for s in data['sets'])
             + f' s a set; the subscriber\'s peak RSS {num(data["subscriber_rss_mb_before"], 0)} -> '
             + num(max(s['subscriber_max_rss_mb'] for s in data['sets']), 0) + ' MB.', '']
    rn = data.get('recon_node_memory')
    if rn:
        lines += ['Recon node collecting a set (`source: fleet`), peak RSS MB: ' + ', '.join(
            f'{k} {num(v, 0)}' for k, v in rn['recon_node_peak_rss_mb'].items()) + '.', '']
    dp = data.get('drone_processes') or {}
    if dp:
        body = [[size, str(d['drones']), ', '.join(num(s['seconds_trigger_to_last_image']) for s in d['sets']),
                 str(sum(len(s['missing_drones']) for s in d['sets'])), num(d.get('drone_rss_mb_mean'), 0)]
                for size, d in dp.items()]
        lines += ['Real `sim_drone` processes (camera on, ideal capture) to one subscriber:', '']
        lines += table(['image size', 'drones', 'trigger to last image, s per set', 'images missing',
                        'RSS MB a drone'], body) + ['']
    ah = data.get('across_hosts_capture_set')
    if ah:
        lines += [f'Across hosts ({ah["from"]}): a {ah["megabytes_per_set"]:.0f} MB set, trigger to collected '
                  f'{num(ah["trigger_to_collected_s"])} s, last capture to collected {num(ah["last_capture_to_collected_s"])} s.', '']
    lines.append('Measured with a benchmark running beside it on 2 shared cores: noisy.')
    return '\n'.join(lines) + '\n\n' + source(rel, data) + '\n'


def viewer_section(rel: str, title: str) -> str:
    data = load(rel)
    body = [[str(r['cap']), num(r['server_reconstruction_s']), num(r['page_ready_s'], 1), num(r['frame_ms_median'], 0),
             num(r['frame_ms_p95'], 0), num(r['fps'], 1), num(r['load_average_1min'], 1)] for r in data['runs']]
    lines = [f'## {title}', '', f'{data["browser"]}; {data["cameras"]} frustums, a {data["scene_points"]}-point '
             f'scene and a {data["reconstruction_points"]}-point reconstruction; per cap (points drawn per cloud).', '']
    lines += table(['cap', 'server: reconstruction s', 'page ready s', 'frame ms median', 'frame ms p95', 'fps',
                    'load average'], body)
    return '\n'.join(lines) + '\n\n' + source(rel, data) + '\n'


def ideal_table1_section(rel: str, title: str) -> str:
    return table1_seed0_section(rel, title)


def flights_section(rel: str, title: str) -> str:
    data = load(rel)
    body = [[k, describe(record_summary(c['flown']), 2), num(c['flown'].get('chamfer_shape_mean')),
             describe(record_summary(c['ideal']), 2)] for k, c in data['cells'].items()]
    lines = [f'## {title}', '', f'The seed-0 plans of the ideal Table I flown (capture {data["capture"]["kind"]}, '
             f'over the blue screen), {data["resolution"][0]} x {data["resolution"][1]}, realizations 0-'
             f'{data["realizations"] - 1}. Chamfer x100, {STD}.', '']
    lines += table(['scenario / method', 'flown', 'flown shape', 'ideal'], body)
    return '\n'.join(lines) + '\n\n' + source(rel, data) + '\n'


#: (section title, results file, renderer), in the order of docs/results.md
CURRENT = [
    ('Table I with the registration in the reward (egp planned again): 3 planning seeds x 5 realizations',
     'results/rerun/issue42_table1_combined/table1_combined.json', lambda rel, t: combined_section(rel, t, 'Table I')),
    ('Fields on a soil that does not repeat: 3 planning seeds x 5 realizations',
     'results/rerun/issue42_fields_soil_combined/fields_combined.json', lambda rel, t: combined_section(rel, t, 'Fields')),
    ('Flights that reconstruct: Table I and the fields before and after the anchored model and ground markers',
     'results/rerun/issue40_flights_fields/flights_check.json', own_markdown('bench.flights_check')),
    ('Table I, realistic capture before the anchored model: 3 planning seeds x 5 realizations',
     'results/rerun/table1_combined/table1_combined.json', lambda rel, t: combined_section(rel, t, 'Table I')),
    ('Table I, seed 0: the plans, their rewards, paired differences', 'results/table1.json', table1_seed0_section),
    ('Fields before the anchored model: 3 planning seeds x 5 realizations',
     'results/rerun/fields_combined/fields_combined.json', lambda rel, t: combined_section(rel, t, 'Fields')),
    ('Plan-quality study, realistic capture', 'results/plan_quality.json', plan_quality_section),
    ('Reward candidates against the plan-quality study', 'results/rerun/issue42_reward_candidates/reward_candidates.json',
     own_markdown('bench.reward_candidates')),
    ('Real photographs', 'results/rerun/issue42_real/real/romi_real_plant.json', own_markdown('bench.bench_real')),
    ('Plant masks', 'results/masks.json', own_markdown('bench.bench_masks')),
    ('Second sortie', 'results/bench_sorties.json', sorties_section),
    ('Coverage of the prior against the Chamfer', 'results/coverage_check.json', own_markdown('bench.coverage_check')),
    ('Reconstruction stages', 'results/bench_recon.json', recon_stages_section),
    ('Cheaper reconstruction settings', 'results/bench_recon_speed.json', own_markdown('bench.bench_recon_speed')),
    ('make run on a soil that does not repeat',
     'results/rerun/issue42_make_run_soil/bench_make_run.json', own_markdown('bench.bench_make_run')),
    ('make run: wall time per setting', 'results/bench_make_run.json', own_markdown('bench.bench_make_run')),
    ('Planners: final reward', 'results/bench_planners.json', planners_section),
    ('Cost of a reward evaluation', 'results/bench_reward.json', reward_cost_section),
    ('The benchmarks on a Dask cluster', 'results/bench_cluster.json', cluster_section),
    ('Image pairs: exhaustive against pose-chosen', 'results/bench_matching.json', matching_section),
    ('Fleet images: transport and memory', 'results/bench_fleet_transport.json', fleet_section),
    ('Fleet routes', 'results/bench_routes.json', own_markdown('bench.bench_routes')),
    ('Viewer frame rates', 'results/bench_viewer.json', viewer_section),
]
IDEAL = [
    ('Table I, ideal capture', 'results/ideal/table1.json', ideal_table1_section),
    ('Table I on the procedural plant (not tuned on), ideal capture', 'results/heldout_procedural/table1.json',
     ideal_table1_section),
    ('Fields, ideal capture', 'results/ideal/bench_fields.json', fields_section),
    ('Plan-quality study, ideal capture', 'results/ideal/plan_quality.json', plan_quality_section),
]
#: superseded runs: (title, file, renderer, what became of it); docs/history.md tells their story
SUPERSEDED = [
    ('Table I, realistic capture, the anchored model and ground markers: 3 planning seeds x 5 realizations',
     'results/rerun/issue40_table1_combined/table1_combined.json', lambda rel, t: combined_section(rel, t, 'Table I'),
     'egp\'s rows were planned before the registration term of the reward (issue 42); superseded by Table I with '
     'it, whose other rows are these records.'),
    ('Fields, the anchored model and ground markers: 3 planning seeds x 5 realizations',
     'results/rerun/issue40_fields_combined/fields_combined.json', lambda rel, t: combined_section(rel, t, 'Fields'),
     'egp\'s rows were planned before the registration term of the reward (issue 42); superseded by the fields '
     'with it, whose other rows are these records.'),
    ('Fields, realistic capture, 2 realizations (2026-11-25)', 'results/bench_fields.json', fields_section,
     'Superseded by the fields with 3 seeds x 5 realizations.'),
    ('Fields, grid rows rerun with every SfM model registered', 'results/rerun/fields_merged_models_grid/bench_fields.json',
     fields_section, 'Superseded by the fields with 3 seeds x 5 realizations.'),
    ('Fields, row rows rerun with every SfM model registered', 'results/rerun/fields_merged_models_row/bench_fields.json',
     fields_section, 'Superseded by the fields with 3 seeds x 5 realizations.'),
    ('Table I plans flown over the blue screen', 'results/flights_blue_screen/table1_flights.json', flights_section,
     'Superseded by Table I under the realistic capture (over the textured soil).'),
    ('Second sortie, three_row and six_rect with every SfM model registered',
     'results/rerun/sorties_merged_models/bench_sorties.json', sorties_section, 'Superseded by the second sortie at a later commit.'),
    ('Second sortie, exhaustive matching', 'results/rerun/sorties_exhaustive/bench_sorties.json', sorties_section,
     'Superseded by the second sortie with pose-chosen pairs (the default).'),
    ('Second sortie, one_plant under coverage-graph', 'results/rerun/sorties_graph/bench_sorties.json', sorties_section,
     'The only run under coverage-graph; not rerun at the commit of the current second sortie.'),
    ('Second sortie, grid_3x3', 'results/rerun/sorties_grid_3x3/bench_sorties.json', sorties_section,
     'Its records, at the same code, were reused by the current second sortie.'),
    ('Plan-quality study, realistic capture before the anchored model',
     'results/rerun/plan_quality_before_anchored/plan_quality.json', plan_quality_section,
     'Superseded by the study rerun under the anchored model and ground markers (issue 42).'),
    ('Fields with the registration in the reward (egp planned again): 3 planning seeds x 5 realizations',
     'results/rerun/issue42_fields_combined/fields_combined.json', lambda rel, t: combined_section(rel, t, 'Fields'),
     'egp by parts before the tuned circle\'s rings were among its whole-field starts (and egp-graph, the same under '
     'coverage-graph); superseded by the fields with them, whose baselines are the same records.'),
    ('Real photographs at 9104f5a', 'results/real/romi_real_plant.json', own_markdown('bench.bench_real'),
     'The same scan (imported with --pose colmap) before the registration term of the reward and the dense pair '
     'budget; superseded by the run at the current code.'),
    ('Table I, egp with the registration\'s parts following exhaustive matching (measured, not kept)',
     'results/rerun/issue42_table1_egp_exhaustive/table1_combined.json', lambda rel, t: combined_section(rel, t, 'Table I'),
     'egp planned with CoverageParams(exhaustive_below=8): below 8 cameras every camera in one part, as the '
     'reconstruction matches every pair (issue 42). Against egp in Table I with the registration (the same seeds and '
     'realizations): no better, six_rect worse (map +0.151 [+0.030, +0.272]); the default stays the pair rule.'),
    ('Fields, egp starting from the circle\'s rings: 3 planning seeds x 5 realizations',
     'results/rerun/issue42_fields_rings_combined/fields_combined.json', lambda rel, t: combined_section(rel, t, 'Fields'),
     'Rendered over one soil texture tiled every 4.1 m (before c835c26), with the baselines\' records of the fields '
     'under the anchored model (planned before the registration term of the reward); superseded by the fields on a '
     'soil that does not repeat, every method planned again at one commit.'),
    ('Fields, egp planned with z-buffer cells of 3 cm on the plant (measured, not kept)',
     'results/rerun/issue42_fields_zcell_combined/fields_combined.json', lambda rel, t: combined_section(rel, t, 'Fields'),
     'egp planned with CoverageParams(zbuffer_cell=0.03) (issue 42): occlusion cells that measure 3 cm on the plant '
     'rather than 64 across the image; the baselines are the current fields\' records. Against egp with the image '
     'grid (the current fields): better on grid_3x3, worse on row_12, where planning seed 0 put the 12 cameras in '
     'three clusters of 4 whose anchored adjustment drifted in every realization (the points kept at the reported '
     'poses). Not kept; the option stays, and the plan-quality study reports it (coverage-object-cells).'),
    ('Plan-quality study, the rewards before the registration term',
     'results/rerun/issue42_plan_quality_before_registration/plan_quality.json', plan_quality_section,
     'The same reconstructions scored by the rewards before coverage weighed the registration (issue 42); '
     'superseded by the study scored again from its records.'),
    ('Plan-quality study, the anchored model before its last resort',
     'results/rerun/issue42_plan_quality_before_last_resort/plan_quality.json', plan_quality_section,
     'The same reconstructions before a drifting anchored adjustment kept the points at the reported poses; '
     'superseded by the study with them.'),
    ('Reward candidates, the anchored model before its last resort',
     'results/rerun/issue42_reward_candidates_before_last_resort/reward_candidates.json',
     own_markdown('bench.reward_candidates'),
     'The candidates on the study before its failures were reconstructed again (the failures\' AUC is measured here).'),
    ('Flights that reconstruct: Table I alone', 'results/rerun/issue40_flights/flights_check.json',
     own_markdown('bench.flights_check'), 'Superseded by the same check with the fields (issue 40).'),
    ('make run with the registration in the reward',
     'results/rerun/issue42_make_run/bench_make_run.json', own_markdown('bench.bench_make_run'),
     'Rendered over the soil tiled every 4.1 m; superseded by make run on a soil that does not repeat (its '
     'drones build a texture per 4.1 m square before their first picture).'),
    ('make run with the drones\' camera thread, the images\' heartbeat and the dense pair budget',
     'results/rerun/issue40_make_run_camera_thread/bench_make_run.json', own_markdown('bench.bench_make_run'),
     'Superseded by make run with the registration in the reward (issue 42: the planner\'s plan moved).'),
    ('make run with the anchored model and ground markers', 'results/rerun/issue40_make_run/bench_make_run.json',
     own_markdown('bench.bench_make_run'), 'Superseded by make run with the drones\' camera thread, the images\' '
     'heartbeat and the dense pair budget (issue 40).'),
    ('Planners, one_plant under coverage, rerun', 'results/rerun/bench_planners_one_plant_coverage.json',
     planners_section, 'A reproduction of the planners table\'s one_plant rows under coverage.'),
]


def render() -> str:
    head = ['# Results', '',
            'Generated by `make docs` (`python -m bench.docs`) from the JSON files under `results/`: do not edit by '
            'hand. Every table names its file, the commit it was measured at (or committed in, for files from '
            'before the benchmarks recorded it) and its command. Machine: x86_64, 2 CPU cores shared with other '
            'work, no GPU, Python 3.11 (each file records its own). Chamfer distances are x100 (Table I\'s '
            'unit); lower is better. Spreads say which they are: "sample std (n-1)" is computed here from the '
            'records, over the units named. Plans: `python -m bench.reference_plans` plans the cells of the '
            'Table I files again (results/reference_plans.json): a table whose plans come out differently is '
            'marked **STALE**. The story of the superseded runs: [history.md](history.md).', '', '## Contents', '']
    parts = [('Current results', CURRENT), ('Under the ideal capture (before the capture model)', IDEAL)]
    for group, items in parts:
        head.append(f'- {group}: ' + '; '.join(f'[{t}](#{anchor(t)})' for t, *_ in items))
    head.append('- Superseded runs: ' + '; '.join(f'[{t}](#{anchor(t)})' for t, *_ in SUPERSEDED))
    body = []
    for group, items in parts:
        body += [f'# {group}', '']
        body += [fn(rel, title) for title, rel, fn in items]
    body += ['# Superseded runs', '', 'Kept for the record (docs/history.md says what each one showed); each is '
             'superseded as said under its title.', '']
    for title, rel, fn, by in SUPERSEDED:
        text = fn(rel, title)
        first, rest = text.split('\n', 1)
        body.append(f'{first}\n\n{by}\n{rest}')
    return '\n'.join(head) + '\n\n' + '\n'.join(body).rstrip() + '\n'


def anchor(title: str) -> str:
    """GitHub's anchor of a heading."""
    keep = ''.join(c for c in title.lower() if c.isalnum() or c in ' -_')
    return keep.replace(' ', '-')


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--out', type=Path, default=OUT)
    ap.add_argument('--check', action='store_true', help='exit 1 when the file differs from what the results give')
    args = ap.parse_args(argv)
    text = render()
    if args.check:
        same = args.out.is_file() and args.out.read_text() == text
        print(f'{args.out}: {"up to date" if same else "differs from the results: run make docs"}')
        return 0 if same else 1
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(f'wrote {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
