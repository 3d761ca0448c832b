"""How every node of the suite runs: typed parameters, signals and exit codes (one home for all three).

Process contract of ``scene``, ``planner`` and ``recon``:

* SIGINT or SIGTERM: the node winds down and exits 0, quietly (no traceback), within
  :data:`SHUTDOWN_DEADLINE` seconds, always; a second SIGINT (Ctrl-C twice) exits at once, a
  repeated SIGTERM changes nothing: a supervisor killed with SIGKILL sends its parent-death
  SIGTERM (``tools/node_process.py``) once per thread of it that the node is handed to as they
  end, and taken as "exit now" it cut the recorder's file short of its summary. A signal that arrives
  while Python is still importing the node's modules, or while the node is being constructed,
  ends the process at once with exit 0 (the console entry, :mod:`vp_scene.node_entry`, answers
  signals before the first heavy import; nothing has started yet that could be lost).
* A bad parameter at start (wrong type, or a value out of range): one log line naming it, exit 2.
* A crash of the executor: the traceback, exit 1.

Why not rclpy's own signal handlers: they shut the context down the moment the signal arrives, so
whatever the node is still doing (answering an action client, publishing, finishing its
constructor) fails with RCLError tracebacks, and a main thread blocked in a
MultiThreadedExecutor's wait can miss the shutdown. Here
the handler only notes the time of the signal (or, while the node is being constructed, ends the
process: raising an exception into the constructor was swallowed where a library's import catches
BaseException, as trimesh's does); the executor spins in a thread of its own; the main thread polls
for the signal, lets the node wind down (``node.on_shutdown(timeout)``, optional: e.g. abort an action goal and
answer its client), shuts the executor and the context down and ends the process with
``os._exit`` (worker threads inside C++ libraries cannot block the exit). A watchdog ends the
process at the deadline whatever happens.

The handler takes no lock: Python runs it in the main thread between two bytecodes, possibly
while that thread holds a lock, and taking the same lock there never returns. It did: the handler
set a ``threading.Event`` that the main thread was waiting on, a signal that landed while
``Event.wait`` held the event's lock hung the node for good, before its watchdog was started (the
main thread in the handler, in ``Condition.__enter__``). So the handler writes a float, the main
thread sleeps in steps of :data:`POLL_S` and starts the watchdog itself.

Typed parameters: every parameter is declared with ``dynamic_typing=True`` and checked here,
so that a wrong type is a one-line error like any other bad value (rclpy would raise
InvalidParameterTypeException with a traceback), and an integer where a float is expected
(``-p fov:=2``) is simply accepted.

Parameter descriptors: a node's parameters are :class:`Param` entries (default, description,
``range``, ``read_only``, ``constraints``), so that ``ros2 param describe`` on a stock install
shows what the node enforces: the inclusive range as an IntegerRange (integer default) or a
FloatingPointRange (float default), ``read_only`` where a change at run time would not be
honoured, and the rules a range cannot say (choices, excluded ends) as additional constraints.
rclpy refuses a ``set_parameters`` outside the range or of a read-only parameter before the
node's own callback runs. At start, :func:`declare_typed` declares the parameters without ranges,
runs the node's check (its own one-line messages), checks the ranges itself (a one-line
ValueError, not rclpy's exception) and only then attaches the full descriptors.
"""
from __future__ import annotations

import math
import os
import signal
import sys
import threading
import time
import traceback
from typing import Any, Callable, NamedTuple, Optional

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

__all__ = ["SHUTDOWN_DEADLINE", "EXIT_OK", "EXIT_CRASHED", "EXIT_BAD_PARAMETERS", "INT_MAX", "LATCHED", "Param", "coerce",
           "declare_typed", "descriptor", "typed_values", "parameter_value", "refuse_bad_changes", "NewestWins",
           "MANAGED", "start_lifecycle", "run_node"]

#: The QoS of the suite's latched topics (scene, plans, fleet assignment and captures): reliable,
#: TRANSIENT_LOCAL, depth 1: a subscriber that joins late still gets the last message.
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)

