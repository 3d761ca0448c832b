"""Scene layouts: where the plants of a scene stand and, optionally, how each one is placed.

A :class:`Layout` is a name, a tuple of :class:`PlantSpec` and a jitter. A spec gives the stalk
position (x, y) on the ground (metres, frame ``map``, REP-103) and, optionally, the plant's yaw
(rad, about +z), scale and model name; what a spec leaves out (None) is drawn at random when the
scene is built (:func:`vp_scene.scenario.make_scene`: yaw ~ U[0, 2 pi), scale ~ U[0.9, 1.1],
model chosen among the loaded ones). ``jitter`` j moves every plant by (dx, dy) ~ U[-j, j]^2
when the scene is built.

Where a layout comes from (:func:`resolve_layout`):

* a built-in name (:data:`BUILTIN_LAYOUTS`): grids centred at the origin, rows along x
  ``plant_spacing`` apart, rows ``row_spacing`` apart along y. ``one_plant`` (1 x 1),
  ``three_row`` (1 x 3), ``six_rect`` (2 x 3) are the scenes of paper Sec. V-A; ``grid_3x3``
  (3 x 3) and ``row_12`` (1 x 12) are larger fields;
* a layout file (.yaml, .yml or .json, :func:`load_layout`) or the same format as a dict
  (:func:`layout_from_dict`; a plan file stores the canonical dict, :meth:`Layout.to_dict`);
* a :class:`Layout` (e.g. :meth:`Layout.from_placements`: a scene's own placements, from which
  the identical scene is rebuilt without the file it came from).

File format (a mapping; unknown keys are errors)::

    name: my_field            # optional string; default: the file stem
    plants:                   # either a list of plants ...
      - {x: 0.0, y: 0.0}                                  # m, required
      - {x: 0.6, y: 0.0, yaw: 1.57, scale: 1.0, model: "12"}
    jitter: 0.0               # optional with plants: m, >= 0, < half the smallest plant distance
    grid:                     # ... or a grid (exactly one of plants and grid)
      rows: 2                 # integer >= 1 (rows along x, stacked along +y)
      columns: 4              # integer >= 1 (plants per row)
      plant_spacing: 0.6      # m along a row (+x), default 0.6
      row_spacing: 0.76       # m between rows (+y), default 0.76
      jitter: 0.05            # m, >= 0, < half the smaller spacing; default 0
      yaw: 0.0                # optional, rad, every plant
      scale: 1.0              # optional, in (0, 3], every plant
      model: "12"             # optional, a model name (PLY stem in the models folder), every plant

The grid's plant (row i, column j), i < rows, j < columns, stands at
x = (j - (columns - 1) / 2) plant_spacing, y = (i - (rows - 1) / 2) row_spacing, row after row.
Limits: a file of at most :data:`MAX_LAYOUT_BYTES` (checked before it is parsed), 1 to
:data:`MAX_PLANTS` plants, at least :data:`MIN_PLANT_DISTANCE` m apart (before
jitter), every plant within :data:`MAX_EXTENT` m of the origin of ``map`` in x and in y (a field
of 200 m x 200 m; beyond, a plan is not a drone sortie), scale in (0, :data:`MAX_SCALE`], no key given twice in one mapping (YAML and
JSON would keep the last silently; :func:`parse_json`, and a YAML loader that refuses them, name
the key and its line). Every error is a :class:`LayoutError` of one line that names the source
(the file) and the field, e.g. ``field.yaml: grid.rows must be an integer >= 1, got 'three'``.

ROS-free: numpy, and PyYAML for .yaml files.
"""
from __future__ import annotations

import functools
import json
import json.decoder
import json.scanner
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, NoReturn, Optional, Union

import numpy as np

from .scene_spec import SCENE

__all__ = ["LayoutError", "PlantSpec", "Layout", "BUILTIN_LAYOUTS", "LAYOUT_SUFFIXES", "MAX_PLANTS", "MAX_LAYOUT_BYTES",
           "MIN_PLANT_DISTANCE", "MAX_SCALE", "MAX_EXTENT", "grid_layout", "builtin_layout", "layout_from_dict",
           "load_layout", "read_scenario", "resolve_layout", "is_layout_file", "parse_json"]

