"""Plant models from PLY files (Corn50, or the user's own), checked before use.

A file is checked in two steps: its header here (format, a vertex element with ``x, y, z`` and
colour channels of a type trimesh decodes right, a non-zero count), then its data as trimesh
decodes them (truncation, NaN / infinite coordinates, unreadable colours), then the plant's size
(:func:`check_plant_size`: metres, stalk through the origin). Every refusal is a
:class:`vp_scene.plants.PlantModelError` naming the file and the problem.

ROS-free: numpy and trimesh only.
"""
from __future__ import annotations

import io
import re
from dataclasses import dataclass
from typing import Any
from pathlib import Path

import numpy as np
import trimesh

from .plants import PathLike, PlantModel, PlantModelError

__all__ = ["MAX_MODEL_COORDINATE", "MIN_PLANT_HEIGHT", "check_plant_size", "load_ply", "load_models", "load_points"]

#: A loaded model must look like a plant in the Corn50 model frame (metres, stalk through the
#: origin, about 2 m tall): every coordinate within this many metres of the origin ...
MAX_MODEL_COORDINATE = 10.0
#: ... and a height (z extent) of at least this many metres.
MIN_PLANT_HEIGHT = 0.01

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
#: Colour channel types that trimesh decodes right (it truncates wider integers to their low byte).
_COLOUR_TYPES = ("u1", "f4", "f8")


@dataclass
class _Element:
    name: str
    count: int
    props: list  # [(name, type)] scalar, or (name, ("list", count_type, item_type))


def _parse_header(raw: bytes, path: Path) -> list[_Element]:
    """The elements of a PLY header; PlantModelError naming the problem."""
    if not raw.startswith(b"ply"):
        raise PlantModelError(f"{path}: not a PLY file (it does not start with 'ply')")
    m = re.search(rb"end_header[ \t]*\r?\n", raw[:1 << 20])
    if m is None:
        raise PlantModelError(f"{path}: corrupt or truncated PLY header (no 'end_header' line)")
    try:
        lines = raw[:m.start()].decode("ascii").splitlines()
    except UnicodeDecodeError:
        raise PlantModelError(f"{path}: corrupt PLY header (non-ASCII bytes)") from None
    fmt = ""
    elements: list[_Element] = []
    for lineno, line in enumerate(lines[1:], start=2):
        tok = line.split()
        if not tok or tok[0] in ("comment", "obj_info"):
            continue
        try:
            if tok[0] == "format":
                fmt = tok[1]
                if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
                    raise PlantModelError(f"{path}: unsupported PLY format {fmt!r}")
            elif tok[0] == "element":
                count = int(tok[2])
                if count < 0:
                    raise ValueError
                elements.append(_Element(tok[1], count, []))
            elif tok[0] == "property":
                if not elements:
                    raise ValueError
                if tok[1] == "list":
                    elements[-1].props.append((tok[4], ("list", _PLY_TYPES[tok[2]], _PLY_TYPES[tok[3]])))
                else:
                    elements[-1].props.append((tok[2], _PLY_TYPES[tok[1]]))
            else:
                raise ValueError
        except (IndexError, KeyError, ValueError):
            raise PlantModelError(f"{path}: corrupt PLY header, line {lineno}: {line.strip()!r}") from None
    if not fmt:
        raise PlantModelError(f"{path}: corrupt PLY header (no 'format' line)")
    return elements


def _vertex_element(raw: bytes, path: Path, colour_needed: bool = True) -> _Element:
    """The checked vertex element of a PLY header.

    trimesh decodes the data (:func:`load_ply`); this strict look at the header is what it does
    not do: name the problem (not a PLY, no end_header, a corrupt line, no x/y/z, no colour, no
    vertices), refuse colour channels it would decode wrongly (16- and 32-bit integers lose all
    but their low byte) and give the declared vertex count (trimesh reads fewer ASCII rows than
    declared without a word).
    """
    elements = _parse_header(raw, path)
    vertex = next((e for e in elements if e.name == "vertex"), None)
    if vertex is None:
        raise PlantModelError(f"{path}: the PLY has no 'vertex' element")
    types = dict(vertex.props)
    for axis in ("x", "y", "z"):
        if axis not in types:
            raise PlantModelError(f"{path}: the PLY vertex element has no '{axis}' property")
    colour = ("red", "green", "blue") if colour_needed else tuple(c for c in ("red", "green", "blue") if c in types)
    if not all(c in types for c in colour):
        raise PlantModelError(f"{path}: the PLY has no per-vertex colour (needs red, green, blue properties; "
                              f"has {', '.join(types)})")
    if any(isinstance(t, tuple) for t in types.values()):
        raise PlantModelError(f"{path}: list properties in the vertex element are not supported")
    bad = [f"{c} ({types[c]})" for c in colour if types[c] not in _COLOUR_TYPES]
    if bad:
        raise PlantModelError(f"{path}: colour channels must be uchar, float or double, got {', '.join(bad)}")
    if vertex.count == 0:
        raise PlantModelError(f"{path}: the point cloud is empty (0 vertices)")
    return vertex