#: Seconds from the first SIGINT/SIGTERM to the end of the process, at most.
SHUTDOWN_DEADLINE = 5.0
#: Seconds a node gets to wind down (``on_shutdown``) within the deadline.
SHUTDOWN_GRACE = 3.0

#: s between two looks of the main thread for a signal (or a crashed executor).
POLL_S = 0.1

EXIT_OK, EXIT_CRASHED, EXIT_BAD_PARAMETERS = 0, 1, 2

_KINDS = {bool: "a boolean", int: "an integer", float: "a number", str: "a string"}

#: Upper end of an IntegerRange for a parameter bounded below only (int64, the ROS integer).
INT_MAX = 2 ** 63 - 1


class Param(NamedTuple):
    """One node parameter: its default (whose type is enforced), a description, the inclusive
    ``range`` (lo, hi) the node enforces (``math.inf``/:data:`INT_MAX` for no upper end), whether
    it is ``read_only`` (fixed at start: a change would not be honoured) and the
    ``constraints`` a range cannot say (e.g. the choices of a string)."""

    default: Any
    description: str
    range: Optional[tuple] = None
    read_only: bool = False
    constraints: str = ""


def descriptor(name: str, spec: Any, limits: bool = True) -> Any:
    """The rcl_interfaces ParameterDescriptor of ``spec`` (a :class:`Param` or a (default,
    description) pair), dynamically typed; ``limits=False`` leaves out range and read_only."""
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

    p = Param(*spec)
    d = ParameterDescriptor(name=name, description=p.description, additional_constraints=p.constraints,
                            dynamic_typing=True)
    if limits:
        d.read_only = p.read_only
        if p.range is not None:
            lo, hi = p.range
            if isinstance(p.default, bool) or not isinstance(p.default, (int, float)):
                raise TypeError(f"parameter '{name}': a range needs a numeric default")
            if isinstance(p.default, int):
                d.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=1)]
            else:
                d.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]
    return d


def _check_range(name: str, spec: Any, value: Any) -> None:
    p = Param(*spec)
    if p.range is None or isinstance(value, bool) or not isinstance(value, (int, float)):
        return
    lo, hi = p.range
    if not lo <= value <= hi:
        top = "" if hi in (math.inf, INT_MAX) else f" and <= {hi:g}"
        raise ValueError(f"parameter '{name}' must be >= {lo:g}{top}, got {value!r}")


def coerce(name: str, value: Any, kind: type) -> Any:
    """``value`` as a parameter of type ``kind`` (bool, int, float, str, or list: a list of
    strings), else ValueError naming the parameter. An integer is accepted where a float is
    expected, and an empty list (``-p names:=[]`` arrives unset) where a list is; nothing else
    is converted."""
    if kind is list:
        if value is None:
            return []
        if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
            raise ValueError(f"parameter '{name}' must be a list of strings (e.g. \"{name}:=[a, b]\"), "
                             f"got {value!r}")
        return list(value)
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if kind is int and (isinstance(value, bool) or not isinstance(value, int)):
        raise ValueError(f"parameter '{name}' must be an integer, got {value!r}")
    if not isinstance(value, kind) or (kind is not bool and isinstance(value, bool)):
        raise ValueError(f"parameter '{name}' must be {_KINDS[kind]}, got {value!r}")
    return value


def declare_typed(node: Any, specs: dict, check: Optional[Callable[[dict], dict]] = None) -> dict:
    """Declare ``specs`` = {name: :class:`Param` or (default, description)} on ``node``,
    dynamically typed (the type of the default is enforced by :func:`typed_values` instead), and
    return the checked start values: ``check(values)`` (the node's rules, its own messages;
    default :func:`typed_values`), then each range. ValueError names the first bad parameter.
    The full descriptors (ranges, read_only) are attached after the checks (see the module
    docstring), so rclpy enforces them from then on."""
    for name, spec in specs.items():
        node.declare_parameter(name, Param(*spec).default, descriptor(name, spec, limits=False))
    values = {name: node.get_parameter(name).value for name in specs}
    checked = check(values) if check is not None else typed_values(specs, values)
    for name, spec in specs.items():
        _check_range(name, spec, values[name])
    for name, spec in specs.items():
        p = Param(*spec)
        if p.range is not None or p.read_only:
            node.set_descriptor(name, descriptor(name, spec))
    return checked


