"""vp_scene.layout: layout files (YAML, JSON; plants and grid), built-ins, explicit values, jitter,
rebuilding from placements, one-line errors naming file and field, and unchanged old scenes."""
from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import numpy as np
import pytest

from vp_scene.build import build_noisy_scene
from vp_scene.layout import (BUILTIN_LAYOUTS, Layout, LayoutError, PlantSpec, layout_from_dict, load_layout,
                             read_scenario, resolve_layout)
from vp_scene.plants import PlantModel
from vp_scene.ply import load_models
from vp_scene.procedural import procedural_corn
from vp_scene.scenario import SCENARIOS, Scene, make_scene, place_points

REPO = Path(__file__).resolve().parents[3]
EXAMPLES = REPO / "examples"
CORN50 = REPO.parent / "shared" / "data" / "corn50"


def _toy_models() -> list[PlantModel]:
    out = []
    for k in range(3):
        rng = np.random.default_rng(k)
        pts = np.stack([0.05 * rng.normal(size=400), 0.05 * rng.normal(size=400), rng.uniform(-1, 1, 400)], 1)
        out.append(PlantModel(f"toy{k}", pts, np.full((400, 3), 40 * k, np.uint8)))
    return out


def _write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _key(scene: Scene) -> list:
    return [(p.model_name, p.yaw, p.scale, tuple(p.position)) for p in scene.plants]


# ------------------------------------------------------------------ the old scenes, unchanged

def _digest(scene: Scene) -> str:
    """sha256 of a scene: points rounded to nanometres (BLAS and libm may differ in the last bit
    between machines; a shifted random stream moves points by centimetres), colours, plant
    indices, and each plant's model index, yaw, scale, position (exact bytes) and model name."""
    h = hashlib.sha256()
    h.update(np.round(scene.points * 1e9).astype(np.int64).tobytes())
    h.update(scene.colors.tobytes())
    h.update(scene.plant_index.tobytes())
    for p in scene.plants:
        h.update(np.array([p.model_index, p.yaw, p.scale, *p.position], dtype=np.float64).tobytes())
        h.update(p.model_name.encode())
    return h.hexdigest()[:16]


#: Computed with the code before layouts existed (commit 4df84e0): (scenario, models, seed,
#: points_per_plant, plant_spacing, row_spacing, digest). Results and cached benchmark plans
#: depend on these scenes.
OLD_SCENES = [
    ("one_plant", None, 0, 300, 0.6, 0.76, "20c46a220952837e"),
    ("one_plant", "corn50", 0, 500, 0.6, 0.76, "b856e779e7a3b7fb"),
    ("one_plant", None, 1, 300, 0.6, 0.76, "fa3a940c5d4c30ed"),
    ("one_plant", "corn50", 1, 500, 0.6, 0.76, "e14e83b880c4a19d"),
    ("one_plant", None, 7, 300, 0.6, 0.76, "8ef480f8786846d2"),
    ("one_plant", "corn50", 7, 500, 0.6, 0.76, "ccf4476de8502a3d"),
    ("three_row", None, 0, 300, 0.6, 0.76, "99151ba90e0305a9"),
    ("three_row", "corn50", 0, 500, 0.6, 0.76, "09af5fe8eeb10958"),
    ("three_row", None, 1, 300, 0.6, 0.76, "495637ea07f36150"),
    ("three_row", "corn50", 1, 500, 0.6, 0.76, "c35bd214cb464397"),
    ("three_row", None, 7, 300, 0.6, 0.76, "e5ea65a85c3208e8"),
    ("three_row", "corn50", 7, 500, 0.6, 0.76, "cc37e3a817b88a70"),
    ("six_rect", None, 0, 300, 0.6, 0.76, "8b95c37c3886c4f9"),
    ("six_rect", "corn50", 0, 500, 0.6, 0.76, "f780769eb5314fb9"),
    ("six_rect", None, 1, 300, 0.6, 0.76, "2da18758323a520c"),
    ("six_rect", "corn50", 1, 500, 0.6, 0.76, "7baab2b73c34505a"),
    ("six_rect", None, 7, 300, 0.6, 0.76, "4449b51894f06d74"),
    ("six_rect", "corn50", 7, 500, 0.6, 0.76, "1e1936bc44d6f769"),
    ("six_rect", None, 3, 200, 0.5, 0.8, "66488780f9e1e77d"),
    ("six_rect", "corn50", 3, 200, 0.5, 0.8, "b804468649bb604d"),
]


