"""Suite-level test helpers: isolated ROS 2 environments, node processes, a test-side rclpy node.

Every ROS process of a test runs with ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` and a
``ROS_DOMAIN_ID`` of its own, reserved through a lock file so that parallel test runs on the
same machine (other checkouts, other engineers) do not share a domain.

Fixtures:
    ros_env       -> dict: os.environ + LOCALHOST discovery + a reserved ROS_DOMAIN_ID.
    start_node    -> factory ``start_node(pkg, exe, params, env, args=()) -> NodeProcess``
                     starting ``install/<pkg>/lib/<pkg>/<exe> --ros-args -p k:=v ...`` in its own
                     session, dying with the test process (tools/node_process.py, shared with
                     tools/run_suite.py); teardown sends SIGTERM, then SIGKILL.
    ros_node      -> factory ``ros_node(env_or_domain_id, name='test_client') -> RosTestNode``:
                     an rclpy context + node + executor in the test process on the same domain;
                     torn down after the test.
    module_nodes  -> (ros_env, start_node, ros_node), shared by a module's tests (nodes that
                     only answer goals).
"""
from __future__ import annotations

import fcntl
import itertools
import os
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Optional, Union

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"

sys.path.insert(0, str(REPO / "tools"))
from node_process import NodeProcess, node_command  # noqa: E402  (tools/node_process.py)

# The test process itself talks DDS (RosTestNode): keep discovery on this machine.
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"

_LOCK_DIR = Path(tempfile.gettempdir()) / "vp_suite_ros_domains"
_counter = itertools.count()
DOMAIN_MIN, DOMAIN_MAX = 1, 200