def typed_values(specs: dict, values: dict) -> dict:
    """{name: value} of ``values`` (names of ``specs`` only) coerced to the type of each default;
    ValueError naming the first bad one. Floats must be finite."""
    out = {}
    for name, value in values.items():
        if name not in specs:
            continue
        kind = type(specs[name][0])
        v = coerce(name, value, kind)
        if kind is float and not math.isfinite(v):
            raise ValueError(f"parameter '{name}' must be a finite number, got {v!r}")
        out[name] = v
    return out


def parameter_value(node: Any, specs: dict, name: str) -> Any:
    """The node's parameter ``name`` now, with the type of its default (an integer fov is a float)."""
    return typed_values(specs, {name: node.get_parameter(name).value})[name]


def refuse_bad_changes(node: Any, specs: dict, check: Callable[[dict], dict]) -> None:
    """Register the node's on-set-parameters callback: a change is applied only when the node's
    values with the change pass ``check``; else it is refused with ``check``'s message (and a
    warning in the log). rclpy has refused ranges and read-only parameters before."""
    from rcl_interfaces.msg import SetParametersResult

    def on_set(params: list) -> Any:
        current = {n: node.get_parameter(n).value for n in specs}
        try:
            check({**current, **{p.name: p.value for p in params}})
        except ValueError as exc:
            node.get_logger().warn(f'parameter change refused: {exc}')
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(on_set)


class NewestWins:
    """A node's "newest plan wins" worker: one thread runs the item in progress to its end; of the
    items that arrive meanwhile only the newest is kept (it replaces an older waiting one, logged
    as ``replaced``), because a newer plan supersedes older ones.

    ``handle(item)`` does the work; an exception out of it does not end the worker: it goes to
    ``on_error(item, exc)`` (unless the worker is stopped: then nothing is reported).
    :meth:`start` starts the thread, :meth:`offer` puts an item in the slot (True: it replaced
    one still waiting), :meth:`stop` ends the worker after its item and wakes every waiter.
    ``lock`` is a Condition the node may share for its other state (``pending`` and ``stopped``
    are read under it)."""

    def __init__(self, name: str, handle: Callable[[Any], None],
                 on_error: Optional[Callable[[Any, Exception], None]] = None, logger: Any = None,
                 replaced: str = "a newer item arrived: it replaces the one waiting") -> None:
        self.lock = threading.Condition()
        self.pending: Any = None
        self.stopped = False
        self._handle, self._on_error = handle, on_error
        self._logger, self._replaced = logger, replaced
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    def start(self) -> "NewestWins":
        self._thread.start()
        return self

    def offer(self, item: Any) -> bool:
        with self.lock:
            replaced = self.pending is not None
            self.pending = item
            self.lock.notify_all()
        if replaced and self._logger is not None:
            self._logger.warn(self._replaced)
        return replaced

    def take(self) -> Any:
        """The next item, waiting for one; None once stopped."""
        with self.lock:
            while self.pending is None and not self.stopped:
                self.lock.wait(0.5)
            if self.stopped:
                return None
            item, self.pending = self.pending, None
            return item

    def stop(self) -> None:
        with self.lock:
            self.stopped = True
            self.lock.notify_all()

    def _run(self) -> None:
        while (item := self.take()) is not None:
            try:
                self._handle(item)
            except Exception as exc:  # noqa: BLE001 - never let one item kill the worker
                if self.stopped:  # the node is being torn down under the worker: nothing to report
                    return
                if self._on_error is not None:
                    self._on_error(item, exc)


