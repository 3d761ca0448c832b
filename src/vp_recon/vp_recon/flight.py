"""A capture set (images + the poses the cameras reported + one pinhole camera) and its folder.

:class:`CapturedViews` is what a flight hands to the reconstruction
(:func:`vp_recon.pipeline.reconstruct_views`), whether it was rendered from a plan
(:func:`vp_recon.pipeline.render_flight`), read from a flight folder (:func:`read_flight`) or,
later, received from the fleet.

The flight folder (README "From a real flight")
------------------------------------------------
A folder ``DIR`` holds the images (PNG or JPEG, RGB, one camera for all) and a pose file,
``DIR/poses.csv`` or COLMAP's text model (:mod:`vp_scene.flight_poses`: the format, its reader
and writer; the planner reads the poses alone).

Distortion: the images of a camera with distortion are undistorted once, as they are read, to a
pinhole camera (COLMAP's undistorter, ``pycolmap.undistort_camera`` / ``undistort_image``: no
blank pixels, the image size may change by a few pixels); everything after works on pinhole
images. :func:`write_flight` writes both files (pinhole: what it writes is undistorted; and an
empty ``points3D.txt``, so that COLMAP reads the model), plus ``flight.json`` (what is known of
a simulated flight: its wind realization and capture model) and the set's ground control. Every
problem of a folder is a :class:`FlightError` with one line naming the file.

Ground control (optional, :mod:`vp_scene.ground_control`): ``DIR/markers.csv`` (``id,x,y,z[,sigma]``:
ArUco markers of OpenCV's ``DICT_4X4_50`` surveyed on the ground, found in the images by
:mod:`vp_recon.gcp`) or OpenDroneMap's ``DIR/gcp_list.txt`` (control points and where they were
seen in which image); both in the poses' frame, metres. The reconstruction is then placed in
``map`` on the control points and the reported poses together (:func:`vp_recon.gcp.register`).

Images are read by :mod:`vp_scene.images` (the header checked before anything is decoded; a
truncated or corrupt image refused). ROS-free: numpy, OpenCV, Pillow, scipy.
"""
from __future__ import annotations

import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional, Sequence, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from vp_scene.ground_control import GroundControl, GroundControlError, read_gcp_list, read_markers_csv, \
    write_gcp_list, write_markers_csv
from vp_scene.camera import as_poses, check_image_side, principal_point_gl, world_to_camera
from vp_scene.folders import write_atomic
from vp_scene.flight_poses import FRAME, POSES_FILE, FlightCamera, FlightError, read_pose_files, write_poses_csv
from vp_scene.images import ImageError, image_size, read_image

from .config import MAX_MEGAPIXELS
from .outputs import write_image

__all__ = ["MARKERS_FILE", "GCP_LIST_FILE", "IMAGE_SUFFIXES", "CapturedViews", "write_flight", "read_flight",
           "capture_folder", "locate_flown", "flown_views", "join_views"]

#: The ground-control files of a flight folder (module docstring).
MARKERS_FILE = "markers.csv"
GCP_LIST_FILE = "gcp_list.txt"
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")

PathLike = Union[str, os.PathLike]


