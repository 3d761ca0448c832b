"""The suite across machines: scene, planner and recon + dispatcher on three "hosts" (Linux
network namespaces) joined by a bridge, DDS over UDP between them.

The lab: namespaces ``vpx<pid>x<n>{s,p,r}`` (scene, planner, recon hosts) each hold ``lo`` and
one end of a veth pair (``eth0``, 10.77.X.1-3/24); the other ends are ports of a bridge in a
fourth namespace (``...b``), so the host's own network is never touched. There is no default
route and no uplink: nothing the test sends can leave the bridge. Traffic is bounded in count
(20 clouds, a 10 Hz heartbeat) and time (every probe ends by itself, every wait has a
deadline); everything is torn down, processes first, also when the test fails (try/finally and
the fixture's finalizer; namespaces left by a test run that was killed are removed by the next).

DDS as these hosts would run it: ``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET`` (multicast discovery
on the bridge), or ``LOCALHOST`` with ``ROS_STATIC_PEERS``. Fast DDS's shared-memory transport
is switched off (``FASTDDS_BUILTIN_TRANSPORTS=UDPv4``): the namespaces share /dev/shm, and a
Fast DDS that took them for one host would pass data through shared memory, past the link the
test takes down. (With Fast DDS 2.14 the data stopped during the link-down with the default
transports as well; the test asserts that it stops.)

A capture set crosses too (issue 20, part 5): drones with cameras (2000 x 1500) on the scene host,
the recon node (``source: fleet``) on the recon host; one set, so the traffic stays bounded.

Needs root and ``ip netns`` (iproute2); elsewhere the tests skip and say why. The numbers
(discovery time, latency of 100k-point clouds, recovery after the link flap) are printed and
written to ``<tmp>/across_hosts.json`` (and to ``$VP_ACROSS_HOSTS_JSON`` when set).
"""
from __future__ import annotations

import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Callable, Optional

import pytest

from node_process import NodeProcess, node_command

REPO = Path(__file__).resolve().parents[1]
PROBE = REPO / "tests" / "netns_probe.py"
PREFIX = "vpx"
HOSTS = {"scene": "s", "planner": "p", "recon": "r"}
_NAME = re.compile(rf"^{PREFIX}(\d+)x\d+[bspr]$")
_labs = iter(range(1, 10_000))

CLOUDS, CLOUD_POINTS, LINK_DOWN_S = 20, 100_000, 5.0
SCENE = dict(scenario="one_plant", points_per_plant=1500, realizations=2, levels=5, seed=4)


def ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, timeout=20, check=check)


def netns_unavailable() -> Optional[str]:
    """Why the lab cannot be built here (None: it can)."""
    if not sys.platform.startswith("linux"):
        return "network namespaces are Linux only"
    if os.geteuid() != 0:
        return "creating network namespaces needs root (run the test as root, e.g. in CI)"
    if shutil.which("ip") is None:
        return "the `ip` command (iproute2) is not installed"
    probe = f"{PREFIX}{os.getpid()}x0b"
    res = ip("netns", "add", probe, check=False)
    if res.returncode != 0:
        return f"`ip netns add` failed: {res.stderr.strip()}"
    ip("netns", "del", probe, check=False)
    return None


def remove_stale_labs() -> None:
    """Namespaces of this test whose test process is gone (a run killed with SIGKILL)."""
    listing = ip("netns", "list", check=False).stdout.split("\n")
    for line in listing:
        name = line.split(" ")[0]
        m = _NAME.match(name)
        if m and not Path(f"/proc/{m.group(1)}").exists():
            ip("netns", "del", name, check=False)


