"""A benchmark's result, written the one way: :func:`publish`.

``<out>/<name>.json`` holds the result and where it came from (:func:`provenance`: the command as
``python -m bench.<name> ...``, the commit, torch's CPU kernels), strict JSON
(``bench.cache.write_json``); ``<out>/<name>.md`` beside it holds its markdown, which is printed
too. ``make docs`` (``bench.docs``) builds docs/results.md from these files. :func:`table` and
:func:`num` are the markdown pieces the reports share.
"""
from __future__ import annotations

import math
import os
import platform
import subprocess
import sys
from pathlib import Path
from typing import Optional, Union

from bench import cpu_capability
from bench.cache import write_json
from bench.common import ROOT


def machine() -> str:
    return f'{platform.machine()}, {os.cpu_count()} CPU cores, Python {platform.python_version()}'


def git_commit() -> Optional[str]:
    """The commit the working tree is at (12 hex digits), ``-dirty`` when tracked files differ
    from it; None outside a git checkout."""
    def git(*args: str) -> str:
        return subprocess.run(['git', *args], cwd=ROOT, capture_output=True, text=True, timeout=30,
                              check=True).stdout.strip()
    try:
        head = git('rev-parse', '--short=12', 'HEAD')
        dirty = git('status', '--porcelain', '--untracked-files=no')
    except (OSError, subprocess.SubprocessError):
        return None
    return head + ('-dirty' if dirty else '')


def provenance() -> dict:
    """``command`` (the argv of this run, as ``python -m bench.<name> ...`` for a benchmark),
    ``commit`` (:func:`git_commit`) and ``torch_cpu_capability`` (:func:`bench.cpu_capability`): what
    docs/results.md prints under every table."""
    argv = list(sys.argv)
    script = Path(argv[0]) if argv else Path()
    if script.suffix == '.py' and script.resolve().parent == ROOT / 'bench':
        argv = ['python', '-m', f'bench.{script.stem}'] + argv[1:]
    return {'command': argv, 'commit': git_commit(), 'torch_cpu_capability': cpu_capability()}


def publish(out: Union[str, Path], name: str, result: dict, markdown: str) -> Path:
    """Write ``out/<name>.json`` (``result`` with its :func:`provenance`) and ``out/<name>.md``
    (``markdown``), print the markdown and the two paths; returns the JSON's path."""
    out = Path(out)
    path = out / f'{name}.json'
    write_json(path, {**result, **provenance()}, indent=1)
    (out / f'{name}.md').write_text(markdown)
    print(markdown, end='' if markdown.endswith('\n') else '\n')
    print(f'wrote {path} and {path.with_suffix(".md")}')
    return path


def num(x, digits: int = 2, sign: bool = False) -> str:
    """A number, '-' for none (None, NaN, inf)."""
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return '-'
    return f'{x:+.{digits}f}' if sign else f'{x:.{digits}f}'


def table(head: list[str], rows: list[list[str]]) -> list[str]:
    """The lines of a markdown table."""
    return ['| ' + ' | '.join(head) + ' |', '|' + '---|' * len(head)] + ['| ' + ' | '.join(r) + ' |' for r in rows]
