"""The pose files of a flight folder: which camera took each image, from where, in ``map``.

Read by the reconstruction (:func:`vp_recon.flight.read_flight`, with the images) and by the
planner choosing among a folder's views (:func:`read_poses`, no pixel read), so they live in
vp_scene, below both. The folder itself (images, ground control): :mod:`vp_recon.flight` and
the README's "From a real flight".

``DIR/poses.csv`` (first choice), a header line then one row per image::

    image,x,y,z,qx,qy,qz,qw,frame,fx,fy,cx,cy,width,height[,k1,k2,p1,p2,k3]
    view_000.png,1.4,0.0,1.2,0.0,0.12,0.0,0.99,map,1000.0,1000.0,999.5,749.5,2000,1500

* ``image``: the file name in DIR (no folders, unique);
* ``x y z``: the camera centre in ``frame``, metres; ``qx qy qz qw``: the camera's attitude as
  a ``geometry_msgs/Pose`` of the suite (the REP-103 *body* frame: x along the optical axis,
  y left, z up; :mod:`vp_scene.camera`), any attitude (a roll about the optical axis is kept),
  so a drone's reported ``PoseStamped`` goes in as is;
* ``frame``: ``map`` (the suite's frame; anything else is refused);
* ``fx fy cx cy``: pinhole intrinsics in pixels, OpenCV / ``sensor_msgs/CameraInfo`` convention
  (pixel centres at integers: cx = (width - 1) / 2 for a centred principal point);
  ``width height``: the image size, which must match the file;
* optional, after them and in any order, the lens distortion :data:`DISTORTION_COLUMNS` (OpenCV's
  and CameraInfo's ``plumb_bob`` k1, k2, p1, p2, k3; a column left out is 0).

``DIR/cameras.txt`` + ``DIR/images.txt`` (COLMAP's text model, the interchange format of
photogrammetry tools; read when there is no poses.csv): cameras of the models
:data:`COLMAP_MODELS` (COLMAP's pixel convention: centres at +0.5), image poses as COLMAP's
``cam_from_world`` (QW QX QY QZ TX TY TZ, optical frame), in ``map``.

Both are read line by line, a UTF-8 byte-order mark (a spreadsheet's CSV) read as such, at most
:data:`MAX_POSES` images (counted as they are read: the rest of a longer file is not read), every
position and quaternion within :data:`vp_scene.camera.MAX_COORDINATE`. Every problem is a
:class:`FlightError` with one line naming the file. ROS-free: numpy, scipy.
"""
from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from vp_scene.camera import as_poses, body_from_optical, check_coordinates

__all__ = ["POSES_FILE", "MAX_POSES", "POSES_COLUMNS", "DISTORTION_COLUMNS", "COLMAP_MODELS", "OPENCV_COEFFS", "FRAME",
           "FlightError", "FlightCamera", "write_poses_csv", "colmap_camera", "read_pose_files", "read_poses"]

PathLike = Union[str, os.PathLike]

POSES_FILE = "poses.csv"
#: The most images a pose file may list, counted as it is read (a huge file is refused before it is
#: read whole). Its readers take far fewer: the planner chooses among at
#: most 2000 candidate views, a reconstruction reads at most 768 megapixels of images.
MAX_POSES = 10_000
POSES_COLUMNS = ("image", "x", "y", "z", "qx", "qy", "qz", "qw", "frame", "fx", "fy", "cx", "cy", "width", "height")
#: Optional columns of poses.csv after :data:`POSES_COLUMNS`: OpenCV's (and CameraInfo plumb_bob's) distortion.
DISTORTION_COLUMNS = ("k1", "k2", "p1", "p2", "k3")
#: COLMAP camera models read from cameras.txt and their parameters (COLMAP's order; the radial
#: and OpenCV ones are OpenCV's distortion model with some coefficients 0, and undistorted).
COLMAP_MODELS = {"SIMPLE_PINHOLE": ("f", "cx", "cy"), "PINHOLE": ("fx", "fy", "cx", "cy"),
                 "SIMPLE_RADIAL": ("f", "cx", "cy", "k1"), "RADIAL": ("f", "cx", "cy", "k1", "k2"),
                 "OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"),
                 "FULL_OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")}
