"""vp_scene.planfile: the one reader of plan.json validates at the boundary, naming file and field."""
from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from vp_scene.planfile import PlanFileError, load_plan

CAMERAS = [[2.0, 0.0, 1.0, -1.0, 0.0, 0.0], [0.0, 2.0, 1.0, 0.0, -1.0, 0.0]]


def write(tmp_path: Path, **fields) -> Path:
    path = tmp_path / "plan.json"
    path.write_text(json.dumps({"cameras": CAMERAS, "scene": {"scenario": "one_plant"}, **fields}))
    return path


def test_angles_default_only_when_absent(tmp_path: Path) -> None:
    plan = load_plan(write(tmp_path))
    assert plan.fov == pytest.approx(math.pi / 2) and plan.theta_match == pytest.approx(math.pi / 4)
    assert load_plan(write(tmp_path, fov=1.2)).fov == pytest.approx(1.2)


@pytest.mark.parametrize("value", [0, 0.0, -0.5, math.pi, "wide", True, [1.0]])
def test_bad_fov_names_field_and_file(tmp_path: Path, value) -> None:
    """``fov: 0`` silently became pi/2, ``fov: "wide"`` named neither field nor file."""
    path = write(tmp_path, fov=value)
    with pytest.raises(PlanFileError) as err:
        load_plan(path)
    assert "'fov'" in str(err.value) and str(path) in str(err.value), str(err.value)


@pytest.mark.parametrize("fields, text", [
    (dict(theta_match="narrow"), "'theta_match'"),
    (dict(image_size=[640]), "'image_size'"),
    (dict(scene={"scenario": "one_plant", "wind": 1}), "unknown 'scene' keys"),
    (dict(cameras=[[1, 2, 3]]), "'cameras'"),
    (dict(cameras=[[1, 2, 3, 0, 0, 0]]), "zero viewing direction"),
])
def test_bad_fields_name_field_and_file(tmp_path: Path, fields: dict, text: str) -> None:
    path = write(tmp_path, **fields)
    with pytest.raises(PlanFileError) as err:
        load_plan(path)
    assert text in str(err.value) and str(path) in str(err.value), str(err.value)


def test_scene_scenario_may_be_a_layout_object(tmp_path: Path) -> None:
    """A plan file carries its layout (the planner writes a layout file's canonical dict)."""
    layout = {"name": "two", "plants": [{"x": 0.0, "y": 0.0}, {"x": 0.5, "y": 0.0, "yaw": 1.0}], "jitter": 0.1}
    plan = load_plan(write(tmp_path, scene={"scenario": layout, "seed": 3}))
    assert plan.scene == {"scenario": layout, "seed": 3}


@pytest.mark.parametrize("scenario, text", [
    ({"plants": [{"x": 0.0, "y": None}]}, "scene.scenario.plants[0].y must be a number (metres), got None"),
    ({"grid": {"rows": 2, "colums": 2}}, "unknown key 'colums' in scene.scenario.grid"),
    ({"plants": [], "name": "x"}, "scene.scenario.plants must hold at least one plant"),
    (3, "'scene' must be an object with a 'scenario'"),
])
def test_bad_layout_object_names_plan_file_and_field(tmp_path: Path, scenario, text: str) -> None:
    path = write(tmp_path, scene={"scenario": scenario})
    with pytest.raises(PlanFileError) as err:
        load_plan(path)
    assert str(err.value).startswith(f"{path}: ") and text in str(err.value), str(err.value)


