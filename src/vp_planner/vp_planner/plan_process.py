"""Planning in a process of its own: :func:`vp_planner.optimizers.plan_views` where a stop is
answered at once, at any stage of the plan.

``plan_views`` asks ``should_stop`` between evaluations and inside its feasible-plan searches,
but some of its stages are one long computation that cannot ask: one evaluation of a hundred
cameras (seconds; a minute with cameras already flown), the KD-trees of a large scene or
reconstruction, a GP fit. :func:`run_plan` runs the plan in a child process forked from
multiprocessing's fork server (which has the planner's modules imported, :func:`warm`: a fork is
cheap, and it carries none of the caller's threads), streams every evaluation's progress back,
and ends the child with SIGKILL as soon as ``should_stop()`` is true: the caller has its answer
within :data:`POLL_S` seconds whatever the child was doing, and the child's memory is freed.

The child dies with the fork server, which ends with the process that started it (Linux's
PR_SET_PDEATHSIG), so a plan never outlives its caller; it ignores SIGINT (a terminal's Ctrl-C
reaches the caller, which decides) and runs torch with the threads asked.

Simulated flights (:mod:`vp_planner.flight_planning`): given a ``simulator``
(:class:`vp_scene.flights.FlightSimulator`, e.g. the planner node's client of the recon node's
``/simulate_flights``), the child plans with a stand-in of the same ``workers`` and
``wind_variance`` whose ``fly`` sends the batch to the caller over the (duplex) pipe and waits; the
caller flies it with the real simulator on a thread of its own, sends each flight back as it comes
(the stand-in hands it to the flight stage) and then the batch's scores, while it keeps looking at
``should_stop``: a stop kills the child at once and ends the batch (the simulator's ``should_stop``
turns true, e.g. the flights' goal is cancelled); its ``warm_up`` asks the caller to ready the
simulator's workers (the simulator's own ``warm_up``, when it has one). The flights' progress comes back as the
evaluations' does (``on_flight``). The library's refusals
come back as the exceptions ``plan_views`` raised (an exception that cannot be pickled comes back
as a RuntimeError naming it); a child that dies without an answer (the kernel's OOM killer) is a
:class:`PlanProcessDied`.

ROS-free: the planner node is its adapter.
"""
from __future__ import annotations

import multiprocessing
import pickle
import signal
import threading
from typing import Any, Callable, Optional

import numpy as np

__all__ = ["POLL_S", "PlanProcessDied", "warm", "run_plan"]

#: s between two looks at ``should_stop`` while the child plans.
POLL_S: float = 0.05
#: Modules the fork server imports once, so that a plan's child starts with them: the planner,
#: and what its modules import only when a method needs it (botorch and gpytorch for egp/gp, the
#: scipy parts of planning by parts), which every child would import again otherwise.
_PRELOAD = ["vp_planner.plan_process", "vp_planner.optimizers", "vp_planner.bo", "vp_planner.bo_planning",
            "vp_planner.parts", "botorch.acquisition.analytic", "botorch.fit", "botorch.models",
            "botorch.models.transforms.outcome", "botorch.optim", "gpytorch", "scipy.cluster.vq", "scipy.optimize"]
#: Linux's prctl option: the signal a process gets when its parent ends.
_PR_SET_PDEATHSIG = 1

Progress = Callable[[int, int, float, Optional[list]], Any]
#: ``on_flight(done, total, score)``: :data:`vp_planner.flight_planning.OnFlight`.
FlightProgress = Callable[[int, int, Any], Any]


class PlanProcessDied(RuntimeError):
    """The planning process ended without an answer (killed by a signal, e.g. out of memory)."""


def _context() -> Any:
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(_PRELOAD)
    return ctx


def warm() -> None:
    """Start the fork server now (it imports the planner's modules: a few seconds in the
    background), so that the first plan does not wait for them; returns at once."""
    from multiprocessing import forkserver

    _context()
    forkserver.ensure_running()


def _die_with_parent() -> None:
    """SIGKILL this process when its parent ends (Linux; elsewhere nothing)."""
    import ctypes

    try:
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):
        pass


