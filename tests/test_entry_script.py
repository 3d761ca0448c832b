"""The entry script (tools/run_suite.py): the three real nodes as processes, one mission, over DDS.

End-to-end on a small configuration, with a separate subscriber process on /camera_plan and a
fleet of simulated drones, fewer than the poses, that the dispatcher routes through them; and the
fault cases: the planner killed mid-run makes the script stop the others and exit non-zero; a
node that exits with a one-line error gets that line reported last, without tracebacks from the
nodes the script stops; the script killed with SIGKILL takes its nodes with it. Every wait has a
deadline.
"""
from __future__ import annotations

import json
import math
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from node_process import NodeProcess  # tools/, on sys.path through conftest.py

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "tools" / "run_suite.py"
ECHO = REPO / "tests" / "echo_camera_plan.py"
#: a small mission under the default (realistic) capture: hover and localization errors, ground markers
SMALL_REALISTIC = ["--scenario", "one_plant", "--cameras", "4", "--points-per-plant", "3000", "--realizations", "2",
                   "--width", "800", "--height", "600"]
SMALL = [*SMALL_REALISTIC, "--capture", "ideal"]  # the plumbing; realistic: test_recon_capture, test_two_sorties
#: egp's simulated flights, as few and small as they go (many: tests/test_flights_nodes.py)
ONE_FLIGHT = ["--sim-flights", "1", "--flight-width", "640", "--flight-height", "480", "--flight-sift-octave", "-1",
              "--flight-dense-scale", "0.5"]


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie is not running
        return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
    except OSError:
        return False


def started_pids(text: str) -> dict:
    return {m.group(1): int(m.group(2)) for m in re.finditer(r"^started (\w+) \(pid (\d+)\)", text, re.M)}


def test_end_to_end_small_mission(ros_env, tmp_path) -> None:
    out = tmp_path / "run"
    echo_out = tmp_path / "echo.json"
    echo = NodeProcess([sys.executable, str(ECHO), str(echo_out), "600"], ros_env, tmp_path / "echo.log")
    try:
        proc = subprocess.run([sys.executable, str(SCRIPT), *SMALL, "--method", "egp", "--evals", "16",
                               "--init", "10", "--drones", "3", "--out", str(out), "--timeout", "500", *ONE_FLIGHT],
                              env=ros_env, capture_output=True, text=True, timeout=560)
        log = proc.stdout + proc.stderr
        assert proc.returncode == 0, log[-6000:]
        assert echo.wait(60) == 0, echo.output()
    finally:
        echo.stop()
    summary = json.loads((out / "summary.json").read_text())
    for key in ("scenario", "method", "cameras", "reward", "chamfer_mean", "chamfer_std", "poses", "seconds"):
        assert key in summary, key
    assert summary["scenario"] == "one_plant" and summary["method"] == "egp"
    assert len(summary["cameras"]) == 4 and len(summary["poses"]) == 4
    assert math.isfinite(summary["chamfer_mean"]) and summary["chamfer_mean"] > 0
    assert summary["capture"] == "ideal" and summary["chamfer_shape_mean"] > 0  # issue 18: the capture recorded
    assert summary["source"] == "fleet"  # issue 20: with drones, their images are reconstructed
    # make run's faster reconstruction settings, recorded (README "Speed of a flight's reconstruction");
    # SIFT keeps its doubled first octave below SIFT_OCTAVE0_FROM pixels (these are 800 wide)
    assert summary["recon_settings"] == {"sift_first_octave": -1, "dense_scale": 0.7}
    assert 0 < summary["reward"] <= 1
    # the plan's one simulated flight, flown by the recon node, chose it (the circle pattern, flown first)
    assert summary["chosen_by"] == "flights" and summary["flights_note"] == "", summary["flights_note"]
    (flight,) = summary["flights"]
    assert flight["source"] == "circle" and flight["draw"]["capture_seed"] >= 2 ** 31 and flight["seconds"] > 0
    assert summary["flight_score"] == flight["score"]["chamfer"] > 0 and "simulated flights" in proc.stdout
    no_truth = summary["no_truth"]  # issue 20, part 4: what a real flight can check
    assert no_truth["registered_images"] >= 2 and 0 < no_truth["coverage_of_prior"] <= 1
    assert no_truth["mean_reprojection_error"] > 0 and no_truth["mean_track_length"] >= 2
    # the run folder keeps every capture set as a flight folder (`make recon IMAGES=...` re-runs it)
    assert len(list(out.glob("plan-*/captures/realization_*/poses.csv"))) == 2, sorted(out.rglob("*"))[:40]
    assert "Chamfer distance x100" in log and "[planner]" in log and "[recon]" in log
    echoed = json.loads(echo_out.read_text())
    assert echoed["frame_id"] == "map"
    np.testing.assert_allclose(echoed["poses"], summary["poses"], atol=1e-9)
    # the fleet: each drone's route is printed, three drones for the four poses, each pose once
    assert re.search(r"^fleet \(min_max\): 3 drones to 4 poses, time on site", proc.stdout, re.M), proc.stdout[-3000:]
    lines = re.findall(r"^  (d\d) -> cams ([\d, ]+): ", proc.stdout, re.M)
    assert sorted(int(c) for _, cs in lines for c in cs.split(", ")) == [0, 1, 2, 3], lines
    fleet = summary["fleet"]
    for entry in fleet["drones"]:  # fleet frame = map here: the goals are the plan's poses
        np.testing.assert_allclose(entry["goal"], summary["poses"][entry["pose_index"]], atol=1e-9)
    assert len(fleet["routes"]) == 3 and fleet["min_separation"] >= fleet["separation"]
    assert fleet["time_on_site"] == pytest.approx(max(r["flight_time"] for r in fleet["routes"]))
    assert all(r["flight_time"] <= fleet["budget"] for r in fleet["routes"])
    pids = started_pids(proc.stdout)
    assert {"recorder", "dispatcher", "sim_d0", "sim_d2"} <= set(pids), pids
    check_recording(out / "run.mcap", summary, drones=3, realizations=2)
    for pid in pids.values():
        assert not alive(pid)


