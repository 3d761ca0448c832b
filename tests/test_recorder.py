"""The recorder node keeps what was sent to it: messages published just before it is told to stop
(the recon node's last score, then every node stopped within a second) are in run.mcap."""
from __future__ import annotations

import signal

from test_entry_script import read_recording


def test_messages_sent_just_before_the_stop_are_recorded(ros_env, start_node, ros_node, tmp_path) -> None:
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from vp_interfaces.msg import ReconstructionScore

    out = tmp_path / "run.mcap"
    rec = start_node("vp_recon", "recorder", {"output": str(out), "discovery_period": 0.2}, ros_env)
    client = ros_node(ros_env)
    pub = client.node.create_publisher(ReconstructionScore, "/reconstruction/score",
                                       QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
    assert client.spin_until(lambda: pub.get_subscription_count() >= 1, 30.0), rec.output()
    assert rec.wait_for_output("recording /reconstruction/score", 30.0), rec.output()
    n = 30  # within the recorder's queue (depth 100): a burst beyond it may lose the oldest
    bulk = [0.5] * 100_000  # 0.8 MB a message: they take a while to arrive and be written
    for k in range(n):
        pub.publish(ReconstructionScore(realization=k, method="burst", coverage_of_prior_per_plant=bulk))
    rec.signal(signal.SIGINT)  # at once: as make run stops its nodes after the aggregate score
    assert rec.wait(20.0) == 0, rec.output()
    _types, messages, _stats = read_recording(out)
    got = [m.realization for m in messages.get("/reconstruction/score", [])]
    assert got == list(range(n)), (len(got), rec.output()[-2000:])