def _portable(exc: BaseException) -> BaseException:
    """``exc`` if it survives pickling, else a RuntimeError naming its type and message."""
    try:
        pickle.loads(pickle.dumps(exc))
        return exc
    except Exception:  # noqa: BLE001 - any failure to round-trip
        return RuntimeError(f"{type(exc).__name__}: {exc}")


class _FlightsOverPipe:
    """The child's :class:`vp_scene.flights.FlightSimulator`: ``fly`` sends ``("fly", (plans,
    draws))`` to the caller and hands each ``("flight", (i, score))`` it gets back to
    ``on_flight`` until ``("flown", scores)`` (``("fly_error", exception)``: raised here). A stop is
    the caller's (it kills this process), so ``should_stop`` is not looked at."""

    def __init__(self, conn: Any, workers: int, wind_variance: float) -> None:
        self.conn, self.workers, self.wind_variance = conn, int(workers), float(wind_variance)

    def warm_up(self) -> None:
        """Ask the caller to ready its simulator's workers (``("warm_up", None)``; no answer)."""
        self.conn.send(("warm_up", None))

    def fly(self, plans: Any, draws: Any, on_flight: Any = None, should_stop: Any = None) -> list:
        self.conn.send(("fly", ([np.asarray(p, dtype=np.float64) for p in plans], list(draws))))
        while True:
            kind, payload = self.conn.recv()
            if kind == "flight":
                if on_flight is not None:
                    on_flight(*payload)
            elif kind == "flown":
                return payload
            else:
                raise payload


