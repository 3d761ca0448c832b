"""vp_recon.viewer without a browser: the scene it builds from a recording (server side), its
bad-input errors, and who may open it (the token, the Origin). The page in a real chromium, fed by
the live node: tests/test_viewer_browser.py."""
from __future__ import annotations

import base64
import os
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vp_recon.recording import RunRecording, qos_profiles_yaml
from vp_recon.viewer import PlanViewer, ViewerError, frustum_poses, load_run, replay_recording
from vp_scene.camera import cameras_to_poses, look_at


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def ring(n: int, radius: float = 1.5, height: float = 1.2) -> np.ndarray:
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return look_at(np.stack([radius * np.cos(a), radius * np.sin(a), np.full(n, height)], -1), np.zeros(3))


def pose_array(cameras: np.ndarray):
    from geometry_msgs.msg import Pose, PoseArray

    msg = PoseArray()
    msg.header.frame_id = "map"
    for x, y, z, qx, qy, qz, qw in cameras_to_poses(cameras):
        p = Pose()
        p.position.x, p.position.y, p.position.z = float(x), float(y), float(z)
        p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w = float(qx), float(qy), float(qz), float(qw)
        msg.poses.append(p)
    return msg


def write_run(folder: Path, cameras: np.ndarray) -> Path:
    """A run folder whose run.mcap holds a scene (2 realizations), a plan and its fleet assignment,
    a drone pose and a reconstruction: what make run records."""
    from geometry_msgs.msg import PoseStamped
    from rclpy.serialization import serialize_message
    from vp_interfaces.msg import DroneAssignment, FleetAssignment
    from vp_scene.cloud import numpy_to_pointcloud2

    grid = np.stack(np.meshgrid(*(np.arange(n) * 0.1 for n in (10, 10, 5)), indexing="ij"), -1).reshape(-1, 3)
    scene = np.stack([grid, grid + 0.03])  # 2 realizations of 500 points, 10 cm apart
    scene_msg = numpy_to_pointcloud2(scene.reshape(-1, 3), np.full((1000, 3), 100, np.uint8),
                                     realization=np.repeat(np.arange(2, dtype=np.uint16), 500), frame_id="map")
    recon = scene[0, :300] + 0.001
    recon_msg = numpy_to_pointcloud2(recon, np.zeros((300, 3), np.uint8),
                                     realization=np.zeros(300, np.uint16), frame_id="map")
    fleet = FleetAssignment()
    fleet.entries = [DroneAssignment(drone=f"d{k}", pose_index=k) for k in range(len(cameras))]
    pose = PoseStamped()
    pose.header.frame_id = "map"
    pose.pose.position.z = 1.0
    folder.mkdir(parents=True, exist_ok=True)
    with RunRecording(folder / "run.mcap") as rec:
        for topic, type_name, msg in (
                ("/scene/noisy_points", "sensor_msgs/msg/PointCloud2", scene_msg),
                ("/camera_plan", "geometry_msgs/msg/PoseArray", pose_array(cameras)),
                ("/fleet/assignment", "vp_interfaces/msg/FleetAssignment", fleet),
                ("/d0/pose", "geometry_msgs/msg/PoseStamped", pose),
                ("/reconstruction/points", "sensor_msgs/msg/PointCloud2", recon_msg)):
            rec.add_topic(topic, type_name, qos_profiles_yaml(True, True, 1))
            rec.write(topic, serialize_message(msg))
    return folder


def test_frustums_look_where_the_cameras_look() -> None:
    cams = ring(5)
    wxyz, pos = frustum_poses(cams)
    z_axis = Rotation.from_quat(wxyz[:, [1, 2, 3, 0]]).apply([0.0, 0.0, 1.0])  # viser: OpenCV frame, z forward
    v = cams[:, 3:] / np.linalg.norm(cams[:, 3:], axis=1, keepdims=True)
    np.testing.assert_allclose(z_axis, v, atol=1e-9)
    np.testing.assert_allclose(pos, cams[:, :3])


def test_a_recorded_run_is_shown_with_one_frustum_per_camera(tmp_path) -> None:
    cams = ring(4)
    viewer = PlanViewer(port=free_port(), max_points=400)
    try:
        replay_recording(viewer, load_run(write_run(tmp_path / "run", cams)))
        assert len(viewer.frustums) == 4
        np.testing.assert_allclose([f.position for f in viewer.frustums], cams[:, :3], atol=1e-6)
        colors = {tuple(int(c) for c in f.color) for f in viewer.frustums}
        assert len(colors) == 4  # one colour per drone
        assert viewer.realization.options == ("0", "1")
        assert "400 of 500 points shown (downsampled)" in viewer.status.content
        assert "coloured by distance to the truth" in viewer.status.content
        assert "uncovered (magenta): 200 of 500" in viewer.status.content
        viewer.points_shown.value = 1000  # the page's display cap (slider): no subset needed any more
        assert "500 of 500 points shown" in viewer.status.content and "downsampled" not in viewer.status.content
        viewer.realization.value = "1"  # the other wind realization: no reconstruction of it
        assert "reconstruction: none for realization 1" in viewer.status.content
    finally:
        viewer.close()


