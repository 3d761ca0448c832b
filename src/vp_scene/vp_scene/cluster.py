"""The suite's cluster engine: a dask.distributed client, on this machine or on a cluster users run.

One home for how the suite talks to Dask (the benchmarks' task runner ``bench/cluster.py`` and the
reconstruction of a plan's realizations in parallel, :func:`vp_recon.pipeline.reconstruct_plan`):

:func:`open_client` gives the client: ``scheduler='local'`` starts a ``LocalCluster`` of
``workers`` processes with one thread each; any other value (or ``DASK_SCHEDULER_ADDRESS`` when
``scheduler`` is None) is the address of a running ``dask scheduler``. Workers start with
OMP/MKL/OPENBLAS thread counts of 1 (Dask's ``distributed.nanny.pre-spawn-environ``, set here
explicitly, plus torch's own count through :class:`OneThread`), so N workers never oversubscribe
N cores. A worker of a remote cluster must import the suite (``install/setup.bash``).

Who can get in (README, "Running the benchmarks on a cluster"): the local cluster listens on
127.0.0.1 only (scheduler, nannies, workers and the dashboard) and speaks TLS with temporary
credentials made for the run (dask's ``Security.temporary()``: a self-signed certificate and key
held in memory, handed to the workers through the process pipe; both sides must present it), so a
client of another local user, or of this one without the run's credentials, is refused: a plain
``Client(address)`` could otherwise run any code in the workers (``client.run``). A remote
scheduler is the user's: ``tls://`` with the certificate files of :class:`TlsFiles` (or dask's
``distributed.comm.tls.*`` config), or ``tcp://`` as it is run.

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
from dataclasses import dataclass
from typing import Iterator, Optional, Sequence

__all__ = ["LOCAL_HOST", "ONE_THREAD_ENV", "OneThread", "KeptLocalCluster", "SchedulerLost", "TlsFiles", "add_tls_args",
           "check_cluster_args", "client_security", "dashboard", "open_client"]

#: The only interface the local cluster listens on (scheduler, nannies, workers, dashboard).
LOCAL_HOST = '127.0.0.1'

#: Environment of every worker process of the local cluster (read before torch/numpy load).
ONE_THREAD_ENV = {'OMP_NUM_THREADS': '1', 'MKL_NUM_THREADS': '1', 'OPENBLAS_NUM_THREADS': '1',
                  'NUMEXPR_NUM_THREADS': '1', 'VECLIB_MAXIMUM_THREADS': '1'}

from distributed import WorkerPlugin  # noqa: E402


class OneThread(WorkerPlugin):
    """Worker plugin: torch (and whatever reads the env later) on one thread per worker; and
    pycolmap imported with the worker's SIGTERM handler kept.

    Importing pycolmap installs glog's failure handler for SIGTERM, which prints a stack trace
    ("*** Aborted at ... SIGTERM received") before the process dies: every worker that had
    reconstructed wrote two such traces into the recon node's log as its cluster closed, as if
    it had crashed. The worker imports it here, at set-up, and puts the handler it had back (as
    the recon node and ``vp_recon.cli`` do for their own process)."""
    name = 'vp-one-thread'

    def setup(self, worker) -> None:
        import signal

        os.environ.update(ONE_THREAD_ENV)
        try:
            import torch
            torch.set_num_threads(1)
        except ImportError:  # a worker without torch runs no planning task anyway
            pass
        try:
            before = signal.getsignal(signal.SIGTERM)
            import pycolmap  # noqa: F401
            signal.signal(signal.SIGTERM, before if before is not None else signal.SIG_DFL)
        except ImportError:  # a worker without pycolmap reconstructs nothing
            pass
        except ValueError:  # not the worker's main thread: the handler cannot be set from here
            pass


#: s a local cluster gets to stop its workers when the work is done
CLOSE_TIMEOUT_S = 60.0

#: s the client tries to reach a scheduler's address (Dask retries a refused connection until then;
#: its default, 30 s, keeps a user waiting that long to learn that nothing listens at an address,
#: while a scheduler just started listens within about a second)
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
    """Close a local cluster; a worker slow to stop (a loaded machine: a nanny's TimeoutError would
    end a run whose results are all in, before it writes them) is a warning, not a failure of the
    work already done: the workers are daemon processes of this one and end
    with it."""
    try:
        cluster.close(timeout=timeout)
    except (TimeoutError, asyncio.TimeoutError) as exc:
        print(f'dask: the local cluster did not stop within {timeout:.0f} s ({type(exc).__name__}); its workers '
              'end with this process', file=sys.stderr)


@dataclass(frozen=True)
class TlsFiles:
    """The PEM files a client of a ``tls://`` scheduler presents (dask's TLS: the CA that signed the
    cluster's certificates, this client's certificate and its key; the key may be in the
    certificate's file). All empty: dask's own config (``distributed.comm.tls.ca-file``,
    ``.client.cert``, ``.client.key``, e.g. ``DASK_DISTRIBUTED__COMM__TLS__CA_FILE``) applies."""
    ca_file: str = ''
    cert: str = ''
    key: str = ''

    @classmethod
    def from_args(cls, args) -> 'TlsFiles':
        """From the options of :func:`add_tls_args`."""
        return cls(args.tls_ca_file or '', args.tls_cert or '', args.tls_key or '')


def add_tls_args(ap) -> None:
    """``--tls-ca-file``, ``--tls-cert``, ``--tls-key`` (a ``tls://`` scheduler), the same in every tool."""
    ap.add_argument('--tls-ca-file', default='', metavar='PEM',
                    help='a tls:// scheduler: the CA certificate that signed the cluster\'s certificates')
    ap.add_argument('--tls-cert', default='', metavar='PEM', help="a tls:// scheduler: this client's certificate")
    ap.add_argument('--tls-key', default='', metavar='PEM',
                    help="a tls:// scheduler: this client's private key (default: in --tls-cert's file)")


def client_security(scheduler: str, tls: TlsFiles = TlsFiles()):
    """The ``distributed.Security`` of a client of the scheduler address ``scheduler`` (not
    'local'); ValueError (one line) when the files and the address do not go together: files for a
    ``tcp://`` address, a ``tls://`` address without a CA and certificate (files or dask's config),
    a file that does not exist."""
    from distributed import Security

    given = {name: path for name, path in (('CA file', tls.ca_file), ('certificate', tls.cert), ('key', tls.key))
             if path}
    is_tls = scheduler.startswith('tls://')
    if given and not is_tls:
        raise ValueError(f'TLS files are for a tls:// scheduler address, got {scheduler!r}')
    for name, path in given.items():
        if not os.path.isfile(path):
            raise ValueError(f'TLS {name} {path}: no such file')
    if given:
        if not (tls.ca_file and tls.cert):
            raise ValueError('TLS needs the CA file and the certificate (the key: its own file or in the '
                             'certificate\'s)')
        return Security(tls_ca_file=tls.ca_file, tls_client_cert=tls.cert, tls_client_key=tls.key or None,
                        require_encryption=True)
    security = Security()  # dask's config (distributed.comm.tls.*)
    if is_tls and not (security.tls_ca_file and security.tls_client_cert):
        raise ValueError(f'scheduler {scheduler} is tls://: give the CA file and this client\'s certificate '
                         '(--tls-ca-file, --tls-cert, --tls-key; or dask\'s distributed.comm.tls config)')
    return security


def dashboard(client) -> str:
    """Where the dashboard of ``client``'s cluster listens: of a local cluster, the socket its HTTP
    server really bound (dask's ``dashboard_link`` names the scheduler's host, whatever the dashboard
    bound to: it said 127.0.0.1 while the dashboard listened on all interfaces); of a remote one,
    dask's link, as the scheduler reports it."""
    cluster = getattr(client, 'cluster', None)
    if cluster is None:
        return f'{client.dashboard_link} (as the scheduler reports it)'
    http = getattr(cluster.scheduler, 'http_server', None)
    if http is None:
        return 'off'
    host = http.address if ':' not in http.address else f'[{http.address}]'
    return f'http://{host}:{http.port}/status'


def check_cluster_args(scheduler: Optional[str], workers: int = 1, tls: TlsFiles = TlsFiles()) -> tuple:
    """(the scheduler: 'local' or an address, the client's ``distributed.Security`` of a remote one
    else None) for :func:`open_client`'s arguments; ValueError (one line) for bad ones."""
    scheduler = scheduler or os.environ.get('DASK_SCHEDULER_ADDRESS') or 'local'
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f'workers must be an integer >= 1, got {workers!r}')
    if scheduler == 'local':
        if tls != TlsFiles():
            raise ValueError("TLS files are for a tls:// scheduler address; the local cluster makes its own "
                             "temporary credentials")
        return scheduler, None
    return scheduler, client_security(scheduler, tls)


