"""A capture set (images + the poses the drones reported + one pinhole camera) and its folder.

:class:`CapturedViews` is what a flight hands to the reconstruction
(:func:`vp_recon.pipeline.reconstruct_views`), whether it was rendered from a plan
(:func:`vp_recon.pipeline.render_flight`), read from a flight folder (:func:`read_flight`) or,
later, received from the fleet.

The flight folder (README "From a real flight")
------------------------------------------------
A folder ``DIR`` holds the images (PNG or JPEG, RGB, one camera for all) and a pose file:

``DIR/poses.csv`` (first choice), a header line then one row per image::

    image,x,y,z,qx,qy,qz,qw,frame,fx,fy,cx,cy,width,height
    view_000.png,1.4,0.0,1.2,0.0,0.12,0.0,0.99,map,1000.0,1000.0,999.5,749.5,2000,1500

* ``image``: the file name in DIR (no folders, unique);
* ``x y z``: the camera centre in ``frame``, metres; ``qx qy qz qw``: the camera's attitude as
  a ``geometry_msgs/Pose`` of the suite (the REP-103 *body* frame: x along the optical axis,
  y left, z up; :mod:`vp_scene.camera`), so a drone's reported ``PoseStamped`` goes in as is;
* ``frame``: ``map`` (the suite's frame; anything else is refused);
* ``fx fy cx cy``: pinhole intrinsics in pixels, OpenCV / ``sensor_msgs/CameraInfo`` convention
  (pixel centres at integers: cx = (width - 1) / 2 for a centred principal point), no
  distortion (undistort first); ``width height``: the image size, which must match the file.

``DIR/cameras.txt`` + ``DIR/images.txt`` (COLMAP's text model, the interchange format of
photogrammetry tools; read when there is no poses.csv): cameras of model ``PINHOLE`` or
``SIMPLE_PINHOLE`` (COLMAP's pixel convention: centres at +0.5), image poses as COLMAP's
``cam_from_world`` (QW QX QY QZ TX TY TZ, optical frame), in ``map``.

The suite's cameras have no roll (a gimbal levels them, :mod:`vp_scene.camera`): a pose with
more than :data:`MAX_ROLL_DEG` of roll about its optical axis is refused (a camera looking
straight down has the convention's yaw: its image x axis along world -y).
:func:`write_flight` writes both files (and an empty ``points3D.txt``, so that
COLMAP reads the model), plus ``flight.json`` (what is known of a simulated flight: its wind
realization and capture model). Every problem of a folder is a :class:`FlightError` with one
line naming the file.

Ground control (optional, :mod:`vp_scene.ground_control`): ``DIR/markers.csv`` (``id,x,y,z[,sigma]``:
ArUco markers of OpenCV's ``DICT_4X4_50`` surveyed on the ground, found in the images by
:mod:`vp_recon.gcp`) or OpenDroneMap's ``DIR/gcp_list.txt`` (control points and where they were
seen in which image); both in the poses' frame, metres. The reconstruction is then placed in
``map`` on the control points and the reported poses together (:func:`vp_recon.gcp.register`).

Images are read by :mod:`vp_scene.images` (the header checked before anything is decoded; a
truncated or corrupt image refused). ROS-free: numpy, OpenCV, Pillow, scipy.
"""
from __future__ import annotations

import csv
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional, Sequence, Union

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from vp_scene.ground_control import GroundControl, GroundControlError, read_gcp_list, read_markers_csv, \
    write_markers_csv
from vp_scene.camera import (body_from_optical, cameras_to_poses, poses_to_cameras, principal_point_gl, roll_of,
                             world_to_camera)
from vp_scene.images import ImageError, image_size, read_image

from .pipeline import MAX_MEGAPIXELS

__all__ = ["POSES_FILE", "MARKERS_FILE", "GCP_LIST_FILE", "POSES_COLUMNS", "IMAGE_SUFFIXES", "FRAME", "MAX_ROLL_DEG", "FlightError", "CapturedViews",
           "write_flight", "read_flight", "read_poses", "capture_folder", "locate_flown", "flown_views", "join_views"]