@pytest.fixture(scope="module")
def corn50() -> list[PlantModel]:
    if not CORN50.is_dir():
        pytest.skip(f"Corn50 data not found at {CORN50} (<repo>/../shared/data/corn50)")
    return load_models(CORN50)


@pytest.mark.parametrize("scenario, models, seed, n, ps, rs, digest", OLD_SCENES)
def test_old_builtin_scenes_unchanged(request, scenario, models, seed, n, ps, rs, digest) -> None:
    loaded = request.getfixturevalue("corn50") if models else None
    scene = make_scene(scenario, models=loaded, seed=seed, points_per_plant=n, plant_spacing=ps, row_spacing=rs)
    assert _digest(scene) == digest
    # the same layout given as a dict (a plan file's form) builds the same scene
    as_dict = resolve_layout(scenario, ps, rs).to_dict()
    assert _digest(make_scene(as_dict, models=loaded, seed=seed, points_per_plant=n)) == digest


# ------------------------------------------------------------------ built-in layouts

def test_builtin_names() -> None:
    assert SCENARIOS == ("one_plant", "three_row", "six_rect", "grid_3x3", "row_12") == tuple(BUILTIN_LAYOUTS)


def test_grid_3x3() -> None:
    lay = resolve_layout("grid_3x3", plant_spacing=0.5, row_spacing=0.8)
    pos = lay.positions()
    assert lay.name == "grid_3x3" and len(lay.plants) == 9 and lay.jitter == 0.0
    ys = np.unique(pos[:, 1].round(9))
    np.testing.assert_allclose(ys, [-0.8, 0.0, 0.8])
    for y in ys:
        np.testing.assert_allclose(np.sort(pos[np.isclose(pos[:, 1], y), 0]), [-0.5, 0.0, 0.5])
    scene = make_scene("grid_3x3", seed=2, points_per_plant=50)
    assert scene.scenario == "grid_3x3" and len(scene.plants) == 9 and scene.points.shape == (450, 3)


def test_row_12() -> None:
    pos = resolve_layout("row_12", plant_spacing=0.4).positions()
    assert pos.shape == (12, 3)
    np.testing.assert_array_equal(pos[:, 1:], 0.0)                       # one line, along x
    np.testing.assert_allclose(np.diff(pos[:, 0]), 0.4)
    assert pos[:, 0].mean() == pytest.approx(0.0, abs=1e-12) and pos[-1, 0] == pytest.approx(2.2)


# ------------------------------------------------------------------ the file format

FIELD_YAML = """\
# comment
name: my_field
grid:
  rows: 2
  columns: 3
  plant_spacing: 0.5
  row_spacing: 0.9
  jitter: 0.1
  scale: 1.5
"""
PLANTS_JSON = {"plants": [{"x": 0, "y": 0}, {"x": 1.0, "y": -0.5, "yaw": 0.5, "scale": 2.0, "model": "toy2"}]}


def test_grid_yaml(tmp_path: Path) -> None:
    lay = load_layout(_write(tmp_path, "f.yaml", FIELD_YAML))
    assert lay.name == "my_field" and len(lay.plants) == 6 and lay.jitter == 0.1
    assert all(p.scale == 1.5 and p.yaw is None and p.model is None for p in lay.plants)
    np.testing.assert_allclose(lay.positions()[:, :2], [[-0.5, -0.45], [0, -0.45], [0.5, -0.45],
                                                        [-0.5, 0.45], [0, 0.45], [0.5, 0.45]])
    assert lay.source.endswith("f.yaml")


