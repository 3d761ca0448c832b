"""The benchmarks (``python -m bench.<name> --help``; README "Development", results in docs/results.md).

The library the benchmarks are built on:

- ``common``: the scenarios and scenes, the planner variants, cached planning runs, the
  reconstruction record of a plan (one wind realization at a time, failures recorded);
- ``cache``: the resumable JSON cache under ``<out>/cache`` and the one JSON writer;
- ``cluster``: the Dask task runner (cached tasks are not submitted, failures are records);
- ``stats``: sample spreads with their n, ranks with failures last, paired t-intervals, Spearman;
- ``options``: the options the benchmarks share (``--models``, ``--out``, the cluster's, ...);
- ``publish``: a result's JSON with its command and commit, its markdown beside it, printed;
- ``reference_plans``: do the tables' plans still come out of the planner;
- ``docs``: docs/results.md (current results) and docs/history_results.md (superseded runs).

The benchmarks a user runs: ``table1`` (Table I; ``table1_combine`` joins runs made in slices),
``bench_fields`` (fields; ``fields_combine``), ``bench_planners``, ``plan_quality``, ``bench_real``
(a real scan's views), ``bench_sorties`` (the second sortie), ``bench_make_run``, ``bench_recon``
(the reconstruction's speed), ``bench_reward`` (a reward evaluation's cost), ``bench_routes`` (fleet
routes), ``bench_cluster`` (the engine on 1 and 2 workers). Studies run once keep their results
under ``results/`` (docs/results.md shows their committed markdown); their code is in git history.

A package: the benchmarks import each other as ``bench.common``, ``bench.stats``, ... and the
tests import them so too (pytest.ini puts the repository root on ``sys.path``). Run them from
the repository root as ``python -m bench.table1 ...``; ``python bench/table1.py ...`` (the form
the recorded commands of older results use) runs the same code (``bench/_script.py``).
Dask workers import them from the repository root (``bench.cluster.open_client`` gives the local
workers that path; remote workers need ``PYTHONPATH=<repo>``).

A benchmark run as a program plans with torch's AVX2 kernels (:func:`pin_cpu_kernels`).
"""
import os
import sys
from typing import Optional

#: torch's CPU kernels of the benchmarks' plans (``ATEN_CPU_CAPABILITY``)
CPU_CAPABILITY = 'avx2'


def pin_cpu_kernels() -> None:
    """Plan with torch's AVX2 kernels unless ``ATEN_CPU_CAPABILITY`` says otherwise (it must be set
    before torch is imported; Dask's local workers inherit it). torch picks its vector kernels by
    CPU, and a BO run follows the last bit of its sums: Table I's one_plant egp plan (reward
    0.8573) comes out again bit for bit under AVX2 and as another plan (0.8600) under AVX512, the
    same code on the same machine (issue 39, item 6). Every x86-64 CPU of the last decade has AVX2;
    MKL, torch's BLAS, still picks its own code path by CPU. The suite's nodes and CLIs keep
    torch's own choice."""
    os.environ.setdefault('ATEN_CPU_CAPABILITY', CPU_CAPABILITY)


def cpu_capability() -> Optional[str]:
    """torch's CPU kernels in this process, None before torch is imported."""
    torch = sys.modules.get('torch')
    return torch.backends.cpu.get_cpu_capability() if torch is not None else None


if sys.argv[:1] == ['-m']:  # python -m bench.<name>: the package is imported while argv[0] is '-m'
    pin_cpu_kernels()
