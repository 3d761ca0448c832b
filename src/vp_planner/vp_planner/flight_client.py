"""The planner node's :class:`vp_scene.flights.FlightSimulator`: a client of the recon node's
``vp_interfaces/action/SimulateFlights`` on ``/simulate_flights``.

:meth:`ActionFlights.fly` sends one goal a batch (the plans' cameras, each plan's draw, the
flights' setting and capture figures, :func:`vp_scene.messages.simulate_flights_goal`), hands each
flight to ``on_flight`` as its feedback comes (in the calling thread, which polls every
:data:`POLL_S`; a flight whose feedback was lost is handed on from the result), and returns one
:class:`~vp_scene.flights.FlightScore` a plan.

DDS loses service answers now and then on a loaded machine (rmw_fastrtps drops a response whose
reply path is not matched, and rclpy drops one that comes back before its request is recorded),
so no answer is waited for without end: a goal whose acceptance is lost is known accepted by its
feedback (the recon node sends one as a batch starts) and its result asked for by its id; one with
neither within :data:`ANSWER_S` is given up; the result is asked for again every
:data:`RESULT_AGAIN_S`, and once every flight is back by feedback it is waited for
:data:`RESULT_GRACE_S` at most. Nothing it meets is an exception: a goal the recon node rejects
(it flies one batch at a time), aborts or never answers, and a server unseen for :data:`LOST_S`
(its node died), make the flights not back scored failures that say why (handed to ``on_flight``
too). ``should_stop()`` true cancels the goal and returns at once (the flights not back:
failures, 'cancelled', not handed on).

The calls block, so they are made off the node's executor (the planning process's flight thread,
:mod:`vp_planner.plan_process`), while the executor's threads complete the client's futures (its
callback group is reentrant). ``workers`` (the batch size) and ``wind_variance`` (the scene's, from
``/scene/description``) are the node's to set.
"""
from __future__ import annotations

import queue
import threading
import time
import uuid
from typing import Callable, Optional, Sequence

import numpy as np
from numpy.typing import NDArray
from rclpy.action.client import ClientGoalHandle
from unique_identifier_msgs.msg import UUID

from vp_interfaces.action import SimulateFlights
from vp_scene.flights import FlightDraw, FlightScore, FlightSettings, OnFlight
from vp_scene.messages import flight_score_of, simulate_flights_goal

__all__ = ["ActionFlights", "POLL_S", "LOST_S", "ANSWER_S", "RESULT_AGAIN_S", "RESULT_GRACE_S"]

#: s between two looks at the goal, its feedback and ``should_stop``.
POLL_S = 0.05
#: s the server may stay unseen before the flights not back are given up (a loaded machine can
#: hide a live node from the graph for seconds; a dead one is gone after DDS's lease, 20 s).
LOST_S = 30.0
#: s a goal may go without an answer (its acceptance, or the feedback a batch starts with).
ANSWER_S = 30.0
#: s between two requests of a goal's result (a lost answer is asked for again).
RESULT_AGAIN_S = 10.0
#: s the result is waited for once every flight is back by feedback.
RESULT_GRACE_S = 10.0
#: The ReconstructionScore code of a flight that was not flown (vp_recon.errors.UNKNOWN).
_NOT_FLOWN = 1


