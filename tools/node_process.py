"""One home for starting the suite's nodes as child processes (tools/run_suite.py and the tests).

A :class:`NodeProcess` is one executable in its own session (so that a Ctrl-C in the terminal
reaches the supervisor only, which then stops its nodes in order). Its output goes to a log file
and, optionally, to stderr with a ``[name]`` prefix. It dies with its supervisor: the child asks
the kernel for SIGTERM when the thread that started it exits (``prctl(PR_SET_PDEATHSIG)``), so a
supervisor killed with SIGKILL leaves no orphaned node behind (every node exits within a few
seconds of SIGTERM, see ``vp_scene.node_runtime``).

Plain Python (no ROS import), Linux only for the parent-death signal.
"""
from __future__ import annotations

import ctypes
import math
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any, Callable, Iterable, Optional

REPO = Path(__file__).resolve().parents[1]

_PR_SET_PDEATHSIG = 1
try:
    _prctl = ctypes.CDLL(None, use_errno=True).prctl  # resolved here: the child must not import
except (OSError, AttributeError):  # pragma: no cover - not Linux
    _prctl = None


def die_with_parent(sig: int = signal.SIGTERM) -> Callable[[], None]:
    """A ``preexec_fn`` for :class:`subprocess.Popen`: the child gets ``sig`` when its parent dies.

    The check of the parent's pid after ``prctl`` closes the race of a parent that died between
    fork and prctl (the child would have been re-parented already and never be signalled). The
    signal can come more than once: a multi-threaded parent that dies hands the child to another
    of its threads still alive, and each hand-over signals it (the nodes take a repeated SIGTERM
    as one, :mod:`vp_scene.node_runtime`).
    """
    parent = os.getpid()

    def preexec() -> None:
        if _prctl is not None:
            _prctl(_PR_SET_PDEATHSIG, int(sig), 0, 0, 0)
        if os.getppid() != parent:
            os.kill(os.getpid(), sig)
    return preexec


_YAML_LITERAL = re.compile(r"^(|~|null|Null|NULL|true|True|TRUE|false|False|FALSE|yes|no|on|off|"
                           r"[-+]?(\d[\d_]*)?\.?\d*([eE][-+]?\d+)?|[-+]?\.(inf|Inf|INF)|\.(nan|NaN|NAN))$")