#: OpenCV's distortion coefficients, in its order, that a camera may have (the rational model's).
OPENCV_COEFFS = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")
#: The one frame of the suite.
FRAME = "map"


class FlightError(ValueError):
    """A flight folder (or capture set) that cannot be reconstructed; the message names the file."""


@dataclass(frozen=True)
class FlightCamera:
    """A flight's camera as read: OpenCV pinhole intrinsics (pixel centres at integers), the image
    size and OpenCV's distortion coefficients :data:`OPENCV_COEFFS` (all 0: a pinhole camera)."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: float
    height: float
    dist: tuple = (0.0,) * len(OPENCV_COEFFS)

    @property
    def K(self) -> NDArray[np.float64]:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def distorted(self) -> bool:
        return any(self.dist)

    def colmap(self, pycolmap: object) -> object:
        """The camera as COLMAP's OPENCV (FULL_OPENCV when k3..k6 are used): OpenCV's model,
        COLMAP's pixel convention (centres at +0.5)."""
        full = any(self.dist[4:])
        return pycolmap.Camera(model="FULL_OPENCV" if full else "OPENCV", width=int(self.width),
                               height=int(self.height), params=[self.fx, self.fy, self.cx + 0.5, self.cy + 0.5, *self.dist[:8 if full else 4]])


def write_poses_csv(path: PathLike, names: Sequence[str], poses: ArrayLike, K: ArrayLike, size: tuple[int, int],
                    distortion: Optional[Sequence[float]] = None) -> None:
    """``poses.csv`` (module docstring) of the images ``names`` taken from ``poses`` (N, 7) (or
    levelled cameras (N, 6)) by one camera: pinhole ``K`` (OpenCV convention) at ``size`` (width,
    height) and, when given, its distortion ``(k1, k2, p1, p2, k3)`` (the optional columns)."""
    P = as_poses(np.asarray(poses, dtype=np.float64).reshape(len(names), -1))
    K = np.asarray(K, dtype=np.float64)
    extra = [] if distortion is None else [repr(float(v)) for v in distortion]
    if len(extra) not in (0, len(DISTORTION_COLUMNS)):
        raise ValueError(f"distortion must be the {len(DISTORTION_COLUMNS)} numbers {DISTORTION_COLUMNS}, "
                         f"got {distortion!r}")
    intr = [repr(float(K[0, 0])), repr(float(K[1, 1])), repr(float(K[0, 2])), repr(float(K[1, 2])),
            str(int(size[0])), str(int(size[1]))]
    with open(path, "w", newline="") as f:
        wr = csv.writer(f)
        wr.writerow(POSES_COLUMNS + (DISTORTION_COLUMNS if extra else ()))
        for name, pose in zip(names, P):
            wr.writerow([name] + [repr(float(v)) for v in pose] + [FRAME] + intr + extra)


def _number(text: str, where: str, what: str) -> float:
    if not text.strip():
        raise FlightError(f"{where}: {what} is empty (missing pose)")
    try:
        v = float(text)
    except (TypeError, ValueError):
        raise FlightError(f"{where}: {what} {text!r} is not a number") from None
    if not math.isfinite(v):
        raise FlightError(f"{where}: {what} is {text} (missing or NaN pose)")
    return v


def _checked_pose(pose: list, what: str) -> list:
    """A pose's numbers (or a centre's), each within :data:`vp_scene.camera.MAX_COORDINATE`."""
    try:
        check_coordinates(pose, what)
    except ValueError as exc:
        raise FlightError(str(exc)) from None
    return pose


def _too_many(path: Path) -> FlightError:
    return FlightError(f"{path}: more than {MAX_POSES} images; a pose file lists at most {MAX_POSES} "
                       "(the rest of the file was not read)")


