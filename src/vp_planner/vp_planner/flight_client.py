"""The planner node's :class:`vp_scene.flights.FlightSimulator`: a client of the recon node's
``vp_interfaces/action/SimulateFlights`` on ``/simulate_flights``.

:meth:`ActionFlights.fly` sends one goal a batch (the plans' cameras, each plan's draw, the
flights' setting and capture figures, :func:`vp_scene.messages.simulate_flights_goal`), hands each
flight to ``on_flight`` as its feedback comes (in the calling thread, which polls every
:data:`POLL_S`; a flight whose feedback was lost is handed on from the result), and returns one
:class:`~vp_scene.flights.FlightScore` a plan. Nothing it meets is an exception: a goal the recon
node rejects (it flies one batch at a time) or aborts, and a server that goes away mid-batch
(:data:`LOST_S` seconds unseen), make the flights not back scored failures that say why (handed to
``on_flight`` too). ``should_stop()`` true cancels the goal and returns at once (the flights not
back: failures, 'cancelled', not handed on).

The calls block, so they are made off the node's executor (the planning process's flight thread,
:mod:`vp_planner.plan_process`), while the executor's threads complete the client's futures (its
callback group is reentrant). ``workers`` (the batch size) and ``wind_variance`` (the scene's, from
``/scene/description``) are the node's to set.
"""
from __future__ import annotations

import queue
import time
from typing import Callable, Optional, Sequence

import numpy as np
from numpy.typing import NDArray

from vp_interfaces.action import SimulateFlights
from vp_scene.flights import FlightDraw, FlightScore, FlightSettings, OnFlight
from vp_scene.messages import flight_score_of, simulate_flights_goal

__all__ = ["ActionFlights", "POLL_S", "LOST_S"]

#: s between two looks at the goal, its feedback and ``should_stop``.
POLL_S = 0.05
#: s the server may stay unseen (its node died) before the flights not back are given up.
LOST_S = 3.0
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
        goal = simulate_flights_goal(plans, draws, self.settings, *self.capture, self.fov)
        sent = self.client.send_goal_async(goal, feedback_callback=lambda fb: came.put(fb.feedback.last))
        why = self._wait(sent, stop)
        if why:  # the goal, accepted now or later, is cancelled
            sent.add_done_callback(lambda f: f.result().cancel_goal_async()
                                   if f.result() is not None and f.result().accepted else None)
            return rest(why)
        handle = sent.result()
        if not handle.accepted:
            return rest('the recon node refused the flights (it flies one batch at a time)')
        self.log(f'flying {len(plans)} plans on /simulate_flights')
        answer = handle.get_result_async()
        why = self._wait(answer, stop, lambda: self._drain(came, report))
        if why:
            if why == 'cancelled':
                handle.cancel_goal_async()
            return rest(why)
        self._drain(came, report)
        result = answer.result().result
        for msg in result.flights:  # those whose feedback was lost
            report(int(msg.plan), flight_score_of(msg))
        if result.error_code != SimulateFlights.Result.NONE:
            return rest(f'/simulate_flights: {result.error_msg}')
        return rest('the recon node did not fly it')

    def _wait(self, future: object, stop: Callable[[], bool], meanwhile: Optional[Callable[[], None]] = None) -> str:
        """Until ``future`` is done (''), or why not: 'cancelled' (``stop()``), or the server lost."""
        unseen_since = None
        while not future.done():
            if meanwhile is not None:
                meanwhile()
            if stop():
                return 'cancelled'
            if self.client.server_is_ready():
                unseen_since = None
            elif unseen_since is None:
                unseen_since = time.monotonic()
            elif time.monotonic() - unseen_since > LOST_S:
                return f'/simulate_flights went away (no recon node for {LOST_S:g} s)'
            time.sleep(POLL_S)
        return ''

    @staticmethod
    def _drain(came: queue.SimpleQueue, report: Callable[[int, FlightScore], None]) -> None:
        while True:
            try:
                msg = came.get_nowait()
            except queue.Empty:
                return
            report(int(msg.plan), flight_score_of(msg))
