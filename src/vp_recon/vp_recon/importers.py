"""Importers: a rig's or a photogrammetry tool's scan folder into the suite's flight folder.

    python -m vp_recon.importers romi SCAN_FOLDER OUT_FOLDER [--pose approximate|colmap] [--every K]

``romi``: a scan of the ROMI plant imager (plant-3d-vision's scan folder): ``images/<name>.jpg``
and, per image, ``metadata/images/<name>.json`` with

* ``approximate_pose`` = [x, y, z, pan, tilt]: the pose the robot reported, millimetres in the
  rig's frame and degrees; pan 0 looks along the rig's +y and grows counter-clockwise (the
  camera's heading from +x is pan + 90 degrees, checked on a real scan against COLMAP's refined
  poses), tilt in degrees below the horizontal. A robot that reports no tilt (0)
  while its camera looks down is common: a reported attitude known only roughly, to be given
  with its sigma (``--report-attitude-sigma``, README "From a real flight");
* ``colmap_camera``: what COLMAP made of the scan, registered to the rig's frame: ``camera_model``
  (COLMAP's model name, width, height, params) and ``rotmat`` / ``tvec`` (cam_from_world,
  millimetres).

The flight folder written (:mod:`vp_recon.flight`): the images copied as they are (no re-encoding)
and ``poses.csv`` in ``map`` = the rig's frame in metres (x, y, z / 1000; z up), with the
scan's intrinsics and lens distortion (the columns k1, k2, p1, p2, k3: the images are undistorted
when the folder is read), and the pose ``--pose`` names: ``approximate`` (default: what the robot
reported, levelled, its attitude as rough as the robot's) or ``colmap`` (the refined poses, roll
kept: a reference). ``flight.json`` says where it came from. ``--every K`` keeps every K-th image
(a sparser capture of the same scan).

Bad input: one line ``import: error: ...`` naming the file, exit 2, and no OUT_FOLDER.
ROS-free: numpy, scipy.
"""
from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from vp_scene.camera import body_from_optical, cameras_to_poses

from vp_scene.flight_poses import COLMAP_MODELS, DISTORTION_COLUMNS, POSES_FILE, FlightError, colmap_camera, \
    write_poses_csv

from .flight import IMAGE_SUFFIXES

__all__ = ["ScanError", "ROMI_POSES", "romi_poses", "import_romi", "main"]

PROG = "import"
#: ``--pose`` of the romi importer.
ROMI_POSES = ("approximate", "colmap")


class ScanError(ValueError):
    """A scan folder that cannot be imported; the message names the file."""


def romi_poses(meta: dict, which: str, where: str = "") -> np.ndarray:
    """The pose (7,) in metres (the rig's frame) of one image's ROMI metadata: ``approximate``
    (the robot's [x, y, z mm, pan, tilt deg], levelled: heading pan + 90 degrees from +x, tilt
    below the horizontal) or ``colmap`` (cam_from_world rotmat / tvec in mm, roll kept)."""
    try:
        if which == "approximate":
            x, y, z, pan, tilt = (float(v) for v in meta["approximate_pose"])
            h, t = math.radians(pan + 90.0), math.radians(tilt)
            v = [math.cos(h) * math.cos(t), math.sin(h) * math.cos(t), -math.sin(t)]
            return cameras_to_poses(np.array([x / 1000.0, y / 1000.0, z / 1000.0, *v]))
        if which == "colmap":
            R = np.asarray(meta["colmap_camera"]["rotmat"], dtype=np.float64).reshape(3, 3)
            t = np.asarray(meta["colmap_camera"]["tvec"], dtype=np.float64).reshape(3)
            if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
                raise ValueError("rotmat is not a rotation")
            return np.concatenate([-R.T @ t / 1000.0, body_from_optical(R)])
    except (KeyError, TypeError, ValueError) as exc:
        raise ScanError(f"{where}: no usable {which} pose ({type(exc).__name__}: {exc})") from None
    raise ValueError(f"pose must be one of {', '.join(ROMI_POSES)}, got {which!r}")


