"""The benchmarks' results cache: one JSON file per finished cell (a plan, a reconstruction), so
that a rerun computes only what is missing (the cache lives under ``<out>/cache/``, git-ignored).

- :func:`cached`: the record stored at a path, or compute, store and return it;
- :func:`load`: the record stored at a path, None when there is none (missing, torn by an
  interrupted write, unreadable): such a cell is computed again;
- :func:`write_json`: the one writer of the benchmarks' JSON, records and reports alike: atomic
  (several cluster workers and the client write the cache at once) and strict (:func:`json_safe`).
"""
from __future__ import annotations

import json
import math
import os
import threading
from pathlib import Path
from typing import Any, Callable, Optional


def load(path: Path) -> Optional[Any]:
    """The JSON stored at ``path``; None when the file is missing, torn or unreadable."""
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def cached(path: Path, compute: Callable[[], Any]) -> Any:
    """The JSON stored at ``path`` (:func:`load`), or ``compute()``, stored (atomically) and returned."""
    value = load(path)
    if value is None:
        value = compute()
        write_json(path, value)
    return value


def json_safe(value: Any) -> Any:
    """``value`` with every non-finite float (NaN, +-inf: a mean of nothing, a std of one value, an
    interval of one pair) as None: JSON has no NaN (RFC 8259), and a ``NaN`` literal is a file that
    strict readers refuse. Readers take None as "no value" (``bench.stats``)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    return value


def write_json(path: Path, value: Any, indent: Optional[int] = None) -> None:
    """Write ``value`` to ``path`` atomically (a temporary file per writer, then ``os.replace``),
    non-finite floats as null (:func:`json_safe`; ``allow_nan=False``: no NaN literal ever
    reaches a file)."""
    text = json.dumps(json_safe(value), indent=indent, allow_nan=False)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f'.{path.name}.{os.getpid()}.{threading.get_ident()}.tmp')
    tmp.write_text(text + ('\n' if indent is not None else ''))
    os.replace(tmp, path)