#: Built-in layouts: name -> (rows, columns) of a grid with the caller's plant and row spacing.
BUILTIN_LAYOUTS: dict[str, tuple[int, int]] = {
    "one_plant": (1, 1),
    "three_row": (1, 3),
    "six_rect": (2, 3),
    "grid_3x3": (3, 3),
    "row_12": (1, 12),
}
#: File name endings of layout files.
LAYOUT_SUFFIXES = (".yaml", ".yml", ".json")
#: At most this many plants in a layout.
MAX_PLANTS = 200
#: A layout file is at most this many bytes, checked before it is parsed: PyYAML takes seconds and
#: hundreds of MB on a huge file before its plant count could be refused. MAX_PLANTS plants with
#: every key and a comment each take 30 KiB.
MAX_LAYOUT_BYTES = 256 * 1024
#: m: the plants of a layout file stand at least this far apart (before jitter).
MIN_PLANT_DISTANCE = 0.1
#: Largest scale a spec may give.
MAX_SCALE = 3.0
#: m: every plant stands within this distance of the origin of ``map``, in x and in y.
MAX_EXTENT = 100.0

_TOP_KEYS = ("name", "plants", "grid", "jitter")
_PLANT_KEYS = ("x", "y", "yaw", "scale", "model")
_GRID_KEYS = ("rows", "columns", "plant_spacing", "row_spacing", "jitter", "yaw", "scale", "model")
_GRID_DEFAULTS = {"plant_spacing": SCENE.plant_spacing, "row_spacing": SCENE.row_spacing, "jitter": 0.0}
_TOLERANCE = 1e-9  # m: 0.3 - 0.2 is 0.1 for the distance rule

Scenario = Union[str, dict, "Layout"]


class LayoutError(ValueError):
    """A layout is missing or malformed; the one-line message names the source and the field."""


@dataclass(frozen=True)
class PlantSpec:
    """One plant of a layout: stalk position (m, frame ``map``) and what is not drawn at random.

    Attributes:
        x, y: stalk base on the ground, m.
        yaw: rad about +z, or None (drawn: U[0, 2 pi)).
        scale: in (0, 3], or None (drawn: U[0.9, 1.1]).
        model: a model name (PLY stem, or ``procedural-<seed>`` without a models folder), or
            None (drawn among the models; a procedural plant of its own without them).
    """

    x: float
    y: float
    yaw: Optional[float] = None
    scale: Optional[float] = None
    model: Optional[str] = None

    def to_dict(self) -> dict:
        """{x, y} and yaw / scale / model where set."""
        out: dict[str, Any] = {"x": float(self.x), "y": float(self.y)}
        for key in ("yaw", "scale", "model"):
            value = getattr(self, key)
            if value is not None:
                out[key] = value if key == "model" else float(value)
        return out


@dataclass(frozen=True)
class Layout:
    """A scene layout: its name, its plants (in scene order) and the jitter (m) of every plant.

    ``source`` says where it came from (a file, a plan file's field, a topic); later errors
    (an unknown model name) name it. It takes no part in comparisons.
    """

    name: str
    plants: tuple[PlantSpec, ...]
    jitter: float = 0.0
    source: str = field(default="", compare=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "plants", tuple(self.plants))
        for i, p in enumerate(self.plants):  # the one extent check of every layout
            if not (abs(p.x) <= MAX_EXTENT and abs(p.y) <= MAX_EXTENT):
                _fail(self.where, f"plant {i} stands at x = {p.x:g}, y = {p.y:g} m, outside the field's "
                                  f"extent of +-{MAX_EXTENT:g} m about the origin of map")

    @property
    def where(self) -> str:
        """The source, for error messages."""
        return self.source or f"layout {self.name!r}"

    def positions(self) -> np.ndarray:
        """(n, 3) stalk positions before jitter (z = 0)."""
        return np.array([(p.x, p.y, 0.0) for p in self.plants], dtype=np.float64).reshape(-1, 3)

    def to_dict(self) -> dict:
        """The canonical file form (``name``, ``plants``, ``jitter``): :func:`layout_from_dict`
        reads it back to an equal layout."""
        return {"name": self.name, "plants": [p.to_dict() for p in self.plants], "jitter": float(self.jitter)}

    @classmethod
    def from_placements(cls, name: str, placements: Iterable[tuple], source: str = "placements") -> "Layout":
        """The layout of a built scene: ``placements`` = (model, yaw, scale, x, y) per plant, as
        a scene publishes them (vp_interfaces/PlantPlacement). Every value is explicit and there
        is no jitter, so the scene is rebuilt exactly (same seed, models and points per plant).
        No distance rule: jittered plants may stand closer than :data:`MIN_PLANT_DISTANCE`."""
        specs = []
        for i, item in enumerate(placements):
            f = f"plants[{i}]"
            try:
                model, yaw, scale, x, y = item
            except (TypeError, ValueError):
                _fail(source, f"{f} must be (model, yaw, scale, x, y), got {item!r}")
            specs.append(PlantSpec(x=_number(source, f"{f}.x", x, "metres"),
                                   y=_number(source, f"{f}.y", y, "metres"),
                                   yaw=_number(source, f"{f}.yaw", yaw, "rad"),
                                   scale=_scale(source, f"{f}.scale", scale),
                                   model=_model(source, f"{f}.model", model)))
        _check_count(source, "plants", len(specs))
        return cls(name=_name(source, "name", name), plants=tuple(specs), jitter=0.0, source=source)


