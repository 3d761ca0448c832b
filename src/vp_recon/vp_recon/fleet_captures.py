"""The fleet's capture sets (the recon node's ``source: fleet``; README "From a real flight"): a
capture trigger sent on ``/fleet/capture`` and, from every drone of the plan's ``/fleet/assignment``,
for each of its poses (in its route's ``order``) an image, ``camera_info`` and reported pose with
one stamp, gathered into a :class:`vp_recon.flight.CapturedViews`. The recon node
(:mod:`vp_recon.recon_node`) owns one :class:`FleetCaptures`; its :meth:`FleetCaptures.capture_sets`
is the fleet as a source of the reconstruction's loop (:func:`vp_recon.pipeline.reconstruct_sets`)."""
from __future__ import annotations

import threading
import time
from collections import OrderedDict
from typing import Callable, Iterator, Optional, Sequence

import numpy as np
from rclpy.node import Node

from vp_recon.errors import CAPTURE_MISSING, ReconError
from vp_recon.flight import CapturedViews, flown_views, join_views
from vp_recon.progress import ReconCancelled
from vp_scene.flight_poses import FlightError
from vp_scene.messages import camera_info_intrinsics, compressed_image_array, drone_topic, image_array, pose_array
from vp_scene.node_runtime import LATCHED

__all__ = ["IMAGE_TRANSPORTS", "CAPTURES_KEPT", "FleetCaptures"]

#: image_transport -> the image topic under camera_topic (the image_transport convention).
IMAGE_TRANSPORTS = {'raw': 'image_raw', 'compressed': 'image_raw/compressed'}
#: /fleet/assignment messages remembered to find the one of a plan.
_ASSIGNMENTS_KEPT = 16
#: captures (stamps) kept per drone until a capture set takes them, at least (a drone with more poses
#: in the latest assignment: as many as its poses); beyond, the oldest is dropped with a log line
#: (memory: a 2000 x 1500 image is 9 MB; a drone that sends unasked would grow it).
CAPTURES_KEPT = 2


