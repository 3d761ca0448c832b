"""The recorder node keeps what was sent to it: messages published just before it is told to stop
(the recon node's last score, then every node stopped within a second) are in run.mcap, and what
it recorded up to a few seconds before a SIGKILL stays readable."""
from __future__ import annotations

import signal

from test_entry_script import read_recording


def recording_scores(ros_env, start_node, ros_node, out):
    """A recorder node writing ``out`` and a publisher of /reconstruction/score it records:
    (recorder, client, publisher)."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from vp_interfaces.msg import ReconstructionScore

    rec = start_node("vp_recon", "recorder", {"output": str(out), "discovery_period": 0.2}, ros_env)
    client = ros_node(ros_env)
    pub = client.node.create_publisher(ReconstructionScore, "/reconstruction/score",
                                       QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
    assert client.spin_until(lambda: pub.get_subscription_count() >= 1, 30.0), rec.output()
    assert rec.wait_for_output("recording /reconstruction/score", 30.0), rec.output()
    return rec, client, pub


def test_messages_sent_just_before_the_stop_are_recorded(ros_env, start_node, ros_node, tmp_path) -> None:
    from vp_interfaces.msg import ReconstructionScore

    out = tmp_path / "run.mcap"
    rec, _client, pub = recording_scores(ros_env, start_node, ros_node, out)
    n = 30  # within the recorder's queue (depth 100): a burst beyond it may lose the oldest
    bulk = [0.5] * 100_000  # 0.8 MB a message: they take a while to arrive and be written
    for k in range(n):
        pub.publish(ReconstructionScore(realization=k, method="burst", coverage_of_prior_per_plant=bulk))
    rec.signal(signal.SIGINT)  # at once: as make run stops its nodes after the aggregate score
    assert rec.wait(20.0) == 0, rec.output()
    _types, messages, _stats = read_recording(out)
    got = [m.realization for m in messages.get("/reconstruction/score", [])]
    assert got == list(range(n)), (len(got), rec.output()[-2000:])


def test_a_sigkilled_recorder_leaves_what_it_recorded_readable(ros_env, start_node, ros_node, tmp_path,
                                                               capfd) -> None:
    """Hardening III, item 9: the recorder wrote nothing to disk until it closed (a SIGKILLed run
    left a 0-byte run.mcap). Messages recorded FLUSH_S before a SIGKILL are in the file, read by
    MCAP's streaming reader and by the viewer, which notes in one line that the recording was cut."""
    from mcap.exceptions import EndOfFile
    from mcap_ros2.decoder import DecoderFactory
    from vp_interfaces.msg import ReconstructionScore

    from vp_recon.recording import FLUSH_S, read_messages
    from vp_recon.viewer import load_run

    out = tmp_path / "run.mcap"
    rec, client, pub = recording_scores(ros_env, start_node, ros_node, out)
    n = 5  # a low rate: far from a full chunk (1 MiB)
    for k in range(n):
        pub.publish(ReconstructionScore(realization=k, method="before the kill"))
    client.spin_until(lambda: False, FLUSH_S + 2.0)  # "a few seconds before the kill"
    rec.signal(signal.SIGKILL)
    assert rec.wait(10) == -signal.SIGKILL
    got = []
    try:
        for _schema, channel, _message, decoded in read_messages(out, [DecoderFactory()]):
            got.append((channel.topic, decoded.realization, decoded.method))
        cut = False
    except EndOfFile:
        cut = True
    assert got == [("/reconstruction/score", k, "before the kill") for k in range(n)], (got, out.stat().st_size)
    assert cut  # no summary, no footer: the writer never closed
    capfd.readouterr()
    assert load_run(tmp_path)["/reconstruction/score"].realization == n - 1
    note = capfd.readouterr().err
    assert note.count("\n") == 1 and "was cut" in note, note
