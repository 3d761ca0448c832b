"""A run's topics in one MCAP file (``<run folder>/run.mcap``) that ``ros2 bag info`` / ``play``
(rosbag2_storage_mcap, Jazzy) and Foxglove read: ROS 2 profile, ``ros2msg`` schemas, ``cdr`` messages.

ROS-free (no rclpy): the recorder node (:mod:`vp_recon.recorder_node`) hands over what DDS
delivered, as serialized CDR bytes, and this module writes them unchanged. Why
``mcap.writer.Writer`` and not ``mcap_ros2.writer.Writer``: the latter encodes Python objects to
CDR again from the schema; the recorder already has the CDR bytes (``raw=True`` subscriptions),
so it writes them through the same low-level writer ``mcap_ros2.writer`` wraps, with the same
``ros2`` profile and schema encoding. Reading back: ``mcap.reader`` + ``mcap_ros2.decoder``.

The schema of a channel is the type's full message definition as rosbag2 builds it: the type's
``.msg`` text, then, for every type it uses (depth first, each once), a line of 80 ``=``, a line
``MSG: pkg/Type`` and that type's ``.msg`` text (:func:`message_definition`). The ``.msg`` files
come from the interface packages' share folders (``<prefix>/share/<pkg>/msg/<Type>.msg``: the
ament prefixes, then the Python prefix, where the PyPI Jazzy wheels install them).

Closing: :meth:`RunRecording.close` writes the summary (schemas, channels, statistics, chunk
indexes) and the footer. Until then the file is a complete MCAP file without a summary after each
chunk: mcap's writer writes into memory (:class:`_OpenEnd`), and each finished chunk goes to the
file in one ``pwrite`` with an end (a DataEnd record, a footer whose ``summary_start`` is 0, the
magic) that the next chunk overwrites. A chunk is finished when it reaches mcap's chunk size, or
at most :data:`FLUSH_S` after its first message. Why: a seeking reader (mcap's ``make_reader`` on
a file, which ``mcap_ros2.reader.read_ros2_messages`` uses) reads the footer at the end of the
file first; a file whose writer was killed ended inside a chunk, read as a footer it raised
``RecordLengthLimitExceeded``, and the streaming reader raised ``EndOfFile`` after the last
complete chunk. A footer without a summary makes the seeking readers scan the data section to
its end (rosbag2's and Foxglove's fall back to such a scan too). A SIGKILL of the writer loses
the chunk in progress (at most FLUSH_S of messages); only a kill inside the one ``pwrite``
leaves a cut last chunk, which the streaming reader reads up to (:func:`read_messages`) and the
seeking readers refuse.
"""
from __future__ import annotations

import os
import re
import sys
import threading
import time
from pathlib import Path
from typing import Callable, Dict, Iterable, List, Optional

__all__ = ["RunRecording", "RecordingError", "message_definition", "find_msg_file", "qos_profiles_yaml",
           "RUN_TOPICS", "FLUSH_S", "read_messages", "is_closed"]

#: s at most between a message being written and its reaching the file (what a SIGKILL loses)
FLUSH_S = 2.0

#: The topics ``make run`` records (fnmatch patterns; ``*`` matches across ``/``): the noisy scene, the
#: plan and its info and markers, the fleet's assignment, every drone's pose and goal, the
#: reconstruction's score and points.
RUN_TOPICS = ("/scene/noisy_points", "/scene/description", "/camera_plan", "/camera_plan/info",
              "/camera_plan/markers", "/fleet/assignment", "/*/pose", "/*/goal_pose", "/*/route",
              "/reconstruction/score", "/reconstruction/points")

_SEPARATOR = "=" * 80
_PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
               "int32", "uint32", "int64", "uint64", "string", "wstring"}


class RecordingError(RuntimeError):
    """A type whose definition cannot be found, or a file that cannot be written."""


def _share_prefixes() -> List[Path]:
    prefixes = [Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p]
    prefixes.append(Path(sys.prefix))
    return prefixes


def find_msg_file(package: str, name: str, prefixes: Optional[Iterable[Path]] = None) -> Path:
    """``<prefix>/share/<package>/msg/<name>.msg`` in the first prefix that has it; RecordingError if none."""
    tried = list(prefixes) if prefixes is not None else _share_prefixes()
    for prefix in tried:
        path = Path(prefix) / "share" / package / "msg" / f"{name}.msg"
        if path.is_file():
            return path
    raise RecordingError(f"no definition of {package}/msg/{name} (looked in {', '.join(str(p) for p in tried)})")


def _split_type(type_name: str) -> tuple:
    """('pkg', 'Type') from 'pkg/msg/Type' or 'pkg/Type'."""
    parts = type_name.split("/")
    if len(parts) == 3 and parts[1] == "msg":
        return parts[0], parts[2]
    if len(parts) == 2:
        return parts[0], parts[1]
    raise RecordingError(f"not a message type name: {type_name!r} (expected pkg/msg/Type)")


