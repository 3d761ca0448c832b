"""The options the benchmarks share, spelt once: ``parser(__doc__, 'models', 'out', 'cluster')``.

A benchmark names the shared options it takes (:data:`SHARED`, in this order in its ``--help``)
and adds its own to the parser it gets; a default of its own for a shared option is a keyword
(``parser(__doc__, 'threads', threads=2)``). The shared options:

- ``models``: ``--models``, the folder of PLY plant models, '' for the procedural plants (default:
  ../shared/data/corn50 when present, :func:`bench.common.default_models`);
- ``out``: ``--out``, the folder the result goes to, its cache under ``<out>/cache`` (default results/);
- ``images``: ``--width`` and ``--height`` of the rendered images (default: the paper's 2000 x 1500);
- ``threads``: ``--threads`` of a reconstruction (0: all cores);
- ``capture``: the capture model of the reconstruction CLI (``--capture`` and its figures; default
  realistic: README "Capture model"; :func:`bench.common.capture_of` reads them);
- ``cluster``: ``--scheduler``, ``--workers`` and the TLS files of a cluster
  (:func:`bench.cluster.cluster_client` opens it).
"""
from __future__ import annotations

import argparse
from typing import Any, Callable

from bench.common import ROOT, default_models

#: where a benchmark writes its result unless ``--out`` says otherwise
RESULTS = ROOT / 'results'


def _models(ap: argparse.ArgumentParser) -> None:
    ap.add_argument('--models', default=default_models(),
                    help="folder of PLY plant models, '' for the procedural plants (default: %(default)r)")


def _out(ap: argparse.ArgumentParser) -> None:
    ap.add_argument('--out', default=str(RESULTS), help='folder of the result and its cache (default: %(default)s)')


def _images(ap: argparse.ArgumentParser) -> None:
    from vp_scene.camera import IMAGE_SIZE, image_side_arg

    ap.add_argument('--width', type=image_side_arg, default=IMAGE_SIZE[0],
                    help='image width, pixels (default %(default)s)')
    ap.add_argument('--height', type=image_side_arg, default=IMAGE_SIZE[1],
                    help='image height, pixels (default %(default)s)')


def _threads(ap: argparse.ArgumentParser) -> None:
    ap.add_argument('--threads', type=int, default=0,
                    help='threads of a reconstruction (0: all cores; 1 when something runs beside it; '
                         'default %(default)s)')


def _capture(ap: argparse.ArgumentParser) -> None:
    from vp_recon.cli import add_capture_arguments

    add_capture_arguments(ap)


def _cluster(ap: argparse.ArgumentParser) -> None:
    from vp_scene.cluster import add_tls_args

    ap.add_argument('--scheduler', default=None,
                    help="'local' (a LocalCluster on this machine: 127.0.0.1, TLS with this run's credentials) or the "
                         "address of a running dask scheduler, e.g. tls://10.0.0.5:8786 with --tls-* or "
                         "tcp://10.0.0.5:8786 (default: $DASK_SCHEDULER_ADDRESS, else local)")
    ap.add_argument('--workers', type=int, default=1,
                    help='worker processes of the local cluster, one thread each (default 1)')
    add_tls_args(ap)


#: the shared options: name -> what adds them to a parser
SHARED: dict[str, Callable[[argparse.ArgumentParser], None]] = {
    'models': _models, 'out': _out, 'images': _images, 'threads': _threads, 'capture': _capture,
    'cluster': _cluster}


def parser(doc: str, *shared: str, **defaults: Any) -> argparse.ArgumentParser:
    """A benchmark's argument parser: described by the first paragraph of its docstring ``doc``,
    with the ``shared`` options named (keys of :data:`SHARED`) and the benchmark's own
    ``defaults`` for them (dest -> value)."""
    unknown = [name for name in shared if name not in SHARED]
    if unknown:
        raise ValueError(f'no shared option {unknown[0]!r}; one of {", ".join(SHARED)}')
    ap = argparse.ArgumentParser(description=doc.split('\n\n')[0])
    for name in shared:
        SHARED[name](ap)
    ap.set_defaults(**defaults)
    return ap