@contextlib.contextmanager
def open_client(scheduler: Optional[str] = None, workers: int = 1, quiet: bool = False,
                pythonpath: Sequence[str] = (), tls: TlsFiles = TlsFiles()) -> Iterator:
    """A ``distributed.Client`` for ``scheduler`` ('local', an address, or None: the environment's
    ``DASK_SCHEDULER_ADDRESS`` else local); closes the client and any cluster it started.
    ``pythonpath``: folders the local cluster's workers import from (besides the suite).
    ``tls``: the client's certificate files for a ``tls://`` scheduler (:func:`client_security`);
    the local cluster makes its own temporary credentials. ValueError for bad arguments."""
    import dask
    from distributed import Client, LocalCluster, Security

    scheduler, security = check_cluster_args(scheduler, workers, tls)
    env = dict(ONE_THREAD_ENV)
    path = [str(p) for p in pythonpath] + [os.environ.get('PYTHONPATH', '')]
    env['PYTHONPATH'] = os.pathsep.join(p for p in path if p)
    log, silence = logging.getLogger('distributed.client'), _Silence()
    with contextlib.ExitStack() as stack:
        stack.callback(log.removeFilter, silence)  # last: after the client closed
        if scheduler == 'local':
            security = Security.temporary()  # per run, in memory (needs the cryptography package)
            # a worker is never paused for its memory: a reconstruction's working set (gigabytes for a
            # field's views) stays with the process after the task (malloc), so a worker at Dask's
            # 80 % pause threshold would take no further task and the work would wait with no
            # message (the pause is logged below ERROR); unpaused, it runs on, and at 95 % its
            # nanny restarts it and the task is retried (Dask's allowed failures), which is reported
            with dask.config.set({'distributed.nanny.pre-spawn-environ': env, 'distributed.worker.memory.pause': False}):
                cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, env=env,
                                       host=LOCAL_HOST, dashboard_address=f'{LOCAL_HOST}:0', security=security,
                                       silence_logs=logging.ERROR)
            stack.callback(close_cluster, cluster)
            client = stack.enter_context(Client(cluster, security=security))
        else:
            client = stack.enter_context(Client(scheduler, timeout=f'{CONNECT_TIMEOUT_S:g}s', security=security))
        try:
            client.register_plugin(OneThread(), name=OneThread.name)
            if not quiet:
                where = f'local cluster {client.scheduler.address} (TLS, this run\'s credentials)' \
                    if scheduler == 'local' else scheduler
                n = len(client.scheduler_info().get('workers', {}))
                print(f'dask: {where}, {n} worker(s); dashboard {dashboard(client)}', file=sys.stderr)
            yield client
        except Exception as exc:
            if not _lost(client, exc):
                raise
            log.addFilter(silence)
            address = getattr(client.scheduler, 'address', None) or scheduler
            raise SchedulerLost(f'lost the Dask scheduler {address} ({type(exc).__name__}); the work on it '
                                'was cancelled') from None