# ---------------------------------------------------------------- the plan file's numbers and keys
@pytest.mark.parametrize("fields, text", [
    (dict(cameras=[[1e300, 0.0, 1.0, -1.0, 0.0, 0.0], CAMERAS[1]]), "'cameras' holds 1e+300"),
    (dict(cameras=[[2.0, 0.0, 1.0, -1e300, 0.0, 0.0], CAMERAS[1]]), "'cameras' holds -1e+300"),
    (dict(cameras=None, poses=[[0.0, 0.0, 20000.0, 0.0, 0.0, 0.0, 1.0]] * 2), "plan.json: 'poses' holds 20000"),
    (dict(fixed_cameras=[[0.0, 1e300, 1.0, 1.0, 0.0, 0.0]]), "'fixed_cameras' holds 1e+300"),
    (dict(image_size=[0, 480]), "'image_size' width must be an integer of 16 to 16384 pixels, got 0"),
    (dict(image_size=[100000, 480]), "'image_size' width must be an integer of 16 to 16384 pixels, got 100000"),
])
def test_numbers_beyond_the_suites_ranges_are_refused_naming_field_and_range(tmp_path: Path, fields, text) -> None:
    """A coordinate of 1e300 gave an OverflowError traceback in the dense step, and `score` printed
    nan and exited 0; a plan's image size had no upper bound. Every coordinate is within
    MAX_COORDINATE of map's origin, every image side in IMAGE_SIDE_RANGE: one line naming both."""
    from vp_scene.camera import MAX_COORDINATE

    plan = {"cameras": CAMERAS, "scene": {"scenario": "one_plant"}, **fields}
    path = tmp_path / "plan.json"
    path.write_text(json.dumps({k: v for k, v in plan.items() if v is not None}))  # cameras None: poses alone
    with pytest.raises(PlanFileError) as err:
        load_plan(path)
    msg = str(err.value)
    assert text in msg and msg.count(str(path)) == 1 and "\n" not in msg, msg
    if "holds" in msg:
        assert f"[-{MAX_COORDINATE:g}, {MAX_COORDINATE:g}]" in msg, msg
    ok = load_plan(write(tmp_path, fixed_cameras=[[0.0, 9999.0, 1.0, 1.0, 0.0, 0.0]]))  # inside: read
    assert ok.fixed_cameras.shape == (1, 6) and load_plan(write(tmp_path)).fixed_cameras.shape == (0, 6)


def test_cameras_and_poses_that_disagree_are_refused(tmp_path: Path) -> None:
    """A plan.json whose ``cameras`` (4) and ``poses`` (10,000) disagree was read by its cameras and
    the poses ignored: one file, two plans. The planner writes both for one plan; a file with both
    must give the same cameras, row by row."""
    from vp_scene.camera import cameras_to_poses

    poses = cameras_to_poses(CAMERAS).tolist()
    assert load_plan(write(tmp_path, poses=poses)).cameras.tolist() == CAMERAS  # the planner's own: agree
    with pytest.raises(PlanFileError, match=r"'cameras' \(2 rows\) and 'poses' \(10000 rows\) disagree"):
        load_plan(write(tmp_path, poses=poses * 5000))
    moved = [list(p) for p in poses]
    moved[1][0] += 0.5
    with pytest.raises(PlanFileError, match=r"'cameras' row 1 and 'poses' row 1 are not the same camera"):
        load_plan(write(tmp_path, poses=moved))


def test_a_key_given_twice_is_refused_and_a_byte_order_mark_is_read(tmp_path: Path) -> None:
    """JSON keeps the last of a key given twice, silently: a plan with two 'cameras' was another
    plan than it showed. Refused, naming the key and its line; a UTF-8 byte-order mark (an editor's)
    is read as one."""
    path = tmp_path / "plan.json"
    path.write_text('{"cameras": %s,\n "scene": {"scenario": "one_plant"},\n "cameras": %s}'
                    % (json.dumps(CAMERAS), json.dumps(CAMERAS[::-1])))
    with pytest.raises(PlanFileError, match=r"plan.json is not valid JSON \(line 3, column \d+: duplicate key "
                                            r"'cameras'"):
        load_plan(path)
    path.write_text('{"cameras": %s, "scene": {"scenario": "one_plant", "seed": 1, "seed": 2}}' % json.dumps(CAMERAS))
    with pytest.raises(PlanFileError, match=r"line 1, column \d+: duplicate key 'seed'"):
        load_plan(path)
    path.write_bytes(b"\xef\xbb\xbf" + json.dumps({"cameras": CAMERAS, "scene": {"scenario": "one_plant"}}).encode())
    assert load_plan(path).cameras.tolist() == CAMERAS
