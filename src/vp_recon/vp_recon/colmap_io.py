"""COLMAP's workspace (pycolmap, CPU): what the sparse step hands COLMAP and what it reads back.

A workspace folder holds ``images/`` (the views as PNG, ``view_000.png``...), ``masks/`` when
features are restricted to the plant (``<image name>.png``, COLMAP's mask convention: features
only where the mask is non-zero), ``database.db`` (cameras, features, matches, pose priors),
``pairs.txt`` (COLMAP's imported pair list: ``name1 name2`` per line) and ``sparse/`` (the
mapper's models). One PINHOLE camera with the known calibration ``f, f, cx, cy`` (COLMAP's pixel
convention: centres at +0.5). A model is a ``pycolmap.Reconstruction``; a model at given poses
holds cam_from_world = (R_cw, t) of :func:`vp_scene.camera.world_to_camera`.
"""
from __future__ import annotations

import contextlib
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Optional, Sequence

import cv2
import numpy as np
import pycolmap
from numpy.typing import NDArray

from vp_scene.camera import principal_point_gl, world_to_camera

from .config import SparseOptions

__all__ = ["Matched", "log_level", "write_images", "extract_and_match", "write_pose_priors", "read_points",
           "model_at_poses"]


@dataclass
class Matched:
    """A workspace after feature extraction and matching.

    Attributes:
        database, image_dir, model_dir: ``database.db``, ``images/``, ``sparse/`` (created).
        names: the images' names, in the order of the views given.
        cameras, images: the database's cameras and its images by name.
        keypoints: SIFT keypoints per image; verified: image pairs with verified matches.
        pair_inliers: verified inlier matches per image pair (i, j), i < j (indices of ``names``).
        matched: image pairs handed to the matcher.
    """

    database: Path
    image_dir: Path
    model_dir: Path
    names: list
    cameras: list
    images: dict
    keypoints: list
    verified: int
    pair_inliers: dict
    matched: int


@contextlib.contextmanager
def log_level(level: Optional[int] = None) -> Iterator[None]:
    """COLMAP's glog ``minloglevel`` set to ``level`` (None: left as it is) and restored afterwards;
    ``pycolmap.bundle_adjustment`` sets it to 0 on its own, and every later call would then print
    its INFO lines."""
    kept = pycolmap.logging.minloglevel
    if level is not None:
        pycolmap.logging.minloglevel = level
    try:
        yield
    finally:
        pycolmap.logging.minloglevel = kept


def write_images(images: Sequence[NDArray[np.uint8]], masks: Optional[Sequence[NDArray[np.bool_]]],
                 workdir: Path) -> tuple[Path, Optional[Path], list[str]]:
    """The views as ``images/view_<i>.png`` (and their masks, dilated so that keypoints on the
    silhouette keep their support, as ``masks/``), each folder made anew: (image folder, mask
    folder or None, names). OSError when an image cannot be written."""
    img_dir = workdir / "images"
    if img_dir.exists():
        shutil.rmtree(img_dir)
    img_dir.mkdir(parents=True)
    mask_dir = None
    if masks is not None:
        mask_dir = workdir / "masks"
        if mask_dir.exists():
            shutil.rmtree(mask_dir)
        mask_dir.mkdir(parents=True)
    names = []
    for i, img in enumerate(images):
        name = f"view_{i:03d}.png"
        if not cv2.imwrite(str(img_dir / name), cv2.cvtColor(np.asarray(img, np.uint8), cv2.COLOR_RGB2BGR)):
            raise OSError(f"cannot write {img_dir / name}")
        if mask_dir is not None:
            m = cv2.dilate(np.asarray(masks[i], np.uint8) * 255, np.ones((9, 9), np.uint8))
            cv2.imwrite(str(mask_dir / f"{name}.png"), m)
        names.append(name)
    return img_dir, mask_dir, names


def _write_pairs(pairs: Sequence[tuple[int, int]], names: Sequence[str], path: Path) -> None:
    """COLMAP's image pair list: one ``name1 name2`` line per pair."""
    path.write_text("".join(f"{names[i]} {names[j]}\n" for i, j in pairs))