def _read_poses_csv(path: Path) -> tuple[list, NDArray[np.float64], list]:
    """(names, poses (N, 7), cameras (:class:`FlightCamera`)) of poses.csv, read row by row."""
    names, poses, cams = [], [], []
    seen: set = set()
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:  # -sig: a byte-order mark is not the header's
            reader = csv.reader(f)
            header = [c.strip() for c in next(reader, [])]
            extra = header[len(POSES_COLUMNS):]
            if header[:len(POSES_COLUMNS)] != list(POSES_COLUMNS) or len(set(extra)) != len(extra) \
                    or not set(extra) <= set(DISTORTION_COLUMNS):
                raise FlightError(f"{path}: the first line must be the header {','.join(POSES_COLUMNS)}, then "
                                  f"optionally any of the distortion columns {','.join(DISTORTION_COLUMNS)}; got "
                                  f"{','.join(header)[:300]!r}")
            columns = tuple(header)
            for line, row in enumerate(reader, start=2):
                if not row or not "".join(row).strip():
                    continue
                where = f"{path} line {line}"
                if len(names) == MAX_POSES:
                    raise _too_many(path)
                if len(row) != len(columns):
                    raise FlightError(f"{where}: {len(row)} columns, expected {len(columns)} ({','.join(columns)})")
                row = [c.strip() for c in row]
                name = row[0]
                if not name or Path(name).name != name:
                    raise FlightError(f"{where}: image {name!r} must be a file name in the folder")
                if name in seen:
                    raise FlightError(f"{where}: duplicate image name {name}")
                pose = _checked_pose([_number(v, f"{where} ({name})", c) for v, c in zip(row[1:8], columns[1:8])],
                                     f"{where} ({name}): the pose")
                if row[8] != FRAME:
                    raise FlightError(f"{where} ({name}): frame {row[8]!r}; poses must be in {FRAME!r}")
                k = [_number(v, f"{where} ({name})", c) for v, c in zip(row[9:], columns[9:])]
                if np.linalg.norm(pose[3:]) < 1e-9:
                    raise FlightError(f"{where} ({name}): the quaternion is zero")
                given = dict(zip(columns[15:], k[6:]))
                seen.add(name)
                names.append(name)
                poses.append(pose)
                cams.append(FlightCamera(*k[:6], dist=tuple(given.get(c, 0.0) for c in OPENCV_COEFFS)))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise FlightError(f"{path}: cannot read: {exc}") from None
    return names, np.array(poses, dtype=np.float64).reshape(-1, 7), cams


def colmap_camera(model: str, w: float, h: float, p: list) -> FlightCamera:
    """A COLMAP camera (:data:`COLMAP_MODELS`; centres at +0.5) as OpenCV's."""
    named = dict(zip(COLMAP_MODELS[model], p))
    fx, fy = (named["f"], named["f"]) if "f" in named else (named["fx"], named["fy"])
    return FlightCamera(fx, fy, named["cx"] - 0.5, named["cy"] - 0.5, w, h,
                   dist=tuple(named.get(c, 0.0) for c in OPENCV_COEFFS))


def _text_lines(path: Path):
    """(line number, text) of a COLMAP text file, one at a time (a model's 2D points make long files)."""
    try:
        with open(path, encoding="utf-8-sig", errors="replace") as f:
            yield from enumerate(f, start=1)
    except OSError as exc:
        raise FlightError(f"{path}: cannot read: {exc.strerror or exc}") from None