def _exit(code: int) -> None:
    """End the process now (after flushing): no interpreter finalization that could wait on
    threads still inside C++ code (COLMAP, Open3D, the DDS middleware)."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:  # noqa: BLE001 - exiting anyway
            pass
    os._exit(code)


#: The ``managed`` parameter of the lifecycle nodes (the planner, the dispatcher).
MANAGED = Param(False, 'false: configure and activate at start (a plain start); true: start unconfigured and wait '
                       'for a lifecycle manager (configure, activate, deactivate, cleanup, shutdown: nav2\'s '
                       'convention)', None, True)


def start_lifecycle(node: Any, managed: bool) -> None:
    """A lifecycle node's start: unless ``managed``, it configures and activates itself now (the
    transitions a manager would drive), so that a plain start serves at once."""
    if not managed:
        node.trigger_configure()
        node.trigger_activate()


def run_node(name: str, make_node: Callable[[], Any], args: Optional[list] = None, num_threads: int = 1,
             grace: float = SHUTDOWN_GRACE, deadline: float = SHUTDOWN_DEADLINE,
             error_prefix: str = "bad parameters") -> int:
    """Run the node built by ``make_node()`` until SIGINT/SIGTERM; never returns (ends the process).

    ``make_node`` raises ValueError (or OSError) naming a bad parameter or configuration: that
    is logged as one line (``<error_prefix>: <message>``) and the exit code is 2.
    ``num_threads`` > 1 spins a MultiThreadedExecutor. A node may define
    ``on_shutdown(timeout) -> bool`` (True: it wound down within ``timeout`` seconds; a lifecycle
    node, whose ``on_shutdown`` is a transition, names it ``wind_down``); it is called after the
    signal, before the executor stops.
    """
    import rclpy
    from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    signalled_at: list = []  # time.monotonic() of the first signal; the handler's only write
    constructing = [True]

    def on_signal(signum: int, _frame: Any) -> None:
        # no lock here, not even an Event's (see the module docstring)
        if signalled_at:  # a second Ctrl-C: no more waiting; a repeated SIGTERM: the deadline holds
            if signum == signal.SIGINT:
                _exit(EXIT_OK)
            return
        if constructing[0]:  # nothing runs yet that could be lost
            _exit(EXIT_OK)
        signalled_at.append(time.monotonic())

    def install() -> None:
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, on_signal)

    install()
    logger = rclpy.logging.get_logger(name)
    node = None
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
        node = make_node()
        # Again: a library the node loaded may have replaced them. glog, which pycolmap loads,
        # installs a SIGTERM handler at import that prints a stack trace and kills the process,
        # so a node using it imports it in its constructor, before this line.
        install()
        constructing[0] = False
    except (ValueError, OSError) as exc:
        constructing[0] = False
        logger.error(f"{error_prefix}: {' '.join(str(exc).split())}")
        _exit(EXIT_BAD_PARAMETERS)
    if signalled_at:  # the signal came right after the constructor
        _exit(EXIT_OK)

    executor = MultiThreadedExecutor(num_threads=num_threads) if num_threads > 1 else SingleThreadedExecutor()
    executor.add_node(node)
    crashed: list = []

    def spin() -> None:
        try:
            executor.spin()
        except Exception:  # noqa: BLE001 - reported below, exit 1
            crashed.append(traceback.format_exc())

    threading.Thread(target=spin, name=f"{name}-executor", daemon=True).start()
    while not signalled_at and not crashed:
        time.sleep(POLL_S)
    if signalled_at:  # from here on the process ends by the deadline, whatever happens
        watchdog = threading.Timer(max(0.0, deadline - (time.monotonic() - signalled_at[0])), _exit,
                                   args=(EXIT_OK,))
        watchdog.daemon = True
        watchdog.start()
    if crashed:
        sys.stderr.write(crashed[0])
        logger.error("the executor crashed; exiting")
        _exit(EXIT_CRASHED)
    wound_down = True
    # a lifecycle node's on_shutdown is its lifecycle transition: it names the hook wind_down
    on_shutdown = getattr(node, "wind_down", None) or getattr(node, "on_shutdown", None)
    if on_shutdown is not None:
        try:
            wound_down = bool(on_shutdown(grace))
        except Exception:  # noqa: BLE001 - exiting anyway
            wound_down = False
    if not wound_down:  # work still running in a callback: tearing down under it would only add noise
        logger.warn("shutting down without waiting for the running work")
        _exit(EXIT_OK)
    executor.shutdown(timeout_sec=1.0)
    try:
        node.destroy_node()
        rclpy.try_shutdown()
    except Exception:  # noqa: BLE001 - the process ends now anyway
        pass
    _exit(EXIT_OK)
    return EXIT_OK  # pragma: no cover
