"""The ``recorder`` node: a run's topics into one MCAP file (:mod:`vp_recon.recording`).

Every ``discovery_period`` s it lists the graph's topics (``get_topic_names_and_types``) and
subscribes, once, to each one that matches a pattern of ``topics`` and has a publisher: a
serialized subscription (``raw=True``: the CDR bytes are written as they arrive, never decoded),
with QoS adapted to the publishers as rosbag2 does (reliable when all of them are, transient local
when all of them are, so latched messages published before the recorder started are recorded
too). On SIGINT/SIGTERM (also its parent's death: ``tools/node_process.py``) the messages still
arriving are written (until none came for 0.5 s, at most the shutdown grace), then the file is
closed (summary and footer written) and the counts logged; until then it reads as a file without
a summary (:mod:`vp_recon.recording`). Signals, exit codes and parameter types follow
:mod:`vp_scene.node_runtime` (a bad parameter or an unwritable file: one line, exit 2).

    ros2 run vp_recon recorder --ros-args -p output:=out/run/run.mcap
"""
from __future__ import annotations

import fnmatch
import importlib
import math
import time
from typing import Dict

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from vp_recon.recording import RUN_TOPICS, RecordingError, RunRecording, qos_profiles_yaml
from vp_scene.node_runtime import Param, declare_typed, run_node, typed_values

#: The node's parameters (:class:`vp_scene.node_runtime.Param`): all read once, at start (read_only).
PARAMS = {
    'output': Param('run.mcap', 'the MCAP file to write (its folder is created)', None, True, 'not empty'),
    'topics': Param(list(RUN_TOPICS), 'topic patterns to record (fnmatch: * also matches /)', None, True),
    'discovery_period': Param(0.5, 's between two looks at the graph for new topics', (0.0, math.inf), True, '> 0'),
}


#: s without a new message after which a stopping recorder closes its file (:meth:`RecorderNode.on_shutdown`).
DRAIN_QUIET_S = 0.5


def check_parameters(values: dict) -> dict:
    v = typed_values(PARAMS, values)
    if not v.get('output', 'x'):
        raise ValueError('output must not be empty')
    if v.get('discovery_period', 1.0) <= 0:
        raise ValueError('discovery_period must be > 0')
    return v


def get_message(type_name: str) -> type:
    """The Python class of 'pkg/msg/Type' (rosidl_runtime_py.utilities.get_message, which the
    PyPI Jazzy wheels do not ship)."""
    pkg, kind, name = type_name.split('/')
    return getattr(importlib.import_module(f'{pkg}.{kind}'), name)


class RecorderNode(Node):
    def __init__(self) -> None:
        super().__init__('recorder')
        v = declare_typed(self, PARAMS, check_parameters)
        self._patterns = list(v['topics']) or list(RUN_TOPICS)
        try:
            self.recording = RunRecording(v['output'])
        except RecordingError as exc:
            raise ValueError(str(exc)) from exc
        self._subscribed: Dict[str, object] = {}
        self._refused: set = set()
        self.create_timer(v['discovery_period'], self._discover)
        self.get_logger().info(f'recording {", ".join(self._patterns)} to {self.recording.path}')
        self._discover()

    def _discover(self) -> None:
        for topic, types in self.get_topic_names_and_types():
            if topic in self._subscribed or topic in self._refused:
                continue
            if not any(fnmatch.fnmatchcase(topic, p) for p in self._patterns):
                continue
            publishers = self.get_publishers_info_by_topic(topic)
            if not publishers:
                continue  # QoS is adapted to the publishers: wait for one
            if len(types) != 1:
                self._refuse(topic, f'{len(types)} types ({", ".join(types)})')
                continue
            reliable = all(p.qos_profile.reliability == ReliabilityPolicy.RELIABLE for p in publishers)
            latched = all(p.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in publishers)
            depth = max(1, max(p.qos_profile.depth for p in publishers))
            try:
                msg_type = get_message(types[0])
                self.recording.add_topic(topic, types[0], qos_profiles_yaml(reliable, latched, depth))
            except (RecordingError, AttributeError, ModuleNotFoundError, ValueError) as exc:
                self._refuse(topic, str(exc))
                continue
            qos = QoSProfile(depth=max(depth, 100),
                             reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)
            self._subscribed[topic] = self.create_subscription(
                msg_type, topic, lambda data, t=topic: self.recording.write(t, data, time.time_ns()), qos, raw=True)
            self.get_logger().info(f'recording {topic} ({types[0]}{", latched" if latched else ""})')

    def _refuse(self, topic: str, why: str) -> None:
        self._refused.add(topic)
        self.get_logger().error(f'not recording {topic}: {why}')

    def on_shutdown(self, timeout: float) -> bool:
        """Close the file once what was sent has been written: the executor still spins here, so
        messages already on their way (``make run`` stops every node within a second of the last
        score) are written until none came for :data:`DRAIN_QUIET_S`, within ``timeout``."""
        deadline = time.monotonic() + timeout
        written = -1
        while written != self.recording.total() and time.monotonic() < deadline:
            written = self.recording.total()
            time.sleep(DRAIN_QUIET_S)
        self.recording.close()
        counts = ', '.join(f'{t} {n}' for t, n in sorted(self.recording.counts.items()))
        self.get_logger().info(f'closed {self.recording.path}: {counts or "no messages"}')
        return True


def main(args=None) -> int:
    """Entry point ``recorder``."""
    return run_node('recorder', RecorderNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
