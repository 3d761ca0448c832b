"""The console entry of every node: signals are answered before the first heavy import.

A console script imports the module that holds ``main`` before ``main`` can install anything,
and the suite's node modules import torch, trimesh, pycolmap, Open3D and rclpy at their top.
During those seconds Python's default handlers would be in charge: SIGINT raises KeyboardInterrupt
wherever the import happens to be (a long traceback, or nothing at all where a library catches
BaseException around its optional imports, as trimesh's ``__init__`` does: the node keeps
running), and SIGTERM ends the process by the default action (exit 143). Here the
entry installs a handler that ends the process at once, quietly, with exit 0 (nothing has been
started yet that could be lost), then imports the node module and runs its ``main``, whose
:func:`vp_scene.node_runtime.run_node` replaces the handler with the node's own shutdown.

``preload`` modules are imported first, under the quiet handler, which is installed again
after each of them: pycolmap (through glog) installs a SIGTERM handler of its own at import that
prints a stack trace and kills the process; only the rest of that one import remains exposed.

What no Python code can cover: the interpreter's own start, before this module runs (a fraction of
a second on an idle machine, seconds on a busy one). A signal then ends the process by Python's defaults
(SIGINT: KeyboardInterrupt; SIGTERM: exit 143). The tests send their signals from the moment the
handler is installed (``/proc/<pid>/status`` shows SIGTERM caught).

Only the standard library is imported here.
"""
from __future__ import annotations

import importlib
import os
import signal
import sys

__all__ = ["start"]


def _quit(_signum: int, _frame: object) -> None:
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:  # noqa: BLE001 - exiting anyway
            pass
    os._exit(0)


def _install() -> None:
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _quit)


def start(module: str, preload: tuple = ()) -> int:
    """Install the quiet early handlers for SIGINT and SIGTERM, import the ``preload`` modules
    (the handlers again after each), import ``module`` and return its ``main()``."""
    _install()
    for name in preload:
        importlib.import_module(name)
        _install()
    return importlib.import_module(module).main()


def scene() -> int:
    return start("vp_scene.scene_node")


def sim_drone() -> int:
    return start("vp_scene.sim_drone_node")