def _read_colmap_text(folder: Path) -> tuple[list, NDArray[np.float64], list]:
    """(names, poses (N, 7) in the suite's body convention, cameras) of COLMAP's text model."""
    cams: dict = {}
    path = folder / "cameras.txt"
    for line, text in _text_lines(path):
        f = text.split()
        if not f or f[0].startswith("#"):
            continue
        where = f"{path} line {line}"
        if len(cams) == MAX_POSES:
            raise _too_many(path)
        if len(f) < 5 or f[1] not in COLMAP_MODELS:
            raise FlightError(f"{where}: camera model {' '.join(f[1:2])!r} is not read; the models read are "
                              f"{', '.join(COLMAP_MODELS)}")
        w, h = (_number(v, where, "size") for v in f[2:4])
        p = [_number(v, where, "parameter") for v in f[4:]]
        if len(p) != len(COLMAP_MODELS[f[1]]):
            raise FlightError(f"{where}: {f[1]} has {len(COLMAP_MODELS[f[1]])} parameters "
                              f"({' '.join(COLMAP_MODELS[f[1]])}), got {len(p)}")
        cams[f[0]] = colmap_camera(f[1], w, h, p)
    path = folder / "images.txt"
    names, poses, used = [], [], []
    seen: set = set()
    # two lines an image (the second, its 2D points, may be empty)
    for line, text in _text_lines(path):
        f = text.split()
        if len(f) != 10 or not f[0].isdigit() or text.lstrip().startswith("#"):
            continue  # a comment, an empty or a POINTS2D line
        where = f"{path} line {line}"
        name = f[9]
        if len(names) == MAX_POSES:
            raise _too_many(path)
        if Path(name).name != name:
            raise FlightError(f"{where}: image {name!r} must be a file name in the folder")
        if name in seen:
            raise FlightError(f"{where}: duplicate image name {name}")
        qw, qx, qy, qz, tx, ty, tz = _checked_pose([_number(v, f"{where} ({name})", "pose") for v in f[1:8]],
                                                   f"{where} ({name}): the pose")
        if f[8] not in cams:
            raise FlightError(f"{where} ({name}): camera {f[8]} is not in cameras.txt")
        if math.hypot(qw, qx, qy, qz) < 1e-9:
            raise FlightError(f"{where} ({name}): the quaternion is zero")
        R_cw = Rotation.from_quat([qx, qy, qz, qw]).as_matrix()
        c = _checked_pose(list(-R_cw.T @ np.array([tx, ty, tz])), f"{where} ({name}): the camera centre")
        poses.append(np.concatenate([c, body_from_optical(R_cw)]))
        seen.add(name)
        names.append(name)
        used.append(cams[f[8]])
    return names, np.array(poses, dtype=np.float64).reshape(-1, 7), used


def read_pose_files(folder: PathLike) -> tuple[list, NDArray[np.float64], list, Path]:
    """(names, poses (N, 7), cameras (:class:`FlightCamera`, one per image), the file read) of a
    flight folder: poses.csv, else COLMAP's text model (module docstring); FlightError naming the
    file (also when the folder has neither)."""
    d = Path(folder)
    if not d.is_dir():
        raise FlightError(f"{d}: not a folder")
    if (d / POSES_FILE).is_file():
        names, poses, cams = _read_poses_csv(d / POSES_FILE)
        return names, poses, cams, d / POSES_FILE
    if (d / "cameras.txt").is_file() and (d / "images.txt").is_file():
        names, poses, cams = _read_colmap_text(d)
        return names, poses, cams, d / "images.txt"
    raise FlightError(f"{d}: no {POSES_FILE} (or COLMAP cameras.txt + images.txt) with the poses")


def read_poses(folder: PathLike) -> tuple[list, NDArray[np.float64], NDArray[np.float64], tuple[int, int]]:
    """The poses of a flight folder without its images: (names, poses (N, 7) as the suite's
    ``geometry_msgs/Pose`` x y z qx qy qz qw, K, (width, height)), from poses.csv or COLMAP's
    text model (module docstring); FlightError naming the file. A planner choosing among a
    folder's views (:mod:`vp_planner.candidates`) needs no pixel of them."""
    names, poses, cams, source = read_pose_files(folder)
    if not names:
        raise FlightError(f"{source}: no image has a pose")
    cam = cams[0]  # its pinhole part: a distorted camera's views are planned as if undistorted
    return list(names), np.asarray(poses, dtype=np.float64), cam.K, (int(cam.width), int(cam.height))
