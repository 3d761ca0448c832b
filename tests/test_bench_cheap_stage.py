"""bench/bench_cheap_stage.py: egp's time given to the other methods, the reward read against time
and evaluations, failures and missing runs counted, and a real (tiny) run end to end."""
from __future__ import annotations

import json

import pytest

from bench import bench_cheap_stage as bcs


def _run(improvements, evaluations, seconds=10.0):
    """A run record: improvements as (wall s, evaluations, best); CPU time half the wall time."""
    return {'reward': improvements[-1][2], 'evaluations': evaluations, 'seconds': seconds, 'cpu_seconds': seconds / 2,
            'improvements': [[t, t / 2, e, b] for t, e, b in improvements], 'load': [1.0, 2.0]}


def test_best_at_reads_time_and_evaluations() -> None:
    run = _run([(0.5, 1, 0.0), (2.0, 5, 0.4), (6.0, 40, 0.7)], 60)
    assert bcs.best_at(run, seconds=0.1) == 0.0  # before the first evaluation
    assert bcs.best_at(run, seconds=2.0) == 0.4 and bcs.best_at(run, seconds=5.9) == 0.4
    assert bcs.best_at(run, seconds=2.9, clock='cpu') == 0.4 and bcs.best_at(run, seconds=3.0, clock='cpu') == 0.7
    assert bcs.best_at(run, evaluations=39) == 0.4 and bcs.best_at(run, evaluations=60) == 0.7
    assert bcs.best_at(run, evaluations=61) is None  # fewer evaluations than asked: no reading
    assert bcs.best_at({'error': 'NoFeasiblePlanError', 'error_msg': 'x'}, seconds=1.0) is None


def test_failures_and_missing_runs_are_counted_and_pairs_skip_them() -> None:
    egp = {0: _run([(1.0, 1, 0.5), (9.0, 100, 0.80)], 100), 1: _run([(1.0, 1, 0.5), (9.0, 100, 0.82)], 100),
           2: {'error': 'RuntimeError', 'error_msg': 'x', 'seconds': 1.0}}
    cmaes = {0: _run([(0.5, 1, 0.6), (4.0, 400, 0.90)], 900), 1: _run([(0.5, 1, 0.6), (9.5, 900, 0.88)], 900),
             2: {'error': 'NO_REFERENCE', 'error_msg': 'egp failed: x'}}
    sa = {0: _run([(0.5, 1, 0.3), (8.0, 700, 0.85)], 800)}  # seed 1 and 2 missing
    runs = {(v, s): r for v, by in (('egp', egp), ('cmaes', cmaes), ('sa', sa)) for s, r in by.items()}
    t = bcs.summarize(runs, ('egp', 'sa', 'cmaes'), 3)
    c = t['variants']['cmaes']['at_fraction']
    assert c['1']['values'] == [0.90, 0.88, None] and (c['1']['n'], c['1']['failed']) == (2, 1)
    assert c['0.5']['values'] == [0.90, 0.6, None]  # seed 1 reached 0.88 after 9.5 s of egp's 10
    assert t['variants']['cmaes']['at_reference_evaluations']['values'] == [0.6, 0.6, None]
    assert t['variants']['sa']['at_fraction']['1']['failed'] == 2 and t['variants']['sa']['errors'] == ['MISSING'] * 2
    d = t['paired']['cmaes']['at_T']
    assert d['n'] == 2 and d['mean'] == pytest.approx(((0.90 - 0.80) + (0.88 - 0.82)) / 2) and d['both_failed'] == 1
    assert t['paired']['sa']['at_T']['n'] == 1 and t['paired']['sa']['at_T']['missing'] == 0
    assert t['winner_at_T'] == 'cmaes' and t['runner_up'] == 'egp'  # fewest failures first, then the highest mean
    text = bcs.markdown({'date': 'd', 'machine': 'm', 'models': 'corn50', 'reward': 'coverage', 'seeds': [0, 1, 2],
                         'evaluations': 100, 'initial': 50, 'cores': 2, 'clock': 'wall',
                         'load_1min': {'min': 1.0, 'mean': 1.5, 'max': 2.0}, 'scenarios': {'one_plant': t}})
    assert '| cmaes | ' in text and '0.8900 +- 0.0141 (n=2, 1 failed)' in text and '0.8500 (n=1, 2 failed)' in text
    assert 'Highest at T: **cmaes**, +0.080' in text


def test_a_tiny_run_writes_its_report(tmp_path) -> None:
    """Procedural one_plant, one seed, egp with 4 evaluations: every variant runs in egp's time,
    each run is cached and the report carries the command and commit."""
    args = ['--models', '', '--scenarios', 'one_plant', '--seeds', '1', '--evaluations', '4', '--initial', '2',
            '--pilot', '10', '--out', str(tmp_path)]
    assert bcs.main(args) == 0
    report = json.loads((tmp_path / 'bench_cheap_stage-procedural.json').read_text())
    assert report['commit'] and report['command'] and report['failed'] == 0 and report['runs'] == len(bcs.VARIANTS)
    records = report['records']
    T = records['one_plant/egp/seed0']['seconds']
    for v in bcs.VARIANTS[1:]:
        r = records[f'one_plant/{v}/seed0']
        assert r['time_limit'] == pytest.approx(T) and r['evaluations'] > 0
        if v != 'sa':  # stopped by the time, not by the registry's bound
            assert r['stopped'] and r['evaluations'] < r['budget']
    assert records['one_plant/sa/seed0']['rate_per_s'] > 0
    assert records['one_plant/sa/seed0']['pilot_evaluations'] == 10
    assert '## one_plant (N = 4)' in (tmp_path / 'bench_cheap_stage-procedural.md').read_text()
    assert len(list((tmp_path / 'cache' / 'cheap_stage').glob('procedural-one_plant-n4-seed0-*.json'))) == 4
