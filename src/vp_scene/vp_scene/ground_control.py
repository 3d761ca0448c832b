"""Ground control points: markers of known position on the soil (one home).

Photogrammetry places a model in the world from two kinds of known things: the poses the
aircraft reports (RTK: about 2 cm and half a degree) and ground control points (GCPs), marks
on the ground whose positions were surveyed (an RTK rover on a tripod, a total station: about
1 cm or better). The poses alone place a small plan badly: the model's scale comes from the
spread of a few camera centres, each 2 cm off, and is then carried to the plant two metres away
(a 4-camera arc 0.5 m wide: the scale percents off, the plant centimetres off in ``map``).
Markers around the plant, surveyed to a centimetre, hold
the scale and the position where the plant is.

Here:

* :class:`GroundControl`: named control points and their surveyed positions (m, ``map``), and
  their survey sigma (m, per axis): what a user knows of a field, read from a flight folder's
  ``markers.csv`` (ArUco markers, found in the images by :mod:`vp_recon.gcp`) or, with the
  points' image observations, from OpenDroneMap's ``gcp_list.txt`` (:func:`read_gcp_list`);
* :func:`marker_layout`: where the simulated capture (:class:`vp_scene.capture.CaptureModel`
  ``gcp_markers``) lays its markers: evenly on the rectangle around the plants, a margin out;
* :func:`marker_image`: the printed marker (OpenCV's ArUco dictionary :data:`ARUCO_DICTIONARY`,
  marker id = the control point's name, with a white quiet zone).

ROS-free: numpy, OpenCV for the marker images.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .camera import check_coordinates

__all__ = ["ARUCO_DICTIONARY", "MAX_MARKERS", "MARKER_MARGIN", "GroundControl", "GcpObservation", "GroundControlError",
           "marker_layout", "marker_image", "read_markers_csv", "read_gcp_list", "write_markers_csv",
           "write_gcp_list"]

#: The ArUco dictionary of the markers (OpenCV ``cv2.aruco.DICT_4X4_50``: 50 markers of 4 x 4
#: bits, the most robust to blur and small size of OpenCV's dictionaries).
ARUCO_DICTIONARY = "DICT_4X4_50"
#: The most markers a capture lays out (the dictionary's size).
MAX_MARKERS = 50
#: m between the plants' x-y box and the rectangle the markers lie on (clear of the leaves).
MARKER_MARGIN = 0.35


class GroundControlError(ValueError):
    """A control file that cannot be read or holds bad values (the message names it)."""


@dataclass(frozen=True)
class GcpObservation:
    """Control point ``name`` seen at pixel (u, v) (OpenCV convention: the centre of the top-left
    pixel is (0, 0)) in image ``image`` (its file name)."""

    name: str
    image: str
    u: float
    v: float


@dataclass(frozen=True)
class GroundControl:
    """Control points: ``positions`` {name: (x, y, z) m in ``map``}, surveyed to ``sigma`` m per
    axis; ``observations`` where they were seen (given by the user: ``gcp_list.txt``; empty: find
    ArUco markers named by their id in the images, :mod:`vp_recon.gcp`)."""

    positions: dict
    sigma: float = 0.01
    observations: tuple = field(default_factory=tuple)

    def __post_init__(self) -> None:
        if not (isinstance(self.sigma, (int, float)) and math.isfinite(self.sigma) and self.sigma > 0):
            raise GroundControlError(f"the control points' survey sigma must be > 0 m, got {self.sigma!r}")
        for name, p in self.positions.items():
            p = np.asarray(p, dtype=np.float64)
            if p.shape != (3,) or not np.all(np.isfinite(p)):
                raise GroundControlError(f"control point {name!r} needs a finite (x, y, z), got {p.tolist()}")
            _in_map(p, f"control point {name!r}")


def _in_map(xyz: ArrayLike, what: str, note: str = "") -> tuple:
    """``xyz`` as a tuple when within :data:`vp_scene.camera.MAX_COORDINATE`, else
    GroundControlError naming ``what`` (and ``note``)."""
    try:
        return tuple(float(v) for v in check_coordinates(xyz, what))
    except ValueError as exc:
        raise GroundControlError(f"{exc}{note}") from None


def marker_layout(points: ArrayLike, count: int, margin: Optional[float] = None) -> NDArray[np.float64]:
    """``count`` marker centres (count, 3) on the ground (z = 0) around ``points`` (the plants,
    (..., 3), m), on the rectangle of their x-y box grown by ``margin`` m: its corners first
    (diagonal ones first: 2 markers span the plot), then any more evenly spaced along its edges. A
    surveyor lays markers where no plant hides them, as far apart as the plot allows."""
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or not 0 <= count <= MAX_MARKERS:
        raise ValueError(f"count must be an integer in [0, {MAX_MARKERS}], got {count!r}")
    margin = MARKER_MARGIN if margin is None else margin
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    lo, hi = p[:, :2].min(axis=0) - margin, p[:, :2].max(axis=0) + margin
    corners = [(lo[0], lo[1]), (hi[0], hi[1]), (hi[0], lo[1]), (lo[0], hi[1])]
    xy = corners[:count]
    w, h = hi - lo
    perimeter = 2.0 * (w + h)
    rest = int(count) - len(xy)
    for i in range(rest):
        s = perimeter * (i + 0.5) / rest
        for (x0, y0), (dx, dy), length in ((corners[0], (1, 0), w), (corners[2], (0, 1), h),
                                           (corners[1], (-1, 0), w), (corners[3], (0, -1), h)):
            if s <= length + 1e-12:
                xy.append((x0 + dx * s, y0 + dy * s))
                break
            s -= length
    out = np.zeros((int(count), 3))
    if count:
        out[:, :2] = np.asarray(xy, dtype=np.float64)
    return out


def marker_image(marker_id: int, pixels: int = 240, border: float = 0.25) -> NDArray[np.uint8]:
    """The printed marker ``marker_id`` of :data:`ARUCO_DICTIONARY`: ``pixels`` square, grey
    uint8, the black code square in the middle of a white quiet zone ``border`` of the side wide on
    each side (the code square is (1 - 2 border) of the print)."""
    import cv2

    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, ARUCO_DICTIONARY))
    inner = int(round(pixels * (1.0 - 2.0 * border)))
    code = cv2.aruco.generateImageMarker(dictionary, int(marker_id), inner)
    out = np.full((pixels, pixels), 255, np.uint8)
    o = (pixels - inner) // 2
    out[o:o + inner, o:o + inner] = code
    return out


def _number(text: str, what: str, where: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise GroundControlError(f"{where}: {what} is not a number: {text!r}") from None
    if not math.isfinite(x):
        raise GroundControlError(f"{where}: {what} is not finite: {text!r}")
    return x


def read_markers_csv(path: Union[str, Path], sigma: float = 0.01) -> GroundControl:
    """ArUco ground markers of a flight folder: ``markers.csv`` with a header ``id,x,y,z`` (the
    marker's id in :data:`ARUCO_DICTIONARY`, its centre in ``map``, metres; optional column
    ``sigma``: the survey sigma, m, the same for all). GroundControlError naming the line."""
    path = Path(path)
    try:
        lines = [ln.strip() for ln in path.read_text(encoding="utf-8-sig").splitlines()
                 if ln.strip() and not ln.startswith("#")]
    except (OSError, UnicodeDecodeError) as exc:
        raise GroundControlError(f"{path}: cannot read: {exc}") from None
    if not lines:
        raise GroundControlError(f"{path}: empty (a header id,x,y,z and one line a marker)")
    head = [c.strip().lower() for c in lines[0].split(",")]
    if not {"id", "x", "y", "z"} <= set(head):
        raise GroundControlError(f"{path}: the header must name id, x, y, z, got {lines[0]!r}")
    positions, sigmas = {}, set()
    for n, ln in enumerate(lines[1:], start=2):
        cells = [c.strip() for c in ln.split(",")]
        if len(cells) != len(head):
            raise GroundControlError(f"{path}, line {n}: {len(cells)} values for {len(head)} columns")
        row = dict(zip(head, cells))
        where = f"{path}, line {n}"
        try:
            mid = int(row["id"])
        except ValueError:
            raise GroundControlError(f"{where}: id must be an integer marker id, got {row['id']!r}") from None
        if not 0 <= mid < MAX_MARKERS:
            raise GroundControlError(f"{where}: marker id {mid} is not in {ARUCO_DICTIONARY} (0-{MAX_MARKERS - 1})")
        if str(mid) in positions:
            raise GroundControlError(f"{where}: marker {mid} is listed twice")
        positions[str(mid)] = _in_map([_number(row[a], a, where) for a in "xyz"], f"{where}: marker {mid}",
                                      " (markers.csv is in the poses' frame)")
        if "sigma" in row:
            sigmas.add(_number(row["sigma"], "sigma", where))
    if len(sigmas) > 1:
        raise GroundControlError(f"{path}: one survey sigma for all markers, got {sorted(sigmas)}")
    return GroundControl(positions=positions, sigma=sigmas.pop() if sigmas else sigma)


def write_markers_csv(control: GroundControl, path: Union[str, Path]) -> Path:
    """:func:`read_markers_csv`'s file of ``control`` (names are marker ids)."""
    path = Path(path)
    rows = ["id,x,y,z,sigma"] + [f"{name},{x!r},{y!r},{z!r},{control.sigma!r}"
                                 for name, (x, y, z) in sorted(control.positions.items(), key=lambda kv: int(kv[0]))]
    path.write_text("\n".join(rows) + "\n")
    return path