class Lab:
    """Three hosts on a private bridge; processes started in them; torn down by :meth:`down`."""

    def __init__(self, tmp_path: Path) -> None:
        tag = f"{PREFIX}{os.getpid()}x{next(_labs)}"
        self.tmp = tmp_path
        self.bridge = tag + "b"
        self.ns = {h: tag + c for h, c in HOSTS.items()}
        self.subnet = 10 + os.getpid() % 240
        self.addr = {h: f"10.77.{self.subnet}.{k + 1}" for k, h in enumerate(HOSTS)}
        self.port = {h: f"v{h}" for h in HOSTS}  # the bridge's end of each host's veth
        self.procs: list[NodeProcess] = []
        self.created: list[str] = []

    def up(self) -> None:
        ip("netns", "add", self.bridge)
        self.created.append(self.bridge)
        ip("-n", self.bridge, "link", "add", "br0", "type", "bridge", "mcast_snooping", "0")
        ip("-n", self.bridge, "link", "set", "br0", "up")
        for h, ns in self.ns.items():
            ip("netns", "add", ns)
            self.created.append(ns)
            ip("-n", ns, "link", "set", "lo", "up")
            ip("-n", self.bridge, "link", "add", self.port[h], "type", "veth", "peer", "name", "eth0", "netns", ns)
            ip("-n", self.bridge, "link", "set", self.port[h], "master", "br0")
            ip("-n", self.bridge, "link", "set", self.port[h], "up")
            ip("-n", ns, "addr", "add", f"{self.addr[h]}/24", "dev", "eth0")
            ip("-n", ns, "link", "set", "eth0", "up")

    def check_isolated(self) -> None:
        """Every host has lo and eth0 only, and no route but its /24."""
        for h, ns in self.ns.items():
            links = sorted(ln.split(":")[1].strip().split("@")[0] for ln in ip("-n", ns, "-o", "link").stdout.splitlines())
            assert links == ["eth0", "lo"], (h, links)
            routes = ip("-n", ns, "route", "show").stdout.strip().splitlines()
            assert routes == [f"10.77.{self.subnet}.0/24 dev eth0 proto kernel scope link src {self.addr[h]}"], routes
            assert not ip("-n", ns, "route", "show", "default").stdout.strip()

    def link(self, host: str, up: bool) -> float:
        """Take the host's link up or down (at the bridge, as a cable pulled out); the time."""
        ip("-n", self.bridge, "link", "set", self.port[host], "up" if up else "down")
        return time.time()

    def bridge_bytes(self) -> int:
        """Bytes the bridge's ports have sent (to the hosts)."""
        stats = json.loads(ip("-n", self.bridge, "-s", "-j", "link", "show").stdout)
        return sum(int(s["stats64"]["tx"]["bytes"]) for s in stats if s["ifname"] in self.port.values())

    def env(self, base: dict, discovery: str) -> dict:
        env = dict(base)
        for k in ("ROS_STATIC_PEERS", "ROS_LOCALHOST_ONLY", "FASTRTPS_DEFAULT_PROFILES_FILE",
                  "FASTDDS_DEFAULT_PROFILES_FILE"):
            env.pop(k, None)
        env["FASTDDS_BUILTIN_TRANSPORTS"] = "UDPv4"  # no shared memory past the link (module docstring)
        env["OMP_NUM_THREADS"] = "1"
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "SUBNET" if discovery == "subnet" else "LOCALHOST"
        return env

    def start(self, host: str, name: str, cmd: list, env: dict, peers: bool = False) -> NodeProcess:
        env = dict(env)
        if peers:
            env["ROS_STATIC_PEERS"] = ";".join(a for h, a in self.addr.items() if h != host)
        proc = NodeProcess(["ip", "netns", "exec", self.ns[host], *cmd], env, self.tmp / f"{host}-{name}.log")
        self.procs.append(proc)
        return proc

    def node(self, host: str, pkg: str, exe: str, params: dict, env: dict, name: Optional[str] = None,
             **kw) -> NodeProcess:
        return self.start(host, name or exe, node_command(pkg, exe, params, name=name), env, **kw)

    def probe(self, host: str, name: str, args: list, env: dict, **kw) -> NodeProcess:
        return self.start(host, name, [sys.executable, str(PROBE), *args, "--name", name], env, **kw)

    def down(self) -> None:
        for proc in reversed(self.procs):
            try:
                proc.stop(timeout=5.0)
            except Exception:  # noqa: BLE001 - tear everything down whatever happens
                pass
        self.procs.clear()
        for ns in reversed(self.created):
            ip("netns", "del", ns, check=False)
        self.created.clear()


@pytest.fixture
def lab(tmp_path):
    """A fresh lab (skips with the reason where namespaces cannot be made); torn down after."""
    why = netns_unavailable()
    if why:
        pytest.skip(why)
    remove_stale_labs()
    made = Lab(tmp_path)
    try:
        made.up()
        yield made
    finally:
        made.down()
        listing = ip("netns", "list", check=False).stdout.split()
        left = [ns for ns in (made.bridge, *made.ns.values()) if ns in listing]
        assert not left, f"namespaces left behind: {left}"


