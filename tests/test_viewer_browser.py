"""The viewer node (vp_recon viewer) seen in a real headless chromium driven by selenium: the page
loads from the URL the node logs (its token included), shows the plan a planner published (N
cameras: the GUI line the viewer writes with its N frustums appears in the page) and follows a new
plan; a page of another origin in the same browser cannot open the viewer's WebSocket, not even
with the token. Skipped only when /usr/bin/chromium is absent; nothing is downloaded (chromedriver
and chromium from Debian, selenium-manager never runs); every wait has a deadline; chromium and
chromedriver are ended on teardown. Also: a port in use is one line and exit 2.

With VP_VIEWER_SCREENSHOT=path the test saves the page (README's docs/viewer.png comes from it).
"""
from __future__ import annotations

import contextlib
import http.server
import os
import re
import socket
import threading
import time
from pathlib import Path
from typing import Iterator

import numpy as np
import pytest
from geometry_msgs.msg import PoseArray
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2

#: Debian's chromium and chromedriver (``/usr/bin``): nothing is downloaded, selenium-manager never runs.
CHROMIUM, CHROMEDRIVER = Path("/usr/bin/chromium"), Path("/usr/bin/chromedriver")
#: Headless, no GPU (WebGL falls back to software rendering), nothing that phones home.
FLAGS = ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-dev-shm-usage", "--window-size=1280,800")


@contextlib.contextmanager
def headless_chromium(page_load_timeout: float = 60.0) -> Iterator[object]:
    """A selenium Chrome driver on the system chromium; chromium and chromedriver end on exit."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for flag in FLAGS:
        options.add_argument(flag)
    service = Service(str(CHROMEDRIVER))
    driver = webdriver.Chrome(service=service, options=options)
    driver.set_page_load_timeout(page_load_timeout)
    try:
        yield driver
    finally:
        try:
            driver.quit()
        finally:
            service.stop()


def page_text(driver) -> str:
    return driver.execute_script("return document.body ? document.body.innerText : ''") or ""


def wait_text(driver, text: str, timeout: float) -> float:
    """Seconds until ``text`` is on the page; AssertionError with the page's text after ``timeout``."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if text in page_text(driver):
            return time.monotonic() - t0
        time.sleep(0.1)
    raise AssertionError(f"{text!r} not on the page within {timeout} s; page text: {page_text(driver)[-1500:]!r}")


def wait_page(driver, url: str, timeout: float) -> None:
    """Load ``url`` once its server answers (it may start after the caller)."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            driver.get(url)
            return
        except Exception:  # noqa: BLE001 - connection refused until the server is up
            if time.monotonic() > deadline:
                raise
            time.sleep(0.5)


LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def plan_msg(n: int, radius: float) -> PoseArray:
    """n cameras on a circle of ``radius`` m at 1.2 m, looking at the plant."""
    from test_recon_node import pose_array  # tests/: one builder of PoseArray test plans
    from vp_scene.camera import look_at

    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return pose_array(look_at(np.stack([radius * np.cos(a), radius * np.sin(a), np.full(n, 1.2)], -1),
                              [0.0, 0.0, 0.4]))


def scene_msg() -> PointCloud2:
    from vp_scene.cloud import numpy_to_pointcloud2

    rng = np.random.default_rng(0)
    t = rng.uniform(0, 0.8, 4000)
    pts = np.stack([0.05 * np.cos(30 * t), 0.05 * np.sin(30 * t), t], -1) + rng.normal(0, 0.01, (4000, 3))
    colors = np.tile(np.array([[60, 160, 60]], np.uint8), (4000, 1))
    return numpy_to_pointcloud2(pts, colors, realization=np.zeros(4000, np.uint16), frame_id="map")


@pytest.fixture
def chromium():
    if not CHROMIUM.exists():
        pytest.skip("/usr/bin/chromium is absent (Debian package chromium)")
    with headless_chromium() as driver:
        yield driver


@contextlib.contextmanager
def other_site():
    """A web site of another origin (http://127.0.0.1:<another port>) serving one empty page."""
    class Page(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            body = b"<!doctype html><title>another site</title>"
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args) -> None:
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Page)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/"
    finally:
        server.shutdown()
        server.server_close()
        thread.join(timeout=10)


#: In the page: open a WebSocket to each URL with viser's subprotocol; 'open' or 'refused' each.
TRY_SOCKETS = """
const [urls, protocol, done] = arguments;
Promise.all(urls.map(u => new Promise(settle => {
  const ws = new WebSocket(u, [protocol]);
  ws.onopen = () => { settle('open'); ws.close(); };
  ws.onclose = () => settle('refused');
}))).then(done);
"""


def test_the_page_shows_the_plan_and_follows_a_new_one(ros_env, start_node, ros_node, chromium) -> None:
    import viser

    port = free_port()
    viewer = start_node("vp_recon", "viewer", {"port": port}, ros_env)
    assert viewer.wait_for_output(f"viewer at http://127.0.0.1:{port}", 60), viewer.output()[-2000:]
    url = re.search(rf"viewer at (http://127\.0\.0\.1:{port}\S*)", viewer.output()).group(1)
    client = ros_node(ros_env)
    scene = client.node.create_publisher(PointCloud2, "/scene/noisy_points", LATCHED)
    plans = client.node.create_publisher(PoseArray, "/camera_plan", LATCHED)
    scene.publish(scene_msg())
    plans.publish(plan_msg(4, 1.5))
    wait_page(chromium, url, 60)  # the URL the node logged, token and all
    wait_text(chromium, "plan: 4 cameras", 90)
    wait_text(chromium, "4000 of 4000 points shown", 30)
    plans.publish(plan_msg(6, 2.0))  # a new plan: the page follows
    wait_text(chromium, "plan: 6 cameras", 60)
    assert "plan: 4 cameras" not in page_text(chromium)
    shot = os.environ.get("VP_VIEWER_SCREENSHOT")
    if shot:
        time.sleep(3.0)  # let the clouds and frustums render
        chromium.save_screenshot(shot)
    # Hardening III, item 3: a site of another origin open in the same browser cannot open the
    # viewer's socket (it got 101 and could read the scene and the plan), even with the token
    sockets = [f"ws://127.0.0.1:{port}", url.replace("http://", "ws://").rstrip("/")]
    with other_site() as site:
        chromium.get(site)
        chromium.set_script_timeout(30)
        tried = chromium.execute_async_script(TRY_SOCKETS, sockets, f"viser-v{viser.__version__}")
    assert tried == ["refused", "refused"], dict(zip(sockets, tried))
    assert viewer.poll() is None, viewer.output()[-2000:]


def test_a_port_in_use_is_one_line_and_exit_2(ros_env, start_node) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen(1)
        port = busy.getsockname()[1]
        viewer = start_node("vp_recon", "viewer", {"port": port}, ros_env)
        code = viewer.wait(60)
    assert code == 2, viewer.output()[-2000:]
    errors = [line for line in viewer.output().splitlines() if "ERROR" in line]
    assert len(errors) == 1 and f"port {port} on 127.0.0.1 is in use" in errors[0], viewer.output()[-2000:]