def read_gcp_list(path: Union[str, Path], sigma: float = 0.01) -> GroundControl:
    """OpenDroneMap's ``gcp_list.txt``: a first line naming the coordinate system, then one line
    per observation ``geo_x geo_y geo_z im_x im_y image_name [gcp_name]`` (whitespace separated;
    pixels from the image's top-left corner). The coordinates must be the flight's own (the
    frame of its poses, metres): the first line is kept as a note, not converted (a projected
    CRS such as UTM, with poses.csv in the same CRS less an offset, is the user's to align); a
    point beyond :data:`vp_scene.camera.MAX_COORDINATE` (UTM's 500 km) is refused, naming that.
    Points without a name are named by their coordinates. GroundControlError naming the line."""
    path = Path(path)
    try:
        lines = [ln.strip() for ln in path.read_text(encoding="utf-8-sig").splitlines()]
    except (OSError, UnicodeDecodeError) as exc:
        raise GroundControlError(f"{path}: cannot read: {exc}") from None
    body = [(n, ln) for n, ln in enumerate(lines[1:], start=2) if ln and not ln.startswith("#")]
    if not lines or not body:
        raise GroundControlError(f"{path}: no observation lines (a coordinate-system line, then "
                                 "'geo_x geo_y geo_z im_x im_y image_name [gcp_name]' lines)")
    positions: dict = {}
    observations = []
    for n, ln in body:
        cells = ln.split()
        where = f"{path}, line {n}"
        if len(cells) < 6:
            raise GroundControlError(f"{where}: expected geo_x geo_y geo_z im_x im_y image_name [gcp_name], got {ln!r}")
        xyz = _in_map([_number(c, a, where) for c, a in zip(cells[:3], ("geo_x", "geo_y", "geo_z"))],
                      f"{where}: geo_x, geo_y, geo_z",
                      f" (the poses' frame, metres; the coordinate system {lines[0][:60]!r} is not converted)")
        u, v = (_number(c, a, where) for c, a in zip(cells[3:5], ("im_x", "im_y")))
        name = cells[6] if len(cells) > 6 else "{:.3f}_{:.3f}_{:.3f}".format(*xyz)
        if name in positions and not np.allclose(positions[name], xyz, atol=1e-6):
            raise GroundControlError(f"{where}: control point {name!r} has two positions")
        positions[name] = xyz
        # pixels as given: whether a tool counts from the first pixel's centre or its corner is half
        # a pixel, well under a marker's detection error
        observations.append(GcpObservation(name=name, image=cells[5], u=u, v=v))
    return GroundControl(positions=positions, sigma=sigma, observations=tuple(observations))


def write_gcp_list(control: GroundControl, path: Union[str, Path]) -> Path:
    """:func:`read_gcp_list`'s file of ``control``'s observations, each point named (its first
    line notes the frame: the flight's own, metres; the survey sigma is not part of the format)."""
    path = Path(path)
    rows = ["# the flight's frame (its poses' frame), metres"]
    for o in control.observations:
        x, y, z = control.positions[o.name]
        rows.append(f"{x!r} {y!r} {z!r} {o.u!r} {o.v!r} {o.image} {o.name}")
    path.write_text("\n".join(rows) + "\n")
    return path