# --------------------------------------------------------------------------------------------
# field checks: one line naming the source and the field
# --------------------------------------------------------------------------------------------

def _fail(source: str, message: str) -> NoReturn:
    raise LayoutError(f"{source}: {message}")


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


def _number(source: str, name: str, value: object, unit: str) -> float:
    if not _is_number(value) or not math.isfinite(float(value)):
        _fail(source, f"{name} must be a number ({unit}), got {value!r}")
    return float(value)


def _scale(source: str, name: str, value: object) -> float:
    if not _is_number(value) or not 0.0 < float(value) <= MAX_SCALE:
        _fail(source, f"{name} must be a number in (0, {MAX_SCALE:g}], got {value!r}")
    return float(value)


def _model(source: str, name: str, value: object) -> str:
    if not isinstance(value, str) or not value.strip():
        _fail(source, f"{name} must be a model name (a PLY file stem, a non-empty string), got {value!r}")
    return value


def _name(source: str, name: str, value: object) -> str:
    if not isinstance(value, str) or not value.strip() or "\n" in value:
        _fail(source, f"{name} must be a non-empty one-line string, got {value!r}")
    return value


def _count(source: str, name: str, value: object) -> int:
    if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < 1:
        _fail(source, f"{name} must be an integer >= 1, got {value!r}")
    return int(value)


def _spacing(source: str, name: str, value: object) -> float:
    if not _is_number(value) or not math.isfinite(float(value)) or float(value) < MIN_PLANT_DISTANCE - _TOLERANCE:
        _fail(source, f"{name} must be a number >= {MIN_PLANT_DISTANCE:g} (metres), got {value!r}")
    return float(value)


def _jitter(source: str, name: str, value: object) -> float:
    if not _is_number(value) or not math.isfinite(float(value)) or float(value) < 0.0:
        _fail(source, f"{name} must be a number >= 0 (metres), got {value!r}")
    return float(value)


def _optional(source: str, name: str, mapping: dict, key: str) -> Any:
    """An optional yaw / scale / model of ``mapping``, checked (None when absent)."""
    if key not in mapping:
        return None
    value = mapping[key]
    if key == "yaw":
        return _number(source, name, value, "rad")
    if key == "scale":
        return _scale(source, name, value)
    return _model(source, name, value)


def _mapping(source: str, name: str, value: object, keys: tuple[str, ...]) -> dict:
    """``value`` as a mapping with only ``keys``."""
    if not isinstance(value, dict):
        _fail(source, f"{name} must be a mapping, got {type(value).__name__} {value!r}")
    for key in value:
        if key not in keys:
            where = f" in {name}" if name else ""
            _fail(source, f"unknown key {key!r}{where} (expected {', '.join(keys)})")
    return value


def _check_count(source: str, name: str, n: int) -> None:
    if n < 1:
        _fail(source, f"{name} must hold at least one plant")
    if n > MAX_PLANTS:
        _fail(source, f"{name} gives {n} plants; a layout has at most {MAX_PLANTS}")


def _closest_pair(xy: np.ndarray) -> tuple[int, int, float]:
    """(i, j, distance) of the two closest points of (n, 2) ``xy``, n >= 2, i < j."""
    d = np.linalg.norm(xy[:, None, :] - xy[None, :, :], axis=2)
    d[np.tril_indices(len(xy))] = np.inf
    i, j = np.unravel_index(int(np.argmin(d)), d.shape)
    return int(i), int(j), float(d[i, j])