def run_cli(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "vp_recon.viewer", *args], capture_output=True, text=True,
                          timeout=timeout)


def test_bad_input_is_one_line_and_exit_2(tmp_path) -> None:
    folder = write_run(tmp_path / "run", ring(3))
    empty = tmp_path / "empty"
    empty.mkdir()
    truncated = tmp_path / "truncated"
    truncated.mkdir()
    data = (folder / "run.mcap").read_bytes()
    (truncated / "run.mcap").write_bytes(data[:200])  # cut inside its first chunk: no message in it
    cases = [(empty, "no recording (run.mcap)"), (tmp_path / "nowhere", "no such run folder"),
             (truncated, "not a readable MCAP recording")]
    for run, said in cases:
        proc = run_cli(str(run), "--port", str(free_port()))
        assert proc.returncode == 2, (run, proc.stdout, proc.stderr)
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and said in lines[0], (run, proc.stderr)
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen(1)
        port = busy.getsockname()[1]
        proc = run_cli(str(folder), "--port", str(port), "--seconds", "5")
    assert proc.returncode == 2, (proc.stdout, proc.stderr)
    assert proc.stderr.strip().splitlines()[-1] == f"error: port {port} on 127.0.0.1 is in use (try --port / make view PORT=...)"
    with pytest.raises(ViewerError, match="no recording"):
        load_run(empty)


def handshake(port: int, path: str, origin=None, websocket: bool = True) -> str:
    """The status line the viewer answers to a WebSocket handshake (or a plain GET) for ``path``."""
    import viser

    lines = [f"GET {path} HTTP/1.1", f"Host: 127.0.0.1:{port}"]
    if websocket:
        lines += ["Upgrade: websocket", "Connection: Upgrade", "Sec-WebSocket-Version: 13",
                  f"Sec-WebSocket-Key: {base64.b64encode(os.urandom(16)).decode()}",
                  f"Sec-WebSocket-Protocol: viser-v{viser.__version__}"]  # what viser's page asks for
    if origin is not None:
        lines.append(f"Origin: {origin}")
    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        s.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
        data = b""
        while b"\r\n" not in data:
            chunk = s.recv(256)
            if not chunk:
                break
            data += chunk
    return data.split(b"\r\n")[0].decode()


def test_only_the_printed_url_from_its_own_page_opens_the_websocket() -> None:
    """Hardening III, item 3: a web page of another origin (``Origin: http://evil.example``) got
    101 Switching Protocols, so any site open in a browser on this machine could read the scene
    and the plan. Now a handshake needs the token of the printed URL and, from a browser, the
    viewer's own origin: anything else is 403 before a byte of the scene is sent."""
    port = free_port()
    viewer = PlanViewer(port=port, max_points=100)
    try:
        own = f"http://127.0.0.1:{port}"
        url = viewer.url
        path = url[len(own):].rstrip("/") or "/"  # the socket viser's page opens: its own path
        assert handshake(port, path, "http://evil.example").endswith(" 403 Forbidden")
        assert handshake(port, path, "null").endswith(" 403 Forbidden")  # a sandboxed or file:// page
        assert handshake(port, "/", own).endswith(" 403 Forbidden")  # no token
        assert url.startswith(own + "/") and len(viewer.token) >= 16, url
        assert handshake(port, "/" + "x" * len(viewer.token), own).endswith(" 403 Forbidden")
        assert handshake(port, path, own).endswith(" 101 Switching Protocols")
        assert handshake(port, path, f"http://localhost:{port}").endswith(" 101 Switching Protocols")
        assert handshake(port, path).endswith(" 101 Switching Protocols")  # not a browser: the token alone
        # the page: at the printed URL; elsewhere a 403 that says to use it
        assert handshake(port, url[len(own):], websocket=False).endswith(" 200 OK")
        assert handshake(port, "/", websocket=False).endswith(" 403 Forbidden")
        assert handshake(port, "/index.html", websocket=False).endswith(" 403 Forbidden")
    finally:
        viewer.close()


def test_a_recording_cut_by_a_kill_is_shown_up_to_then(tmp_path, capfd) -> None:
    """Hardening III, item 9: a run.mcap whose recorder was killed (no summary, its end cut) is read
    up to its last complete chunk, with one line saying it was cut (it was refused as unreadable)."""
    folder = write_run(tmp_path / "run", ring(3))
    data = (folder / "run.mcap").read_bytes()
    cut = tmp_path / "cut"
    cut.mkdir()
    (cut / "run.mcap").write_bytes(data[: len(data) // 2])  # the chunk whole, the summary and footer cut
    capfd.readouterr()
    assert load_run(folder).keys() == load_run(cut).keys()
    err = capfd.readouterr().err
    assert err.count("\n") == 1 and f"{cut / 'run.mcap'} was cut" in err, err
