#!/usr/bin/env python3
"""docs/results.md and docs/history_results.md from the results files: ``make docs``.

docs/results.md holds the current results (:data:`CURRENT`, :data:`IDEAL`), docs/history_results.md
the runs later ones superseded (:data:`SUPERSEDED`, each with what superseded it): which is which
is decided here, in those lists. Every figure of both is read from a file under results/ by this
script (a JSON file, or the markdown a retired study committed beside it), never copied by hand
(tests/test_docs.py regenerates both and compares them with the committed files), and every table
names the file, the commit and the command it came from: the ``commit`` and ``command`` the
benchmark recorded (``bench.publish.publish``), or for a file written before benchmarks recorded
them the commit that committed it and the command from the README of the time (:data:`LEGACY`, a
mapping of this script). A Table I file whose plans were planned again and found to differ
(``python -m bench.reference_plans`` -> results/reference_plans.json) is marked stale. Spreads are
named: "sample std (n-1)" where this script computes them from the records, "population std" where
a file holds one so computed.

``--check``: exit 1 when a document is not what the results give (nothing written).
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

if not __package__:  # python bench/docs.py: as python -m bench.docs (bench/_script.py)
    import _script  # noqa: F401
from bench import reference_plans  # noqa: E402
from bench.common import ROOT  # noqa: E402
from bench.publish import num, table  # noqa: E402
from bench.stats import describe, describe_difference, summary  # noqa: E402

OUT = ROOT / 'docs'
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


# ---------------------------------------------------------------- smaller benchmarks

def own_markdown(module: str) -> Callable[[str, str], str]:
    """A section from a benchmark's own ``markdown(data)`` of its JSON (``module``: the benchmark,
    imported when the section is rendered)."""
    def render(rel: str, title: str) -> str:
        data = load(rel)
        md = demote(importlib.import_module(module).markdown(data), 2).split('\n', 1)[1].lstrip()
        return f'## {title}\n\n{md}\n{source(rel, data)}\n'
    return render


def committed_markdown(rel: str, title: str) -> str:
    """A section from the markdown committed beside a results file (``results/<study>.md``): the
    report of a study whose code has retired (it is in git history), as that study wrote it."""
    data = load(rel)
    md = demote((ROOT / rel).with_suffix('.md').read_text(), 2).split('\n', 1)[1].lstrip()
    return f'## {title}\n\n{md}\n{source(rel, data)}\n'


#: (section title, results file, renderer), in the order of docs/results.md
CURRENT = [
    ("Table I after: egp's plans checked by simulated flights: 3 planning seeds x 5 realizations",
     'results/rerun/issue52_table1_combined/table1_combined.json', lambda rel, t: combined_section(rel, t, 'Table I')),
    ("Fields after (row_12, grid_3x3): egp's plans checked by simulated flights: 3 planning seeds x 5 realizations",
     'results/rerun/issue52_fields_combined/fields_combined.json', lambda rel, t: combined_section(rel, t, 'Fields')),
    ("Flights chosen by batch BO, measured and not kept: one_plant, 3 planning seeds x 5 realizations (row "
     "'egp (flight bo)')", 'results/rerun/issue52_flight_bo_one_plant_combined/table1_combined.json',
     lambda rel, t: combined_section(rel, t, 'Table I')),
    ('Flights chosen by batch BO, measured and not kept: row_12, seed 0 x 5 realizations (egp-flight-bo)',
     'results/rerun/issue52_flight_bo_row_seed0_combined/fields_combined.json',
     lambda rel, t: combined_section(rel, t, 'Fields')),
    ('Flights chosen by batch BO, measured and not kept: grid_3x3, seed 0 x 5 realizations (egp-flight-bo)',
     'results/rerun/issue52_flight_bo_grid_seed0_combined/fields_combined.json',
     lambda rel, t: combined_section(rel, t, 'Fields')),
    ('Table I before the simulated flights, the registration in the reward: 3 planning seeds x 5 realizations',
     'results/rerun/issue42_table1_combined/table1_combined.json', lambda rel, t: combined_section(rel, t, 'Table I')),
    ('Fields on a soil that does not repeat: 3 planning seeds x 5 realizations',
     'results/rerun/issue42_fields_soil_combined/fields_combined.json', lambda rel, t: combined_section(rel, t, 'Fields')),
    ('Flights that reconstruct: Table I and the fields before and after the anchored model and ground markers',
     'results/rerun/issue40_flights_fields/flights_check.json', committed_markdown),
    ('Table I, realistic capture before the anchored model: 3 planning seeds x 5 realizations',
     'results/rerun/table1_combined/table1_combined.json', lambda rel, t: combined_section(rel, t, 'Table I')),
    ('Table I, seed 0: the plans, their rewards, paired differences', 'results/table1.json', table1_seed0_section),
    ("row_12 planning with egp's simulated flights (seed 0, plan only)",
     'results/rerun/issue52_row12_planning/bench_fields.json', committed_markdown),
    ('Fields before the anchored model: 3 planning seeds x 5 realizations',
     'results/rerun/fields_combined/fields_combined.json', lambda rel, t: combined_section(rel, t, 'Fields')),
    ('Plan-quality study, realistic capture', 'results/plan_quality.json', own_markdown('bench.plan_quality')),
    ('Reward candidates against the plan-quality study', 'results/rerun/issue42_reward_candidates/reward_candidates.json',
     committed_markdown),
    ('Real photographs', 'results/rerun/issue42_real/real/romi_real_plant.json', own_markdown('bench.bench_real')),
    ('Plant masks', 'results/masks.json', committed_markdown),
    ('Second sortie', 'results/bench_sorties.json', sorties_section),
    ('Coverage of the prior against the Chamfer', 'results/coverage_check.json', committed_markdown),
    ("Planning time: one_plant with egp's simulated flights (the CLI)",
     'results/rerun/issue52_plan_time/bench_plan_time.json', own_markdown('bench.bench_plan_time')),
    ('Reconstruction stages', 'results/bench_recon.json', own_markdown('bench.bench_recon')),
    ('Cheaper reconstruction settings', 'results/bench_recon_speed.json', committed_markdown),
    ("make run after: egp's plans checked by simulated flights, the recon node's flight workers readied while the "
     "cheap stage computes", 'results/rerun/issue52_make_run_recon_warm/bench_make_run.json',
     own_markdown('bench.bench_make_run')),
    ('make run before the simulated flights (a soil that does not repeat)',
     'results/rerun/issue42_make_run_soil/bench_make_run.json', own_markdown('bench.bench_make_run')),
    ('make run: wall time per setting', 'results/bench_make_run.json', own_markdown('bench.bench_make_run')),
    ('Planners: final reward', 'results/bench_planners.json', own_markdown('bench.bench_planners')),
    ("The cheap stage: egp's CPU time given to CMA-ES, SA and random search",
     'results/bench_cheap_stage-corn50-cpu.json', own_markdown('bench.bench_cheap_stage')),
    ("The cheap stage: egp's wall time given to CMA-ES, SA and random search (one_plant, a loaded machine)",
     'results/bench_cheap_stage-corn50.json', own_markdown('bench.bench_cheap_stage')),
    ('Cost of a reward evaluation', 'results/bench_reward.json', own_markdown('bench.bench_reward')),
    ('The benchmarks on a Dask cluster', 'results/bench_cluster.json', own_markdown('bench.bench_cluster')),
    ('Image pairs: exhaustive against pose-chosen', 'results/bench_matching.json', committed_markdown),
    ('Fleet images: transport and memory', 'results/bench_fleet_transport.json', committed_markdown),
    ('Fleet routes', 'results/bench_routes.json', own_markdown('bench.bench_routes')),
    ('Viewer frame rates', 'results/bench_viewer.json', committed_markdown),
]
IDEAL = [
    ('Table I, ideal capture', 'results/ideal/table1.json', table1_seed0_section),
    ('Table I on the procedural plant (not tuned on), ideal capture', 'results/heldout_procedural/table1.json',
     table1_seed0_section),
    ('Fields, ideal capture', 'results/ideal/bench_fields.json', fields_section),
    ('Plan-quality study, ideal capture', 'results/ideal/plan_quality.json', own_markdown('bench.plan_quality')),
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
    ('Table I plans flown over the blue screen', 'results/flights_blue_screen/table1_flights.json', committed_markdown,
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
     'results/rerun/plan_quality_before_anchored/plan_quality.json', own_markdown('bench.plan_quality'),
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
     'results/rerun/issue42_plan_quality_before_registration/plan_quality.json', own_markdown('bench.plan_quality'),
     'The same reconstructions scored by the rewards before coverage weighed the registration (issue 42); '
     'superseded by the study scored again from its records.'),
    ('Plan-quality study, the anchored model before its last resort',
     'results/rerun/issue42_plan_quality_before_last_resort/plan_quality.json', own_markdown('bench.plan_quality'),
     'The same reconstructions before a drifting anchored adjustment kept the points at the reported poses; '
     'superseded by the study with them.'),
    ('Reward candidates, the anchored model before its last resort',
     'results/rerun/issue42_reward_candidates_before_last_resort/reward_candidates.json',
     committed_markdown,
     'The candidates on the study before its failures were reconstructed again (the failures\' AUC is measured here).'),
    ('Flights that reconstruct: Table I alone', 'results/rerun/issue40_flights/flights_check.json',
     committed_markdown, 'Superseded by the same check with the fields (issue 40).'),
    ("make run with egp's simulated flights, before the recon node readied its flight workers",
     'results/rerun/issue52_make_run_warm/bench_make_run.json', own_markdown('bench.bench_make_run'),
     'Superseded by make run with the planner asking the recon node to ready its flight workers as the cheap stage '
     'starts (a goal with no plans; the same Chamfer).'),
    ("make run with egp's first simulated flights",
     'results/rerun/issue52_make_run/bench_make_run.json', own_markdown('bench.bench_make_run'),
     'Superseded by make run with the flights\' workers readied while the cheap stage computes, one batch of flights '
     'and no segmentation pass in a realistic flight\'s render (the same Chamfer).'),
    ('make run with the registration in the reward',
     'results/rerun/issue42_make_run/bench_make_run.json', own_markdown('bench.bench_make_run'),
     'Rendered over the soil tiled every 4.1 m; superseded by make run before the simulated flights (its '
     'drones build a texture per 4.1 m square before their first picture).'),
    ('make run with the drones\' camera thread, the images\' heartbeat and the dense pair budget',
     'results/rerun/issue40_make_run_camera_thread/bench_make_run.json', own_markdown('bench.bench_make_run'),
     'Superseded by make run with the registration in the reward (issue 42: the planner\'s plan moved).'),
    ('make run with the anchored model and ground markers', 'results/rerun/issue40_make_run/bench_make_run.json',
     own_markdown('bench.bench_make_run'), 'Superseded by make run with the drones\' camera thread, the images\' '
     'heartbeat and the dense pair budget (issue 40).'),
    ('Planners, one_plant under coverage, rerun', 'results/rerun/bench_planners_one_plant_coverage.json',
     own_markdown('bench.bench_planners'), 'A reproduction of the planners table\'s one_plant rows under coverage.'),
]


#: the generated documents under docs/: the current results, and the superseded runs' tables
RESULTS_MD, SUPERSEDED_MD = 'results.md', 'history_results.md'


def preamble(what: str) -> list[str]:
    """The opening paragraph both documents share: what they are, how to read their tables."""
    return [f'Generated by `make docs` (`python -m bench.docs`) from the JSON files under `results/`: do not edit '
            f'by hand. {what} Every table names its file, the commit it was measured at (or committed in, for files '
            'from before the benchmarks recorded it) and its command. Machine: x86_64, 2 CPU cores shared with other '
            'work, no GPU, Python 3.11 (each file records its own). Chamfer distances are x100 (Table I\'s '
            'unit); lower is better. Spreads say which they are: "sample std (n-1)" is computed here from the '
            'records, over the units named. Plans: `python -m bench.reference_plans` plans the cells of the '
            'Table I files again (results/reference_plans.json): a table whose plans come out differently is '
            'marked **STALE**.']


def render_results() -> str:
    """docs/results.md: the current results (:data:`CURRENT`, :data:`IDEAL`)."""
    head = ['# Results', ''] + preamble(
        f'The runs later ones superseded are in [{SUPERSEDED_MD}]({SUPERSEDED_MD}), their story in '
        '[history.md](history.md).') + ['', '## Contents', '']
    parts = [('Current results', CURRENT), ('Under the ideal capture (before the capture model)', IDEAL)]
    for group, items in parts:
        head.append(f'- {group}: ' + '; '.join(f'[{t}](#{anchor(t)})' for t, *_ in items))
    body = []
    for group, items in parts:
        body += [f'# {group}', '']
        body += [fn(rel, title) for title, rel, fn in items]
    return '\n'.join(head) + '\n\n' + '\n'.join(body).rstrip() + '\n'


def render_superseded() -> str:
    """docs/history_results.md: the superseded runs (:data:`SUPERSEDED`), each with what superseded it."""
    head = ['# Superseded runs', ''] + preamble(
        f'Kept for the record: each run here was superseded as said under its title; the current results are in '
        f'[{RESULTS_MD}]({RESULTS_MD}), what each run showed in [history.md](history.md).') + ['', '## Contents', '']
    head += [f'- [{t}](#{anchor(t)})' for t, *_ in SUPERSEDED]
    body = []
    for title, rel, fn, by in SUPERSEDED:
        first, rest = fn(rel, title).split('\n', 1)
        body.append(f'{first}\n\n{by}\n{rest}')
    return '\n'.join(head) + '\n\n' + '\n'.join(body).rstrip() + '\n'


def render() -> dict[str, str]:
    """The generated documents: file name under docs/ -> its text."""
    return {RESULTS_MD: render_results(), SUPERSEDED_MD: render_superseded()}


def anchor(title: str) -> str:
    """GitHub's anchor of a heading."""
    keep = ''.join(c for c in title.lower() if c.isalnum() or c in ' -_')
    return keep.replace(' ', '-')


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--out', type=Path, default=OUT, help='folder of the documents (default: %(default)s)')
    ap.add_argument('--check', action='store_true', help='exit 1 when a document differs from what the results give')
    args = ap.parse_args(argv)
    stale = 0
    for name, text in render().items():
        path = args.out / name
        if args.check:
            same = path.is_file() and path.read_text() == text
            stale += not same
            print(f'{path}: {"up to date" if same else "differs from the results: run make docs"}')
            continue
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
        print(f'wrote {path}')
    return 1 if stale else 0


if __name__ == '__main__':
    sys.exit(main())