class KeptLocalCluster:
    """A local cluster kept open for a node's life (the recon node's ``scheduler: local``).

    Starting a local cluster costs seconds (the worker processes import the suite and torch), for
    every plan if it were opened per plan. :meth:`warm` opens it in the background as the node starts (while
    the planner plans), :meth:`get` hands out the open client (opening it, or a new one when the
    worker count changed or the cluster died, under a lock), :meth:`close` ends it. Remote
    schedulers are the user's: they stay per plan (:func:`open_client`)."""

    def __init__(self) -> None:
        import threading

        self._lock = threading.Lock()
        self._stack: Optional[contextlib.ExitStack] = None
        self._client = None
        self._workers = 0

    def warm(self, workers: int) -> None:
        """Open the cluster in a daemon thread (a failure there is met again, and reported, by :meth:`get`)."""
        import threading

        def run() -> None:
            try:
                self.get(workers)
            except Exception:  # noqa: BLE001 - get() raises it where a plan can report it
                pass

        threading.Thread(target=run, name='dask-warm', daemon=True).start()

    def get(self, workers: int):
        """The open client of a local cluster of ``workers`` one-thread workers (OSError as
        :func:`open_client` when it cannot start)."""
        with self._lock:
            alive = self._client is not None and getattr(self._client, 'status', '') == 'running'
            if alive and self._workers == workers:
                return self._client
            self._close()
            stack = contextlib.ExitStack()
            try:
                self._client = stack.enter_context(open_client('local', workers, quiet=True))
            except BaseException:
                stack.close()
                raise
            self._stack, self._workers = stack, workers
            return self._client

    def _close(self) -> None:
        stack, self._stack, self._client = self._stack, None, None
        if stack is not None:
            stack.close()

    def close(self) -> None:
        """Close the cluster (its workers end with this process anyway)."""
        with self._lock:
            self._close()
