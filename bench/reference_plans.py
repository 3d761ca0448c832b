#!/usr/bin/env python3
"""Do the plans the result tables rest on still come out of the planner? (issue 39, item 6)

A table's Chamfer figures are the reconstructions of its plans; a table describes the code only
while planning its cells again gives the same cameras. Two checks:

- ``python -m bench.reference_plans [TABLE.json ...] [--scenarios ...] [--rows ...]`` plans every
  seed-0 cell of Table I files again (default ``results/table1.json``; each cell keeps its plan's
  ``cameras``) with the table's settings (its rows' method and reward, its evaluations, 50 initial
  evaluations as ``bench/table1.py``, its plants, scene seed 0, one torch thread) and compares the
  cameras within :data:`TOLERANCE` (:func:`compare`). Writes ``results/reference_plans.json``: per table file and cell whether the
  plan reproduces, the largest camera difference, the table's reward and today's, and the commit
  and date of the check (a later check of a cell replaces the earlier one). ``python -m bench.docs``
  marks a table stale in docs/results.md while any of its checked plans does not reproduce.
  An egp plan takes 10-60 s: run it beside other work with ``nice`` and ``OMP_NUM_THREADS=1``, and
  with ``--out`` outside the checkout (the file is tracked: writing it would mark the commit of the
  later cells ``-dirty``), then copy it in.
- ``python -m bench.reference_plans --pins`` writes ``tests/data/reference_plans.json``: the
  cameras of :data:`PINS`, small plans (seconds each); ``--verify-pins`` plans them again and
  compares them within :data:`TOLERANCE`, one JSON line a pin (``bit_identical`` says whether they
  also agree bit for bit), exit 1 when one moved: ``tests/test_reference_plans.py`` runs it.
  Rewrite the pins only on purpose, with a commit that says why the plans changed.

Why a tolerance, not bits: BLAS and torch kernels round differently on different CPU models, even
with the same instruction set (``ATEN_CPU_CAPABILITY=avx2``), so the same code plans the same
cameras to about 1e-10 m, not bit for bit, on another machine. What a change of the planner moves
is far larger: its optimizers step by millimetres at least (trust regions, grids, annealing
moves), so a camera more than 1 um away or turned by more than 1 urad, or a reward more than 1e-9
away, is another plan. Both plan with torch's AVX2 kernels (``bench.pin_cpu_kernels``), as the
committed tables were planned: under AVX512 Table I's one_plant egp plan comes out as another plan.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Iterator, Optional

import numpy as np

if not __package__:  # python bench/reference_plans.py: as python -m bench.reference_plans (bench/_script.py)
    import _script  # noqa: F401
from bench import cpu_capability  # noqa: E402
from bench.cache import write_json  # noqa: E402
from bench.common import CORN50, ROOT, SCENARIOS, plan_cell  # noqa: E402
from bench.publish import git_commit, provenance  # noqa: E402

RESULTS = ROOT / 'results' / 'reference_plans.json'
PINS_FILE = ROOT / 'tests' / 'data' / 'reference_plans.json'
#: what a pin is besides its cameras (a pin of other settings is another pin)
PINS_KEYS = ('scenario', 'variant', 'reward_model', 'evaluations', 'initial_evaluations', 'models')
#: initial evaluations of egp/gp in Table I (bench/table1.py's default; older table files do not record it)
TABLE_INIT = 50

#: The pinned plans of the test suite: name -> (scenario, variant of bench.common.VARIANTS, reward,
#: evaluations, initial evaluations, plants: '' procedural or 'corn50'). Small budgets: seconds each;
#: egp's pins are its cheap stage (``egp-cheap``: no simulated flights, whose reconstructions are
#: not bit-reproducible across machines and take minutes), the plans its flights choose among.
PINS = {
    'one_plant-circle': ('one_plant', 'circle', 'coverage', 100, 50, ''),
    'one_plant-arc': ('one_plant', 'arc', 'coverage', 100, 50, ''),
    'one_plant-sa': ('one_plant', 'sa', 'coverage', 100, 50, ''),
    'one_plant-egp': ('one_plant', 'egp-cheap', 'coverage', 20, 12, ''),
    'one_plant-egp-paper-config': ('one_plant', 'egp-paper-config', 'paper', 20, 12, ''),
    'corn50-one_plant-egp': ('one_plant', 'egp-cheap', 'coverage', 20, 12, 'corn50'),
}


def models_folder(tag: str) -> Optional[str]:
    """The plants folder of a table's ``models`` tag: '' for the procedural corn, ../shared's Corn50
    for 'corn50'; None where that folder is not on this machine."""
    if tag in ('', 'procedural'):
        return ''
    if tag == CORN50.name:
        return str(CORN50) if CORN50.is_dir() else None
    return None


def digest(cameras) -> str:
    """sha256 of the cameras as float64 (bit-identical plans have the same digest)."""
    return hashlib.sha256(np.ascontiguousarray(np.asarray(cameras, dtype=np.float64)).tobytes()).hexdigest()


def replan(scenario: str, variant: str, reward: str, evals: int, init: int, models: str, seed: int = 0) -> dict:
    """The plan of a cell computed afresh (``bench.common.plan_cell`` in a throw-away cache)."""
    with tempfile.TemporaryDirectory(prefix='vp_reference_plans_') as tmp:
        return plan_cell(Path(tmp), scenario, variant, seed, evals, init, models, None, reward)


#: What "the same plan" allows (module docstring): each camera's centre (m), the angle between its
#: viewing directions (rad) and the reward (absolute).
TOLERANCE = {'position_m': 1e-6, 'direction_rad': 1e-6, 'reward': 1e-9}


def direction_angles(a, b) -> np.ndarray:
    """Angles (rad) between the viewing directions of cameras ``a`` and ``b`` (M, 6), row by row:
    atan2 of the cross and dot products, exact near 0 where arccos of the dot is not."""
    va, vb = np.asarray(a, dtype=float)[:, 3:], np.asarray(b, dtype=float)[:, 3:]
    return np.arctan2(np.linalg.norm(np.cross(va, vb), axis=1), np.einsum('ij,ij->i', va, vb))


def compare(reference, now, reward_reference: Optional[float] = None, reward_now: Optional[float] = None) -> dict:
    """``reproduces``: the same cameras within :data:`TOLERANCE` (and the same reward, when both are
    given); ``bit_identical``; the largest centre distance (m) and direction angle (rad)."""
    a, b = np.asarray(reference, dtype=float), np.asarray(now, dtype=float)
    same_shape = a.ndim == 2 and a.shape == b.shape and a.shape[1] == 6 and a.size > 0
    dc = float(np.max(np.linalg.norm(a[:, :3] - b[:, :3], axis=1))) if same_shape else None
    dv = float(np.max(direction_angles(a, b))) if same_shape else None
    close = same_shape and np.isfinite([dc, dv]).all() and dc <= TOLERANCE['position_m'] \
        and dv <= TOLERANCE['direction_rad']
    if reward_reference is not None and reward_now is not None:
        close = close and abs(float(reward_reference) - float(reward_now)) <= TOLERANCE['reward']
    return {'reproduces': bool(close), 'bit_identical': bool(a.shape == b.shape and np.array_equal(a, b)),
            'max_position_diff_m': dc, 'max_direction_diff_rad': dv}


def check_table(path: Path, scenarios=None, rows=None, log=print) -> Iterator[tuple[str, dict]]:
    """(cell, check record) of the seed-0 plans of one Table I file, one cell at a time (cells
    without cameras, or whose plants are not on this machine, are left out, with a line saying so)."""
    table = json.loads(path.read_text())
    models = models_folder(table.get('models', ''))
    for name, cell in table.get('cells', {}).items():
        scenario, row = name.split('/', 1)
        if (scenarios and scenario not in scenarios) or (rows and row not in rows) or not cell.get('cameras'):
            continue
        if models is None:
            log(f'{path}: {name}: plants {table.get("models")!r} not on this machine, not checked')
            continue
        variant, reward = table['rows'][row]
        t0 = time.monotonic()
        plan = replan(scenario, variant, reward, int(table['evaluations']), TABLE_INIT, models)
        rec = {**compare(cell['cameras'], plan['cameras'], cell.get('reward'), plan['reward']),
               'reward_table': cell.get('reward'),
               'reward_now': plan['reward'], 'seconds': round(time.monotonic() - t0, 1),
               'commit': git_commit(), 'date': datetime.now(timezone.utc).strftime('%Y-%m-%d'),
               'torch_cpu_capability': cpu_capability()}
        log(f'{path}: {name}: {"reproduces" if rec["reproduces"] else "DIFFERS"} (reward {rec["reward_table"]} '
            f'-> {rec["reward_now"]}, cameras within {rec["max_position_diff_m"]} m and {rec["max_direction_diff_rad"]} rad, '
            f'{rec["seconds"]} s)')
        yield name, rec


def load(path: Path = RESULTS) -> dict:
    """The recorded checks, ``{'tables': {table path: {'cells': {cell: record}}}}`` ({} when none)."""
    return json.loads(path.read_text()) if path.is_file() else {'tables': {}}


def stale_cells(checks: dict, table: str) -> list[str]:
    """The cells of ``table`` (a path relative to the repository) whose plans were found not to reproduce."""
    cells = checks.get('tables', {}).get(table, {}).get('cells', {})
    return sorted(c for c, r in cells.items() if not r.get('reproduces'))


def pin_record(name: str) -> Optional[dict]:
    """The plan of pin ``name`` computed now, as the pins file keeps it (None: its plants are absent)."""
    scenario, variant, reward, evals, init, tag = PINS[name]
    models = models_folder(tag)
    if models is None:
        return None
    plan = replan(scenario, variant, reward, evals, init, models)
    return {'scenario': scenario, 'variant': variant, 'reward_model': reward, 'evaluations': evals,
            'initial_evaluations': init, 'models': tag or 'procedural', 'cameras': plan['cameras'],
            'sha256': digest(plan['cameras']), 'reward': plan['reward'], 'torch_cpu_capability': cpu_capability()}


def verify_pins(path: Path = PINS_FILE) -> bool:
    """Plan every pin again and compare it with the pinned cameras (:func:`compare`); prints one
    JSON line a pin (``name``, ``reproduces`` or ``skipped``, ``bit_identical``, the differences,
    the digests, rewards and the CPU kernels used)."""
    pinned = json.loads(path.read_text())['pins']
    ok = True
    for name in PINS:
        now = pin_record(name)
        if now is None:
            print(json.dumps({'name': name, 'skipped': f'plants {PINS[name][5]!r} not on this machine'}), flush=True)
            continue
        pin = pinned.get(name)
        diff = compare(pin['cameras'], now['cameras'], pin['reward'], now['reward']) if pin is not None else {}
        same = pin is not None and {k: pin[k] for k in PINS_KEYS} == {k: now[k] for k in PINS_KEYS} \
            and diff['reproduces']
        ok &= same
        print(json.dumps({'name': name, 'reproduces': same, **{k: v for k, v in diff.items() if k != 'reproduces'},
                          'sha256_pinned': pin and pin['sha256'],
                          'sha256_now': now['sha256'], 'reward_pinned': pin and pin['reward'],
                          'reward_now': now['reward'], 'torch_cpu_capability': now['torch_cpu_capability']}),
              flush=True)
    return ok


def write_pins(path: Path = PINS_FILE) -> dict:
    pins = {}
    for name in PINS:
        rec = pin_record(name)
        if rec is None:
            raise SystemExit(f'reference_plans: the plants of pin {name} are not on this machine')
        pins[name] = rec
        print(f'{name}: reward {rec["reward"]:.6f} sha256 {rec["sha256"][:16]}')
    write_json(path, {'note': 'plans pinned by tests/test_reference_plans.py (python -m bench.reference_plans --pins)',
                      **provenance(), 'pins': pins}, indent=1)
    return pins


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('tables', nargs='*', type=Path, default=[ROOT / 'results' / 'table1.json'],
                    help='Table I results files (default results/table1.json)')
    ap.add_argument('--scenarios', nargs='+', choices=list(SCENARIOS), help='only these scenarios')
    ap.add_argument('--rows', nargs='+', help="only these rows, e.g. circle arc sa egp")
    ap.add_argument('--out', type=Path, default=RESULTS)
    ap.add_argument('--pins', action='store_true', help=f'write the test pins ({PINS_FILE.relative_to(ROOT)}) instead')
    ap.add_argument('--verify-pins', action='store_true', help='plan the test pins again and compare (exit 1: moved)')
    args = ap.parse_args(argv)
    import torch

    torch.set_num_threads(1)
    if args.pins:
        write_pins()
        return 0
    if args.verify_pins:
        return 0 if verify_pins() else 1
    for path in args.tables:
        if not path.is_file():
            ap.error(f'no such table: {path}')
    checks = load(args.out)
    for path in args.tables:
        key = str(path.resolve().relative_to(ROOT)) if path.resolve().is_relative_to(ROOT) else str(path)
        entry = checks['tables'].setdefault(key, {'cells': {}})
        for name, rec in check_table(path, args.scenarios, args.rows):
            entry['cells'][name] = rec
            write_json(args.out, {**checks, **provenance()}, indent=1)  # after every cell: a long run keeps its progress
    return 0


if __name__ == '__main__':
    sys.exit(main())