def _used_types(text: str, package: str) -> List[str]:
    """'pkg/Type' of every non-primitive field type of a ``.msg`` text, in order (constants skipped)."""
    used: List[str] = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        tokens = line.split()
        if len(tokens) < 2 or "=" in tokens[1] or (len(tokens) > 2 and tokens[2].startswith("=")):
            continue  # a constant (NAME=value) or a malformed line: no type to follow
        base = re.sub(r"\[[^\]]*\]$", "", tokens[0])
        base = re.sub(r"<=\d+$", "", base)  # bounded strings
        if base in _PRIMITIVES:
            continue
        if "/" not in base:
            base = "std_msgs/Header" if base == "Header" else f"{package}/{base}"
        pkg, name = _split_type(base)
        full = f"{pkg}/{name}"
        if full not in used:
            used.append(full)
    return used


def message_definition(type_name: str, find: Callable[[str, str], Path] = find_msg_file) -> str:
    """The full definition of ``type_name`` ('pkg/msg/Type') as rosbag2 writes it in a schema: its
    ``.msg`` text, then each type it uses, depth first and once, after a separator line and
    ``MSG: pkg/Type``."""
    package, name = _split_type(type_name)
    top = find(package, name).read_text()
    parts = [top.rstrip("\n")]
    seen = {f"{package}/{name}"}

    def visit(text: str, pkg: str) -> None:
        for dep in _used_types(text, pkg):
            if dep in seen:
                continue
            seen.add(dep)
            dpkg, dname = dep.split("/")
            dtext = find(dpkg, dname).read_text()
            parts.append(f"{_SEPARATOR}\nMSG: {dep}\n{dtext.rstrip(chr(10))}")
            visit(dtext, dpkg)

    visit(top, package)
    return "\n".join(parts) + "\n"


def qos_profiles_yaml(reliable: bool, transient_local: bool, depth: int) -> str:
    """rosbag2's (Jazzy) ``offered_qos_profiles`` for one publisher: ``ros2 bag play`` republishes
    a latched topic as latched."""
    infinite = "    sec: 9223372036\n    nsec: 854775807\n"
    return ("- history: keep_last\n"
            f"  depth: {depth}\n"
            f"  reliability: {'reliable' if reliable else 'best_effort'}\n"
            f"  durability: {'transient_local' if transient_local else 'volatile'}\n"
            f"  deadline:\n{infinite}"
            f"  lifespan:\n{infinite}"
            "  liveliness: automatic\n"
            f"  liveliness_lease_duration:\n{infinite}"
            "  avoid_ros_namespace_conventions: false\n")


def _open_end() -> bytes:
    """The end of a recording still being written: a DataEnd record, a footer without a summary
    (``summary_start`` 0: readers scan the data section) and the closing magic."""
    from mcap.data_stream import RecordBuilder
    from mcap.records import DataEnd, Footer
    from mcap.writer import MCAP0_MAGIC

    builder = RecordBuilder()
    DataEnd(data_section_crc=0).write(builder)  # 0: no data CRC (mcap's writer computes none either)
    Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(builder)
    return builder.end() + MCAP0_MAGIC


class _OpenEnd:
    """The file under mcap's ``Writer``: what the writer writes is kept in memory until
    :meth:`flush` writes it, followed by :func:`_open_end`, in one ``pwrite`` over the previous
    end, so that the file on disk is a complete MCAP file between any two writes. :meth:`close`
    writes the rest (the writer's own summary and footer) without that end."""

    def __init__(self, path: Path) -> None:
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        self._end = _open_end()
        self._written = 0  # bytes of the writer's on disk; the open end follows them
        self._pending = bytearray()

    def write(self, data: bytes) -> int:
        self._pending += data
        return len(data)

    def tell(self) -> int:
        return self._written + len(self._pending)

    @property
    def pending(self) -> bool:
        """Whether the writer wrote bytes that are not on disk yet."""
        return bool(self._pending)

    def _pwrite(self, tail: bytes) -> int:
        data = memoryview(bytes(self._pending) + tail)
        at = self._written
        while data:  # a regular file's write is short only on a signal or a full disk
            n = os.pwrite(self._fd, data, at)
            data, at = data[n:], at + n
        self._written += len(self._pending)
        self._pending.clear()
        return at

    def flush(self) -> None:
        self._pwrite(self._end)

    def close(self) -> None:
        try:
            os.ftruncate(self._fd, self._pwrite(b""))  # the writer's end is never shorter than the open one
        finally:
            os.close(self._fd)


