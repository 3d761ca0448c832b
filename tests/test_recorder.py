"""The recorder node keeps what was sent to it: messages published just before it is told to stop
(the recon node's last score, then every node stopped within a second) are in run.mcap, and what
it recorded up to a few seconds before a SIGKILL reads with the standard readers."""
from __future__ import annotations

import signal

from test_entry_script import read_recording, standard_reads


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
    """A SIGKILL of the recorder loses at most its chunk in progress: the messages recorded
    FLUSH_S before the kill are in the file, and the standard readers (mcap_ros2's
    read_ros2_messages, mcap's make_reader) read it, as the viewer does, with a one-line note that
    the recording was cut. They raised RecordLengthLimitExceeded on such a file (no footer)."""
    from vp_interfaces.msg import ReconstructionScore

    from vp_recon.recording import FLUSH_S
    from vp_recon.viewer import load_run

    out = tmp_path / "run.mcap"
    rec, client, pub = recording_scores(ros_env, start_node, ros_node, out)
    sent = [(k, "flushed") for k in range(5)] + [(k, "last chunk") for k in range(5, 10)]
    for k, method in sent[:5]:  # a low rate: far from a full chunk (1 MiB)
        pub.publish(ReconstructionScore(realization=k, method=method))
    client.spin_until(lambda: False, FLUSH_S + 2.0)  # the chunk flushed
    for k, method in sent[5:]:
        pub.publish(ReconstructionScore(realization=k, method=method))
    rec.signal(signal.SIGKILL)  # the chunk in progress, some of the last five or none, is lost
    assert rec.wait(10) == -signal.SIGKILL
    reads = standard_reads(out)
    got = [(m.realization, m.method) for m in reads["read_ros2_messages"]["/reconstruction/score"]]
    assert got[:5] == sent[:5] and got == sent[:len(got)], (got, out.stat().st_size)
    assert len(reads["make_reader"]["/reconstruction/score"]) == len(got)
    capfd.readouterr()
    assert load_run(tmp_path)["/reconstruction/score"].realization == got[-1][0]
    note = capfd.readouterr().err
    assert note.count("\n") == 1 and "was cut" in note, note