def test_two_sorties(ros_env, tmp_path) -> None:
    """--rounds 2 plans a second sortie of M cameras given the N flown and their reconstruction
    (the goal's fixed_cameras and reconstruction), and the recon reconstructs from all N + M
    images; summary.json has one record per sortie. As `make run ROUNDS=2` flies it: the default
    realistic capture (ground markers), drones whose images the recon takes (source fleet), the
    first sortie's read back from its capture sets with the field's markers, so that the two
    sets are one reconstruction placed on the same ground control.

    The same mission runs with --managed: the planner and the dispatcher start unconfigured
    (managed:=true) and the script configures and activates them, as a lifecycle manager would,
    before the mission flies (the unmanaged start: test_end_to_end_small_mission)."""
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, str(SCRIPT), *SMALL_REALISTIC, "--realizations", "1", "--method", "circle",
                           "--evals", "16", "--rounds", "2", "--cameras2", "2", "--drones", "4", "--out", str(out),
                           "--managed", "--timeout", "500"], env=ros_env, capture_output=True, text=True, timeout=560)
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, log[-6000:]
    for node in ("planner", "dispatcher"):
        assert f"{node}: configured and activated (lifecycle)" in proc.stdout, proc.stdout[-3000:]
        assert log.index(f"{node} configured") < log.index(f"{node} ready"), log[-3000:]
    assert "Chamfer distance x100" in proc.stdout
    assert "second sortie: 2 cameras given the 4 flown" in log
    assert "with 4 cameras already flown" in log  # the planner counted them
    assert "with the 4 images of the cameras already flown" in log  # the recon read sortie 1's back
    summary = json.loads((out / "summary.json").read_text())
    assert summary["source"] == "fleet" and summary["capture"] == "realistic"
    first, second = summary["rounds"]
    assert (first["num_cameras"], first["fixed_cameras"], first["images"]) == (4, 0, 4)
    assert (second["num_cameras"], second["fixed_cameras"], second["images"]) == (2, 4, 6)
    assert len(first["cameras"]) == 4 and len(second["cameras"]) == 2
    for r in (first, second):
        assert 0 < r["reward"] <= 1 and math.isfinite(r["chamfer_mean"]) and r["chamfer_mean"] > 0 and r["seconds"] > 0
    assert summary["chamfer_mean"] == second["chamfer_mean"] and summary["cameras"] == second["cameras"]
    assert summary["registered_images"] > 4  # one model: images of both sorties registered together
    sets = sorted(out.glob("plan-*/captures/realization_0"))  # the capture sets, with the field's markers
    assert [len(list(d.glob("view_*.png"))) for d in sets] == [4, 6], sets
    assert (sets[0] / "markers.csv").read_text() == (sets[1] / "markers.csv").read_text()
    types, messages, _stats = read_recording(out / "run.mcap")
    infos = messages["/camera_plan/info"]
    assert [len(m.fixed_poses) for m in infos] == [0, 4]  # the second plan names the cameras flown
    np.testing.assert_allclose([[p.position.x, p.position.y, p.position.z] for p in infos[1].fixed_poses],
                               np.asarray(first["cameras"])[:, :3], atol=1e-9)


