"""A request's sizes are bounded at every entry, before anything is allocated: the planner CLI, the
recon CLI reading a plan.json's scene, the scene node's parameters and the recon node's rebuild of
/scene/description (vp_scene.limits: realizations x points x plants, with the plan's cameras for
the planner); seeds have one range at every flag. Every probe of a big input runs in a child whose
address space is capped, so that a regression fails here instead of taking the machine down."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from node_process import NodeProcess, node_command  # tools/, on sys.path through conftest.py
from vp_scene.limits import MAX_POINTS_PER_PLANT, MAX_REALIZATIONS, MAX_SEED

#: the address space of a probe (torch, pycolmap and their libraries need about 3 GiB of it)
CAP = 6 << 30
#: runs ``module.main(argv)`` for each argv of sys.argv[3] (JSON) under the cap sys.argv[2];
#: prints [[exit code, stderr], ...]
_PROBE = """
import contextlib, importlib, io, json, resource, sys
resource.setrlimit(resource.RLIMIT_AS, (int(sys.argv[2]), int(sys.argv[2])))
main, out = importlib.import_module(sys.argv[1]).main, []
for argv in json.loads(sys.argv[3]):
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code
    out.append([code, err.getvalue()])
print(json.dumps(out))
"""
#: execs sys.argv[2:] with its address space capped at sys.argv[1] bytes
_CAPPED = "import os, resource, sys; c = int(sys.argv[1]); resource.setrlimit(resource.RLIMIT_AS, (c, c)); " \
          "os.execv(sys.argv[2], sys.argv[2:])"
BEYOND = [  # realizations 100000 grew the planner CLI by gigabytes; the third fits the caps, not the memory
    (["--realizations", "100000"], f"realizations = 100000 is above the bound of {MAX_REALIZATIONS}"),
    (["--points-per-plant", str(10 ** 9)], f"points_per_plant = 1000000000 is above the bound of {MAX_POINTS_PER_PLANT}"),
    (["--scenario", "row_12", "--points-per-plant", str(MAX_POINTS_PER_PLANT), "--realizations",
      str(MAX_REALIZATIONS)], "a scene of 12 plant(s) x 1000000 points x 100 realizations would need about"),
]


def probe(module: str, cases: list) -> list:
    """[(exit code, stderr lines)] of ``module.main(argv)`` for each argv, in one capped child."""
    p = subprocess.run([sys.executable, "-c", _PROBE, module, str(CAP), json.dumps(cases)], capture_output=True,
                       text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-3000:]
    return [(code, [ln for ln in err.splitlines() if ln.strip()]) for code, err in json.loads(p.stdout)]


def test_the_planner_cli_refuses_a_scene_beyond_its_bounds(tmp_path: Path) -> None:
    out = tmp_path / "out"
    base = ["--method", "circle", "--evals", "5", "--cameras", "4", "--out", str(out), "--no-progress"]
    for (code, lines), (_, text) in zip(probe("vp_planner.cli", [base + a for a, _ in BEYOND]), BEYOND):
        assert code == 2 and len(lines) == 1 and text in lines[0], lines
    assert not out.exists()


def test_the_planner_cli_checks_what_the_cameras_multiply_first(tmp_path: Path, monkeypatch, capsys) -> None:
    """The scene fits, its 100 cameras' reward does not: refused before the scene is built."""
    from vp_planner.cli import main
    from vp_scene import build, limits

    monkeypatch.setattr(limits, "available_memory", lambda: 1 << 30)
    monkeypatch.setattr(build, "build_noisy_scene", lambda **k: pytest.fail("the scene was built"))
    assert main(["--method", "circle", "--cameras", "100", "--evals", "5", "--realizations", "20",
                 "--points-per-plant", "3000", "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "num_cameras = 100 on 20 x 3000 points" in lines[0] and "GiB" in lines[0], lines


def test_the_recon_cli_refuses_a_plan_files_scene_beyond_its_bounds(tmp_path: Path) -> None:
    """plan.json's scene gave ArrayMemoryError tracebacks."""
    cases = []
    for k, (flags, _) in enumerate(BEYOND[:2]):
        scene = {"scenario": "one_plant", flags[0][2:].replace("-", "_"): int(flags[1])}
        plan = tmp_path / f"plan{k}.json"
        plan.write_text(json.dumps({"cameras": [[2, 0, 1, -1, 0, 0], [0, 2, 1, 0, -1, 0]], "scene": scene}))
        cases.append(["--plan", str(plan), "--out", str(tmp_path / f"out{k}"), "--no-progress"])
    for k, ((code, lines), (_, text)) in enumerate(zip(probe("vp_recon.cli", cases), BEYOND)):
        assert code == 2 and len(lines) == 1 and "cannot rebuild the scene" in lines[0] and text in lines[0], lines
        assert not any((tmp_path / f"out{k}").glob("*")), sorted((tmp_path / f"out{k}").glob("*"))


@pytest.mark.parametrize("params, text", [
    ({"realizations": MAX_REALIZATIONS + 1}, f"parameter 'realizations' must be >= 1 and <= {MAX_REALIZATIONS}"),
    ({"scenario": "row_12", "points_per_plant": MAX_POINTS_PER_PLANT, "realizations": MAX_REALIZATIONS},
     "cannot build the scene: a scene of 12 plant(s) x 1000000 points x 100 realizations would need about"),
])
def test_the_scene_node_refuses_a_scene_beyond_its_bounds(params, text, ros_env, tmp_path: Path) -> None:
    node = NodeProcess([sys.executable, "-c", _CAPPED, str(CAP), *node_command("vp_scene", "scene", params)],
                       ros_env, tmp_path / "scene.log")
    try:
        assert node.wait(60.0) == 2, node.output()
        lines = [ln for ln in node.output().splitlines() if ln.strip()]
        assert len(lines) == 1 and text in lines[0], lines
    finally:
        node.stop()


def test_the_recon_nodes_rebuild_refuses_a_description_beyond_its_bounds(monkeypatch) -> None:
    """The recon node (and a simulated drone) rebuild the scene of /scene/description: a ValueError
    (the node's NO_SCENE) before anything is built."""
    from vp_interfaces.msg import PlantPlacement, SceneDescription

    from vp_scene import build
    from vp_scene.limits import SceneTooLargeError
    from vp_scene.messages import scene_of_description

    monkeypatch.setattr(build, "make_scene", lambda *a, **k: pytest.fail("the scene was built"))
    desc = SceneDescription(scenario="one_plant", seed=0, points_per_plant=4000, plant_spacing=0.6, row_spacing=0.76,
                            levels=10, realizations=100000, wind_variance=0.002, wind_direction=0.0,
                            plants=[PlantPlacement(model="procedural-1", yaw=0.0, scale=1.0)])
    with pytest.raises(SceneTooLargeError, match=f"above the bound of {MAX_REALIZATIONS}"):
        scene_of_description(desc)


@pytest.mark.parametrize("module, flag", [
    ("vp_planner.cli", "--seed"), ("vp_recon.cli", "--capture-seed"), ("run_suite", "--seed"),
    ("bench.bench_fields", "--seed"), ("bench.bench_real", "--seed"), ("bench.bench_sorties", "--seed"),
])
def test_seed_flags_name_their_range(module, flag, capsys) -> None:
    """--seed 2**64 gave "Overflow when unpacking long long" from torch."""
    import importlib

    parse = importlib.import_module(module).parse_args
    with pytest.raises(SystemExit) as info:
        parse([flag, str(2 ** 64), "--plan", "plan.json", "--out", "out"] if module == "vp_recon.cli"
              else [flag, str(2 ** 64)])
    err = capsys.readouterr().err
    assert info.value.code == 2 and f"argument {flag}: must be an integer from 0 to {MAX_SEED}" in err, err
    assert "Traceback" not in err