def check_plant_size(points: np.ndarray, where: object) -> None:
    """PlantModelError (naming ``where``) unless the points look like a plant in the model frame:
    every coordinate within :data:`MAX_MODEL_COORDINATE` m of the origin and at least
    :data:`MIN_PLANT_HEIGHT` m tall (a file in millimetres, or with absurd coordinates, would
    put cameras kilometres away and fail much later in meshing)."""
    far = float(np.abs(points).max())
    height = float(np.ptp(points[:, 2]))
    if far > MAX_MODEL_COORDINATE or height < MIN_PLANT_HEIGHT:
        lo, hi = points.min(axis=0), points.max(axis=0)
        raise PlantModelError(
            f"{where}: implausible plant size: the points span {np.round(lo, 3).tolist()} to "
            f"{np.round(hi, 3).tolist()} m; a plant model is expected in metres, stalk through the origin, "
            f"within {MAX_MODEL_COORDINATE:g} m of it and at least {MIN_PLANT_HEIGHT:g} m tall")


def _read_vertices(path: PathLike, colour_needed: bool) -> tuple[Any, np.ndarray]:
    """The trimesh object of a PLY file and its (V, 3) finite vertices; PlantModelError naming
    the file and the problem (missing, not a PLY, corrupt, truncated, no vertices, NaN)."""
    path = Path(path)
    if not path.is_file():
        raise PlantModelError(f"{path}: PLY file not found")
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise PlantModelError(f"{path}: cannot read the PLY file ({exc.strerror or exc})") from None
    vertex = _vertex_element(raw, path, colour_needed)
    try:
        loaded = trimesh.load(io.BytesIO(raw), file_type="ply", process=False)
    except Exception as exc:  # noqa: BLE001 - whatever the parser says, name the file
        text = " ".join(str(exc).split())
        if "unexpected length" in text:
            raise PlantModelError(f"{path}: truncated PLY: the data are shorter than the header declares "
                                  f"({vertex.count} vertices)") from None
        raise PlantModelError(f"{path}: corrupt PLY data ({type(exc).__name__}: {text})") from None
    points = np.asarray(getattr(loaded, "vertices", np.zeros((0, 3))), dtype=np.float64)
    if len(points) != vertex.count:
        raise PlantModelError(f"{path}: truncated PLY: the header declares {vertex.count} vertices, "
                              f"the file has {len(points)}")
    bad = int(np.count_nonzero(~np.isfinite(points).all(axis=1)))
    if bad:
        raise PlantModelError(f"{path}: {bad} of {len(points)} points have NaN or infinite coordinates")
    return loaded, points


def load_points(path: PathLike) -> np.ndarray:
    """The (V, 3) points of any PLY point cloud or mesh (a reconstruction: colour optional, any
    size, the file's frame); PlantModelError as :func:`load_ply` for a missing, corrupt,
    truncated or empty file or non-finite coordinates."""
    return _read_vertices(path, False)[1]


def load_ply(path: PathLike) -> PlantModel:
    """Load a coloured PLY point cloud (binary little/big endian or ASCII) as a :class:`PlantModel`.

    The vertex element needs ``x, y, z`` and ``red, green, blue`` (uchar, or float in [0, 1]).
    Other elements (faces) are ignored. The model keeps the file's frame (Corn50: stalk along +z
    through the origin, centroid z = 0), which is checked for a plausible plant size
    (:func:`check_plant_size`). The data are decoded by trimesh; the header is checked here
    first (:func:`_vertex_element` says what trimesh does not check).

    Raises:
        PlantModelError: missing file, not a PLY, corrupt or truncated data, no colour, no
            vertices, NaN / infinite coordinates or an implausible size; the message names the
            file and the problem.
    """
    path = Path(path)
    loaded, points = _read_vertices(path, True)
    if isinstance(loaded, trimesh.Trimesh):
        colors = np.asarray(loaded.visual.vertex_colors)
    else:
        colors = np.asarray(getattr(loaded, "colors", np.zeros((0, 4))))
    if colors.shape[0] != len(points):
        raise PlantModelError(f"{path}: the PLY colours could not be read")
    check_plant_size(points, path)
    return PlantModel(name=path.stem, points=points, colors=colors[:, :3].astype(np.uint8), mesh=None)


def load_models(folder: PathLike) -> list[PlantModel]:
    """Load every ``*.ply`` of a folder (sorted by file name) as plant models.

    Raises:
        PlantModelError: the folder is missing / not a folder, holds no ``.ply`` file, or a file
            cannot be loaded (see :func:`load_ply`).
    """
    folder = Path(folder)
    if not folder.exists():
        raise PlantModelError(f"models folder not found: {folder}")
    if not folder.is_dir():
        raise PlantModelError(f"models folder is not a folder: {folder}")
    files = sorted((p for p in folder.iterdir() if p.is_file() and p.suffix.lower() == ".ply"),
                   key=lambda p: p.name)
    if not files:
        raise PlantModelError(f"models folder has no .ply files: {folder}")
    return [load_ply(p) for p in files]
