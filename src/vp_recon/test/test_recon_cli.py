"""python -m vp_recon.cli: outputs of a small plan, exit code 2 and one-line errors for bad input."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from vp_recon.cli import main
from vp_scene.ply import load_ply

SCENE = {"scenario": "one_plant", "models": None, "seed": 0, "points_per_plant": 2000, "plant_spacing": 0.6,
         "row_spacing": 0.76, "levels": 10, "realizations": 2, "wind_variance": 0.002, "wind_direction": 0.0}


def _plan(tmp_path: Path, cameras=None, **extra) -> Path:
    if cameras is None:
        a = np.deg2rad(30.0 * np.arange(4))
        c = np.stack([1.4 * np.cos(a), 1.4 * np.sin(a), np.full(4, 1.2)], axis=1)
        cameras = np.concatenate([c, np.array([0.0, 0.0, 0.9]) - c], axis=1).tolist()
    plan = {"scenario": "one_plant", "method": "ring", "cameras": cameras, "reward": 0.5, "fov": math.pi / 2,
            "scene": SCENE, **extra}
    p = tmp_path / "plan.json"
    p.write_text(json.dumps(plan))
    return p


def test_cli_writes_outputs(tmp_path: Path) -> None:
    """(The plan's image_size is the rendered size, as `score` reads it: no --width here.)"""
    out = tmp_path / "out"
    rc = main(["--plan", str(_plan(tmp_path, image_size=[640, 480])), "--out", str(out), "--capture", "ideal",
               "--realizations", "1", "--no-progress"])
    assert rc == 0
    data = json.loads((out / "recon.json").read_text())
    assert (data["width"], data["height"]) == (640, 480)
    for key in ("chamfer_mean", "chamfer_std", "per_realization", "seconds", "units", "method", "reward"):
        assert key in data, key
    assert "x 100" in data["units"]
    (r,) = data["per_realization"]
    assert r["realization"] == 1 and r["images"] >= 2 and r["points"] > 1000
    assert data["chamfer_mean"] == pytest.approx(r["chamfer"]) and data["chamfer_std"] == 0.0
    assert 0.1 < r["chamfer"] < 5.0                      # x 100: centimetres, a good plan scores ~1-2
    assert r["chamfer"] == pytest.approx(r["accuracy"] + r["completeness"])
    assert len(load_ply(out / "recon_1.ply").points) == r["points"]
    assert (out / "views.png").stat().st_size > 1000
    # the metrics without a ground truth (issue 20, part 4), per realization and over them
    assert r["registered_images"] == r["images"] and 0 < r["mean_reprojection_error"] < 2.0
    assert r["mean_track_length"] >= 2.0 and 0.2 < r["coverage_of_prior"] <= 1.0
    assert len(r["coverage_of_prior_per_plant"]) == 1 and r["coverage_tau"] == 0.02
    assert data["no_truth"]["coverage_of_prior"] == r["coverage_of_prior"]
    assert (out / "uncovered_1.png").stat().st_size > 1000


def test_cli_matching_option(tmp_path: Path, capsys) -> None:
    """--matching poses on 4 cameras: pairs from the poses (auto would match all 6), in recon.json."""
    out = tmp_path / "out"
    rc = main(["--plan", str(_plan(tmp_path)), "--out", str(out), "--width", "640", "--height", "480", "--capture", "ideal",
               "--realizations", "0", "--sparse-only", "--matching", "poses", "--no-progress"])
    assert rc == 0, capsys.readouterr().err
    data = json.loads((out / "recon.json").read_text())
    (r,) = data["per_realization"]
    assert data["matching"] == "poses" and r["matching"] == "poses" and 3 <= r["matched_pairs"] < 6
    capsys.readouterr()
    with pytest.raises(SystemExit) as ei:                 # argparse refuses an unknown choice
        main(["--plan", str(_plan(tmp_path)), "--out", str(tmp_path), "--matching", "magic"])
    err = capsys.readouterr().err
    assert ei.value.code == 2 and err.startswith("recon: error: argument --matching") and err.count("\n") == 1


def _fails(tmp_path: Path, capsys, args: list, match: str) -> None:
    rc = main(args + ["--no-progress"])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert err.startswith("recon: error:") and match in err and err.count("\n") == 1


def test_cli_missing_and_corrupt_plan(tmp_path: Path, capsys) -> None:
    _fails(tmp_path, capsys, ["--plan", str(tmp_path / "nope.json"), "--out", str(tmp_path)], "not found")
    bad = tmp_path / "bad.json"
    bad.write_text('{"cameras": [[0, 0')
    _fails(tmp_path, capsys, ["--plan", str(bad), "--out", str(tmp_path)], "not valid JSON")
    bad.write_text("[1, 2]")
    _fails(tmp_path, capsys, ["--plan", str(bad), "--out", str(tmp_path)], "JSON object")
    bad.write_text(json.dumps({"cameras": []}))
    _fails(tmp_path, capsys, ["--plan", str(bad), "--out", str(tmp_path)], "scene")


def test_cli_bad_plan_contents(tmp_path: Path, capsys) -> None:
    _fails(tmp_path, capsys, ["--plan", str(_plan(tmp_path, cameras=[])), "--out", str(tmp_path)], "no cameras")
    _fails(tmp_path, capsys, ["--plan", str(_plan(tmp_path, cameras=[[1, 2, 3]])), "--out", str(tmp_path)],
           "shape")
    p = _plan(tmp_path)
    d = json.loads(p.read_text())
    d["scene"]["scenario"] = "moon"
    p.write_text(json.dumps(d))
    out = tmp_path / "new_out"
    _fails(tmp_path, capsys, ["--plan", str(p), "--out", str(out)], "moon")
    assert not out.exists()  # issue 10, item 12: a bad scene left an empty output folder


def test_cli_unwritable_out_and_bad_args(tmp_path: Path, capsys) -> None:
    f = tmp_path / "file"
    f.write_text("x")
    _fails(tmp_path, capsys, ["--plan", str(_plan(tmp_path)), "--out", str(f)], "not writable")
    _fails(tmp_path, capsys, ["--plan", str(_plan(tmp_path)), "--out", str(tmp_path), "--realizations", "a"],
           "comma-separated")
    _fails(tmp_path, capsys, ["--plan", str(_plan(tmp_path)), "--out", str(tmp_path), "--dense-scale", "0"],
           "dense_scale must be in (0, 1]")


def test_cli_refuses_a_plan_of_more_cameras_than_max_cameras(tmp_path: Path, capsys, monkeypatch) -> None:
    """Hardening III, item 4: the CLI reconstructed a plan of any size (200 cameras: 7 minutes,
    5.8 GB; every image of a realization is held at once). A plan of more than --max-cameras
    (default MAX_CAMERAS, the recon node's max_cameras) is refused with exit 2 and one line
    before its scene is built or anything rendered; the flag goes with --plan only."""
    import vp_scene.build

    a = np.deg2rad(np.linspace(0.0, 360.0, 257, endpoint=False))
    c = np.stack([1.7 * np.cos(a), 1.7 * np.sin(a), np.full(len(a), 1.2)], axis=1)
    big = _plan(tmp_path, cameras=np.concatenate([c, np.array([0.0, 0.0, 0.9]) - c], axis=1).tolist())
    out = tmp_path / "out"
    with monkeypatch.context() as tripwire:
        tripwire.setattr(vp_scene.build, "build_noisy_scene", lambda **k: pytest.fail("the scene was built"))
        _fails(tmp_path, capsys, ["--plan", str(big), "--out", str(out)],
               f"{big}: the plan has 257 cameras; at most 256 are reconstructed (--max-cameras")
        _fails(tmp_path, capsys, ["--plan", str(_plan(tmp_path)), "--out", str(out), "--max-cameras", "3"],
               "the plan has 4 cameras; at most 3 are reconstructed")
        for args, match in ((["--max-cameras", "1"], "--max-cameras must be >= 2"),
                            (["--max-megapixels", "5000"], "--max-megapixels goes with --images")):
            with pytest.raises(SystemExit) as ei:
                main(["--plan", str(big), "--out", str(out), *args])
            err = capsys.readouterr().err
            assert ei.value.code == 2 and match in err and err.count("\n") == 1, err
    assert not out.exists()
    from vp_recon.config import MAX_CAMERAS, MAX_MEGAPIXELS

    assert (MAX_CAMERAS, MAX_MEGAPIXELS) == (256, 768)


def test_cli_nothing_visible_records_error(tmp_path: Path, capsys) -> None:
    cams = [[1.4, 0.0, 1.2, 1.0, 0.0, 0.0], [0.0, 1.4, 1.2, 0.0, 1.0, 0.0]]      # looking away
    rc = main(["--plan", str(_plan(tmp_path, cameras=cams)), "--out", str(tmp_path / "o"), "--capture", "ideal", "--width", "320",
               "--height", "240", "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 1 and "[NOTHING_VISIBLE]" in err
    data = json.loads((tmp_path / "o" / "recon.json").read_text())
    assert data["error"]["code"] == 4 and data["error"]["name"] == "NOTHING_VISIBLE"
    assert [p.name for p in (tmp_path / "o").iterdir()] == ["recon.json"]  # no stage left behind


def _entries(folder: Path) -> dict:
    return {p.name: p.read_bytes() for p in folder.iterdir()}  # hidden ones too


def test_a_reused_out_is_refused_and_replaced_only_by_a_success(tmp_path: Path, capsys) -> None:
    """Hardening III, item 8: a second run into an OUT that holds a reconstruction is refused with
    the hint --overwrite, and touches nothing; with --overwrite a run that fails keeps the earlier
    result whole (its error recon.json is not put beside the earlier recon_1.ply) and one that
    succeeds replaces it as a whole (recon_1.ply goes with it); the plan beside them stays."""
    out = tmp_path / "out"
    plan = _plan(tmp_path)
    out.mkdir()
    (out / "plan.json").write_bytes(plan.read_bytes())  # make plan, then make recon, into one folder
    base = ["--out", str(out), "--capture", "ideal", "--width", "640", "--height", "480", "--sparse-only",
            "--no-progress"]
    assert main(["--plan", str(plan), "--realizations", "1"] + base) == 0, capsys.readouterr().err
    capsys.readouterr()
    first = _entries(out)
    assert {"plan.json", "recon.json", "recon_1.ply"} <= set(first)

    rc = main(["--plan", str(plan), "--realizations", "0"] + base)
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1, err
    assert err.startswith(f"recon: error: {out} already holds a result (recon.json, recon_1.ply") and "--overwrite" in err
    assert _entries(out) == first

    (tmp_path / "away").mkdir()
    away = _plan(tmp_path / "away", cameras=[[1.4, 0.0, 1.2, 1.0, 0.0, 0.0], [0.0, 1.4, 1.2, 0.0, 1.0, 0.0]])
    rc = main(["--plan", str(away), "--overwrite"] + base)
    err = capsys.readouterr().err
    assert rc == 1 and err.count("\n") == 1 and "[NOTHING_VISIBLE]" in err and "keeps its earlier result" in err, err
    assert _entries(out) == first

    assert main(["--plan", str(plan), "--realizations", "0", "--overwrite"] + base) == 0, capsys.readouterr().err
    now = _entries(out)
    assert sorted(now) == ["plan.json", "recon.json", "recon_0.ply", "uncovered_0.png", "views.png"], sorted(now)
    assert now["plan.json"] == first["plan.json"]
    assert [r["realization"] for r in json.loads(now["recon.json"])["per_realization"]] == [0]


def test_no_scheduler_at_the_address_is_one_line_and_leaves_no_folder(tmp_path: Path, capfd, monkeypatch) -> None:
    """Hardening III, item 11: nothing listens at the --scheduler address: exit 2, one line naming
    it (every line on the process's stderr: capfd), and no empty OUT left behind. Dask retries a
    refused connection until the client's connect timeout, 10 s (vp_scene.cluster), 1 s here."""
    import vp_scene.cluster

    monkeypatch.setattr(vp_scene.cluster, "CONNECT_TIMEOUT_S", 1.0, raising=False)
    out = tmp_path / "o"
    rc = main(["--plan", str(_plan(tmp_path)), "--out", str(out), "--capture", "ideal", "--width", "320",
               "--height", "240", "--no-progress", "--scheduler", "tcp://127.0.0.1:1"])
    err = capfd.readouterr().err
    assert rc == 2 and err.startswith("recon: error:") and err.count("\n") == 1 and "tcp://127.0.0.1:1" in err, err
    assert not out.exists()


def test_sigterm_after_colmap_ran_exits_quietly(tmp_path: Path) -> None:
    """pycolmap loads glog, whose handler turns SIGTERM into an abort with a stack trace; the CLI
    ends a terminated run as an interrupted one (exit 130, one line)."""
    import os
    import signal
    import subprocess
    import sys
    import time

    plan = _plan(tmp_path)
    proc = subprocess.Popen([sys.executable, "-m", "vp_recon.cli", "--plan", str(plan), "--out", str(tmp_path / "o"),
                             "--width", "640", "--height", "480"], stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    err = ""
    deadline = time.monotonic() + 120
    try:
        while "sparse" not in err or "1/2" not in err.split("sparse")[-1]:  # COLMAP has run once
            assert time.monotonic() < deadline, err
            ch = proc.stderr.read(1)
            assert ch or proc.poll() is None, err
            err += ch
        proc.send_signal(signal.SIGTERM)
        _, rest = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    err += rest
    assert proc.returncode == 130, err[-2000:]
    assert "Aborted" not in err and "Traceback" not in err and err.rstrip().endswith("recon: interrupted")
    assert not (tmp_path / "o").exists()  # Hardening III, item 11: no empty (or half-written) OUT


_QUICK = ["--capture", "ideal", "--width", "640", "--height", "480", "--sparse-only", "--no-progress"]


def test_a_refused_realization_writes_nothing_and_the_corrected_run_is_accepted(tmp_path: Path, capsys) -> None:
    """`--realizations 99` exited 2 but left a recon.json in OUT, so the corrected run was refused
    as 'already holds a result'. The realizations are checked against the scene before OUT is
    touched: OUT keeps what it held, and the corrected run goes through."""
    out = tmp_path / "out"
    plan = _plan(tmp_path)
    out.mkdir()
    (out / "plan.json").write_bytes(plan.read_bytes())
    before = _entries(out)
    for bad, words in (("99", "realization(s) [99] do not exist (the scene has 2: 0..1)"),
                       ("1,1", "duplicate realizations in [1, 1]")):
        _fails(tmp_path, capsys, ["--plan", str(plan), "--out", str(out), "--realizations", bad] + _QUICK,
               f"--realizations: {words}")
        assert _entries(out) == before
    assert main(["--plan", str(plan), "--out", str(out), "--realizations", "1"] + _QUICK) == 0, capsys.readouterr().err
    assert {"plan.json", "recon.json", "recon_1.ply"} <= set(_entries(out))


def test_a_full_disk_fails_the_run_with_output_not_writable_and_keeps_out(tmp_path: Path, capsys, monkeypatch) -> None:
    """A run whose results cannot all be written (the disk fills as the cloud is written: ENOSPC
    from the OS call) is a failure: [OUTPUT_NOT_WRITABLE] naming the file and the full disk, one
    line, exit 2, no Chamfer printed, and OUT as it was (no half result, no stage)."""
    import errno

    out = tmp_path / "out"
    plan = _plan(tmp_path)
    out.mkdir()
    (out / "plan.json").write_bytes(plan.read_bytes())
    before = _entries(out)
    write_bytes = Path.write_bytes

    def full(self: Path, data) -> int:
        if self.name.startswith(".recon_"):  # the cloud's temporary file
            raise OSError(errno.ENOSPC, "No space left on device")
        return write_bytes(self, data)

    monkeypatch.setattr(Path, "write_bytes", full)
    rc = main(["--plan", str(plan), "--out", str(out), "--realizations", "0"] + _QUICK)
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "chamfer" not in err, err
    assert err.startswith(f"recon: error: [OUTPUT_NOT_WRITABLE] could not write {out}/.partial-recon-") and \
        "recon_0.ply: the disk is full (No space left on device)" in err, err
    assert _entries(out) == before


def test_what_a_killed_run_left_is_removed_by_the_next_but_a_live_runs_is_kept(tmp_path: Path, capsys,
                                                                              monkeypatch) -> None:
    """A recon SIGKILLed mid-run left its stage (OUT/.partial-recon-*) and its COLMAP workspace
    (<temp>/vp_recon_*, 20-25 MB) for ever. Both name their owner's pid and hold its lock: the
    next run removes those whose owner is gone, never those of a run still going (here: a live
    process holding a stage and a workspace)."""
    import os
    import signal
    import subprocess
    import sys
    import tempfile
    import time

    temp, out = tmp_path / "temp", tmp_path / "out"
    temp.mkdir()
    out.mkdir()
    plan = _plan(tmp_path)
    env = {**os.environ, "TMPDIR": str(temp)}
    hold = ("import sys\nfrom vp_scene.folders import OwnedFolder\n"
            f"a, b = OwnedFolder('vp_recon_'), OwnedFolder('.partial-recon-', {str(out)!r})\n"
            "print(a.path, b.path, flush=True)\nsys.stdin.read()\n")
    live = subprocess.Popen([sys.executable, "-c", hold], env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            text=True)
    kept = [Path(p) for p in live.stdout.readline().split()]
    killed = subprocess.Popen([sys.executable, "-m", "vp_recon.cli", "--plan", str(plan), "--out", str(out),
                               "--realizations", "0"] + _QUICK, env=env, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while not (list(out.glob(f".partial-recon-{killed.pid}-*")) and list(temp.glob(f"vp_recon_{killed.pid}-*"))):
            assert killed.poll() is None and time.monotonic() < deadline, "the run made no stage and workspace"
            time.sleep(0.02)
        killed.send_signal(signal.SIGKILL)
    finally:
        killed.kill()
        killed.wait(30)
    left = list(out.glob(f".partial-recon-{killed.pid}-*")) + list(temp.glob(f"vp_recon_{killed.pid}-*"))
    assert len(left) == 2 and len(kept) == 2 and all(p.is_dir() for p in kept), (left, kept)  # what the kill left, the live run's
    try:
        monkeypatch.setattr(tempfile, "tempdir", str(temp))
        assert main(["--plan", str(plan), "--out", str(out), "--realizations", "0"] + _QUICK) == 0, \
            capsys.readouterr().err
        assert not any(p.exists() for p in left) and all(p.is_dir() for p in kept)
        assert sorted(p.name for p in out.iterdir() if p.name.startswith(".")) == [kept[1].name]
        assert [p.name for p in temp.iterdir()] == [kept[0].name]  # this run's own workspace went with it
    finally:
        live.stdin.close()
        live.wait(30)
