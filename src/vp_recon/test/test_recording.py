"""vp_recon.recording without ROS nodes: the schema text rosbag2 would write, a round trip through
mcap's reader and mcap_ros2's decoder, a recording whose writer was killed read by the standard
readers, a missing definition, an unwritable file."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from vp_recon.recording import (RecordingError, RunRecording, is_closed, message_definition, qos_profiles_yaml,
                                read_messages)


def test_definition_lists_each_used_type_once_depth_first() -> None:
    text = message_definition("geometry_msgs/msg/PoseArray")
    blocks = text.split("=" * 80 + "\n")
    assert [b.splitlines()[0] for b in blocks[1:]] == [
        "MSG: std_msgs/Header", "MSG: builtin_interfaces/Time", "MSG: geometry_msgs/Pose",
        "MSG: geometry_msgs/Point", "MSG: geometry_msgs/Quaternion"]
    assert "Pose[] poses" in blocks[0]


def test_a_package_relative_type_is_found_in_its_own_package() -> None:
    # FleetAssignment uses DroneAssignment without a package prefix
    text = message_definition("vp_interfaces/msg/FleetAssignment")
    assert "MSG: vp_interfaces/DroneAssignment" in text


def test_round_trip_through_mcap_ros2_decoder(tmp_path) -> None:
    from geometry_msgs.msg import Pose, PoseArray
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rclpy.serialization import serialize_message

    msg = PoseArray()
    msg.header.frame_id = "map"
    msg.poses = [Pose() for _ in range(3)]
    msg.poses[2].position.z = 2.5
    path = tmp_path / "run.mcap"
    with RunRecording(path) as rec:
        rec.add_topic("/camera_plan", "geometry_msgs/msg/PoseArray", qos_profiles_yaml(True, True, 1))
        rec.write("/camera_plan", serialize_message(msg))
        rec.write("/camera_plan", serialize_message(msg))
    rec.write("/camera_plan", serialize_message(msg))  # after close: ignored
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        got = [(c.topic, s.name, d) for s, c, _m, d in reader.iter_decoded_messages()]
        assert reader.get_summary().statistics.message_count == 2
    assert [(t, n) for t, n, _d in got] == [("/camera_plan", "geometry_msgs/msg/PoseArray")] * 2
    assert got[0][2].header.frame_id == "map" and got[0][2].poses[2].position.z == 2.5


def _realizations(path) -> dict:
    """The messages of ``path`` as the standard readers give them: their log times (make_reader's
    iter_messages; the test writes realization k at log time k) and realizations (read_ros2_messages)."""
    from mcap.reader import make_reader

    with warnings.catch_warnings():  # mcap_ros2.reader warns that it is deprecated; the users call it
        warnings.simplefilter("ignore", DeprecationWarning)
        from mcap_ros2.reader import read_ros2_messages

    with open(path, "rb") as f:
        logged = [m.log_time for _s, _c, m in make_reader(f).iter_messages()]
    return {"make_reader": logged, "read_ros2_messages": [m.ros_msg.realization for m in read_ros2_messages(str(path))]}


def test_a_killed_writer_leaves_a_file_the_standard_readers_read(tmp_path) -> None:
    """What a SIGKILL of the writer leaves on disk (the file's bytes while it is open) reads with
    make_reader and read_ros2_messages, every message but those of the chunk in progress; a chunk
    that filled up is on disk at once. The file was cut inside a chunk with no footer, and both
    readers raised RecordLengthLimitExceeded (they read the footer at the end first)."""
    from mcap.exceptions import EndOfFile
    from mcap_ros2.decoder import DecoderFactory
    from rclpy.serialization import serialize_message
    from vp_interfaces.msg import ReconstructionScore

    path = tmp_path / "run.mcap"
    rec = RunRecording(path)
    assert _realizations(path) == {"make_reader": [], "read_ros2_messages": []}  # before the first message

    def send(k: int, size: int = 0) -> None:  # random values: a chunk that compresses little
        values = np.random.default_rng(k).random(size).tolist()
        rec.write("/reconstruction/score", serialize_message(
            ReconstructionScore(realization=k, coverage_of_prior_per_plant=values)), log_time_ns=k)

    rec.add_topic("/reconstruction/score", "vp_interfaces/msg/ReconstructionScore", qos_profiles_yaml(True, True, 1))
    for k in range(3):
        send(k)
    rec.flush()  # the flush thread's doing, FLUSH_S after the first message
    send(3, 200_000)  # 1.6 MB: over mcap's chunk size, the chunk is finished with it
    send(4)  # the chunk in progress: what a kill now loses
    killed = tmp_path / "killed.mcap"
    killed.write_bytes(path.read_bytes())
    want = {"make_reader": [0, 1, 2, 3], "read_ros2_messages": [0, 1, 2, 3]}
    assert _realizations(killed) == want and not is_closed(killed)
    rec.close()
    assert _realizations(path) == {k: v + [4] for k, v in want.items()} and is_closed(path)
    # a kill inside the one write of a chunk cuts it: the streaming reader reads the chunks before it
    data = killed.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) - 100_000])  # the 1.6 MB chunk cut
    got = []
    with pytest.raises(EndOfFile):
        for *_r, decoded in read_messages(cut, [DecoderFactory()]):
            got.append(decoded.realization)
    assert got == [0, 1, 2] and not is_closed(cut)


def test_unknown_type_and_unwritable_file_are_one_line_errors(tmp_path) -> None:
    with pytest.raises(RecordingError, match="no definition of vp_interfaces/msg/NoSuchType"):
        message_definition("vp_interfaces/msg/NoSuchType")
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(RecordingError, match="cannot write"):
        RunRecording(blocker / "run.mcap")