class FleetCaptures:
    """The drones' capture sets (source fleet; README "From a real flight").

    ``/fleet/assignment`` says which drone holds which pose of a plan; for each drone named there
    the node subscribes ``{camera_topic}/image_raw`` (sensor_msgs/Image; with ``image_transport``
    compressed ``image_raw/compressed``, sensor_msgs/CompressedImage), ``camera_info`` and
    ``pose`` (the reported PoseStamped). Every message received is kept by its stamp until a
    capture set takes it (nothing received is lost, also what arrives while a set is being
    reconstructed); a capture older than the trigger asking for it belongs to an older plan or
    realization and is ignored with a log line. A drone's captures of one trigger are its poses'
    in its route's order (it photographs them as it flies them): the k-th, by stamp, is its k-th pose.

    Memory: an image is converted to its array as it arrives (a view of the message's buffer,
    which is then the only copy), and at most :data:`CAPTURES_KEPT` captures are kept per drone,
    or its poses' number (the oldest beyond is dropped with a log line): a capture set of N
    images costs the node about N images' bytes, not three times that."""

    def __init__(self, node: Node, lock: threading.Condition) -> None:
        from vp_interfaces.msg import CaptureTrigger, FleetAssignment

        self._node, self._lock = node, lock
        self._assignments: OrderedDict = OrderedDict()  # plan stamp key -> FleetAssignment
        self._got: dict = {}  # drone -> {stamp ns: {kind: msg}}
        self._subscribed: set = set()
        self._keep: dict = {}  # drone -> captures kept (its poses in the latest assignment, at least CAPTURES_KEPT)
        self._topic = ''
        self._trigger = node.create_publisher(CaptureTrigger, '/fleet/capture', LATCHED)
        self._trigger_type = CaptureTrigger
        node.create_subscription(FleetAssignment, '/fleet/assignment', self._on_assignment, LATCHED)

    @staticmethod
    def _ns(stamp) -> int:
        return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)

    def _on_assignment(self, msg) -> None:
        with self._lock:
            self._assignments[self._ns(msg.plan_stamp)] = msg
            for d in {e.drone for e in msg.entries}:
                self._keep[d] = max(CAPTURES_KEPT, sum(e.drone == d for e in msg.entries))
            while len(self._assignments) > _ASSIGNMENTS_KEPT:
                self._assignments.popitem(last=False)
            self._lock.notify_all()

    def _subscribe(self, drone: str, topic: str, transport: str = 'raw') -> None:
        """Subscribe the drone's image (``image_raw`` or ``image_raw/compressed``, by
        ``transport``), ``camera_info`` and ``pose`` under ``topic``, once per topic name."""
        from geometry_msgs.msg import PoseStamped
        from sensor_msgs.msg import CameraInfo, CompressedImage, Image

        base = drone_topic(topic, drone)
        image = ('compressed', CompressedImage) if transport == 'compressed' else ('image', Image)
        for kind, t, name in ((*image, IMAGE_TRANSPORTS[transport]), ('info', CameraInfo, 'camera_info'),
                              ('pose', PoseStamped, 'pose')):
            if f'{base}/{name}' in self._subscribed:
                continue
            self._subscribed.add(f'{base}/{name}')
            self._node.create_subscription(t, f'{base}/{name}', lambda m, d=drone, k=kind: self._on(d, k, m), LATCHED)
            self._node.get_logger().info(f'subscribed {base}/{name}')

    def _on(self, drone: str, kind: str, msg) -> None:
        stamp = self._ns(msg.header.stamp)
        if kind in ('image', 'compressed'):  # kept as the array: the message itself is let go
            try:  # raw: a view of msg.data; compressed: decoded, one image at a time as they come
                msg = image_array(msg) if kind == 'image' else compressed_image_array(msg)
            except ValueError as exc:
                msg = exc  # reported when a capture set takes it
            kind = 'image'
        with self._lock:
            got = self._got.setdefault(drone, {})
            got.setdefault(stamp, {})[kind] = msg
            dropped = sorted(got)[:-self._keep.get(drone, CAPTURES_KEPT)]
            for t in dropped:
                del got[t]
            self._lock.notify_all()
        for t in dropped:
            self._node.get_logger().warning(f'capture of {drone} stamped {t} ns dropped: '
                                            f'{self._keep.get(drone, CAPTURES_KEPT)} newer ones are waiting for a '
                                            'capture set (memory)')

    def capture(self, plan_stamp, num_poses: int, k: int, timeout: float, topic: str, stopped,
                transport: str = 'raw') -> object:
        """The capture set of realization ``k`` of the plan: trigger, then for every pose of the
        plan's assignment one image, camera_info and pose with one stamp (not older than the
        trigger) from its drone (a drone's k-th capture by stamp is its k-th pose in route order),
        as :class:`vp_recon.flight.CapturedViews` in pose order; None when ``stopped()``.
        ReconError CAPTURE_MISSING naming the drones that sent too few."""
        key = self._ns(plan_stamp)
        deadline = time.monotonic() + timeout
        with self._lock:
            self._lock.wait_for(lambda: key in self._assignments or stopped(), timeout=timeout)
            fleet = self._assignments.get(key)
        if stopped():
            return None
        if fleet is None:
            raise ReconError(CAPTURE_MISSING, f'no /fleet/assignment for the plan within capture_timeout {timeout:g} s')
        if fleet.error_code or len(fleet.entries) != num_poses:
            raise ReconError(CAPTURE_MISSING, f'the dispatcher sent no drone to {num_poses - len(fleet.entries)} of '
                                              f'the {num_poses} poses: {fleet.error_msg or "no assignment"}')
        entries = sorted(fleet.entries, key=lambda e: e.pose_index)
        route = {}  # drone -> its poses' entries in flying order
        for e in sorted(fleet.entries, key=lambda e: (e.drone, e.order)):
            route.setdefault(e.drone, []).append(e)
        drones = list(route)
        for d in drones:
            self._subscribe(d, topic, transport)
        asked = self.now_ns()
        trigger = self._trigger_type(realization=int(k), plan_stamp=plan_stamp)
        trigger.header.frame_id = fleet.header.frame_id
        trigger.header.stamp = self._node.get_clock().now().to_msg()
        self._trigger.publish(trigger)
        self._node.get_logger().info(f'capture {k} of the plan asked of {", ".join(drones)}')

        def complete(d: str) -> list:
            """The drone's complete captures since the trigger, oldest first (its poses' order)."""
            return [m for t, m in sorted(self._got.get(d, {}).items()) if t >= asked and len(m) == 3]

        with self._lock:
            self._lock.wait_for(lambda: stopped() or all(len(complete(d)) >= len(route[d]) for d in drones),
                                timeout=max(0.0, deadline - time.monotonic()))
            if stopped():
                return None
            taken = {d: complete(d)[:len(route[d])] for d in drones}
            for d in drones:  # older captures: another plan or realization's
                for t in [t for t in self._got.get(d, {}) if t < asked]:
                    self._node.get_logger().info(f'capture of {d} stamped {t} ns is older than capture {k} '
                                                 'of this plan: ignored')
                    del self._got[d][t]
                for t in [t for t, m in self._got.get(d, {}).items() if any(m is x for x in taken[d])]:
                    del self._got[d][t]  # taken
        missing = [f'{d} ({len(taken[d])} of {len(route[d])})' if len(route[d]) > 1 else d
                   for d in drones if len(taken[d]) < len(route[d])]
        if missing:
            raise ReconError(CAPTURE_MISSING, f'no capture from drone(s) {", ".join(missing)} within capture_timeout '
                                              f'{timeout:g} s (capture {k})')
        sets = {e.pose_index: taken[d][n] for d in drones for n, e in enumerate(route[d])}
        try:
            intr = [camera_info_intrinsics(sets[e.pose_index]['info']) for e in entries]
            if any(not np.allclose(a[0], intr[0][0]) or a[1:] != intr[0][1:] for a in intr):
                raise ValueError('the drones\' cameras differ (one camera model per flight)')
            bad = [(e.drone, sets[e.pose_index]['image']) for e in entries
                   if isinstance(sets[e.pose_index]['image'], Exception)]
            if bad:
                raise ValueError(f'the image of {bad[0][0]}: {bad[0][1]}')
            for e, (_, w, h) in zip(entries, intr):  # K is the camera_info's size's: another size is another camera
                im = sets[e.pose_index]['image']
                if (im.shape[1], im.shape[0]) != (w, h):
                    raise ValueError(f'the image of {e.drone} is {im.shape[1]}x{im.shape[0]} pixels, its camera_info '
                                     f'says {w}x{h}')
            return CapturedViews(
                names=[f'view_{e.pose_index:03d}.png' for e in entries],
                images=[sets[e.pose_index]['image'] for e in entries],
                reported=np.array([pose_array(sets[e.pose_index]['pose'].pose) for e in entries]),  # roll kept
                K=intr[0][0], realization=int(k)).validate()
        except (ValueError, FlightError) as exc:
            raise ReconError(CAPTURE_MISSING, f'capture {k} from the fleet is unusable: {exc}') from None

    def capture_sets(self, plan_stamp, num_poses: int, realizations: int, timeout: float, topic: str,
                     stopped: Callable[[], bool], transport: str = 'raw', control: object = None,
                     flown: Optional[Sequence[tuple]] = None) -> Iterator[CapturedViews]:
        """The fleet as a source of capture sets: realizations 0..``realizations``-1 of the plan,
        each taken when the loop asks for it (:meth:`capture`), with ``control`` (the field's
        ground control, :class:`vp_scene.ground_control.GroundControl` or None). A second
        sortie's cameras already flown (``flown``: :func:`vp_recon.flight.locate_flown`) put
        their images of the realization first (:func:`vp_recon.flight.flown_views`), as the
        render source orders the cameras. A ReconError names its realization (CAPTURE_MISSING);
        ReconCancelled once ``stopped()``."""
        log = self._node.get_logger()
        for k in range(realizations):
            try:
                views = self.capture(plan_stamp, num_poses, k, timeout, topic, stopped, transport=transport)
                if views is None:
                    raise ReconCancelled('stopped while waiting for the fleet')
                views.control = control
                log.info(f'capture {k}: {len(views.images)} images from the fleet '
                         f'({sum(im.nbytes for im in views.images) / 1e6:.0f} MB) collected')
                if flown:
                    try:
                        views = join_views([flown_views(flown, k), views])
                    except FlightError as exc:
                        raise ReconError(CAPTURE_MISSING, f'the images of the cameras already flown: {exc}') from None
                    log.info(f'capture {k}: with the {len(flown)} images of the cameras already flown')
            except ReconError as exc:
                exc.realization = k
                raise
            yield views

    def now_ns(self) -> int:
        return self._ns(self._node.get_clock().now().to_msg())