def test_grid_json_and_plants_yaml_defaults(tmp_path: Path) -> None:
    lay = load_layout(_write(tmp_path, "g.json", json.dumps({"grid": {"rows": 1, "columns": 2}})))
    assert lay.name == "g" and lay.jitter == 0.0                          # name: the file stem
    np.testing.assert_allclose(lay.positions()[:, :2], [[-0.3, 0.0], [0.3, 0.0]])   # default spacing 0.6
    lay = load_layout(_write(tmp_path, "p.yml", "plants:\n  - {x: 1, y: 2}\n  - {x: 1.5, y: 2, yaw: -1}\n"))
    assert lay.name == "p" and lay.plants == (PlantSpec(1.0, 2.0), PlantSpec(1.5, 2.0, yaw=-1.0))


def test_plants_json_and_round_trip(tmp_path: Path) -> None:
    lay = load_layout(_write(tmp_path, "two.json", json.dumps(PLANTS_JSON)))
    assert lay.plants == (PlantSpec(0.0, 0.0), PlantSpec(1.0, -0.5, yaw=0.5, scale=2.0, model="toy2"))
    d = lay.to_dict()
    assert d == {"name": "two", "plants": [{"x": 0.0, "y": 0.0},
                                           {"x": 1.0, "y": -0.5, "yaw": 0.5, "scale": 2.0, "model": "toy2"}],
                 "jitter": 0.0}
    assert layout_from_dict(json.loads(json.dumps(d)), "plan.json") == lay
    grid = load_layout(_write(tmp_path, "f.yaml", FIELD_YAML))
    assert layout_from_dict(json.loads(json.dumps(grid.to_dict())), "plan.json") == grid


def test_example_files() -> None:
    field = load_layout(EXAMPLES / "field.yaml")
    assert field.name == "small_field" and len(field.plants) == 8 and field.jitter == 0.05
    assert len(np.unique(field.positions()[:, 1].round(9))) == 2
    plants = load_layout(EXAMPLES / "plants.json")
    assert plants.name == "four_plants" and len(plants.plants) == 4
    scene = make_scene(str(EXAMPLES / "plants.json"), seed=0, points_per_plant=50)
    assert scene.scenario == "four_plants" and scene.plants[2].scale == 1.2


# ------------------------------------------------------------------ explicit values, jitter

@pytest.mark.parametrize("procedural", [False, True])
def test_explicit_values_override_without_shifting_the_draws(procedural: bool) -> None:
    models = None if procedural else _toy_models()
    name = "procedural-5" if procedural else "toy1"
    free = Layout("free", (PlantSpec(-1, 0), PlantSpec(0, 0), PlantSpec(1, 0)))
    fixed = Layout("fixed", (PlantSpec(-1, 0), PlantSpec(0, 0, yaw=7.0, scale=2.5, model=name), PlantSpec(1, 0)))
    a = make_scene(free, models=models, seed=4, points_per_plant=60)
    b = make_scene(fixed, models=models, seed=4, points_per_plant=60)
    p = b.plants[1]
    assert p.model_name == name and b.models[p.model_index].name == name
    assert p.yaw == pytest.approx(7.0 - 2 * math.pi) and p.scale == 2.5           # yaw wrapped to [0, 2 pi)
    if procedural:  # that procedural plant, placed as given
        np.testing.assert_array_equal(b.points[b.plant_index == 1],
                                      place_points(procedural_corn(5, n_points=60).points, p))
    else:
        assert (b.colors[b.plant_index == 1] == 40).all()                         # toy1's colour
    assert p.z_range[1] > 2.5 * 1.9                                               # 2.5 x a ~2 m plant
    for i in (0, 2):                                                              # the others unchanged
        assert _key(a)[i] == _key(b)[i]
        np.testing.assert_array_equal(a.points[a.plant_index == i], b.points[b.plant_index == i])