def extract_and_match(workdir: Path, images: Sequence[NDArray[np.uint8]],
                      masks: Optional[Sequence[NDArray[np.bool_]]], K: NDArray[np.float64],
                      pairs: Optional[Sequence[tuple[int, int]]], options: SparseOptions,
                      centres: Optional[NDArray[np.float64]] = None) -> tuple[Matched, dict]:
    """SIFT features of the views into a new ``database.db`` (one PINHOLE camera of ``K``; on the
    masks' plant pixels only when given), the camera ``centres`` as pose priors known to
    ``options.prior_sigma`` when given (:func:`write_pose_priors`), then matching with geometric
    verification: every pair (``pairs`` None) or the listed ones (``pairs.txt``). Returns the
    :class:`Matched` workspace and the seconds of ``extract`` and ``match``."""
    num_threads = options.num_threads
    seconds = {}
    t0 = time.perf_counter()
    workdir.mkdir(parents=True, exist_ok=True)
    img_dir, mask_dir, names = write_images(images, masks, workdir)
    db_path = workdir / "database.db"
    if db_path.exists():
        db_path.unlink()
    cx, cy = principal_point_gl(K)
    reader = pycolmap.ImageReaderOptions()
    reader.camera_model = "PINHOLE"
    reader.camera_params = ",".join(repr(float(x)) for x in (K[0, 0], K[1, 1], cx, cy))
    if mask_dir is not None:
        reader.mask_path = str(mask_dir)
    extraction = pycolmap.FeatureExtractionOptions()
    extraction.num_threads = num_threads
    extraction.sift.max_num_features = int(options.max_features)
    extraction.sift.first_octave = int(options.sift_first_octave)
    device = pycolmap.Device.cpu
    pycolmap.extract_features(db_path, img_dir, image_names=names, camera_mode=pycolmap.CameraMode.SINGLE,
                              reader_options=reader, extraction_options=extraction, device=device)
    if centres is not None:
        write_pose_priors(db_path, names, np.asarray(centres, dtype=np.float64).reshape(-1, 3), options.prior_sigma)
    seconds["extract"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    matching = pycolmap.FeatureMatchingOptions()
    matching.num_threads = num_threads
    if pairs is None:
        pycolmap.match_exhaustive(db_path, matching_options=matching, device=device)
        matched = len(names) * (len(names) - 1) // 2
    else:
        pair_file = workdir / "pairs.txt"
        _write_pairs(pairs, names, pair_file)
        pycolmap.match_image_pairs(db_path, matching_options=matching,
                                   pairing_options=pycolmap.ImportedPairingOptions(match_list_path=str(pair_file)),
                                   device=device)
        matched = len(pairs)
    seconds["match"] = time.perf_counter() - t0
    model_dir = workdir / "sparse"
    with pycolmap.Database.open(db_path) as db:
        db_images = {im.name: im for im in db.read_all_images()}
        db_cameras = db.read_all_cameras()
        keypoints = [db.num_keypoints_for_image(db_images[n].image_id) if n in db_images else 0 for n in names]
        verified = int(db.num_verified_image_pairs())
        index = {db_images[n].image_id: i for i, n in enumerate(names) if n in db_images}
        pair_inliers = {}
        for pair_id, n_inl in zip(*db.read_two_view_geometry_num_inliers()):
            a, b = (index.get(x) for x in pycolmap.pair_id_to_image_pair(pair_id))
            if a is not None and b is not None and n_inl > 0:
                pair_inliers[(min(a, b), max(a, b))] = int(n_inl)
    return Matched(db_path, img_dir, model_dir, names, db_cameras, db_images, keypoints, verified, pair_inliers,
                   matched), seconds


def write_pose_priors(db_path: Path, names: Sequence[str], centres: NDArray[np.float64], sigma: float) -> None:
    """Each image's camera centre as a COLMAP pose prior (Cartesian, isotropic ``sigma`` m);
    ValueError for centres that are not finite (N, 3)."""
    if centres.shape != (len(names), 3) or not np.all(np.isfinite(centres)):
        raise ValueError(f"prior_centres must be finite, ({len(names)}, 3), got shape {centres.shape}")
    cov = np.eye(3) * max(float(sigma), 1e-3) ** 2
    with pycolmap.Database.open(db_path) as db:
        by_name = {im.name: im for im in db.read_all_images()}
        for name, c in zip(names, centres):
            im = by_name.get(name)
            if im is None:
                continue
            prior = pycolmap.PosePrior(position=c.reshape(3, 1), position_covariance=cov,
                                       coordinate_system=pycolmap.PosePriorCoordinateSystem.CARTESIAN)
            prior.corr_data_id = pycolmap.data_t(pycolmap.sensor_t(pycolmap.SensorType.CAMERA, im.camera_id),
                                                 im.image_id)
            db.write_pose_prior(prior)


def read_points(rec: object) -> tuple[NDArray[np.float64], NDArray[np.uint8], float]:
    """A model's points (P, 3), their colours (P, 3) uint8 and the mean track length (0 without points)."""
    pts = rec.points3D
    if len(pts) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.uint8), 0.0
    xyz = np.array([p.xyz for p in pts.values()], dtype=np.float64).reshape(-1, 3)
    rgb = np.array([p.color for p in pts.values()], dtype=np.uint8).reshape(-1, 3)
    track = float(np.mean([p.track.length() for p in pts.values()]))
    return xyz, rgb, track


def model_at_poses(matched: Matched, cams: NDArray[np.float64]) -> object:
    """A reconstruction holding the workspace's images at the poses of ``cams`` (no points yet)."""
    rec = pycolmap.Reconstruction()
    for cam in matched.cameras:
        rec.add_camera_with_trivial_rig(cam)
    R, t = world_to_camera(cams)
    for i, name in enumerate(matched.names):
        dbi = matched.images[name]
        image = pycolmap.Image(name=name, camera_id=dbi.camera_id, image_id=dbi.image_id)
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(R[i]), t[i].reshape(3, 1))
        rec.add_image_with_trivial_frame(image, pose)
    return rec
