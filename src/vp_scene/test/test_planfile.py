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
    """Issue 10, item 12: ``fov: 0`` silently became pi/2, ``fov: "wide"`` named neither field nor file."""
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