def events(proc: NodeProcess, ev: Optional[str] = None) -> list:
    out = []
    for line in proc.output().splitlines():
        if line.startswith("{"):
            try:
                e = json.loads(line)
            except ValueError:
                continue
            if ev is None or e["ev"] == ev:
                out.append(e)
    return out


def wait(predicate: Callable[[], object], timeout: float, what: str, *procs: NodeProcess):
    """Poll until ``predicate()`` is truthy (its value) or fail at the deadline with the logs."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.05)
    value = predicate()
    if value:
        return value
    logs = "\n".join(f"--- {p.log_path.name}\n{p.output()[-2500:]}" for p in procs)
    pytest.fail(f"timed out after {timeout:.0f} s waiting for {what}\n{logs}")


def ms(x: float) -> float:
    return round(1000.0 * x, 2)


def report(numbers: dict, tmp_path: Path, capsys) -> None:
    text = json.dumps(numbers, indent=2)
    (tmp_path / "across_hosts.json").write_text(text)
    if os.environ.get("VP_ACROSS_HOSTS_JSON"):
        Path(os.environ["VP_ACROSS_HOSTS_JSON"]).write_text(text)
    with capsys.disabled():
        print(f"\nacross hosts ({tmp_path / 'across_hosts.json'}):\n{text}")


def test_scene_planner_recon_and_dispatcher_on_three_hosts(lab, ros_env, tmp_path, capsys) -> None:
    """The plan crosses hosts and reaches the dispatcher and the drones; a recon and a probe
    started late on their host get the latched plan and scene; 100k-point clouds cross with a
    measured latency; after the planner host's link is down for 5 s (no data crosses meanwhile)
    and comes back, the next plan is delivered and dispatched."""
    t_start = time.monotonic()
    lab.check_isolated()
    env = lab.env(ros_env, "subnet")  # a reserved ROS_DOMAIN_ID of its own
    drones = ["d0", "d1", "d2"]
    trigger_clouds, trigger_goal = tmp_path / "clouds.go", tmp_path / "goal.go"

    # discovery, measured before the nodes load the machine: the talker (planner host) finds
    # the listener (recon host) that is already up
    # the probes outlive the whole test even on a loaded machine (170 s was too short beside a
    # reconstruction); the lab stops them at teardown, so their traffic stays bounded in time
    listener = lab.probe("recon", "listener", ["listen", "--seconds", "420"], env)
    wait(lambda: events(listener, "ready"), 30, "the listener", listener)
    talker = lab.probe("planner", "talker", ["talk", "--seconds", "400", "--clouds", str(CLOUDS), "--points",
                                             str(CLOUD_POINTS), "--rate", "2", "--trigger", str(trigger_clouds)], env)
    discovered = wait(lambda: events(talker, "discovered"), 60, "discovery across hosts", talker, listener)
    discovery = [discovered[0]["seconds"]]

    # latency of large clouds across hosts (planner host -> recon host), measured before the nodes
    # start: on real machines they would not share the CPU with the other hosts' nodes
    trigger_clouds.touch()
    clouds = wait(lambda: len(events(listener, "cloud")) >= CLOUDS and events(listener, "cloud"), 60,
                  f"{CLOUDS} clouds", talker, listener)
    cloud_bytes = events(talker, "cloud_size")[0]["bytes"]
    latencies = sorted(c["t"] - c["stamp"] for c in clouds)
    assert len(clouds) == CLOUDS and all(c["bytes"] == cloud_bytes for c in clouds)

    scene = lab.node("scene", "vp_scene", "scene", SCENE, env)
    planner = lab.node("planner", "vp_planner", "planner", {"autostart": True, "method": "circle", "num_cameras": 2,
                                                            "evaluations": 6, "num_threads": 1}, env)
    dispatcher = lab.node("recon", "vp_planner", "dispatcher", {"drones": drones, "scene_timeout": 60.0}, env)
    sims = [lab.node("scene", "vp_scene", "sim_drone", {"drone": d, "x": float(k), "y": -4.0, "speed": 5.0}, env,
                     name=f"sim_{d}") for k, d in enumerate(drones)]
    everyone = (listener, talker, scene, planner, dispatcher, *sims)

    # the plan crosses hosts: scene (host 1) -> planner (host 2) -> listener and dispatcher (host 3)
    plan = wait(lambda: events(listener, "plan"), 90, "the plan on the recon host", *everyone)[0]
    assert plan["poses"] == 2 and plan["frame"] == "map"

    def answer(stamp: float):
        return [a for a in events(listener, "assignment") if abs(a["plan_stamp"] - stamp) < 1e-6]
    first = wait(lambda: answer(plan["stamp"]), 60, "the dispatch of the first plan", *everyone)[-1]
    assert first["error_code"] == 0, first["error_msg"]
    assert len({e["drone"] for e in first["entries"]}) == 2
    for e in first["entries"]:  # the goals crossed back to the drones on the scene host
        sim = sims[drones.index(e["drone"])]
        x, y, z = e["goal"]
        wait(lambda: f"goal ({x:.2f}, {y:.2f}, {z:.2f})" in sim.output(), 30, f"{e['drone']}'s goal", sim, dispatcher)

    # late subscribers on the recon host: the recon node and a probe get the latched plan and scene
    late_start = time.time()
    late = lab.probe("recon", "late", ["listen", "--seconds", "60", "--latched-only"], env)
    recon = lab.node("recon", "vp_recon", "recon", {"width": 160, "height": 120, "max_realizations": 1,
                                                    "dense": False, "num_threads": 1, "scene_timeout": 60.0,
                                                    "output_folder": str(tmp_path / "recon")}, env)
    late_plan = wait(lambda: events(late, "plan"), 60, "the latched plan at a late subscriber", late)[0]
    late_scene = wait(lambda: events(late, "scene"), 60, "the latched scene at a late subscriber", late)[0]
    late_ready = events(late, "ready")[0]
    assert late_plan["stamp"] == plan["stamp"] and late_scene["points"] == 2 * SCENE["points_per_plant"]
    wait(lambda: "plan received: 2 cameras" in recon.output() and "ground truth: 2 realizations" in recon.output()
         and "scene description: one_plant" in recon.output(), 90, "the late recon's plan and scene", recon)
    # and it works on them: it ends the plan with an aggregate score or a plan error, whatever the
    # (tiny) reconstruction gives; read from its log, since the probe listens to
    # /reconstruction/score volatile and a recon that fails within a second can publish before the
    # probe is matched
    wait(lambda: "aggregate: Chamfer" in recon.output() or "]: plan: realization" in recon.output(), 120,
         "the recon's result for the plan", recon)

    # the link flap: the planner host's cable out for 5 s; then the next plan
    goal = lab.probe("planner", "goal", ["goal", "--seconds", "60", "--trigger", str(trigger_goal), "--cameras", "3"],
                     env)
    wait(lambda: events(goal, "server"), 30, "the goal client's /plan_views server (every endpoint)", goal, planner)
    t_down = lab.link("planner", up=False)
    time.sleep(LINK_DOWN_S)
    t_up = lab.link("planner", up=True)
    trigger_goal.touch()
    result = wait(lambda: events(goal, "result"), 60, "the plan after the link flap", goal, planner)[0]
    assert result["error_code"] == 0 and result["poses"] == 3, result
    after = wait(lambda: [p for p in events(listener, "plan") if abs(p["stamp"] - result["stamp"]) < 1e-6], 30,
                 "the next plan on the recon host", listener, planner)[0]
    redispatch = wait(lambda: answer(result["stamp"]), 30, "the dispatch of the next plan", dispatcher)[-1]
    assert redispatch["error_code"] == 0 and len(redispatch["entries"]) == 3, redispatch
    # the heartbeat is reliable and in order: nothing sent after the link went down is delivered
    # until the writer has resent what the reader missed (it learns of the gap from the writer's
    # periodic HEARTBEAT), so the beats resume some seconds after the link, not with the next plan
    # (CI of stop 43 looked at once and found none). The wait is for the beats sent well inside the
    # outage themselves: waiting for any beat stamped after t_down returned on the first resent one
    # (sent in the outage's first half second) and read the listener before the rest were printed
    # (CI of stop 46)
    wait(lambda: [b for b in events(listener, "beat") if t_down + 0.5 < b["stamp"] < t_up - 0.5], 30,
         "the heartbeats sent during the link-down, after it came back (resent from the history)", listener, talker)
    beats = events(listener, "beat")
    # a heartbeat sent after the link went down cannot arrive before it is up, unless the data
    # takes another path (shared memory): then taking the link down would prove nothing
    during = [b for b in beats if b["stamp"] > t_down and b["t"] < t_up]
    assert not during, f"{len(during)} heartbeats crossed while the link was down: the test link is not the path"
    held = [b for b in beats if t_down + 0.5 < b["stamp"] < t_up - 0.5]
    assert held, "no heartbeat sent while the link was down arrived after it came back (resent from the history)"
    recovered = [b["t"] for b in beats if b["t"] >= t_up]
    assert recovered, "no heartbeat after the link came back"

    numbers = {
        "machine": "one kernel, 3 network namespaces on a veth bridge; CPU shared with whatever else runs",
        "discovery": "ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET, FASTDDS_BUILTIN_TRANSPORTS=UDPv4",
        "discovery_s": [round(x, 3) for x in discovery],
        "cloud_points": CLOUD_POINTS, "cloud_bytes": cloud_bytes, "clouds": len(clouds),
        "cloud_latency_ms": {"median": ms(statistics.median(latencies)), "min": ms(latencies[0]),
                             "p90": ms(latencies[int(0.9 * (len(latencies) - 1))]), "max": ms(latencies[-1])},
        "first_plan_delivery_ms": ms(plan["t"] - plan["stamp"]),  # includes matching: published at once
        "late_subscriber_latched_plan_s": round(late_plan["t"] - late_ready["t"], 3),
        "late_subscriber_latched_scene_s": round(late_scene["t"] - late_ready["t"], 3),
        "late_subscriber_started_after_plan_s": round(late_start - plan["t"], 3),
        "link_down_s": round(t_up - t_down, 3),
        "recovery_s": round(recovered[0] - t_up, 3),
        "next_plan_delivered_after_link_up_s": round(after["t"] - t_up, 3),
        "next_plan_delivery_ms": ms(after["t"] - after["stamp"]),
        "next_plan_dispatched_after_link_up_s": round(redispatch["t"] - t_up, 3),
        "bridge_tx_bytes": lab.bridge_bytes(),
        "test_seconds": round(time.monotonic() - t_start, 1),
    }
    report(numbers, tmp_path, capsys)
    assert numbers["cloud_latency_ms"]["median"] < 1000, numbers  # a sanity bound, far above the measured
    for proc in (scene, planner, dispatcher, recon, *sims):
        assert proc.alive(), proc.output()[-2000:]
        assert "Traceback" not in proc.output(), proc.output()[-3000:]


def test_localhost_stays_local_and_static_peers_cross(lab, ros_env, tmp_path, capsys) -> None:
    """ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST (the suite's default on one machine) finds nothing
    on the other hosts; the same range with ROS_STATIC_PEERS naming them does, and the plan
    crosses."""
    lab.check_isolated()
    env = lab.env(ros_env, "localhost")
    listener = lab.probe("recon", "listener", ["listen", "--seconds", "8"], env)
    wait(lambda: events(listener, "ready"), 30, "the listener", listener)
    talker = lab.probe("planner", "talker", ["talk", "--seconds", "5", "--clouds", "0"], env)
    assert wait(lambda: events(talker, "end"), 30, "the talker's end", talker)
    assert not events(talker, "discovered") and not events(listener, "beat"), "LOCALHOST discovery left the host"
    listener.stop()

    listener = lab.probe("recon", "peers_listener", ["listen", "--seconds", "60"], env, peers=True)
    wait(lambda: events(listener, "ready"), 30, "the listener", listener)
    talker = lab.probe("planner", "peers_talker", ["talk", "--seconds", "30", "--clouds", "0"], env, peers=True)
    scene = lab.node("scene", "vp_scene", "scene", SCENE, env, peers=True)
    planner = lab.node("planner", "vp_planner", "planner", {"autostart": True, "method": "circle", "num_cameras": 2,
                                                            "evaluations": 6, "num_threads": 1}, env, peers=True)
    discovered = wait(lambda: events(talker, "discovered"), 30, "discovery through static peers", talker, listener)
    plan = wait(lambda: events(listener, "plan"), 90, "the plan through static peers", listener, scene, planner)[0]
    assert plan["poses"] == 2
    numbers = {"discovery": "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST + ROS_STATIC_PEERS, UDPv4",
               "discovery_s": round(discovered[0]["seconds"], 3)}
    with capsys.disabled():
        print(f"\nstatic peers: {json.dumps(numbers)}")
    (tmp_path / "static_peers.json").write_text(json.dumps(numbers, indent=2))


_LOG_TIME = re.compile(r"^\[\w+\] \[(\d+\.\d+)\] \[[^\]]+\]: (.*)$")


def log_times(proc: NodeProcess, text: str) -> list:
    """The ROS log stamps (s, the one kernel's clock of all hosts) of the lines holding ``text``."""
    return [float(m.group(1)) for m in map(_LOG_TIME.match, proc.output().splitlines()) if m and text in m.group(2)]


def test_a_capture_set_crosses_hosts(lab, ros_env, tmp_path, capsys) -> None:
    """Issue 20, part 5: the drones (sim_drone, camera:=true, 2000 x 1500) and the scene on one
    host, the planner on a second, dispatcher and recon (source fleet) on a third: the plan is
    dispatched, the drones fly to their goals, the recon's trigger crosses to them, and their
    capture set (image_raw, camera_info, pose of every drone) crosses back and is collected;
    the recon ends the plan (score or plan error) and every node keeps running."""
    lab.check_isolated()
    env = lab.env(ros_env, "subnet")
    drones = ["d0", "d1", "d2"]
    size = dict(width=2000, height=1500)
    scene = lab.node("scene", "vp_scene", "scene", SCENE, env)
    sims = [lab.node("scene", "vp_scene", "sim_drone", {"drone": d, "x": float(k), "y": -3.0, "speed": 5.0,
                                                          "camera": True, "capture": "ideal", **size}, env,
                     name=f"sim_{d}") for k, d in enumerate(drones)]
    recon = lab.node("recon", "vp_recon", "recon", {"source": "fleet", **size, "capture": "ideal",
                                                    "max_realizations": 1, "dense": False, "num_threads": 1,
                                                    "sift_first_octave": 0,  # the images cross; SIFT as make run
                                                    "capture_timeout": 240.0, "scene_timeout": 120.0,
                                                    "record_captures": False,
                                                    "output_folder": str(tmp_path / "recon")}, env)
    dispatcher = lab.node("recon", "vp_planner", "dispatcher", {"drones": drones, "scene_timeout": 120.0}, env)
    planner = lab.node("planner", "vp_planner", "planner", {"autostart": True, "method": "circle", "num_cameras": 3,
                                                            "evaluations": 6, "num_threads": 1}, env)
    everyone = (scene, planner, dispatcher, recon, *sims)
    asked = wait(lambda: log_times(recon, "capture 0 of the plan asked of"), 240, "the recon's capture trigger",
                 *everyone)
    collected = wait(lambda: log_times(recon, "capture 0: 3 images from the fleet"), 240,
                     "the capture set on the recon host", *everyone)
    captured = [wait(lambda s=s: log_times(s, "captured pose"), 10, "the drone's capture log", s) for s in sims]
    assert all(len(c) == 1 for c in captured), "one trigger, one capture per drone"
    wait(lambda: "aggregate: Chamfer" in recon.output() or "]: plan: " in recon.output(), 300,
         "the recon's result for the plan", recon)
    numbers = {
        "hosts": "scene + 3 sim_drone (camera 2000x1500) | planner | dispatcher + recon (source fleet)",
        "discovery": "ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET, FASTDDS_BUILTIN_TRANSPORTS=UDPv4",
        "megabytes_per_set": round(len(drones) * size["width"] * size["height"] * 3 / 1e6, 1),
        "trigger_to_collected_s": round(collected[0] - asked[0], 3),
        "last_capture_to_collected_s": round(collected[0] - max(c[0] for c in captured), 3),
        "bridge_tx_bytes": lab.bridge_bytes(),
        "recon_result": next(ln.split("]: ", 1)[1] for ln in recon.output().splitlines()
                             if "aggregate: Chamfer" in ln or "]: plan: " in ln)[:200],
    }
    text = json.dumps(numbers, indent=2)
    (tmp_path / "across_hosts_capture.json").write_text(text)
    with capsys.disabled():
        print(f"\ncapture set across hosts: {text}")
    assert numbers["bridge_tx_bytes"] > len(drones) * size["width"] * size["height"] * 3  # the set crossed
    for proc in everyone:
        assert proc.alive(), proc.output()[-2000:]
        assert "Traceback" not in proc.output(), proc.output()[-3000:]
