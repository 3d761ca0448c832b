"""Reconstructions as Dask tasks (:func:`vp_scene.cluster.open_client` gives the client): a task's
call and its answer (:func:`worker_call`, :func:`worker_result`: a ReconError crosses as its code
and message) and a plan's realizations reconstructed in parallel (:func:`on_cluster`). The recon
node's fleet source submits its capture sets through the same two."""
from __future__ import annotations

from pathlib import Path
from typing import Callable, Optional

import numpy as np
from numpy.typing import NDArray

from .config import ReconConfig
from .errors import ReconError
from .progress import STAGES, ProgressFn, tick
from .results import RealizationFn, RealizationResult

__all__ = ["worker_call", "worker_result", "on_cluster"]


def worker_call(reconstruct: Callable, *args, **kwargs) -> tuple:
    """``reconstruct(*args, **kwargs)`` on a Dask worker (:func:`vp_recon.pipeline.reconstruct_realization`,
    or :func:`vp_recon.pipeline.reconstruct_captured` for a fleet's capture set): ('ok', result) or ('error', code,
    message) (a ReconError travels as its fields: the exception's own pickling is not part of its
    contract)."""
    try:
        return ("ok", reconstruct(*args, **kwargs))
    except ReconError as exc:
        return ("error", exc.code, str(exc))


def worker_result(out: tuple, k: int) -> RealizationResult:
    """The result of a :func:`worker_call`, or its ReconError raised with ``.realization = k``."""
    if out[0] == "error":
        exc = ReconError(out[1], out[2])
        exc.realization = k
        raise exc
    return out[1]


def on_cluster(client: object, reconstruct: Callable, noisy_scene: object, cams: NDArray[np.float64],
               cfg: ReconConfig, ks: list, work_root: Optional[Path], progress: Optional[ProgressFn],
               on_realization: Optional[RealizationFn]) -> list:
    """:func:`vp_recon.pipeline.reconstruct_plan`'s loop on a Dask cluster: one task a realization,
    ``reconstruct(scene, k, cams, config, workdir=...)`` (:func:`vp_recon.pipeline.reconstruct_realization`)."""
    from distributed import as_completed

    scene = client.scatter(noisy_scene, broadcast=True)
    futures = {}
    for n, k in enumerate(ks):
        keep = cfg.keep_images and (n == 0 or on_realization is not None)
        sub = ReconConfig(**{**cfg.__dict__, "keep_images": keep, "num_threads": 1})
        futures[client.submit(worker_call, reconstruct, scene, k, cams, sub, workdir=work_root,
                              pure=False)] = (n, k)
    done: dict = {}
    failed: dict = {}
    try:
        for fut in as_completed(list(futures)):
            n, k = futures[fut]
            try:
                res = worker_result(fut.result(), k)
            except ReconError as exc:
                failed[n] = exc
                continue
            for stage in STAGES:
                tick(progress, stage, k)
            if on_realization is not None:
                on_realization(res)
            if n > 0:
                res.rendered = []
            done[n] = res
            if failed and min(failed) < min(set(range(len(ks))) - set(done) - set(failed), default=len(ks)):
                break  # the first failing realization in order is known: the plan fails with it
    finally:
        client.cancel([f for f in futures if not f.done()])
    if failed:
        raise failed[min(failed)]
    return [done[n] for n in range(len(ks))]
