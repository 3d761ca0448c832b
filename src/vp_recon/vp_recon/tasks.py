"""Reconstructions as Dask tasks (:func:`vp_scene.cluster.open_client` gives the client): a task's
call and its answer (:func:`worker_call`, :func:`worker_result`: a ReconError crosses as its code
and message) and the queue of a loop's capture sets on a cluster (:class:`ClusterQueue`, used by
:func:`vp_recon.pipeline.reconstruct_sets`)."""
from __future__ import annotations

import ctypes
import ctypes.util
import gc
from collections import deque
from typing import Callable, Iterator, Optional

from .errors import ReconError
from .progress import STAGES, ProgressFn, ReconCancelled, tick
from .results import RealizationResult

__all__ = ["release_heap", "worker_call", "worker_result", "ClusterQueue"]


def release_heap() -> None:
    """Give the heap a reconstruction freed back to the system: a garbage collection, then glibc's
    ``malloc_trim(0)``. A reconstruction's images, features and depth maps are freed when it
    returns, but glibc keeps most of those pages (its arenas, fragmented by the C++ libraries'
    threads), so that a process that reconstructs again and again (a Dask worker flying a plan's
    flights, the reconstruction's tasks) grows with every reconstruction until the worker pauses
    at Dask's memory threshold; with the tasks that wait on it long-running, a cluster of paused
    workers waits for ever. Nothing where the C library is not glibc."""
    gc.collect()
    if _LIBC is not None:
        _LIBC.malloc_trim(0)


def _glibc() -> Optional[ctypes.CDLL]:
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name) if name else None
        return libc if libc is not None and hasattr(libc, "malloc_trim") else None
    except OSError:
        return None


_LIBC = _glibc()


def worker_call(reconstruct: Callable, *args, **kwargs) -> tuple:
    """``reconstruct(*args, **kwargs)`` on a Dask worker (:func:`vp_recon.pipeline.reconstruct_set`):
    ('ok', result) or ('error', code, message) (a ReconError travels as its fields: the
    exception's own pickling is not part of its contract); the heap it freed goes back to the
    system (:func:`release_heap`)."""
    try:
        return ("ok", reconstruct(*args, **kwargs))
    except ReconError as exc:
        return ("error", exc.code, str(exc))
    finally:
        release_heap()


def worker_result(out: tuple, k: int) -> RealizationResult:
    """The result of a :func:`worker_call`, or its ReconError raised with ``.realization = k``."""
    if out[0] == "error":
        exc = ReconError(out[1], out[2])
        exc.realization = k
        raise exc
    return out[1]


class ClusterQueue:
    """Reconstructions on a Dask cluster, one task a capture set, submitted as the sets come and
    taken back in the order they were submitted: the records are the in-process ones, in the
    in-process order, and the failure rule reads "the first failing set in that order" (a later
    set's failure waits for the earlier ones to succeed). The scene goes to every worker once;
    ``should_stop()`` (checked while a result is awaited) raises ReconCancelled."""

    def __init__(self, client: object, noisy_scene: object, should_stop: Optional[Callable[[], bool]] = None) -> None:
        self._client = client
        # a key of its own (hash=False): the same scene scattered under its content's key by another
        # queue or batch on this client would be released with that one's future
        self._scene = client.scatter(noisy_scene, broadcast=True, hash=False)
        self._should_stop = should_stop
        self._pending: deque = deque()  # (k, future), in the order submitted

    def submit(self, k: int, reconstruct: Callable, *args) -> None:
        """``reconstruct(scene, *args)`` of realization ``k`` on a worker (:func:`worker_call`)."""
        self._pending.append((k, self._client.submit(worker_call, reconstruct, self._scene, *args, pure=False)))

    def take(self, progress: Optional[ProgressFn], block: bool) -> Iterator[RealizationResult]:
        """The results at the head of the queue that are done (all of them: ``block``), in order,
        each after ``progress(stage, k)`` of its stages; the first failure in that order is
        raised (ReconError with its realization)."""
        from distributed import wait

        while self._pending and (block or self._pending[0][1].done()):
            k, fut = self._pending[0]
            while not fut.done():
                if self._should_stop is not None and self._should_stop():
                    raise ReconCancelled("stopped while reconstructing on the cluster")
                try:
                    wait(fut, timeout=0.5)
                except TimeoutError:  # distributed.wait's way of saying 'not yet'
                    pass
            self._pending.popleft()
            res = worker_result(fut.result(), k)
            for stage in STAGES:
                tick(progress, stage, k)
            yield res

    def cancel(self) -> None:
        """Cancel the tasks not taken back."""
        if self._pending:
            self._client.cancel([f for _, f in self._pending])