class DomainLease:
    """A ROS domain id reserved by an exclusive lock file (released by :meth:`release`)."""

    def __init__(self) -> None:
        _LOCK_DIR.mkdir(parents=True, exist_ok=True)
        avoid = {os.environ.get("ROS_DOMAIN_ID", ""), "0", "42", "77"}  # ids that other runs use unlocked
        span = DOMAIN_MAX - DOMAIN_MIN + 1
        start = (os.getpid() * 37 + next(_counter) * 11) % span
        for k in range(span):
            did = DOMAIN_MIN + (start + k) % span
            if str(did) in avoid:
                continue
            fh = open(_LOCK_DIR / f"{did}.lock", "w")
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                fh.close()
                continue
            fh.write(f"{os.getpid()}\n")
            fh.flush()
            self.domain_id, self._fh = did, fh
            return
        raise RuntimeError(f"no free ROS domain id in {DOMAIN_MIN}..{DOMAIN_MAX}")

    def release(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None


def make_ros_env(domain_id: int, base: Optional[dict] = None) -> dict:
    """An environment for a ROS process: LOCALHOST discovery, this domain, unbuffered logs."""
    env = dict(os.environ if base is None else base)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["ROS_DOMAIN_ID"] = str(int(domain_id))
    env["PYTHONUNBUFFERED"] = "1"
    env["RCUTILS_COLORIZED_OUTPUT"] = "0"
    env["RCUTILS_LOGGING_BUFFERED_STREAM"] = "0"
    return env


@contextmanager
def leased_ros_env() -> Iterator[dict]:
    """os.environ with LOCALHOST discovery and a reserved ROS_DOMAIN_ID, released on exit."""
    lease = DomainLease()
    try:
        yield make_ros_env(lease.domain_id)
    finally:
        lease.release()


@pytest.fixture
def ros_env():
    """dict: os.environ with LOCALHOST discovery and a reserved, unique ROS_DOMAIN_ID."""
    with leased_ros_env() as env:
        yield env


@pytest.fixture
def start_node(tmp_path: Path):
    """Factory: ``start_node(pkg, exe, params, env, args=()) -> NodeProcess``; stopped at teardown."""
    with starting_nodes(tmp_path) as start:
        yield start


@pytest.fixture(scope="module")
def module_nodes(tmp_path_factory):
    """``(ros_env, start_node, ros_node)`` shared by a module's tests, the nodes stopped after the
    last one: for tests that only send goals to a node, each starting it again would cost its start."""
    with leased_ros_env() as env, starting_nodes(tmp_path_factory.mktemp("nodes")) as start, \
            making_ros_nodes() as make:
        yield env, start, make


@contextmanager
def starting_nodes(folder: Path) -> Iterator[Callable[..., NodeProcess]]:
    """A ``start_node`` factory whose nodes log into ``folder`` and are stopped on exit."""
    started: list[NodeProcess] = []

    def _start(pkg: str, exe: str, params: Optional[dict] = None, env: Optional[dict] = None,
               args: Iterable[str] = ()) -> NodeProcess:
        if env is None or env.get("ROS_AUTOMATIC_DISCOVERY_RANGE") != "LOCALHOST" or "ROS_DOMAIN_ID" not in env:
            raise ValueError("start_node needs an env from the ros_env fixture (LOCALHOST + ROS_DOMAIN_ID)")
        try:
            cmd = node_command(pkg, exe, params, args)
        except FileNotFoundError as exc:
            pytest.fail(f"{pkg}/{exe} is not installed: {exc}")
        log = folder / f"{pkg}-{exe}-{len(started)}.log"
        node = NodeProcess(cmd, env, log)
        started.append(node)
        return node

    try:
        yield _start
    finally:
        for node in reversed(started):
            node.stop()


class RosTestNode:
    """An rclpy context, node and executor in the test process, on a given domain.

    ``spin_until(predicate, timeout)`` spins until the predicate holds (True) or times out (False).
    """

    def __init__(self, domain_id: int, name: str = "test_client") -> None:
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor

        os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        self.domain_id = int(domain_id)
        self.context = Context()
        rclpy.init(args=[], context=self.context, domain_id=self.domain_id)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.nodes: list = []
        self.node = self.add_node(name)

    def add_node(self, name: str):
        """Another node in the same context (e.g. a late subscriber)."""
        import rclpy

        node = rclpy.create_node(name, context=self.context)
        self.executor.add_node(node)
        self.nodes.append(node)
        return node

    def subscribe(self, msg_type: type, topic: str, qos: Any = 10, node: Any = None) -> list:
        """Subscribe and return the list that received messages are appended to."""
        received: list = []
        (node or self.node).create_subscription(msg_type, topic, received.append, qos)
        return received

    def spin_until(self, predicate: Callable[[], bool], timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while True:
            if predicate():
                return True
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return bool(predicate())
            self.executor.spin_once(timeout_sec=min(0.05, remaining))

    def spin_future(self, future: Any, timeout: float) -> Any:
        """Spin until a future is done; returns its result (pytest.fail on timeout)."""
        if not self.spin_until(future.done, timeout):
            pytest.fail(f"no answer within {timeout} s")
        return future.result()

    def call(self, send: Callable[[], Any], timeout: float, resend_every: float = 5.0) -> Any:
        """The answer to an idempotent service call: ``send()`` sends it (returns its future) and is
        called again every ``resend_every`` s until one of the requests is answered (pytest.fail after
        ``timeout``). For the first call of a client: ``service_is_ready()`` can hold before the
        server has matched this client's response reader, and the server then drops the response
        after a bounded wait (ros2/rmw_fastrtps#390); stop 36's CI lost a ListParameters answer so."""
        deadline = time.monotonic() + timeout
        futures: list = []
        while True:
            futures.append(send())
            wait = min(resend_every, deadline - time.monotonic())
            if self.spin_until(lambda: any(f.done() for f in futures), max(wait, 0.0)):
                return next(f for f in futures if f.done()).result()
            if time.monotonic() >= deadline:
                pytest.fail(f"no answer within {timeout} s ({len(futures)} requests sent)")

    def wait_for_publishers(self, topic: str, count: int = 1, timeout: float = 10.0) -> bool:
        return self.spin_until(lambda: self.node.count_publishers(topic) >= count, timeout)

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=1.0)
        for node in self.nodes:
            node.destroy_node()
        self.context.try_shutdown()


@contextmanager
def making_ros_nodes() -> Iterator[Callable[..., RosTestNode]]:
    """A ``ros_node`` factory whose test nodes are closed on exit."""
    made: list[RosTestNode] = []

    def _make(env_or_domain: Union[dict, int], name: str = "test_client") -> RosTestNode:
        did = int(env_or_domain["ROS_DOMAIN_ID"]) if isinstance(env_or_domain, dict) else int(env_or_domain)
        n = RosTestNode(did, name)
        made.append(n)
        return n

    try:
        yield _make
    finally:
        for n in reversed(made):
            n.close()


@pytest.fixture
def ros_node():
    """Factory: ``ros_node(env_or_domain_id, name='test_client') -> RosTestNode`` (closed at teardown)."""
    with making_ros_nodes() as make:
        yield make