def _camera(meta: dict, where: str) -> tuple:
    """(K (3, 3) OpenCV convention, (width, height), distortion (k1, k2, p1, p2, k3)) of a ROMI
    image's ``colmap_camera.camera_model``."""
    try:
        cm = meta["colmap_camera"]["camera_model"]
        model, w, h, params = str(cm["model"]), int(cm["width"]), int(cm["height"]), [float(p) for p in cm["params"]]
    except (KeyError, TypeError, ValueError) as exc:
        raise ScanError(f"{where}: no camera model (colmap_camera.camera_model: {type(exc).__name__}: {exc})") from None
    if model not in COLMAP_MODELS or len(params) != len(COLMAP_MODELS[model]):
        raise ScanError(f"{where}: camera model {model} with {len(params)} parameters is not one of "
                           f"{', '.join(COLMAP_MODELS)}")
    cam = colmap_camera(model, w, h, params)
    if any(cam.dist[len(DISTORTION_COLUMNS):]):
        raise ScanError(f"{where}: k4..k6 of {model} have no poses.csv column")
    return cam.K, (w, h), tuple(cam.dist[:len(DISTORTION_COLUMNS)])


def import_romi(scan: Path, out: Path, pose: str = "approximate", every: int = 1) -> Path:
    """Write the flight folder ``out`` of the ROMI scan folder ``scan`` (module docstring);
    ScanError naming the file for a bad scan, an existing ``out``."""
    if pose not in ROMI_POSES:
        raise ScanError(f"--pose must be one of {', '.join(ROMI_POSES)}, got {pose!r}")
    if every < 1:
        raise ScanError(f"--every must be >= 1, got {every}")
    meta_dir, img_dir = scan / "metadata" / "images", scan / "images"
    if not meta_dir.is_dir() or not img_dir.is_dir():
        raise ScanError(f"{scan}: not a ROMI scan folder (no metadata/images/ and images/)")
    if out.exists():
        raise ScanError(f"{out}: exists; the importer writes a new flight folder")
    files = sorted(meta_dir.glob("*.json"))[::every]
    if len(files) < 2:
        raise ScanError(f"{meta_dir}: {len(files)} image metadata file(s) kept; a flight needs at least 2")
    images = {p.stem: p for p in img_dir.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES}
    names, poses, camera = [], [], None
    for f in files:
        try:
            meta = json.loads(f.read_text())
        except (OSError, ValueError) as exc:
            raise ScanError(f"{f}: not a JSON file ({exc})") from None
        if not isinstance(meta, dict):
            raise ScanError(f"{f}: not a JSON object")
        if f.stem not in images:
            raise ScanError(f"{f}: no image {f.stem}.jpg (or .png) in {img_dir}")
        cam = _camera(meta, str(f))
        if camera is None:
            camera = cam
        elif not (np.allclose(cam[0], camera[0]) and cam[1:] == camera[1:]):
            raise ScanError(f"{f}: its camera differs from {files[0].name}'s (one camera per flight)")
        poses.append(romi_poses(meta, pose, str(f)))
        names.append(images[f.stem].name)
    out.parent.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=f".{out.name}-", dir=out.parent))
    try:
        for name in names:
            shutil.copyfile(img_dir / name, stage / name)
        K, size, dist = camera
        write_poses_csv(stage / POSES_FILE, names, np.array(poses), K, size, dist)
        (stage / "flight.json").write_text(json.dumps({
            "source": "romi", "scan": str(scan.resolve()), "pose": pose, "every": every, "realization": None,
            "frame": "map: the rig's frame in metres (x, y, z / 1000), z up"}, indent=1))
        stage.rename(out)
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
    return out


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{PROG}: error: {message} (see --help)\n")


def main(argv: Optional[Sequence[str]] = None) -> int:
    p = _Parser(prog=PROG, description="Import a rig's scan folder as the suite's flight folder "
                                       "(README 'From a real flight').")
    sub = p.add_subparsers(dest="format", required=True)
    romi = sub.add_parser("romi", help="a ROMI plant imager scan (images/ + metadata/images/*.json)")
    romi.add_argument("scan", help="the scan folder")
    romi.add_argument("out", help="the flight folder to write (must not exist)")
    romi.add_argument("--pose", default="approximate", choices=ROMI_POSES,
                      help="approximate (default): the pose the robot reported (its attitude rough: reconstruct "
                           "with --report-attitude-sigma); colmap: the scan's refined poses (a reference)")
    romi.add_argument("--every", type=int, default=1, help="keep every K-th image (default 1: all)")
    args = p.parse_args(argv)
    try:
        out = import_romi(Path(args.scan), Path(args.out), args.pose, args.every)
    except (ScanError, FlightError, OSError) as exc:
        print(f"{PROG}: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    print(f"{PROG}: {out} ({POSES_FILE}: {args.pose} poses, metres in the rig's frame)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