@dataclass
class CapturedViews:
    """N images of one pinhole camera with the poses the cameras reported.

    Attributes:
        names: N unique image file names.
        images: N RGB uint8 (H, W, 3), all of one size.
        reported: the reported poses in ``map``: (N, 7) (x, y, z, qx, qy, qz, qw), any attitude,
            or (N, 6) levelled cameras [c, v] (a plan flown in simulation; kept as given, so that
            its geometry is bit for bit the plan's: :func:`vp_scene.camera.as_poses` gives their
            poses). Every consumer takes either (:mod:`vp_scene.camera`).
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
        if rep.shape not in ((n, 6), (n, 7)) or not np.all(np.isfinite(rep)):
            raise FlightError(f"reported poses must be {n} finite poses (x, y, z, qx, qy, qz, qw) or [c, v] rows, "
                              f"got shape {rep.shape}")
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


def _undistorter(cam: FlightCamera) -> tuple[object, FlightCamera]:
    """(undistort(image) -> image, the pinhole camera of the undistorted images) of a camera with
    distortion: COLMAP's undistorter (no blank pixels; the size may change by a few pixels), the
    one COLMAP applies before its dense stereo, so that the rest of the suite stays pinhole."""
    import pycolmap

    options = pycolmap.UndistortCameraOptions()
    source = cam.colmap(pycolmap)
    pin = pycolmap.undistort_camera(options, source)
    fx, fy, cx, cy = (float(v) for v in pin.params)

    def undistort(image: NDArray[np.uint8]) -> NDArray[np.uint8]:
        out, _ = pycolmap.undistort_image(options, pycolmap.Bitmap.from_array(np.ascontiguousarray(image)), source)
        return np.ascontiguousarray(out.to_array()[..., :3], dtype=np.uint8)

    return undistort, FlightCamera(fx, fy, cx - 0.5, cy - 0.5, int(pin.width), int(pin.height))


def write_flight(views: CapturedViews, folder: PathLike, meta: Optional[dict] = None) -> Path:
    """Write a capture set as a flight folder (module docstring): the images (PNG, lossless),
    ``poses.csv``, COLMAP's ``cameras.txt`` / ``images.txt`` / ``points3D.txt`` and
    ``flight.json`` (``meta`` and the realization) and the ground control (``markers.csv``, or
    ``gcp_list.txt`` for control points with observations). Every file is written whole or not at
    all (:func:`vp_scene.folders.write_atomic`: OutputError naming it), the pose file last: a
    folder that has poses.csv is complete."""
    views.validate()
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    w, h = views.size
    K = np.asarray(views.K, dtype=np.float64)

    def atomic(name: str, write) -> None:
        write_atomic(out / name, write)

    for name, im in zip(views.names, views.images):
        write_image(out / name, im)
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
    if views.control is not None:  # ArUco markers, or control points with their observations
        if views.control.observations:
            atomic(GCP_LIST_FILE, lambda p: write_gcp_list(views.control, p))
        else:
            atomic(MARKERS_FILE, lambda p: write_markers_csv(views.control, p))
    atomic(POSES_FILE, lambda p: write_poses_csv(p, views.names, views.reported, K, (w, h)))
    return out


def read_flight(folder: PathLike, max_megapixels: float = MAX_MEGAPIXELS) -> CapturedViews:
    """The capture set of a flight folder (module docstring); FlightError naming the file for a
    missing, corrupt or truncated image, a size not matching its intrinsics, a missing or NaN
    pose, an image without a pose, duplicate names, intrinsics that differ, or fewer than 2
    images. Every image's header is read before any is decoded: an image of more than
    :data:`vp_scene.images.MAX_IMAGE_PIXELS` pixels, or images of more than ``max_megapixels``
    together (:data:`vp_recon.config.MAX_MEGAPIXELS`: memory; undistorted images counted at
    their undistorted size), are refused before decoding. A camera with distortion is
    undistorted as its images are read (module docstring; ``seconds['undistort']``)."""
    d = Path(folder)
    names, poses, cams, source = read_pose_files(d)
    present = sorted(p.name for p in d.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
    unposed = sorted(set(present) - set(names))
    if unposed:
        raise FlightError(f"{d / unposed[0]}: no pose in {source.name} (missing pose)")
    if len(names) < 2:
        raise FlightError(f"{source}: {len(names)} image(s); a reconstruction needs at least 2")
    if any(k != cams[0] for k in cams):
        i = next(i for i, k in enumerate(cams) if k != cams[0])
        raise FlightError(f"{source} ({names[i]}): intrinsics differ from {names[0]}'s (one camera per flight)")
    cam = cams[0]
    w, h = cam.width, cam.height
    try:
        check_image_side("the image width", w)
        check_image_side("the image height", h)
    except ValueError as exc:
        raise FlightError(f"{source}: {exc}") from None
    if not (cam.fx > 0 and cam.fy > 0):
        raise FlightError(f"{source}: bad intrinsics fx {cam.fx} fy {cam.fy}")
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
    undistort, pinhole = None, cam
    if cam.distorted and pixels <= max_megapixels * 1e6:
        try:
            undistort, pinhole = _undistorter(cam)
        except (ValueError, RuntimeError) as exc:
            raise FlightError(f"{source}: cannot undistort the camera (distortion {cam.dist}): {exc}") from None
        pixels = max(pixels, len(names) * pinhole.width * pinhole.height)
    if pixels > max_megapixels * 1e6:
        raise FlightError(f"{d}: its {len(names)} images have {pixels / 1e6:.4g} megapixels; at most "
                          f"{max_megapixels:g} are reconstructed at once (--max-megapixels; memory)")
    images, seconds = [], 0.0
    for name in names:
        path = d / name
        try:
            im = read_image(path)
        except ImageError as exc:
            raise FlightError(str(exc)) from None
        if (im.shape[1], im.shape[0]) != (int(w), int(h)):
            raise FlightError(f"{path}: {im.shape[1]}x{im.shape[0]} pixels, but {source.name} gives "
                              f"{int(w)}x{int(h)}")
        if undistort is not None:
            t0 = time.perf_counter()
            im = undistort(im)
            seconds += time.perf_counter() - t0
        images.append(im)
    realization = None
    if (d / "flight.json").is_file():
        try:
            realization = json.loads((d / "flight.json").read_text()).get("realization")
        except (ValueError, AttributeError):
            raise FlightError(f"{d / 'flight.json'}: not a JSON object") from None
    return CapturedViews(names=list(names), images=images, reported=poses, K=pinhole.K, realization=realization,
                         control=_read_control(d), seconds={"undistort": seconds} if undistort else {}).validate()


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
    in the order given, with the ground control their capture sets kept (the field's markers:
    :func:`join_views` checks that every part shares one camera and one ground control, so that
    the new sortie's images join them). FlightError naming a folder that is missing or does not
    hold the camera."""
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
                                    realization=int(k), control=v.control))
    return join_views(single)


