"""vp_recon.recording without ROS nodes: the schema text rosbag2 would write, a round trip through
mcap's reader and mcap_ros2's decoder, a missing definition, an unwritable file."""
from __future__ import annotations

import pytest

from vp_recon.recording import (RecordingError, RunRecording, message_definition, qos_profiles_yaml)


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


def test_unknown_type_and_unwritable_file_are_one_line_errors(tmp_path) -> None:
    with pytest.raises(RecordingError, match="no definition of vp_interfaces/msg/NoSuchType"):
        message_definition("vp_interfaces/msg/NoSuchType")
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(RecordingError, match="cannot write"):
        RunRecording(blocker / "run.mcap")
