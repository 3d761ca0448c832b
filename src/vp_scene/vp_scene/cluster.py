"""The suite's cluster engine: a dask.distributed client, on this machine or on a cluster users run.

One home for how the suite talks to Dask (the benchmarks' task runner ``bench/cluster.py`` and the
reconstruction of a plan's realizations in parallel, :func:`vp_recon.pipeline.reconstruct_plan`):

:func:`open_client` gives the client: ``scheduler='local'`` starts a ``LocalCluster`` of
``workers`` processes with one thread each; any other value (or ``DASK_SCHEDULER_ADDRESS`` when
``scheduler`` is None) is the address of a running ``dask scheduler``. Workers start with
OMP/MKL/OPENBLAS thread counts of 1 (Dask's ``distributed.nanny.pre-spawn-environ``, set here
explicitly, plus torch's own count through :class:`OneThread`), so N workers never oversubscribe
N cores. A worker of a remote cluster must import the suite (``install/setup.bash``).

A scheduler address where nothing answers fails within :data:`CONNECT_TIMEOUT_S` (an OSError).
A scheduler lost while the client is open (killed, its host gone) ends the work in the ``with``
block with one :class:`SchedulerLost` naming it, instead of Dask's cancelled futures and its
client's reconnection tracebacks.
"""
from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import sys
from typing import Iterator, Optional, Sequence

__all__ = ["ONE_THREAD_ENV", "OneThread", "SchedulerLost", "open_client"]

#: Environment of every worker process of the local cluster (read before torch/numpy load).
ONE_THREAD_ENV = {'OMP_NUM_THREADS': '1', 'MKL_NUM_THREADS': '1', 'OPENBLAS_NUM_THREADS': '1',
                  'NUMEXPR_NUM_THREADS': '1', 'VECLIB_MAXIMUM_THREADS': '1'}

from distributed import WorkerPlugin  # noqa: E402


class OneThread(WorkerPlugin):
    """Worker plugin: torch (and whatever reads the env later) on one thread per worker."""
    name = 'vp-one-thread'

    def setup(self, worker) -> None:
        os.environ.update(ONE_THREAD_ENV)
        try:
            import torch
            torch.set_num_threads(1)
        except ImportError:  # a worker without torch runs no planning task anyway
            pass


#: s a local cluster gets to stop its workers when the work is done
CLOSE_TIMEOUT_S = 60.0

#: s the client tries to reach a scheduler's address (Dask retries a refused connection until then;
#: its default, 30 s, kept a user waiting 31 s to learn that nothing listens at an address; a
#: scheduler just started listens within about 1 s: 0.7 s measured with the 2 cores loaded 2x)
CONNECT_TIMEOUT_S = 10.0


class SchedulerLost(ConnectionError):
    """The Dask scheduler of an open client was lost (killed, its host or the network gone): the
    work on it is cancelled. One line that names it."""


def _lost(client: object, exc: BaseException) -> bool:
    """Whether ``exc``, raised by work on ``client``, says that the client lost its scheduler:
    futures cancelled for 'scheduler-connection-lost', or a connection error or cancellation
    while the client is not connected."""
    from concurrent.futures import CancelledError

    if getattr(exc, 'reason', None) == 'scheduler-connection-lost':  # distributed's FutureCancelledError
        return True
    return (isinstance(exc, (CancelledError, OSError))
            and getattr(client, 'status', 'running') != 'running')


class _Silence(logging.Filter):
    """Drops every record: ``distributed.client``'s, while a client that lost its scheduler
    closes (its reconnection, cancelled by the close, logs a traceback or 'Failed to reconnect';
    :class:`SchedulerLost` says it in one line)."""

    def filter(self, record: logging.LogRecord) -> bool:
        return False


def close_cluster(cluster: object, timeout: float = CLOSE_TIMEOUT_S) -> None:
    """Close a local cluster; a worker slow to stop (a loaded machine: a benchmark ended with a
    nanny's TimeoutError after all its results were cached, and wrote none of them) is a warning,
    not a failure of the work already done: the workers are daemon processes of this one and end
    with it."""
    try:
        cluster.close(timeout=timeout)
    except (TimeoutError, asyncio.TimeoutError) as exc:
        print(f'dask: the local cluster did not stop within {timeout:.0f} s ({type(exc).__name__}); its workers '
              'end with this process', file=sys.stderr)


@contextlib.contextmanager
def open_client(scheduler: Optional[str] = None, workers: int = 1, quiet: bool = False,
                pythonpath: Sequence[str] = ()) -> Iterator:
    """A ``distributed.Client`` for ``scheduler`` ('local', an address, or None: the environment's
    ``DASK_SCHEDULER_ADDRESS`` else local); closes the client and any cluster it started.
    ``pythonpath``: folders the local cluster's workers import from (besides the suite)."""
    import dask
    from distributed import Client, LocalCluster

    scheduler = scheduler or os.environ.get('DASK_SCHEDULER_ADDRESS') or 'local'
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f'workers must be an integer >= 1, got {workers!r}')
    env = dict(ONE_THREAD_ENV)
    path = [str(p) for p in pythonpath] + [os.environ.get('PYTHONPATH', '')]
    env['PYTHONPATH'] = os.pathsep.join(p for p in path if p)
    log, silence = logging.getLogger('distributed.client'), _Silence()
    with contextlib.ExitStack() as stack:
        stack.callback(log.removeFilter, silence)  # last: after the client closed
        if scheduler == 'local':
            with dask.config.set({'distributed.nanny.pre-spawn-environ': env}):
                cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, env=env,
                                       dashboard_address=':0', silence_logs=logging.ERROR)
            stack.callback(close_cluster, cluster)
            client = stack.enter_context(Client(cluster))
        else:
            client = stack.enter_context(Client(scheduler, timeout=f'{CONNECT_TIMEOUT_S:g}s'))
        try:
            client.register_plugin(OneThread(), name=OneThread.name)
            if not quiet:
                where = 'local cluster' if scheduler == 'local' else scheduler
                n = len(client.scheduler_info().get('workers', {}))
                print(f'dask: {where}, {n} worker(s); dashboard {client.dashboard_link}', file=sys.stderr)
            yield client
        except Exception as exc:
            if not _lost(client, exc):
                raise
            log.addFilter(silence)
            address = getattr(client.scheduler, 'address', None) or scheduler
            raise SchedulerLost(f'lost the Dask scheduler {address} ({type(exc).__name__}); the work on it '
                                'was cancelled') from None
