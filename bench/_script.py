"""``python bench/<name>.py`` runs as ``python -m bench.<name>`` would: the repository root, not
bench/, goes first on ``sys.path``, so ``bench`` is a package and ``bench.common`` is one module,
and the benchmark plans with the kernels of :func:`bench.pin_cpu_kernels`. The one place the
benchmarks touch ``sys.path``; a script imports it only when run by its path:

    if not __package__:  # python bench/<name>.py
        import _script  # noqa: F401
"""
import sys
from pathlib import Path

sys.path[0] = str(Path(__file__).resolve().parent.parent)

from bench import pin_cpu_kernels  # noqa: E402

pin_cpu_kernels()