def test_jitter_bounded_seeded_and_separate() -> None:
    lay = resolve_layout({"grid": {"rows": 3, "columns": 4, "jitter": 0.2}})
    nominal = lay.positions()
    a = make_scene(lay, seed=1, points_per_plant=20)
    shift = np.array([p.position for p in a.plants]) - nominal
    assert np.abs(shift[:, :2]).max() <= 0.2 and np.abs(shift[:, :2]).max() > 0.1 and (shift[:, 2] == 0).all()
    assert len({round(float(s), 9) for s in shift[:, 0]}) == 12                # each plant its own
    again = make_scene(lay, seed=1, points_per_plant=20)
    np.testing.assert_array_equal(a.points, again.points)
    other = make_scene(lay, seed=2, points_per_plant=20)
    assert not np.allclose([p.position for p in a.plants], [p.position for p in other.plants])
    still = make_scene(Layout("still", lay.plants), seed=1, points_per_plant=20)  # its own stream:
    assert [(p.yaw, p.scale, p.model_name) for p in a.plants] == [(p.yaw, p.scale, p.model_name)
                                                                  for p in still.plants]


@pytest.mark.parametrize("procedural", [True, False])
def test_rebuilt_from_placements_is_identical(procedural: bool) -> None:
    models = None if procedural else _toy_models()
    kw = dict(seed=5, points_per_plant=80)
    scene = make_scene(str(EXAMPLES / "field.yaml"), models=models, **kw)
    lay = Layout.from_placements("small_field", [(p.model_name, p.yaw, p.scale, p.position[0], p.position[1])
                                                 for p in scene.plants], source="/scene/description")
    again = make_scene(lay, models=models, **kw)
    assert again.points.tobytes() == scene.points.tobytes() and again.colors.tobytes() == scene.colors.tobytes()
    assert _key(again) == _key(scene) and again.scenario == "small_field"


# ------------------------------------------------------------------ errors: one line, file and field