class ActionFlights:
    """Flies batches on ``/simulate_flights`` (module docstring) through ``client`` (an rclpy
    ActionClient of SimulateFlights), at ``settings``, photographed with these reported-pose errors
    and ground control, with field of view ``fov`` (rad); ``log(text)`` gets a line a batch."""

    def __init__(self, client: object, settings: FlightSettings, report_position_sigma: float,
                 report_attitude_sigma: float, ground_control: bool, fov: float, workers: int,
                 wind_variance: float, log: Optional[Callable[[str], None]] = None) -> None:
        self.client, self.settings, self.fov = client, settings, float(fov)
        self.capture = (float(report_position_sigma), float(report_attitude_sigma), bool(ground_control))
        self.workers, self.wind_variance = int(workers), float(wind_variance)
        self.log = log or (lambda _text: None)

    def warm_up(self) -> None:
        """Ask the recon node to ready its flight workers for this setting (a goal with no plans),
        and return at once: the planner calls it before its cheap stage, whose seconds the
        warm-up then overlaps. Nothing is sent without a server; the answer is not waited for."""
        if self.client.server_is_ready():
            self.client.send_goal_async(simulate_flights_goal([], [], self.settings, *self.capture, self.fov))

    def fly(self, plans: Sequence[NDArray[np.float64]], draws: Sequence[FlightDraw],
            on_flight: Optional[OnFlight] = None, should_stop: Optional[Callable[[], bool]] = None
            ) -> list[FlightScore]:
        stop = should_stop or (lambda: False)
        scores: list[Optional[FlightScore]] = [None] * len(plans)

        def report(i: int, score: FlightScore) -> None:
            if 0 <= i < len(scores) and scores[i] is None:
                scores[i] = score
                if on_flight is not None:
                    on_flight(i, score)

        def rest(reason: str) -> list[FlightScore]:
            """The scores, the flights not back failures for ``reason``: scored failures handed to
            ``on_flight`` as any flight (the flight stage counts them), but for a cancel."""
            for i, d in enumerate(draws):
                if scores[i] is None:
                    failure = FlightScore(draw=d, failed=True, error_code=_NOT_FLOWN, reason=reason)
                    if reason == 'cancelled':
                        scores[i] = failure
                    else:
                        report(i, failure)
            return list(scores)

        if stop():  # a stop seen first by the caller's other threads: nothing is sent
            return rest('cancelled')
        came: queue.SimpleQueue = queue.SimpleQueue()
        started = threading.Event()  # a feedback of this goal came: the recon node flies it

        def feedback(msg: object) -> None:
            started.set()
            came.put(msg.feedback)

        goal_id = UUID(uuid=list(uuid.uuid4().bytes))
        goal = simulate_flights_goal(plans, draws, self.settings, *self.capture, self.fov)
        sent = self.client.send_goal_async(goal, feedback_callback=feedback, goal_uuid=goal_id)
        handle, why = self._accepted(sent, started, goal_id, stop)
        if why:
            return rest(why)
        if not handle.accepted:
            return rest('the recon node refused the flights (it flies one batch at a time)')
        self.log(f'flying {len(plans)} plans on /simulate_flights')
        result, why = self._result(handle, stop, lambda: self._drain(came, report), lambda: None not in scores)
        if why:
            return rest(why)
        self._drain(came, report)
        if result is None:  # every flight came back by feedback; the result's answer did not
            return list(scores)
        for msg in result.flights:  # those whose feedback was lost
            report(int(msg.plan), flight_score_of(msg))
        if result.error_code != SimulateFlights.Result.NONE:
            return rest(f'/simulate_flights: {result.error_msg}')
        return rest('the recon node did not fly it')

    def _accepted(self, sent: object, started: threading.Event, goal_id: UUID, stop: Callable[[], bool]):
        """(the goal's handle, '') once it is answered, or known accepted by its feedback (the
        answer lost: a handle made from its id); (None, why) for a stop, a lost server or no answer
        within :data:`ANSWER_S` (an acceptance that comes later is cancelled)."""
        why = self._wait(lambda: sent.done() or started.is_set(), stop, ANSWER_S,
                         f'the recon node did not answer the flights\' goal within {ANSWER_S:g} s')
        if sent.done():
            return sent.result(), why
        if started.is_set() and not why:
            return ClientGoalHandle(self.client, goal_id, SimulateFlights.Impl.SendGoalService.Response(accepted=True)), ''
        sent.add_done_callback(lambda f: f.result().cancel_goal_async()
                               if f.result() is not None and f.result().accepted else None)
        return None, why

    def _result(self, handle: object, stop: Callable[[], bool], meanwhile: Callable[[], None],
                all_back: Callable[[], bool]):
        """(the goal's result, '') as answered, asked for again every :data:`RESULT_AGAIN_S`;
        (None, '') when every flight is back by feedback and no answer came within
        :data:`RESULT_GRACE_S`; (None, why) for a stop (the goal cancelled) or a lost server."""
        asked = [handle.get_result_async()]
        last_ask, back_at = time.monotonic(), None

        def answered() -> bool:
            nonlocal last_ask, back_at
            meanwhile()
            now = time.monotonic()
            if any(f.done() for f in asked):
                return True
            if all_back():
                back_at = back_at or now
                if now - back_at > RESULT_GRACE_S:
                    return True
            if now - last_ask > RESULT_AGAIN_S:
                asked.append(handle.get_result_async())
                last_ask = now
            return False

        why = self._wait(answered, stop)
        if why == 'cancelled':
            handle.cancel_goal_async()
        done = [f for f in asked if f.done()]
        return (done[0].result().result if done and not why else None), why

    def _wait(self, ready: Callable[[], bool], stop: Callable[[], bool], timeout: Optional[float] = None,
              late: str = '') -> str:
        """Until ``ready()`` (''), or why not: 'cancelled' (``stop()``), the server lost, or
        ``late`` after ``timeout`` seconds."""
        t0, unseen_since = time.monotonic(), None
        while not ready():
            if stop():
                return 'cancelled'
            now = time.monotonic()
            if timeout is not None and now - t0 > timeout:
                return late
            if self.client.server_is_ready():
                unseen_since = None
            elif unseen_since is None:
                unseen_since = now
            elif now - unseen_since > LOST_S:
                return f'/simulate_flights went away (no recon node for {LOST_S:g} s)'
            time.sleep(POLL_S)
        return ''

    @staticmethod
    def _drain(came: queue.SimpleQueue, report: Callable[[int, FlightScore], None]) -> None:
        while True:
            try:
                fb = came.get_nowait()
            except queue.Empty:
                return
            if fb.flights_done:  # the batch's first feedback, sent as it starts, carries no flight
                report(int(fb.last.plan), flight_score_of(fb.last))