def test_the_reconstruction_goes_to_the_planner_thinned() -> None:
    """A first sortie's cloud (millions of points in a field) goes into the second goal as the
    mean of every occupied 5 mm voxel, in its frame."""
    import run_suite
    from vp_scene.cloud import numpy_to_pointcloud2, pointcloud2_to_numpy

    rng = np.random.default_rng(0)
    points = np.concatenate([rng.uniform(0.0, 0.004, (500, 3)), rng.uniform(1.0, 1.004, (500, 3))])
    thin = run_suite.thinned_cloud(numpy_to_pointcloud2(points, frame_id="map"))
    got, _colors, _ = pointcloud2_to_numpy(thin)
    assert thin.header.frame_id == "map" and len(got) == 2
    np.testing.assert_allclose(sorted(got[:, 0]), [points[:500, 0].mean(), points[500:, 0].mean()], atol=1e-6)


def read_recording(path: Path) -> tuple[dict, dict, dict]:
    """(topic -> schema name, topic -> decoded messages, the file's summary statistics) of an MCAP
    file, read with mcap's seeking reader (it needs the summary that closing writes) and
    mcap_ros2's decoder."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    types, messages = {}, {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None, f"{path}: not closed (no summary)"
        assert reader.get_header().profile == "ros2"
        for schema, channel, _message, decoded in reader.iter_decoded_messages():
            assert channel.message_encoding == "cdr" and schema.encoding == "ros2msg"
            assert "offered_qos_profiles" in channel.metadata, channel.topic
            types[channel.topic] = schema.name
            messages.setdefault(channel.topic, []).append(decoded)
    return types, messages, summary.statistics


def standard_reads(path: Path) -> dict:
    """reader -> topic -> messages of an MCAP file as a user's script reads it: mcap_ros2's
    ``read_ros2_messages`` (decoded) and mcap's ``make_reader(...).iter_messages()`` (raw); both
    read the footer at the file's end first, also of a file whose writer was killed."""
    import warnings

    from mcap.reader import make_reader

    with warnings.catch_warnings():  # mcap_ros2.reader warns that it is deprecated; users still call it
        warnings.simplefilter("ignore", DeprecationWarning)
        from mcap_ros2.reader import read_ros2_messages
    reads: dict = {"read_ros2_messages": {}, "make_reader": {}}
    for m in read_ros2_messages(str(path)):
        reads["read_ros2_messages"].setdefault(m.channel.topic, []).append(m.ros_msg)
    with open(path, "rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages():
            reads["make_reader"].setdefault(channel.topic, []).append(message)
    return reads


def check_recording(path: Path, summary: dict, drones: int, realizations: int) -> None:
    """run.mcap of a finished run: every topic of the run with its type, the plan as in summary.json."""
    types, messages, stats = read_recording(path)
    expected = {"/scene/noisy_points": "sensor_msgs/msg/PointCloud2", "/camera_plan": "geometry_msgs/msg/PoseArray",
                "/camera_plan/info": "vp_interfaces/msg/CameraPlan",
                "/camera_plan/markers": "visualization_msgs/msg/MarkerArray",
                "/fleet/assignment": "vp_interfaces/msg/FleetAssignment",
                "/reconstruction/score": "vp_interfaces/msg/ReconstructionScore",
                "/reconstruction/points": "sensor_msgs/msg/PointCloud2"}
    for d in range(drones):
        expected[f"/d{d}/pose"] = "geometry_msgs/msg/PoseStamped"
    for entry in summary["fleet"]["drones"]:
        expected[f"/{entry['drone']}/goal_pose"] = "geometry_msgs/msg/PoseStamped"
    for topic, type_name in expected.items():
        assert types.get(topic) == type_name, (topic, sorted(types.items()))
    assert stats.message_count == sum(len(m) for m in messages.values())
    for topic in ("/scene/noisy_points", "/camera_plan", "/camera_plan/info"):
        assert len(messages[topic]) == 1, (topic, len(messages[topic]))
    plan = messages["/camera_plan"][0]
    assert plan.header.frame_id == "map"
    np.testing.assert_allclose([[p.position.x, p.position.y, p.position.z, p.orientation.x, p.orientation.y,
                                 p.orientation.z, p.orientation.w] for p in plan.poses], summary["poses"], atol=1e-9)
    assert len(messages["/reconstruction/score"]) == realizations + 1  # each realization, then the aggregate
    assert messages["/reconstruction/score"][-1].chamfer == summary["chamfer_mean"]
    cloud = messages["/scene/noisy_points"][0]
    assert cloud.width * cloud.height > 0 and len(cloud.data) == cloud.row_step * cloud.height
    assert all(len(messages[f"/d{d}/pose"]) >= 2 for d in range(drones))


def wait_gone(pids: dict, timeout: float) -> list:
    """Names of the processes still alive after waiting up to ``timeout`` seconds for all to end."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and any(alive(p) for p in pids.values()):
        time.sleep(0.1)
    return [name for name, pid in pids.items() if alive(pid)]


def start_script(ros_env, tmp_path, *args) -> NodeProcess:
    """run_suite.py as a child process (its output collected by a reader thread: no blocking reads)."""
    return NodeProcess([sys.executable, str(SCRIPT), *SMALL, "--out", str(tmp_path / "run"), *args],
                       ros_env, tmp_path / "run_suite.log")


def planning_started(ros_env, tmp_path) -> tuple[NodeProcess, dict]:
    """The script on a long egp mission, once the planner works on the goal; (script, node pids)."""
    script = start_script(ros_env, tmp_path, "--method", "egp", "--evals", "1000", "--init", "10",
                          "--timeout", "300")
    assert script.wait_for_output("planning 4 cameras", 120), script.output()[-3000:]
    pids = started_pids(script.output())
    assert set(pids) == {"recorder", "scene", "planner", "recon"}, script.output()[-3000:]
    return script, pids


def test_killing_the_planner_stops_everything(ros_env, tmp_path) -> None:
    script, pids = planning_started(ros_env, tmp_path)
    try:
        os.kill(pids["planner"], signal.SIGKILL)
        code = script.wait(60)
    finally:
        script.stop()
    text = script.output()
    assert code == 3, text[-3000:]
    assert re.search(r'node "planner" died', text), text[-3000:]
    assert not wait_gone(pids, 10.0), text[-3000:]


def test_a_running_script_holds_its_folder_and_ctrl_c_leaves_a_readable_recording(ros_env, tmp_path,
                                                                                   capsys) -> None:
    """While the script plans, its --out is locked: a second run_suite.py into it (a real second
    process) is refused in one line naming the first, exit 2, and moves nothing aside (it moved
    the first run's folder mid-run: two plan folders, one summary, run.mcap of two recorders), and
    so are the planner's and the recon's CLIs. Then SIGINT (Ctrl-C): exit 130, the nodes stopped,
    run.mcap closed (it has its summary) with what was published so far (the scene, no plan
    yet), and the folder free again."""
    from vp_planner.cli import main as plan_main
    from vp_recon.cli import main as recon_main
    from vp_scene.folders import FolderLock

    script, pids = planning_started(ros_env, tmp_path)
    out = tmp_path / "run"
    try:
        held = sorted(p.name for p in out.iterdir())
        second = subprocess.run([sys.executable, str(SCRIPT), *SMALL, "--method", "circle", "--out", str(out)],
                                env=ros_env, capture_output=True, text=True, timeout=120)
        refusal = f"--out {out} is in use by another run (pid {script.pid}): wait until it ends, or give another --out"
        assert second.returncode == 2, second.stdout + second.stderr
        assert (second.stdout + second.stderr).strip().splitlines() == [f"error: {refusal}"], second.stdout + second.stderr
        capsys.readouterr()
        assert plan_main(["--scenario", "one_plant", "--method", "circle", "--cameras", "2", "--evals", "2",
                          "--out", str(out), "--no-progress"]) == 2
        plan = tmp_path / "plan.json"
        plan.write_text(json.dumps({"scenario": "one_plant", "method": "ring", "reward": 0.5, "fov": math.pi / 2,
                                    "cameras": [[1.4, 0, 1.2, -1.4, 0, -0.3], [-1.4, 0, 1.2, 1.4, 0, -0.3]],
                                    "scene": {"scenario": "one_plant", "models": None, "seed": 0,
                                              "points_per_plant": 2000, "realizations": 2}}))
        assert recon_main(["--plan", str(plan), "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.splitlines() == [f"plan: error: {refusal}", f"recon: error: {refusal}"], err
        assert [p.name for p in tmp_path.iterdir() if p.name.startswith("run-")] == []  # nothing moved aside
        assert set(held) <= {p.name for p in out.iterdir()} and script.alive()
        script.signal(signal.SIGINT)
        code = script.wait(60)
    finally:
        script.stop()
    text = script.output()
    assert code == 130, text[-3000:]
    assert not wait_gone(pids, 10.0), text[-3000:]
    types, messages, _stats = read_recording(out / "run.mcap")
    assert types["/scene/noisy_points"] == "sensor_msgs/msg/PointCloud2" and len(messages["/scene/noisy_points"]) == 1
    assert "/camera_plan" not in messages
    FolderLock.check(out)


def test_sigkill_of_the_script_takes_the_nodes_with_it(ros_env, tmp_path) -> None:
    """No orphaned nodes when the supervisor itself is killed. run.mcap reads with the standard
    readers (mcap_ros2's read_ros2_messages, mcap's make_reader) at once, while the recorder still
    finishes it (they raised RecordLengthLimitExceeded: no footer), and once the recorder has
    ended it is closed with its summary, the scene in it. The folder's lock dies with the run."""
    from vp_recon.recording import is_closed
    from vp_scene.folders import FolderLock

    script, pids = planning_started(ros_env, tmp_path)
    bag = tmp_path / "run" / "run.mcap"
    try:
        script.signal(signal.SIGKILL)
        assert script.wait(10) == -signal.SIGKILL
        at_once = standard_reads(bag)
        t0 = time.monotonic()
        left = wait_gone(pids, 15.0)
    finally:
        for pid in pids.values():  # never leave them behind, even when the test fails
            if alive(pid):
                os.kill(pid, signal.SIGKILL)
    assert not left, f"still running {time.monotonic() - t0:.1f} s after the script was killed: {left}"
    assert is_closed(bag)  # the recorder finished it on its parent-death signal
    closed = standard_reads(bag)
    for reader, topics in closed.items():
        assert len(topics["/scene/noisy_points"]) == 1, (reader, sorted(topics))
        assert all(len(at_once[reader].get(t, [])) <= len(m) for t, m in topics.items()), (reader, at_once, closed)
    FolderLock.check(tmp_path / "run")  # no lock left behind by the killed run


def test_a_dead_node_is_reported_last_without_tracebacks(ros_env, tmp_path) -> None:
    """The scene node exits at once with a one-line error (its layout names a plant model that
    needs a models folder: the script reads the layout, the scene resolves its models); the script
    stops the others; its last line names the node and repeats that error, and no node prints a
    traceback while being stopped."""
    earlier = tmp_path / "run"  # make run twice lost (and mixed) the first run
    earlier.mkdir()
    (earlier / "summary.json").write_text('{"earlier": true}')
    (earlier / "run.mcap").write_bytes(b"the earlier recording")
    layout = tmp_path / "field.yaml"
    layout.write_text("grid:\n  rows: 1\n  columns: 2\n  model: no_such_plant\n")
    script = start_script(ros_env, tmp_path, "--method", "circle", "--evals", "4", "--scenario", str(layout),
                          "--timeout", "120")
    try:
        code = script.wait(120)
    finally:
        script.stop()
    text = script.output()
    assert code == 3, text[-3000:]
    last = text.strip().splitlines()[-1]
    assert 'node "scene" died (exit code 2)' in last and "no_such_plant" in last, text[-3000:]
    assert "Traceback" not in text and "KeyboardInterrupt" not in text, text[-6000:]
    # the earlier run was moved aside, whole, before this one started: nothing lost, nothing mixed
    (moved,) = [p for p in tmp_path.iterdir() if re.fullmatch(r"run-\d{8}-\d{6}", p.name)]
    assert f"the earlier output in {earlier} was moved to {moved}" in text, text[-3000:]
    assert sorted(p.name for p in moved.iterdir()) == ["run.mcap", "summary.json"]
    assert (moved / "summary.json").read_text() == '{"earlier": true}'
    assert not (earlier / "summary.json").exists() and (earlier / "recon.log").exists()


def test_a_run_whose_outputs_are_not_all_written_fails_with_output_not_writable(ros_env, tmp_path) -> None:
    """The suite on a full disk logged 'could not write the outputs of realization 0', then printed
    the Chamfer, exited 0 and wrote error_code 0. A realization whose files cannot be written (here
    a folder stands where its cloud goes, put there as the plan's folder appears) fails the plan:
    its score and the aggregate say OUTPUT_NOT_WRITABLE naming the file, summary.json records it,
    the script exits 1 with that as its last line and prints no Chamfer."""
    out = tmp_path / "run"
    script = start_script(ros_env, tmp_path, "--method", "circle", "--evals", "16", "--recon-workers", "1",
                          "--timeout", "300")
    try:
        deadline = time.monotonic() + 240
        while not list(out.glob("plan-*")):
            assert script.poll() is None and time.monotonic() < deadline, script.output()[-3000:]
            time.sleep(0.02)
        (plan_dir,) = out.glob("plan-*")
        for k in (0, 1):  # the realizations reconstruct one after the other: at least one is blocked
            try:
                (plan_dir / f"recon_{k}.ply").mkdir()
            except FileExistsError:
                pass
        code = script.wait(240)
    finally:
        script.stop()
    text = script.output()
    assert code == 1, text[-3000:]
    last = text.strip().splitlines()[-1]
    assert last.startswith("error: reconstruction failed (error_code 6 OUTPUT_NOT_WRITABLE): realization ") and \
        f"its outputs are not all written: could not write {plan_dir}/recon_" in last, text[-3000:]
    assert "Chamfer distance x100" not in text
    summary = json.loads((out / "summary.json").read_text())
    assert summary["error_code"] == 6 and summary["chamfer_mean"] is None and "Is a directory" in summary["error_msg"]
    failed = [r for r in summary["per_realization"] if r["error_code"] == 6]
    assert len(failed) == 1 and "could not write" in failed[0]["error_msg"], summary["per_realization"]


def test_an_out_of_other_files_is_refused(tmp_path) -> None:
    """Hardening III, item 8: an --out that holds files that are not an output of the suite is
    refused (the run's files would mix with them; a later run would move the folder aside)."""
    import run_suite

    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(FileExistsError, match="holds other files"):
        run_suite.prepare_out(tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]
    lock, moved = run_suite.prepare_out(tmp_path / "new")
    assert moved is None and (tmp_path / "new").is_dir()
    lock.release()
    lock, moved = run_suite.prepare_out(tmp_path / "new")
    assert moved is None  # empty: used as it is
    lock.release()


def test_a_domain_id_outside_ros_range_is_a_usage_error(monkeypatch, capsys) -> None:
    """--domain-id 300 gave Fast DDS's raw port error once the nodes started; the range ROS 2
    documents (0-232) is checked at parse time, for $ROS_DOMAIN_ID too."""
    import run_suite

    for argv, env, said in ((["--domain-id", "300"], "7", "--domain-id must be in 0-232, got 300"),
                            (["--domain-id", "-1"], "7", "--domain-id must be in 0-232, got -1"),
                            ([], "300", "ROS_DOMAIN_ID (environment) must be an integer in 0-232, got '300'"),
                            ([], "abc", "ROS_DOMAIN_ID (environment) must be an integer in 0-232, got 'abc'")):
        monkeypatch.setenv("ROS_DOMAIN_ID", env)
        with pytest.raises(SystemExit) as exited:
            run_suite.parse_args(argv)
        assert exited.value.code == 2
        assert capsys.readouterr().err.strip().splitlines()[-1].endswith(f"error: {said}"), argv
    assert run_suite.parse_args(["--domain-id", "232"]).domain_id == 232
    monkeypatch.setenv("ROS_DOMAIN_ID", "0")
    assert run_suite.parse_args([]).domain_id == 0
    monkeypatch.delenv("ROS_DOMAIN_ID")
    assert 10 <= run_suite.parse_args([]).domain_id < 210


def test_layout_file_goes_to_the_scene_node_as_an_absolute_path(monkeypatch) -> None:
    """--scenario FILE: read at once; the scene node gets the absolute path (it may run elsewhere),
    summary.json the layout's name; a built-in name is passed on as it is."""
    import run_suite

    monkeypatch.chdir(REPO)
    args = run_suite.parse_args(["--scenario", "examples/field.yaml"])
    assert args.scenario == args.scenario_file == str(REPO / "examples" / "field.yaml")
    assert args.scenario_name == "small_field"
    args = run_suite.parse_args(["--scenario", "row_12"])
    assert args.scenario == args.scenario_name == "row_12" and args.scenario_file is None


def test_bad_layout_file_is_a_usage_error_before_any_node_starts(ros_env, tmp_path) -> None:
    bad = tmp_path / "field.yaml"
    bad.write_text("grid: {rows: three, columns: 2}\n")
    proc = subprocess.run([sys.executable, str(SCRIPT), "--scenario", str(bad), "--out", str(tmp_path / "run")],
                          env=ros_env, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    last = proc.stderr.strip().splitlines()[-1]
    assert f"--scenario: {bad}: grid.rows must be an integer >= 1, got 'three'" in last, proc.stderr
    assert "started" not in proc.stdout and not (tmp_path / "run").exists()


def test_make_runs_sift_octave_follows_the_image_width() -> None:
    """make run's SIFT starts at the image's own resolution at the paper's 2000 x 1500, and keeps
    COLMAP's doubled first octave on small images (too few keypoints without it); given, as given."""
    import run_suite

    assert run_suite.parse_args([]).sift_first_octave == 0 and run_suite.parse_args([]).dense_scale == 0.7
    assert run_suite.parse_args(["--width", "800", "--height", "600"]).sift_first_octave == -1
    assert run_suite.parse_args(["--width", "800", "--sift-first-octave", "0"]).sift_first_octave == 0
    assert run_suite.parse_args(["--sift-first-octave", "-1"]).sift_first_octave == -1


def test_the_script_offers_every_method_of_the_planner() -> None:
    """run_suite offers the registry's methods (vp_planner.methods, torch-free), as the planner does."""
    import run_suite
    from vp_planner.methods import METHODS

    assert tuple(run_suite.METHODS) == tuple(METHODS)
    assert run_suite.parse_args(["--method", "lawnmower"]).method == "lawnmower"


def test_a_goal_whose_acceptance_was_lost_still_gets_its_result(ros_env, start_node, monkeypatch) -> None:
    """The script's recovery when the planner accepts a goal but its answer is lost (rmw_fastrtps
    drops a service response sent before the reply path is matched): once the goal's feedback
    arrives, a handle made from the goal id alone gets the plan."""
    import run_suite

    monkeypatch.setenv("ROS_DOMAIN_ID", ros_env["ROS_DOMAIN_ID"])
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    start_node("vp_scene", "scene", {"scenario": "one_plant", "points_per_plant": 500, "realizations": 2}, ros_env)
    planner = start_node("vp_planner", "planner", {"num_threads": 1}, ros_env)
    args = run_suite.parse_args(["--cameras", "3", "--method", "random", "--evals", "30"])
    mission = run_suite.Mission(args)
    try:
        deadline = time.monotonic() + 120
        run_suite.wait_for(lambda: mission.scene_ready.is_set() and mission.client.server_is_ready(), [planner],
                           deadline, "scene and server")
        _ignored, goal_id = mission.send_goal()        # as if its response never came
        run_suite.wait_for(lambda: mission.feedback_seen, [planner], deadline, "feedback")
        result_future = mission.accepted_handle(goal_id).get_result_async()
        run_suite.wait_for(result_future.done, [planner], deadline, "the result")
        result = result_future.result().result
        assert result.error_code == 0 and len(result.cameras) == 3 * 6 and result.evaluations == 30
    finally:
        mission.close()
