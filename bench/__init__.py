"""The benchmarks (``python -m bench.<name> --help``; README "Development", results in docs/results.md).

A package: the benchmarks import each other as ``bench.common``, ``bench.stats``, ... and the
tests import them so too (pytest.ini puts the repository root on ``sys.path``). Run them from
the repository root as ``python -m bench.table1 ...``; ``python bench/table1.py ...`` (the form
the recorded commands of older results use) runs the same code (``bench/_script.py``).
Dask workers import them from the repository root (``bench.cluster.open_client`` gives the local
workers that path; remote workers need ``PYTHONPATH=<repo>``).
"""