# --------------------------------------------------------------------------------------------
# construction
# --------------------------------------------------------------------------------------------

def grid_layout(name: str, rows: int, columns: int, plant_spacing: float = SCENE.plant_spacing,
                row_spacing: float = SCENE.row_spacing,
                jitter: float = 0.0, yaw: Optional[float] = None, scale: Optional[float] = None,
                model: Optional[str] = None, source: str = "") -> Layout:
    """A rows x columns grid centred at the origin, row after row (the caller checks the values):
    plant (i, j) at x = (j - (columns - 1) / 2) plant_spacing, y = (i - (rows - 1) / 2) row_spacing."""
    specs = tuple(PlantSpec(x=(j - (columns - 1) / 2) * plant_spacing, y=(i - (rows - 1) / 2) * row_spacing,
                            yaw=yaw, scale=scale, model=model)
                  for i in range(rows) for j in range(columns))
    return Layout(name=name, plants=specs, jitter=jitter, source=source)


def _positive(name: str, value: object) -> float:
    """A spacing of a built-in layout: any number > 0 (ValueError naming it)."""
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise LayoutError(f"{name} must be a number > 0, got {value!r}") from None
    if not math.isfinite(v) or v <= 0:
        raise LayoutError(f"{name} must be > 0, got {value!r}")
    return v


def builtin_layout(name: str, plant_spacing: float = SCENE.plant_spacing,
                   row_spacing: float = SCENE.row_spacing) -> Layout:
    """The built-in layout ``name`` (:data:`BUILTIN_LAYOUTS`) with these spacings (m, > 0)."""
    if name not in BUILTIN_LAYOUTS:
        raise LayoutError(f"unknown scenario {name!r}; expected one of {', '.join(BUILTIN_LAYOUTS)}, "
                          f"or a layout file ({', '.join(LAYOUT_SUFFIXES)})")
    rows, columns = BUILTIN_LAYOUTS[name]
    return grid_layout(name, rows, columns, _positive("plant_spacing", plant_spacing),
                       _positive("row_spacing", row_spacing), source=f"built-in layout {name!r}")


def _parse_grid(source: str, prefix: str, value: object, name: str) -> Layout:
    g = _mapping(source, f"{prefix}grid", value, _GRID_KEYS)
    f = f"{prefix}grid."
    for key in ("rows", "columns"):
        if key not in g:
            _fail(source, f"{f}{key} is required (an integer >= 1)")
    rows, columns = _count(source, f"{f}rows", g["rows"]), _count(source, f"{f}columns", g["columns"])
    _check_count(source, f"{prefix}grid", rows * columns)
    ps = _spacing(source, f"{f}plant_spacing", g.get("plant_spacing", _GRID_DEFAULTS["plant_spacing"]))
    rs = _spacing(source, f"{f}row_spacing", g.get("row_spacing", _GRID_DEFAULTS["row_spacing"]))
    jitter = _jitter(source, f"{f}jitter", g.get("jitter", _GRID_DEFAULTS["jitter"]))
    if jitter >= min(ps, rs) / 2:
        _fail(source, f"{f}jitter must be less than half the smaller spacing ({min(ps, rs) / 2:g} m), got {jitter:g}")
    return grid_layout(name, rows, columns, ps, rs, jitter, yaw=_optional(source, f"{f}yaw", g, "yaw"),
                       scale=_optional(source, f"{f}scale", g, "scale"),
                       model=_optional(source, f"{f}model", g, "model"), source=source)