BAD_FILES = [
    ("field.yaml", "grid: {rows: three, columns: 2}", "field.yaml: grid.rows must be an integer >= 1, got 'three'"),
    ("field.yaml", "plants:\n- {x: 0, y: 0}\n- {x: 1, y: 0}\n- {x: null, y: 1}",
     "field.yaml: plants[2].x must be a number (metres), got None"),
    ("field.yaml", "grid: {rows: 2, columns: 2, rowz: 3}",
     "field.yaml: unknown key 'rowz' in grid (expected rows, columns, plant_spacing, row_spacing, jitter, yaw, "
     "scale, model)"),
    ("field.yaml", "name: a\ngrid:\n  rows: [1\n", "field.yaml is not valid YAML (line 4, column 1"),
    ("field.yaml", "plants:\n- {x: 0, y: 0}\n- {x: 1, y: 0}\n- {x: 2, y: 0}\n- {x: 0.02, y: 0}",
     "field.yaml: plants[0] and plants[3] are 0.02 m apart (plants must be at least 0.1 m apart)"),
    ("field.json", '{"grid": {"rows": 2,, }}',
     "field.json is not valid JSON (line 1, column 21: Expecting property name"),
    ("field.json", '{"plants": [{"x": 0, "y": 0, "scale": 5}]}',
     "field.json: plants[0].scale must be a number in (0, 3], got 5"),
    ("field.json", '{"plants": [{"x": 0, "y": 0, "yaw": "north"}]}',
     "field.json: plants[0].yaw must be a number (rad), got 'north'"),
    ("field.json", '{"plants": [{"x": 0, "y": 0, "model": 12}]}',
     "field.json: plants[0].model must be a model name"),
    ("field.json", '{"plants": [{"x": 0, "y": 0}, {"x": 1, "z": 0}]}',
     "field.json: unknown key 'z' in plants[1] (expected x, y, yaw, scale, model)"),
    ("field.json", '{"plants": [{"x": 0}]}', "field.json: plants[0].y is required"),
    ("field.json", '{"plants": []}', "field.json: plants must hold at least one plant"),
    ("field.json", '{"plants": {"x": 0}}', "field.json: plants must be a list"),
    ("field.json", '{"plants": [{"x": 0, "y": 0}], "grid": {"rows": 1, "columns": 1}}',
     "field.json: the layout needs exactly one of 'plants'"),
    ("field.json", '{"name": "x"}', "field.json: the layout needs exactly one of 'plants'"),
    ("field.json", '{"name": 3, "grid": {"rows": 1, "columns": 1}}', "field.json: name must be a non-empty"),
    ("field.json", '{"grid": {"rows": 1, "columns": 1}, "size": 3}',
     "field.json: unknown key 'size' (expected name, plants, grid, jitter)"),
    ("field.json", '[1, 2]', "field.json: the layout must be a mapping"),
    ("field.yaml", "", "field.yaml: the layout must be a mapping"),
    ("field.yaml", "grid: {rows: 20, columns: 11}", "field.yaml: grid gives 220 plants; a layout has at most 200"),
    ("field.yaml", "grid: {rows: 2, columns: 2, jitter: 0.3}",
     "field.yaml: grid.jitter must be less than half the smaller spacing (0.3 m), got 0.3"),
    ("field.yaml", "grid: {rows: 2, columns: 2, jitter: -0.1}", "field.yaml: grid.jitter must be a number >= 0"),
    ("field.yaml", "grid: {rows: 2, columns: 2, plant_spacing: 0.05}",
     "field.yaml: grid.plant_spacing must be a number >= 0.1 (metres), got 0.05"),
    ("field.yaml", "grid: {rows: 2}", "field.yaml: grid.columns is required"),
    ("field.yaml", "grid: {rows: 1, columns: 1}\njitter: 0.1", "field.yaml: jitter: with a grid, give the jitter"),
    ("field.yaml", "plants: [{x: 0, y: 0}, {x: 1, y: 0}]\njitter: 0.6",
     "field.yaml: jitter must be less than half the smallest distance between two plants (0.5 m), got 0.6"),
    ("field.yaml", "plants: [{x: .inf, y: 0}]", "field.yaml: plants[0].x must be a number (metres), got inf"),
    # a plant at x = 1e9 was planned (reward 0, cameras 1e9 m up)
    ("field.yaml", "plants: [{x: 0, y: 0}, {x: 1000000000, y: 0}]",
     "field.yaml: plant 1 stands at x = 1e+09, y = 0 m, outside the field's extent of +-100 m"),
    ("field.yaml", "plants: [{x: 0, y: -100.5}]", "field.yaml: plant 0 stands at x = 0, y = -100.5 m, outside"),
    ("field.yaml", "grid: {rows: 1, columns: 10, plant_spacing: 25}",
     "field.yaml: plant 0 stands at x = -112.5, y = 0 m, outside the field's extent"),
    # a key given twice was taken, the last one silently winning
    ("field.yaml", "grid:\n  rows: 1\n  columns: 2\ngrid:\n  rows: 3\n  columns: 3\n",
     "field.yaml is not valid YAML (line 4, column 1: duplicate key 'grid' (first on line 1;"),
    ("field.yaml", "plants:\n  - x: 0\n    y: 0\n    x: 1\n", "field.yaml is not valid YAML (line 4, column 5: "
     "duplicate key 'x' (first on line 2;"),
    ("field.yaml", "plants: [{x: 0, x: 1, y: 0}]", "(line 1, column 17: duplicate key 'x' (first on line 1;"),
    ("field.json", '{"grid": {"rows": 1, "columns": 2},\n "grid": {"rows": 3, "columns": 3}}',
     "field.json is not valid JSON (line 2, column 8: duplicate key 'grid'"),
    ("field.json", '{"plants": [{"x": 0, "y": 0,\n  "x": 1}]}', "(line 2, column 6: duplicate key 'x'"),
]


