"""bench/ is a package (issue 39, item 4): its modules import each other as ``bench.<name>``, from
anywhere the repository root is on the path (tests, Dask workers, ``python -m bench.<name>``), and
``python bench/<name>.py`` still runs (the recorded commands of older results use it); nothing in
bench/ or tests/ puts bench/ on ``sys.path`` by hand."""
from __future__ import annotations

import ast
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
BENCH = REPO / "bench"
MODULES = sorted(p.stem for p in BENCH.glob("*.py") if not p.stem.startswith("_"))


def _env() -> dict:
    return dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))


def test_every_bench_module_imports_as_a_package_module(tmp_path):
    """Each module once, as ``bench.<name>``: no twin ``common`` beside ``bench.common`` (two copies
    of a module hold two caches and two sets of classes)."""
    code = ("import importlib, sys\nfor m in %r: importlib.import_module('bench.' + m)\n"
            "twins = sorted(m for m in %r if m in sys.modules)\nassert not twins, twins\n") % (MODULES, MODULES)
    res = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=_env(), capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0, res.stderr[-2000:]


def test_a_benchmark_runs_by_its_path_and_as_a_module(tmp_path):
    by_path = subprocess.run([sys.executable, str(BENCH / "table1_combine.py"), "--help"], cwd=tmp_path,
                             capture_output=True, text=True, timeout=60)
    assert by_path.returncode == 0 and "usage: table1_combine.py" in by_path.stdout, by_path.stderr[-2000:]
    as_module = subprocess.run([sys.executable, "-m", "bench.table1_combine", "--help"], cwd=REPO,
                               capture_output=True, text=True, timeout=60)
    assert as_module.returncode == 0 and "usage: table1_combine.py" in as_module.stdout, as_module.stderr[-2000:]


def _touches_sys_path(path: Path) -> list[str]:
    """The lines of ``path`` that change ``sys.path`` (insert, append, assignment)."""
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        target = None
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) \
                and node.func.attr in ("insert", "append", "extend"):
            target = node.func.value
        elif isinstance(node, (ast.Assign, ast.AugAssign)):
            target = node.targets[0] if isinstance(node, ast.Assign) else node.target
            target = target.value if isinstance(target, ast.Subscript) else target
        if target is not None and ast.unparse(target) == "sys.path":
            found.append(f"{path.relative_to(REPO)}:{node.lineno}")
    return found


def test_only_the_script_shim_touches_sys_path_for_bench():
    found = [hit for p in sorted(BENCH.glob("*.py")) if p.name != "_script.py" for hit in _touches_sys_path(p)]
    assert found == [], found
    importers = [p for p in sorted((REPO / "tests").glob("*.py")) if "from bench" in p.read_text()]
    assert importers and [hit for p in importers for hit in _touches_sys_path(p)] == []


def test_the_shared_options_are_spelt_once():
    """--models, --out, --width/--height, --threads, the capture's and the cluster's options come
    from bench.options: the same flags and defaults in every benchmark that takes them."""
    from bench import bench_fields, bench_sorties, options, plan_quality, table1

    shared = vars(options.parser("", *options.SHARED).parse_args([]))
    for module in (table1, bench_fields, bench_sorties, plan_quality):
        args = vars(module.parse_args([]))
        assert {k: args[k] for k in shared} == shared, module.__name__
    flags = re.compile(r"""add_argument\(\s*["']--(models|capture|scheduler|tls-[a-z-]+)["']""")
    assert [p.name for p in BENCH.glob("*.py") if p.name != "options.py" and flags.search(p.read_text())] == []
    with pytest.raises(ValueError, match="no shared option 'model'"):
        options.parser("", "model")