def _parse_plants(source: str, prefix: str, value: object, jitter: object, name: str) -> Layout:
    if not isinstance(value, list):
        _fail(source, f"{prefix}plants must be a list of mappings with x and y, got {type(value).__name__}")
    _check_count(source, f"{prefix}plants", len(value))
    specs = []
    for i, item in enumerate(value):
        f = f"{prefix}plants[{i}]"
        p = _mapping(source, f, item, _PLANT_KEYS)
        for key in ("x", "y"):
            if key not in p:
                _fail(source, f"{f}.{key} is required (a number, metres)")
        specs.append(PlantSpec(x=_number(source, f"{f}.x", p["x"], "metres"),
                               y=_number(source, f"{f}.y", p["y"], "metres"),
                               yaw=_optional(source, f"{f}.yaw", p, "yaw"),
                               scale=_optional(source, f"{f}.scale", p, "scale"),
                               model=_optional(source, f"{f}.model", p, "model")))
    j = _jitter(source, f"{prefix}jitter", jitter)
    if len(specs) > 1:
        a, b, d = _closest_pair(np.array([(s.x, s.y) for s in specs]))
        if d < MIN_PLANT_DISTANCE - _TOLERANCE:
            _fail(source, f"{prefix}plants[{a}] and {prefix}plants[{b}] are {d:.3g} m apart "
                          f"(plants must be at least {MIN_PLANT_DISTANCE:g} m apart)")
        if j >= d / 2:
            _fail(source, f"{prefix}jitter must be less than half the smallest distance between two plants "
                          f"({d / 2:g} m), got {j:g}")
    return Layout(name=name, plants=tuple(specs), jitter=j, source=source)


def layout_from_dict(data: object, source: str, field_prefix: str = "", default_name: str = "layout") -> Layout:
    """The layout of a mapping in the file format (see the module docstring).

    Args:
        source: names the origin in every error (a file path, a plan file).
        field_prefix: put before every field name (``"scene.scenario."`` in a plan file).
        default_name: the name when the mapping has none (a file's stem).
    """
    where = field_prefix.rstrip(".") or "the layout"
    if not isinstance(data, dict):
        _fail(source, f"{where} must be a mapping with 'plants' or 'grid', got {type(data).__name__}")
    _mapping(source, field_prefix.rstrip("."), data, _TOP_KEYS)
    name = _name(source, f"{field_prefix}name", data["name"]) if "name" in data else default_name
    if ("plants" in data) == ("grid" in data):
        _fail(source, f"{where} needs exactly one of 'plants' (a list of plants) and 'grid' (rows x columns)")
    if "grid" in data:
        if "jitter" in data:
            _fail(source, f"{field_prefix}jitter: with a grid, give the jitter inside it ({field_prefix}grid.jitter)")
        return _parse_grid(source, field_prefix, data["grid"], name)
    return _parse_plants(source, field_prefix, data["plants"], data.get("jitter", 0.0), name)


def is_layout_file(scenario: str) -> bool:
    """Whether a scenario string names a layout file (by its ending), not a built-in layout."""
    return scenario.lower().endswith(LAYOUT_SUFFIXES)


def _unique_object(s_and_end: tuple, strict: bool, scan_once, object_hook, object_pairs_hook, memo=None,
                   _w=json.decoder.WHITESPACE.match):
    """json's object parser, refusing a key given twice (the decoder's ``parse_object``): each
    value's position is recorded as it is scanned, so the duplicate's line is known."""
    starts: list = []

    def value(text: str, at: int):
        starts.append(at)
        return scan_once(text, at)

    pairs, end = json.decoder.JSONObject(s_and_end, strict, value, None, list, memo, _w)
    seen: set = set()
    for (key, _), at in zip(pairs, starts):
        if key in seen:
            text = s_and_end[0]  # the error points at the colon after the key
            raise json.JSONDecodeError(f"duplicate key {key!r} (JSON would keep the last one silently)",
                                       text, max(text.rfind(":", 0, at), 0))
        seen.add(key)
    return dict(pairs), end


@functools.lru_cache(maxsize=None)
def _json_decoder() -> json.JSONDecoder:
    decoder = json.JSONDecoder()
    decoder.parse_object = _unique_object
    decoder.scan_once = json.scanner.py_make_scanner(decoder)  # the pure-Python scanner calls parse_object
    return decoder


class _KeyTwice(Exception):
    """A JSON object gave a key twice (found by the fast parser; the slow one names its line)."""


def _unique_pairs(pairs: list) -> dict:
    out = dict(pairs)
    if len(out) != len(pairs):
        raise _KeyTwice
    return out


def parse_json(text: str, source: str) -> object:
    """``text`` parsed as JSON, a key given twice in one object refused; LayoutError naming
    ``source``, the line and the problem (a layout file's JSON and a plan file's)."""
    try:
        try:
            return json.loads(text, object_pairs_hook=_unique_pairs)
        except _KeyTwice:  # again with the pure-Python parser, which knows where the key is
            return _json_decoder().decode(text)
    except json.JSONDecodeError as exc:
        raise LayoutError(f"{source} is not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})") from None
    except RecursionError:
        raise LayoutError(f"{source} is not valid JSON (nested too deeply)") from None