POSES_FILE = "poses.csv"
#: The ground-control files of a flight folder (module docstring).
MARKERS_FILE = "markers.csv"
GCP_LIST_FILE = "gcp_list.txt"
POSES_COLUMNS = ("image", "x", "y", "z", "qx", "qy", "qz", "qw", "frame", "fx", "fy", "cx", "cy", "width", "height")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
#: The one frame of the suite.
FRAME = "map"
#: degrees: a pose with more roll about its optical axis is refused. The suite's cameras are
#: levelled (no roll, :mod:`vp_scene.camera`) and the registration to ``map`` uses the reported
#: attitudes: a roll dropped silently would turn the whole reconstruction by it. A gimbal holds
#: about 0.01 degree; 2 degrees leaves room for a drone's attitude estimate.
MAX_ROLL_DEG = 2.0

PathLike = Union[str, os.PathLike]


class FlightError(ValueError):
    """A flight folder (or capture set) that cannot be reconstructed; the message names the file."""


@dataclass
class CapturedViews:
    """N images of one pinhole camera with the poses the drones reported.

    Attributes:
        names: N unique image file names.
        images: N RGB uint8 (H, W, 3), all of one size.
        reported: (N, 6) reported cameras [c, v] in ``map`` (:mod:`vp_scene.camera`).
        K: 3x3 intrinsics, OpenCV pixel convention.
        masks: N plant masks (H, W) bool, or None: from the images (the reconstruction's choice).
        fov: the horizontal field of view, rad (None: from K).
        realization: the wind realization of a simulated flight (None: unknown, a real one).
        seconds: time it took to make them (mesh, render), when rendered.
        control: ground control points (:class:`vp_scene.ground_control.GroundControl`) of the
            flight, or None.
    """

    names: list
    images: list
    reported: NDArray[np.float64]
    K: NDArray[np.float64]
    masks: Optional[list] = None
    fov: Optional[float] = None
    realization: Optional[int] = None
    seconds: dict = field(default_factory=dict)
    control: Optional[GroundControl] = None

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) of the images."""
        h, w = np.asarray(self.images[0]).shape[:2]
        return int(w), int(h)

    @property
    def horizontal_fov(self) -> float:
        """``fov``, else 2 atan(W / (2 fx))."""
        return float(self.fov) if self.fov is not None else 2.0 * math.atan(0.5 * self.size[0] / float(self.K[0, 0]))

    def validate(self) -> "CapturedViews":
        """FlightError naming the first problem (count, names, sizes, poses); returns self."""
        n = len(self.images)
        if n < 2:
            raise FlightError(f"a reconstruction needs at least 2 images, the capture set has {n}")
        if len(self.names) != n or len(set(self.names)) != n:
            raise FlightError(f"{n} images need {n} unique names, got {list(self.names)}")
        rep = np.asarray(self.reported, dtype=np.float64)
        if rep.shape != (n, 6) or not np.all(np.isfinite(rep)):
            raise FlightError(f"reported poses must be {n} finite [c, v] rows, got shape {rep.shape}")
        size = self.size
        for name, im in zip(self.names, self.images):
            a = np.asarray(im)
            if a.dtype != np.uint8 or a.ndim != 3 or a.shape[2] != 3 or (a.shape[1], a.shape[0]) != size:
                raise FlightError(f"{name}: must be RGB uint8 of {size[0]}x{size[1]}, got {a.dtype} {a.shape}")
        if self.masks is not None and len(self.masks) != n:
            raise FlightError(f"{len(self.masks)} masks for {n} images")
        if self.control is not None:
            unknown = sorted({o.image for o in self.control.observations} - set(self.names))
            if unknown:
                raise FlightError(f"ground control observed in images that are not in the flight: {unknown[:3]}")
        return self


def _intrinsics_row(K: NDArray[np.float64], width: int, height: int) -> list:
    return [repr(float(K[0, 0])), repr(float(K[1, 1])), repr(float(K[0, 2])), repr(float(K[1, 2])),
            str(int(width)), str(int(height))]


def write_flight(views: CapturedViews, folder: PathLike, meta: Optional[dict] = None) -> Path:
    """Write a capture set as a flight folder (module docstring): the images (PNG, lossless),
    ``poses.csv``, COLMAP's ``cameras.txt`` / ``images.txt`` / ``points3D.txt`` and
    ``flight.json`` (``meta`` and the realization). Every file is written under a temporary
    name and renamed, the pose files last: a folder that has poses.csv is complete."""
    views.validate()
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    w, h = views.size
    K = np.asarray(views.K, dtype=np.float64)

    def atomic(name: str, write) -> None:
        tmp = out / f".{name}.tmp"
        write(tmp)
        tmp.replace(out / name)

    for name, im in zip(views.names, views.images):
        suffix = Path(name).suffix or ".png"

        def write_image(tmp: Path, im=im, suffix=suffix) -> None:
            ok, buf = cv2.imencode(suffix, cv2.cvtColor(np.asarray(im, np.uint8), cv2.COLOR_RGB2BGR))
            if not ok:
                raise OSError(f"cannot encode {name}")
            tmp.write_bytes(buf.tobytes())

        atomic(name, write_image)
    poses = cameras_to_poses(views.reported)
    R, t = world_to_camera(views.reported)
    cx, cy = principal_point_gl(K)
    meta = {**(meta or {}), "realization": views.realization, "frame": FRAME, "images": list(views.names)}
    atomic("flight.json", lambda p: p.write_text(json.dumps(meta, indent=1)))
    atomic("cameras.txt", lambda p: p.write_text(
        "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
        f"1 PINHOLE {w} {h} " + " ".join(repr(float(v)) for v in (K[0, 0], K[1, 1], cx, cy)) + "\n"))
    lines = ["# Image list with two lines of data per image:",
             "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME", "#   POINTS2D[] as (X, Y, POINT3D_ID)"]
    for i, name in enumerate(views.names):
        qx, qy, qz, qw = Rotation.from_matrix(R[i]).as_quat()
        lines += [" ".join([str(i + 1)] + [repr(float(v)) for v in (qw, qx, qy, qz, *t[i])] + ["1", name]), ""]
    atomic("images.txt", lambda p: p.write_text("\n".join(lines) + "\n"))
    atomic("points3D.txt", lambda p: p.write_text("# 3D point list (empty: poses only)\n"))
    if views.control is not None:
        if views.control.observations:
            raise FlightError("write_flight writes ArUco markers (markers.csv), not observed control points")
        atomic(MARKERS_FILE, lambda p: write_markers_csv(views.control, p))

    def write_poses(p: Path) -> None:
        with open(p, "w", newline="") as f:
            wr = csv.writer(f)
            wr.writerow(POSES_COLUMNS)
            for name, pose in zip(views.names, poses):
                wr.writerow([name] + [repr(float(v)) for v in pose] + [FRAME] + _intrinsics_row(K, w, h))

    atomic(POSES_FILE, write_poses)
    return out


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


def _read_poses_csv(path: Path) -> tuple[list, NDArray[np.float64], list]:
    """(names, poses (N, 7), intrinsics rows [fx, fy, cx, cy, w, h]) of poses.csv."""
    names, poses, intr = [], [], []
    try:
        with open(path, newline="") as f:
            rows = list(csv.reader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise FlightError(f"{path}: cannot read: {exc}") from None
    if not rows or [c.strip() for c in rows[0]] != list(POSES_COLUMNS):
        raise FlightError(f"{path}: the first line must be the header {','.join(POSES_COLUMNS)}")
    for line, row in enumerate(rows[1:], start=2):
        if not row or not "".join(row).strip():
            continue
        where = f"{path} line {line}"
        if len(row) != len(POSES_COLUMNS):
            raise FlightError(f"{where}: {len(row)} columns, expected {len(POSES_COLUMNS)} ({','.join(POSES_COLUMNS)})")
        row = [c.strip() for c in row]
        name = row[0]
        if not name or Path(name).name != name:
            raise FlightError(f"{where}: image {name!r} must be a file name in the folder")
        if name in names:
            raise FlightError(f"{where}: duplicate image name {name}")
        pose = [_number(v, f"{where} ({name})", c) for v, c in zip(row[1:8], POSES_COLUMNS[1:8])]
        if row[8] != FRAME:
            raise FlightError(f"{where} ({name}): frame {row[8]!r}; poses must be in {FRAME!r}")
        k = [_number(v, f"{where} ({name})", c) for v, c in zip(row[9:], POSES_COLUMNS[9:])]
        if np.linalg.norm(pose[3:]) < 1e-9:
            raise FlightError(f"{where} ({name}): the quaternion is zero")
        names.append(name)
        poses.append(pose)
        intr.append(k)
    return names, np.array(poses, dtype=np.float64).reshape(-1, 7), intr


def _read_colmap_text(folder: Path) -> tuple[list, NDArray[np.float64], list]:
    """(names, poses (N, 7) in the suite's body convention, intrinsics rows) of COLMAP's text model."""
    cams: dict = {}
    path = folder / "cameras.txt"
    for line, text in enumerate(path.read_text(errors="replace").splitlines(), start=1):
        f = text.split()
        if not f or f[0].startswith("#"):
            continue
        where = f"{path} line {line}"
        if len(f) < 5 or f[1] not in ("PINHOLE", "SIMPLE_PINHOLE"):
            raise FlightError(f"{where}: only PINHOLE and SIMPLE_PINHOLE cameras (no distortion) are read, "
                              f"got {' '.join(f[:2])!r}")
        w, h = (_number(v, where, "size") for v in f[2:4])
        p = [_number(v, where, "parameter") for v in f[4:]]
        if len(p) != (4 if f[1] == "PINHOLE" else 3):
            raise FlightError(f"{where}: {f[1]} has {4 if f[1] == 'PINHOLE' else 3} parameters, got {len(p)}")
        fx, fy, cx, cy = p if f[1] == "PINHOLE" else (p[0], p[0], p[1], p[2])
        cams[f[0]] = [fx, fy, cx - 0.5, cy - 0.5, w, h]  # COLMAP's pixel centres at +0.5 -> OpenCV's
    path = folder / "images.txt"
    names, poses, intr = [], [], []
    data = [(n, t) for n, t in enumerate(path.read_text(errors="replace").splitlines(), start=1)
            if t.strip() and not t.lstrip().startswith("#")]
    # two lines an image (the second, its 2D points, may be empty and then was dropped above)
    for line, text in data:
        f = text.split()
        if len(f) != 10 or not f[0].isdigit():
            continue  # a POINTS2D line
        where = f"{path} line {line}"
        name = f[9]
        if Path(name).name != name:
            raise FlightError(f"{where}: image {name!r} must be a file name in the folder")
        if name in names:
            raise FlightError(f"{where}: duplicate image name {name}")
        qw, qx, qy, qz, tx, ty, tz = (_number(v, f"{where} ({name})", "pose") for v in f[1:8])
        if f[8] not in cams:
            raise FlightError(f"{where} ({name}): camera {f[8]} is not in cameras.txt")
        if math.hypot(qw, qx, qy, qz) < 1e-9:
            raise FlightError(f"{where} ({name}): the quaternion is zero")
        R_cw = Rotation.from_quat([qx, qy, qz, qw]).as_matrix()
        c = -R_cw.T @ np.array([tx, ty, tz])
        poses.append(np.concatenate([c, body_from_optical(R_cw)]))
        names.append(name)
        intr.append(cams[f[8]])
    return names, np.array(poses, dtype=np.float64).reshape(-1, 7), intr


def read_flight(folder: PathLike, max_megapixels: float = MAX_MEGAPIXELS) -> CapturedViews:
    """The capture set of a flight folder (module docstring); FlightError naming the file for a
    missing, corrupt or truncated image, a size not matching its intrinsics, a missing or NaN
    pose, an image without a pose, duplicate names, intrinsics that differ, or fewer than 2
    images. Every image's header is read before any is decoded: an image of more than
    :data:`vp_scene.images.MAX_IMAGE_PIXELS` pixels, or images of more than ``max_megapixels``
    together (:data:`vp_recon.pipeline.MAX_MEGAPIXELS`: memory), are refused before decoding."""
    d = Path(folder)
    if not d.is_dir():
        raise FlightError(f"{d}: not a folder")
    if (d / POSES_FILE).is_file():
        names, poses, intr = _read_poses_csv(d / POSES_FILE)
        source = d / POSES_FILE
    elif (d / "cameras.txt").is_file() and (d / "images.txt").is_file():
        names, poses, intr = _read_colmap_text(d)
        source = d / "images.txt"
    else:
        raise FlightError(f"{d}: no {POSES_FILE} (or COLMAP cameras.txt + images.txt) with the poses")
    present = sorted(p.name for p in d.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
    unposed = sorted(set(present) - set(names))
    if unposed:
        raise FlightError(f"{d / unposed[0]}: no pose in {source.name} (missing pose)")
    if len(names) < 2:
        raise FlightError(f"{source}: {len(names)} image(s); a reconstruction needs at least 2")
    roll = np.degrees(roll_of(poses))
    if len(roll) and np.max(np.abs(roll)) > MAX_ROLL_DEG:
        i = int(np.argmax(np.abs(roll)))
        raise FlightError(f"{source} ({names[i]}): roll of {roll[i]:.1f} deg about the optical axis; the suite's "
                          f"cameras are levelled (at most {MAX_ROLL_DEG:g} deg, README 'From a real flight')")
    if any(k != intr[0] for k in intr):
        i = next(i for i, k in enumerate(intr) if k != intr[0])
        raise FlightError(f"{source} ({names[i]}): intrinsics differ from {names[0]}'s (one camera per flight)")
    fx, fy, cx, cy, w, h = intr[0]
    if not (fx > 0 and fy > 0 and w >= 16 and h >= 16 and w == int(w) and h == int(h)):
        raise FlightError(f"{source}: bad intrinsics fx {fx} fy {fy} size {w}x{h}")
    pixels = 0
    for name in names:  # the headers first: nothing is decoded of a folder that is refused
        path = d / name
        if not path.is_file():
            raise FlightError(f"{path}: missing (listed in {source.name})")
        try:
            with open(path, "rb") as f:
                _, iw, ih = image_size(f, str(path))
        except OSError as exc:
            raise FlightError(f"{path}: cannot read: {exc.strerror or exc}") from None
        except ImageError as exc:
            raise FlightError(str(exc)) from None
        pixels += iw * ih
    if pixels > max_megapixels * 1e6:
        raise FlightError(f"{d}: its {len(names)} images have {pixels / 1e6:.4g} megapixels; at most "
                          f"{max_megapixels:g} are reconstructed at once (--max-megapixels; memory)")
    images = []
    for name in names:
        path = d / name
        try:
            im = read_image(path)
        except ImageError as exc:
            raise FlightError(str(exc)) from None
        if (im.shape[1], im.shape[0]) != (int(w), int(h)):
            raise FlightError(f"{path}: {im.shape[1]}x{im.shape[0]} pixels, but {source.name} gives "
                              f"{int(w)}x{int(h)}")
        images.append(im)
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    realization = None
    if (d / "flight.json").is_file():
        try:
            realization = json.loads((d / "flight.json").read_text()).get("realization")
        except (ValueError, AttributeError):
            raise FlightError(f"{d / 'flight.json'}: not a JSON object") from None
    return CapturedViews(names=list(names), images=images, reported=poses_to_cameras(poses), K=K,
                         realization=realization, control=_read_control(d)).validate()


def _read_control(d: Path) -> Optional[GroundControl]:
    """The folder's ground control (module docstring), or None; FlightError for a bad file or both."""
    files = [f for f in (d / MARKERS_FILE, d / GCP_LIST_FILE) if f.is_file()]
    if not files:
        return None
    if len(files) > 1:
        raise FlightError(f"{d}: both {MARKERS_FILE} and {GCP_LIST_FILE}: give one kind of ground control")
    try:
        return read_markers_csv(files[0]) if files[0].name == MARKERS_FILE else read_gcp_list(files[0])
    except GroundControlError as exc:
        raise FlightError(str(exc)) from None


def capture_folder(plan_folder: PathLike, k: int) -> Path:
    """Where a plan folder keeps realization ``k``'s capture set (the recon node's ``record_captures``)."""
    return Path(plan_folder) / "captures" / f"realization_{int(k)}"


def locate_flown(flown: Sequence[tuple], cameras: NDArray[np.float64], tol: float = 1e-6) -> list[tuple[Path, int]]:
    """For each camera already flown (a row [c, v] of ``cameras``), the plan folder of the newest
    earlier sortie that flew it and the camera's index in that plan.

    Args:
        flown: earlier sorties, oldest first, as (their planned cameras (N, 6), their plan folder).
        cameras: (F, 6) the cameras a second sortie's plan names as flown (``fixed_poses``).
        tol: largest difference of a centre (m) or a unit viewing direction that still matches.

    Raises:
        FlightError: naming the cameras no earlier sortie flew.
    """
    def unit(c: ArrayLike) -> NDArray[np.float64]:  # [c, v / |v|]
        c = np.asarray(c, dtype=np.float64).reshape(-1, 6)
        return np.hstack([c[:, :3], c[:, 3:] / np.maximum(np.linalg.norm(c[:, 3:], axis=1, keepdims=True), 1e-12)])

    cams = unit(cameras)
    earlier = [(unit(planned), Path(folder)) for planned, folder in reversed(list(flown))]  # newest first
    found, missing = [], []
    for i, c in enumerate(cams):
        hit = next(((folder, int(j)) for planned, folder in earlier
                    for j in np.flatnonzero(np.all(np.abs(planned - c) <= tol, axis=1))[:1]), None)
        (found if hit is not None else missing).append(hit if hit is not None else i)
    if missing:
        raise FlightError(f"{len(missing)} of the {len(cams)} cameras already flown (indices {missing}) were not "
                          f"flown by an earlier sortie this node reconstructed from the fleet")
    return found


def flown_views(located: Sequence[tuple[Path, int]], k: int) -> CapturedViews:
    """Realization ``k``'s images and reported poses of the cameras :func:`locate_flown` found,
    read back from each plan folder's capture set (:func:`capture_folder`, :func:`read_flight`),
    in the order given (joined by :func:`join_views`, which checks they share one camera).
    FlightError naming a folder that is missing or does not hold the camera."""
    sets: dict = {}  # plan folder -> its capture set of realization k, read once
    single = []
    for folder, j in located:
        if folder not in sets:
            d = capture_folder(folder, k)
            if not (d / POSES_FILE).is_file():
                raise FlightError(f"{d}: no capture set of realization {k} kept (the recon node's "
                                  "record_captures was off, or the folder was removed)")
            sets[folder] = read_flight(d, max_megapixels=math.inf)  # the node's own, bounded when made
        v = sets[folder]
        if j >= len(v.images):
            raise FlightError(f"{capture_folder(folder, k)}: {len(v.images)} images, camera {j} is not among them")
        single.append(CapturedViews(names=[v.names[j]], images=[v.images[j]], reported=v.reported[j:j + 1], K=v.K,
                                    realization=int(k)))
    return join_views(single)


def join_views(parts: Sequence[CapturedViews]) -> CapturedViews:
    """One capture set of several (the sorties of a flight, in order): images renamed
    ``view_000.png``... in that order; masks kept only when every part has them.

    Raises:
        FlightError: the parts differ in image size, intrinsics or realization.
    """
    parts = [p for p in parts if len(p.images)]
    if not parts:
        raise FlightError("no capture set to join")
    first = parts[0]
    for p in parts[1:]:
        if p.size != first.size or not np.allclose(p.K, first.K):
            raise FlightError(f"capture sets of different cameras ({first.size[0]}x{first.size[1]} and "
                              f"{p.size[0]}x{p.size[1]}, or other intrinsics) cannot be reconstructed together")
        if p.realization != first.realization:
            raise FlightError(f"capture sets of realizations {first.realization} and {p.realization}")
        if p.control != first.control:
            raise FlightError("capture sets of different ground control cannot be reconstructed together")
    images = [im for p in parts for im in p.images]
    masks = [m for p in parts for m in p.masks] if all(p.masks is not None for p in parts) else None
    return CapturedViews(names=[f"view_{i:03d}.png" for i in range(len(images))], images=images,
                         reported=np.concatenate([np.asarray(p.reported, np.float64).reshape(-1, 6) for p in parts]),
                         K=first.K, masks=masks, fov=first.fov, realization=first.realization, control=first.control)


def read_poses(folder: PathLike) -> tuple[list, NDArray[np.float64], NDArray[np.float64], tuple[int, int]]:
    """The poses of a flight folder without its images: (names, poses (N, 7) as the suite's
    ``geometry_msgs/Pose`` x y z qx qy qz qw, K, (width, height)), from poses.csv or COLMAP's
    text model (module docstring); FlightError naming the file. A planner choosing among a
    folder's views (:mod:`vp_planner.candidates`) needs no pixel of them."""
    d = Path(folder)
    if not d.is_dir():
        raise FlightError(f"{d}: not a folder")
    if (d / POSES_FILE).is_file():
        names, poses, intr = _read_poses_csv(d / POSES_FILE)
    elif (d / "cameras.txt").is_file() and (d / "images.txt").is_file():
        names, poses, intr = _read_colmap_text(d)
    else:
        raise FlightError(f"{d}: no {POSES_FILE} (or COLMAP cameras.txt + images.txt) with the poses")
    if not names:
        raise FlightError(f"{d}: no image has a pose")
    fx, fy, cx, cy, w, h = intr[0]
    return list(names), poses, np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]), (int(w), int(h))