class RunRecording:
    """One MCAP file being written; thread-safe. ``add_topic`` once per topic, then ``write``
    serialized messages; ``close`` (idempotent) finishes the file."""

    def __init__(self, path: os.PathLike, definition: Callable[[str], str] = message_definition):
        from mcap.writer import CompressionType, Writer
        from mcap_ros2 import __version__ as mcap_ros2_version

        self.path = Path(path)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = _OpenEnd(self.path)
        except OSError as exc:
            raise RecordingError(f"cannot write {self.path}: {exc.strerror or exc}") from exc
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
        self._writer.start(profile="ros2", library=f"vp_recon recording (mcap-ros2-support {mcap_ros2_version})")
        self._writer.flush()  # the header and the open end: a recording killed before its first message is MCAP
        self._dirty = False  # messages not flushed yet
        self._definition = definition
        self._schemas: Dict[str, int] = {}
        self._channels: Dict[str, int] = {}
        self._sequence: Dict[str, int] = {}
        self.counts: Dict[str, int] = {}
        self._lock = threading.Lock()
        self._closed = False
        # a thread, not the writes, flushes: the last messages before a quiet spell reach the file too
        self._stop = threading.Event()
        threading.Thread(target=self._flush_every, name="mcap-flush", daemon=True).start()

    def _flush_every(self) -> None:
        while not self._stop.wait(FLUSH_S):
            self.flush()

    def flush(self) -> None:
        """Finish the chunk in progress and hand it to the OS with the open end (a SIGKILL of this
        process then loses none of it; no fsync: an OS crash may)."""
        with self._lock:
            if self._closed or not self._dirty:
                return
            self._dirty = False
            self._writer.flush()

    def add_topic(self, topic: str, type_name: str, qos_yaml: str = "") -> None:
        """Register ``topic`` of ``type_name`` ('pkg/msg/Type'); RecordingError when its definition
        cannot be found. A topic added twice keeps its first registration."""
        with self._lock:
            if self._closed or topic in self._channels:
                return
            if type_name not in self._schemas:
                text = self._definition(type_name)
                self._schemas[type_name] = self._writer.register_schema(type_name, "ros2msg", text.encode())
            self._channels[topic] = self._writer.register_channel(
                topic=topic, message_encoding="cdr", schema_id=self._schemas[type_name],
                metadata={"offered_qos_profiles": qos_yaml} if qos_yaml else {})
            self._sequence[topic] = 0
            self.counts[topic] = 0

    def write(self, topic: str, data: bytes, log_time_ns: Optional[int] = None) -> None:
        """One serialized (CDR) message on an added topic; ignored after ``close``."""
        with self._lock:
            if self._closed:
                return
            now = time.time_ns() if log_time_ns is None else log_time_ns
            self._writer.add_message(channel_id=self._channels[topic], log_time=now, publish_time=now,
                                     sequence=self._sequence[topic], data=bytes(data))
            self._sequence[topic] += 1
            self.counts[topic] += 1
            self._dirty = True
            if self._file.pending:  # the message filled a chunk, which the writer finished: to the file now
                self._file.flush()
                self._dirty = False

    def total(self) -> int:
        """Messages written so far, all topics."""
        with self._lock:
            return sum(self.counts.values())

    def close(self) -> None:
        self._stop.set()
        with self._lock:
            if self._closed:
                return
            self._closed = True
            try:
                self._writer.finish()
            finally:
                self._file.close()  # what finish wrote: the last chunk, the summary and the footer

    def __enter__(self) -> "RunRecording":
        return self

    def __exit__(self, *_exc) -> None:
        self.close()


def read_messages(path: os.PathLike, decoder_factories: Iterable = ()) -> Iterable[tuple]:
    """(schema, channel, message, decoded) of every message of an MCAP file, in file order, with
    MCAP's streaming reader: a file whose writer was killed is read to its end (see the module
    docstring; :func:`is_closed` tells it from a closed one), one cut inside a write up to its
    last complete chunk, then :class:`mcap.exceptions.EndOfFile`. Other McapErrors: a file that
    is not a recording."""
    from mcap.reader import NonSeekingReader

    with open(path, "rb") as f:
        yield from NonSeekingReader(f, decoder_factories=list(decoder_factories)).iter_decoded_messages(
            log_time_order=False)


def is_closed(path: os.PathLike) -> bool:
    """Whether an MCAP file ends with its summary, as :meth:`RunRecording.close` leaves it; False
    for one whose writer was killed (a footer without a summary, or a cut end) or that cannot be
    read."""
    from mcap.exceptions import McapError
    from mcap.reader import SeekingReader

    try:
        with open(path, "rb") as f:
            return SeekingReader(f).get_summary() is not None
    except (McapError, OSError, EOFError, ValueError):
        return False