def _joined_poses(parts: Sequence[ArrayLike]) -> NDArray[np.float64]:
    """The reported poses of several capture sets, one after the other: as given when all are
    [c, v] rows or all poses, else all as poses."""
    arrays = [np.asarray(p, dtype=np.float64) for p in parts]
    if len({a.shape[1] for a in arrays}) > 1:
        arrays = [as_poses(a) for a in arrays]
    return np.concatenate(arrays)


def _control_text(control: Optional[GroundControl]) -> str:
    """A capture set's ground control in a few words (join_views' refusal)."""
    if control is None:
        return "none"
    return f"{len(control.positions)} points, sigma {control.sigma:g} m"


def join_views(parts: Sequence[CapturedViews]) -> CapturedViews:
    """One capture set of several (the sorties of a flight, in order): images renamed
    ``view_000.png``... in that order; masks kept only when every part has them.

    Raises:
        FlightError: the parts differ in image size, intrinsics, realization or ground control
            (one field's sorties share its markers; sets of other control points, or one with
            control and one without, are not one flight).
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
            raise FlightError(f"capture sets of different ground control ({_control_text(first.control)} and "
                              f"{_control_text(p.control)}) cannot be reconstructed together")
    images = [im for p in parts for im in p.images]
    masks = [m for p in parts for m in p.masks] if all(p.masks is not None for p in parts) else None
    return CapturedViews(names=[f"view_{i:03d}.png" for i in range(len(images))], images=images,
                         reported=_joined_poses([p.reported for p in parts]),
                         K=first.K, masks=masks, fov=first.fov, realization=first.realization, control=first.control)