def _child(conn: Any, request: Any, realizations: np.ndarray, threads: int,
           flights: Optional[tuple] = None) -> None:
    """The child's work: ``plan_views`` with a callback that sends each evaluation's progress
    (and, with ``flights`` = (workers, wind_variance), a :class:`_FlightsOverPipe` simulator whose
    flights' progress is sent too), then ``("result", PlanResult)`` or ``("error", exception)``."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _die_with_parent()
    import torch

    from .optimizers import plan_views

    torch.set_num_threads(int(threads))

    def progress(done: int, total: int, best: float, weights: Optional[list]) -> bool:
        conn.send(("progress", (done, total, best, weights)))
        return True

    def flown(done: int, total: int, score: Any) -> None:
        conn.send(("flight_progress", (done, total, score)))

    simulator = None if flights is None else _FlightsOverPipe(conn, *flights)
    try:
        message: tuple = ("result", plan_views(request, realizations, callback=progress, simulator=simulator,
                                               on_flight=flown))
    except Exception as exc:  # noqa: BLE001 - every failure goes back to the caller
        message = ("error", _portable(exc))
    try:
        conn.send(message)
    except (pickle.PicklingError, TypeError, AttributeError) as exc:
        conn.send(("error", RuntimeError(f"the plan's answer cannot be sent: {type(exc).__name__}: {exc}")))
    conn.close()


def _death(child: Any) -> str:
    code = child.exitcode
    if code is not None and code < 0:
        name = signal.Signals(-code).name if -code in signal.Signals._value2member_map_ else str(-code)
        why = " (out of memory?)" if -code == signal.SIGKILL else ""
        return f"the planning process was killed by {name}{why} before it answered"
    return f"the planning process ended (exit code {code}) before it answered"


class _Start(threading.Thread):
    """Starts the child (which waits for the fork server while it imports the planner's modules)
    beside the caller, who keeps looking at ``should_stop`` meanwhile."""

    def __init__(self, child: Any, conn: Any) -> None:
        super().__init__(name="plan-start", daemon=True)
        self.child, self.conn = child, conn
        self.error: Optional[BaseException] = None

    def run(self) -> None:
        try:
            self.child.start()
        except BaseException as exc:  # noqa: BLE001 - raised again in the caller's thread
            self.error = exc
        finally:
            self.conn.close()  # the child holds the sending end: its end is the pipe's end

    def end(self) -> None:
        """Kill the child and reap it, now, or once it has started (in the background)."""
        if self.is_alive():
            threading.Thread(target=lambda: (self.join(), self.end()), name="plan-end", daemon=True).start()
            return
        if self.error is None:
            if self.child.is_alive():
                self.child.kill()
            self.child.join()


class _Flying(threading.Thread):
    """Flies one batch the child sent with the caller's simulator, sending each flight back as it
    comes, then the scores (or the simulator's exception); a child gone meanwhile is no error."""

    def __init__(self, simulator: Any, conn: Any, batch: tuple, should_stop: Callable[[], bool],
                 lock: threading.Lock) -> None:
        super().__init__(name="plan-flights", daemon=True)
        self.simulator, self.conn, self.batch, self.should_stop, self.lock = simulator, conn, batch, should_stop, lock

    def _send(self, message: tuple) -> None:
        with self.lock:  # run_plan closes the pipe under it: never a write to a closed (or reused) descriptor
            try:
                self.conn.send(message)
            except (OSError, ValueError):  # the child ended (a stop, a death): its flights are moot
                pass

    def run(self) -> None:
        plans, draws = self.batch
        try:
            scores = self.simulator.fly(plans, draws, on_flight=lambda i, score: self._send(("flight", (i, score))),
                                        should_stop=self.should_stop)
            message: tuple = ("flown", list(scores))
        except Exception as exc:  # noqa: BLE001 - the child raises it where the flights were asked for
            message = ("fly_error", _portable(exc))
        self._send(message)


def run_plan(request: Any, realizations: Any, progress: Optional[Progress] = None,
             should_stop: Optional[Callable[[], bool]] = None, threads: int = 1, simulator: Any = None,
             on_flight: Optional[FlightProgress] = None) -> Optional[Any]:
    """``plan_views(request, realizations)`` in a child process (the module docstring).

    Args:
        request: the :class:`~vp_planner.request.PlanRequest`.
        realizations: (K, P, 3) noisy scene realizations (copied to the child).
        progress: ``progress(done, total, best, weights)`` in the caller's thread after each
            evaluation the child made (``plan_views``' callback).
        should_stop: asked every :data:`POLL_S` seconds from the start (the fork server's
            imports included); True ends the child at once.
        threads: torch threads of the child.
        simulator: the :class:`vp_scene.flights.FlightSimulator` the plan's simulated flights are
            flown with, here (its ``workers`` and ``wind_variance`` are read once, now); None:
            ``plan_views`` without one.
        on_flight: ``on_flight(done, total, score)`` in the caller's thread after each flight.

    Returns:
        The :class:`~vp_planner.optimizers.PlanResult`, or None when ``should_stop()`` ended the
        plan (the child is killed; one still starting is killed once it has started).

    Raises:
        What ``plan_views`` raised (its refusals: ValueError subclasses); PlanProcessDied when
        the child ended without an answer.
    """
    ctx = _context()
    answers, conn = ctx.Pipe(duplex=True)
    flights = None if simulator is None else (int(simulator.workers), float(simulator.wind_variance))
    child = ctx.Process(target=_child, args=(conn, request, np.asarray(realizations, dtype=np.float64), int(threads),
                                             flights), name="plan", daemon=True)
    ended = threading.Event()  # set as run_plan returns: a batch still flying stops
    sending = threading.Lock()  # the flights' thread sends to the child; the pipe is closed under it

    def flights_stop() -> bool:
        return ended.is_set() or (should_stop is not None and should_stop())

    start = _Start(child, conn)
    start.start()
    try:
        while True:
            if should_stop is not None and should_stop():
                return None
            if start.is_alive():
                start.join(POLL_S)
                continue
            if start.error is not None:
                raise start.error
            if not answers.poll(POLL_S):
                continue
            try:
                kind, payload = answers.recv()
            except EOFError:
                child.join(5.0)
                raise PlanProcessDied(_death(child)) from None
            if should_stop is not None and should_stop():  # a stop wins over what the child said meanwhile
                return None
            if kind == "progress":
                if progress is not None:
                    progress(*payload)
            elif kind == "fly":
                _Flying(simulator, answers, payload, flights_stop, sending).start()
            elif kind == "warm_up":  # returns at once (the simulator's warm_up does not wait)
                if callable(getattr(simulator, "warm_up", None)):
                    simulator.warm_up()
            elif kind == "flight_progress":
                if on_flight is not None:
                    on_flight(*payload)
            elif kind == "result":
                return payload
            else:
                raise payload
    finally:
        ended.set()
        start.end()  # first: a send to a child killed fails at once, and lets go of the lock
        with sending:
            answers.close()