@functools.lru_cache(maxsize=None)
def _yaml_loader() -> type:
    """PyYAML's SafeLoader refusing a key given twice in one mapping (naming it and both lines)."""
    import yaml

    class UniqueKeyLoader(yaml.SafeLoader):
        pass

    def mapping(loader: yaml.SafeLoader, node: yaml.MappingNode, deep: bool = False) -> dict:
        first: dict = {}
        for key_node, _ in node.value:
            key = loader.construct_object(key_node, deep=True)
            try:
                again = key in first
            except TypeError:
                continue  # an unhashable key: SafeLoader's own error below
            if again:
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {key!r} (first on line {first[key] + 1}; YAML would keep the last "
                    "one silently)", key_node.start_mark)
            first[key] = key_node.start_mark.line
        return loader.construct_mapping(node, deep=deep)

    UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, mapping)
    return UniqueKeyLoader


def _read(path: Path) -> object:
    """The parsed content of a .json or .yaml/.yml file of at most :data:`MAX_LAYOUT_BYTES`
    (LayoutError naming the file; a larger one is refused before it is parsed; a key given twice
    in one mapping is refused, naming it and its line)."""
    try:
        with open(path, "rb") as f:
            data = f.read(MAX_LAYOUT_BYTES + 1)  # no more than that is read, whatever the file
        if len(data) > MAX_LAYOUT_BYTES:
            raise LayoutError(f"{path}: larger than {MAX_LAYOUT_BYTES // 1024} KiB; a layout file of at most "
                              f"{MAX_PLANTS} plants is smaller")
        text = data.decode("utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise LayoutError(f"cannot read layout file {path}: {getattr(exc, 'strerror', None) or exc}") from None
    if path.suffix.lower() == ".json":
        return parse_json(text, str(path))
    import yaml

    try:
        return yaml.load(text, Loader=_yaml_loader())  # noqa: S506 (a SafeLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        problem = " ".join(str(getattr(exc, "problem", None) or exc).split())
        at = f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""
        raise LayoutError(f"{path} is not valid YAML ({at}{problem})") from None


def load_layout(path: Union[str, Path]) -> Layout:
    """Read a layout file (.yaml, .yml or .json); its name defaults to the file stem."""
    p = Path(path)
    if p.suffix.lower() not in LAYOUT_SUFFIXES:
        raise LayoutError(f"{p}: a layout file must end in {', '.join(LAYOUT_SUFFIXES)}")
    if not p.is_file():
        raise LayoutError(f"layout file not found: {p}")
    return layout_from_dict(_read(p), str(p), default_name=p.stem)


def read_scenario(text: str) -> Optional[Layout]:
    """A scenario as a command line gives it: None for a built-in layout name, else the layout
    file it names, read and checked now (LayoutError of one line: the file and the field, or that
    ``text`` is neither a layout name nor a layout file)."""
    if text in BUILTIN_LAYOUTS:
        return None
    if not is_layout_file(text):
        raise LayoutError(f"{text!r} is neither a layout name ({', '.join(BUILTIN_LAYOUTS)}) "
                          f"nor a layout file ({', '.join(LAYOUT_SUFFIXES)})")
    return load_layout(text)


def resolve_layout(scenario: Scenario, plant_spacing: float = SCENE.plant_spacing,
                   row_spacing: float = SCENE.row_spacing, source: str = "scenario") -> Layout:
    """The layout of a scenario: a built-in name (with these spacings), a path to a layout file,
    a dict of the file format (errors name ``source``) or a Layout (returned as it is).
    The spacings are checked (> 0) whatever the scenario, as they always were."""
    _positive("plant_spacing", plant_spacing)
    _positive("row_spacing", row_spacing)
    if isinstance(scenario, Layout):
        return scenario
    if isinstance(scenario, dict):
        return layout_from_dict(scenario, source)
    if isinstance(scenario, (str, Path)) and is_layout_file(str(scenario)):
        return load_layout(scenario)
    if isinstance(scenario, str):
        return builtin_layout(scenario, plant_spacing, row_spacing)
    raise LayoutError(f"{source} must be a layout name, a layout file or a layout mapping, "
                      f"got {type(scenario).__name__}")