def ros_arg_value(value: Any) -> str:
    """A Python value as the YAML text of ``-p name:=value`` (strings quoted when YAML would
    read them as another type)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else (".nan" if math.isnan(value) else
                                                         (".inf" if value > 0 else "-.inf"))
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(ros_arg_value(v) for v in value) + "]"
    s = str(value)
    if _YAML_LITERAL.match(s) or re.search(r"[:#\[\]{},'\"&*!|>%@`]|^[-?]", s) or s != s.strip():
        return "'" + s.replace("'", "''") + "'"
    return s


def executable(pkg: str, exe: str) -> Path:
    """``<repo>/install/<pkg>/lib/<pkg>/<exe>``, else the package prefix from the ament index."""
    path = REPO / "install" / pkg / "lib" / pkg / exe
    if path.exists():
        return path
    try:
        from ament_index_python.packages import get_package_prefix

        return Path(get_package_prefix(pkg)) / "lib" / pkg / exe
    except Exception:  # noqa: BLE001 - report the expected path
        return path


def node_command(pkg: str, exe: str, params: Optional[dict] = None, args: Iterable[str] = (),
                 name: Optional[str] = None) -> list:
    """``[<exe>, *args, --ros-args, (-r __node:=name), -p k:=v ...]``; FileNotFoundError when the
    package is not built. Parameters whose value is None are left out (the node's default)."""
    path = executable(pkg, exe)
    if not path.exists():
        raise FileNotFoundError(f"{path} not found: run `make setup` first")
    cmd = [str(path), *args, "--ros-args"]
    if name:
        cmd += ["-r", f"__node:={name}"]
    for key, value in (params or {}).items():
        if value is not None:
            cmd += ["-p", f"{key}:={ros_arg_value(value)}"]
    return cmd


class NodeProcess:
    """A command (usually a ROS node) as a child process in its own session.

    Output (stdout and stderr) goes line by line to ``log_path`` and, when ``echo`` is given, to
    this process's stderr prefixed with ``[echo]`` (:meth:`mute` stops the echo). The child gets
    SIGTERM when the thread that created this object exits (see the module docstring), and keeps
    the descriptors ``pass_fds`` open (e.g. its run's folder lock, ``vp_scene.folders.FolderLock``).
    """

    def __init__(self, cmd: list, env: dict, log_path: Path, echo: Optional[str] = None,
                 pass_fds: Iterable[int] = ()) -> None:
        self.cmd, self.log_path, self.echo = list(cmd), Path(log_path), echo
        self._lines: list[str] = []
        self._lock = threading.Lock()
        self._muted = threading.Event()
        self._log = open(self.log_path, "w", errors="replace")
        self.proc = subprocess.Popen(self.cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     stdin=subprocess.DEVNULL, start_new_session=True, pass_fds=tuple(pass_fds),
                                     preexec_fn=die_with_parent(), text=True, errors="replace", bufsize=1)
        self._thread = threading.Thread(target=self._pump, name=f"pump-{echo or self.proc.pid}", daemon=True)
        self._thread.start()

    def _pump(self) -> None:
        for line in self.proc.stdout:
            with self._lock:
                self._lines.append(line)
                if not self._log.closed:
                    self._log.write(line)
                    self._log.flush()
            if self.echo and not self._muted.is_set():
                sys.stderr.write(f"[{self.echo}] {line}")
        self.proc.stdout.close()

    @property
    def pid(self) -> int:
        return self.proc.pid

    def alive(self) -> bool:
        return self.proc.poll() is None

    def poll(self) -> Optional[int]:
        return self.proc.poll()

    def output(self) -> str:
        """Everything the process has written so far."""
        with self._lock:
            return "".join(self._lines)

    def last_line(self) -> str:
        """The last non-empty line of output ('' when none)."""
        with self._lock:
            return next((ln.strip() for ln in reversed(self._lines) if ln.strip()), "")

    def wait_for_output(self, text: str, timeout: float) -> bool:
        """Wait until ``text`` appears in the output (False at the deadline or when it exited)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if text in self.output():
                return True
            if not self.alive():
                self._thread.join(timeout=1.0)
                return text in self.output()
            time.sleep(0.05)
        return text in self.output()

    def wait(self, timeout: float) -> Optional[int]:
        """Exit status, or None if still running after ``timeout`` seconds."""
        try:
            code = self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            return None
        self._thread.join(timeout=1.0)  # the last lines
        return code

    def mute(self) -> None:
        """Stop echoing the output to stderr (the log file keeps everything)."""
        self._muted.set()

    def signal(self, sig: int) -> None:
        """Send ``sig`` to the process (not its group)."""
        try:
            os.kill(self.proc.pid, sig)
        except ProcessLookupError:
            pass

    def _signal_group(self, sig: int) -> None:
        try:
            os.killpg(self.proc.pid, sig)
        except (ProcessLookupError, PermissionError):
            pass

    def stop(self, timeout: float = 10.0) -> Optional[int]:
        """SIGTERM the process group (the suite's nodes exit 0 within seconds), then SIGKILL; the
        exit status. The suite's nodes answer SIGINT and SIGTERM alike (exit 0, also while still
        importing: :mod:`vp_scene.node_entry`); SIGTERM also ends other commands quietly."""
        for sig, wait in ((signal.SIGTERM, timeout), (signal.SIGKILL, 3.0)):
            if not self.alive():
                break
            self._signal_group(sig)
            self.wait(wait)
        self._signal_group(signal.SIGKILL)  # helper processes of an exited leader
        self._thread.join(timeout=2.0)
        with self._lock:
            self._log.close()
        return self.proc.returncode