@pytest.mark.parametrize("name, text, message", BAD_FILES)
def test_bad_file_is_one_line_naming_file_and_field(tmp_path: Path, name: str, text: str, message: str) -> None:
    path = _write(tmp_path, name, text)
    with pytest.raises(LayoutError) as err:
        load_layout(path)
    text = str(err.value)
    assert "\n" not in text and text.startswith(str(path)), text
    assert message in text.replace(str(tmp_path) + "/", ""), text


def test_extent_is_checked_for_every_kind_of_layout() -> None:
    """One extent check for files, built-in layouts and rebuilt placements."""
    from vp_scene.layout import MAX_EXTENT, builtin_layout

    assert MAX_EXTENT == 100.0
    with pytest.raises(LayoutError, match="^built-in layout 'row_12': plant 0 stands at x = -6.05e"):
        builtin_layout("row_12", plant_spacing=1.1e8)
    with pytest.raises(LayoutError, match="^scene: plant 1 stands at x = 3, y = 250 m"):
        Layout.from_placements("f", [("a", 0.0, 1.0, 0.0, 0.0), ("a", 0.0, 1.0, 3.0, 250.0)], source="scene")
    edge = Layout.from_placements("f", [("a", 0.0, 1.0, 100.0, -100.0)])
    assert edge.positions()[0, 0] == 100.0


def test_missing_and_unknown(tmp_path: Path) -> None:
    with pytest.raises(LayoutError, match="^layout file not found: .*field.yaml$"):
        load_layout(tmp_path / "field.yaml")
    with pytest.raises(LayoutError, match="layout file not found"):
        resolve_layout(str(tmp_path / "field.yml"))
    with pytest.raises(LayoutError, match="unknown scenario 'field.txt'; expected one of one_plant, .*row_12"):
        resolve_layout("field.txt")
    with pytest.raises(LayoutError, match="plant_spacing must be > 0"):
        resolve_layout(str(EXAMPLES / "field.yaml"), plant_spacing=0.0)


def test_command_line_scenario_is_a_name_or_a_file_read_at_once(tmp_path: Path) -> None:
    assert read_scenario("row_12") is None
    assert read_scenario(str(EXAMPLES / "field.yaml")) == load_layout(EXAMPLES / "field.yaml")
    with pytest.raises(LayoutError, match=r"^'nine_square' is neither a layout name \(one_plant, .*row_12\) "
                                          r"nor a layout file \(.yaml, .yml, .json\)$"):
        read_scenario("nine_square")
    with pytest.raises(LayoutError, match="^layout file not found: .*field.json$"):
        read_scenario(str(tmp_path / "field.json"))


def test_a_huge_layout_file_is_refused_before_it_is_parsed(tmp_path: Path, monkeypatch) -> None:
    """A YAML layout of 100,000 plants (2.4 MB) was parsed whole (18 s,
    640 MB) before its plant count was refused. A file over MAX_LAYOUT_BYTES is refused unparsed,
    in one line naming it; a layout of MAX_PLANTS plants with every key and a comment a plant is
    well under the cap."""
    import yaml

    huge = tmp_path / "huge.yaml"
    huge.write_text("plants:\n" + "".join(f"  - {{x: {0.2 * i:.1f}, y: 0.0}}\n" for i in range(100_000)))
    with monkeypatch.context() as tripwire:
        tripwire.setattr(yaml, "safe_load", lambda *a, **k: pytest.fail("the file was parsed"))
        tripwire.setattr(json, "loads", lambda *a, **k: pytest.fail("the file was parsed"))
        for path in (huge, tmp_path / "huge.json"):
            huge.rename(path)
            with pytest.raises(LayoutError) as err:
                load_layout(path)
            assert str(err.value) == f"{path}: larger than 256 KiB; a layout file of at most 200 plants is smaller"
    from vp_scene.layout import MAX_LAYOUT_BYTES, MAX_PLANTS

    assert MAX_LAYOUT_BYTES == 256 * 1024
    full = tmp_path / "full.yaml"
    full.write_text("# " + "a long comment " * 20 + "\nname: full\nplants:\n" + "".join(
        f"  # plant {i}: row {i // 20}, column {i % 20}, a model of its own, turned and scaled\n"
        f"  - {{x: {0.5 * (i % 20) - 4.75:.6f}, y: {0.8 * (i // 20) - 3.6:.6f}, yaw: 1.570796, scale: 1.05, "
        f"model: procedural-{1000 + i}}}\n" for i in range(MAX_PLANTS)))
    assert full.stat().st_size < MAX_LAYOUT_BYTES / 8
    assert len(load_layout(full).plants) == MAX_PLANTS


