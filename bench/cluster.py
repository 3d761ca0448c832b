"""The benchmarks' task engine: dask.distributed, on this machine or on a cluster users already run.

Every benchmark builds a list of :class:`Task` (a pure function of picklable arguments that returns
a plain JSON record, usually through ``bench.cache.cached``) and hands it to :func:`run_tasks`:

- a task whose result is already in the results cache (``Task.cache``, one JSON file per cell) is
  not submitted: the cache stays the unit of resumability, a rerun finishes only the missing tasks;
- every other task is submitted to the Dask scheduler, one progress bar runs over all tasks of
  the benchmark (the cached ones count as done);
- a task that raises is recorded as ``{'error': <exception type>, 'error_msg': <message>}``, never
  dropped; a worker that dies mid-task has its task rerun elsewhere by the scheduler (Dask's own
  ``distributed.scheduler.allowed-failures``; we do not re-implement it).

:func:`open_client` gives the client: ``scheduler='local'`` starts a ``LocalCluster`` of
``workers`` processes with one thread each; any other value (or ``DASK_SCHEDULER_ADDRESS`` when
``scheduler`` is None) is the address of a running ``dask scheduler``. Workers start with
OMP/MKL/OPENBLAS thread counts of 1 (Dask's ``distributed.nanny.pre-spawn-environ``, set here
explicitly, plus torch's own count through ``vp_scene.cluster.OneThread``), so N workers never oversubscribe
N cores. A worker of a remote cluster must import the suite (``install/setup.bash``) and this
package (``PYTHONPATH=<repo>``, the repository root); the client writes every record into its
own results cache (workers need not share its disk; a reconstruction's clouds and images stay on the
worker that made them), see the README, "Running the benchmarks on a cluster".
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Hashable, Optional

from bench.cache import load, write_json
from bench.common import ROOT
from vp_scene.cluster import TlsFiles, check_cluster_args
from vp_scene.cluster import open_client as _open_client


@dataclass
class Task:
    """One unit of a benchmark: ``fn(*args)`` on a worker, its record under ``key``.
    ``cache``: the JSON file ``fn`` writes its record to (None: not cached)."""
    key: Hashable
    fn: Callable[..., Any]
    args: tuple = ()
    cache: Optional[Path] = None
    label: str = field(default='')


def open_client(scheduler: Optional[str] = None, workers: int = 1, quiet: bool = False, tls: TlsFiles = TlsFiles()):
    """:func:`vp_scene.cluster.open_client` whose local workers also import the ``bench`` package
    (the repository root on their ``PYTHONPATH``)."""
    return _open_client(scheduler, workers, quiet, pythonpath=(str(ROOT),), tls=tls)


def cluster_client(args: argparse.Namespace, quiet: bool = False):
    """:func:`open_client` of the ``cluster`` options (``bench.options``); options that do not go
    together (TLS files for 'local' or a tcp:// address, a missing file...): one line
    ``<prog>: error: ...`` and exit 2, before anything runs."""
    tls = TlsFiles.from_args(args)
    try:
        check_cluster_args(args.scheduler, args.workers, tls)
    except ValueError as exc:
        print(f'{Path(sys.argv[0]).name}: error: {exc}', file=sys.stderr)
        raise SystemExit(2) from None
    return open_client(args.scheduler, args.workers, quiet, tls)


def _record(fn: Callable[..., Any], args: tuple) -> tuple[bool, Any]:
    """Run a task on a worker: (True, its record), or (False, a named error record) when it
    raises (never lost; not cached, so that a rerun tries again)."""
    try:
        return True, fn(*args)
    except Exception as exc:  # noqa: BLE001 - every failure is a result of the benchmark
        return False, {'error': type(exc).__name__, 'error_msg': str(exc)}


def run_tasks(client, tasks: list[Task], desc: str = 'tasks', timeout: Optional[float] = None) -> dict:
    """Every task's record by key, in the order given: cached ones read, the others run on the
    cluster under one progress bar; failures are ``{'error', 'error_msg'}`` records.
    ``timeout``: seconds for all of them (None: no limit), else ``TimeoutError``."""
    from distributed import as_completed
    from tqdm import tqdm

    keys = [t.key for t in tasks]
    if len(set(keys)) != len(keys):
        raise ValueError('run_tasks: two tasks share a key')
    records: dict = {}
    todo = []
    for t in tasks:
        hit = None if t.cache is None else load(t.cache)
        if hit is None:
            todo.append(t)
        else:
            records[t.key] = hit
    bar = tqdm(total=len(tasks), initial=len(records), desc=desc, unit='task', file=sys.stdout, mininterval=2)
    futures = {}
    for t in todo:
        fut = client.submit(_record, t.fn, t.args, pure=False)
        futures[fut] = t
    try:
        for fut in as_completed(futures, timeout=timeout):
            t = futures[fut]
            try:
                ok, records[t.key] = fut.result()
                if ok and t.cache is not None:  # the client's copy: workers may not share its disk
                    write_json(t.cache, records[t.key])
            except Exception as exc:  # noqa: BLE001 - e.g. KilledWorker after Dask's retries
                records[t.key] = {'error': type(exc).__name__, 'error_msg': str(exc)}
            bar.set_postfix_str(str(t.label or t.key)[:60])
            bar.update()
    finally:
        bar.close()
        client.cancel([f for f in futures if not f.done()])  # on a timeout or ^C: nothing left running
    return {k: records[k] for k in keys}