def test_dict_errors_name_the_given_source() -> None:
    with pytest.raises(LayoutError) as err:
        layout_from_dict({"plants": [{"x": 0, "y": None}]}, "out/plan.json", field_prefix="scene.scenario.")
    assert str(err.value) == "out/plan.json: scene.scenario.plants[0].y must be a number (metres), got None"


def test_model_names_are_checked_when_built(tmp_path: Path) -> None:
    path = _write(tmp_path, "m.yaml", "plants:\n- {x: 0, y: 0}\n- {x: 1, y: 0, model: corn7}\n")
    with pytest.raises(LayoutError) as err:
        make_scene(str(path), models=_toy_models(), points_per_plant=10)
    assert str(err.value) == f"{path}: plants[1].model 'corn7' is not one of the models (toy0, toy1, toy2)"
    with pytest.raises(LayoutError) as err:
        make_scene(str(path), points_per_plant=10)
    assert str(err.value).startswith(f"{path}: plants[1].model 'corn7' needs a models folder")


def test_bad_layout_fails_before_the_models_are_read(tmp_path: Path) -> None:
    bad = _write(tmp_path, "bad.yaml", "grid: {rows: 0, columns: 2}")
    with pytest.raises(LayoutError, match="grid.rows must be an integer >= 1, got 0"):
        build_noisy_scene(str(bad), models=tmp_path / "no_such_models_folder")


def count_layout_resolutions(monkeypatch) -> list:
    """Every module's ``resolve_layout`` counted in the returned list (one entry a call)."""
    import sys

    from vp_scene import layout as layout_module

    calls: list = []
    real = layout_module.resolve_layout

    def counted(*args, **kwargs):
        calls.append(args[0])
        return real(*args, **kwargs)

    for name in ("vp_scene.layout", "vp_scene.scenario", "vp_scene.build", "vp_planner.cli"):
        if name in sys.modules:
            monkeypatch.setattr(sys.modules[name], "resolve_layout", counted, raising=False)
    return calls


def test_a_scene_build_resolves_its_layout_once(tmp_path: Path, monkeypatch) -> None:
    """build.py and scenario.py each resolved the layout; make_scene is the
    one place now, and a models folder is read after the layout is checked."""
    path = _write(tmp_path, "two.yaml", "plants:\n- {x: 0, y: 0}\n- {x: 1, y: 0}\n")
    calls = count_layout_resolutions(monkeypatch)
    noisy, models = build_noisy_scene(str(path), models="", points_per_plant=20, realizations=2)
    assert calls == [str(path)] and noisy.scene.scenario == "two" and len(models) == 2
    with pytest.raises(ValueError, match="no_such_models_folder"):
        make_scene("one_plant", models=str(tmp_path / "no_such_models_folder"), points_per_plant=10)


def test_from_placements_checks_values() -> None:
    with pytest.raises(LayoutError, match=r"^/scene/description: plants\[1\]\.scale must be a number in \(0, 3\]"):
        Layout.from_placements("s", [("a", 0.0, 1.0, 0.0, 0.0), ("b", 0.0, -1.0, 1.0, 0.0)], "/scene/description")
    with pytest.raises(LayoutError, match="plants must hold at least one plant"):
        Layout.from_placements("s", [], "/scene/description")
