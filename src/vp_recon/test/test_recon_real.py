"""Real flight folders in (issue 41, part 1): any attitude end to end (a camera's roll kept from
poses.csv to the registration, the pairs, the dense step and the viewer), COLMAP's and OpenCV's
lens distortion undistorted as a folder is read, reported attitudes known only roughly weighed by
their sigma, and the ROMI scan importer (on the dev scan of ../shared where it is present)."""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vp_scene.camera import cameras_to_poses, look_at, poses_to_cameras, roll_of, world_to_camera
from vp_scene.capture import IDEAL, CaptureModel

from vp_recon.cli import main as recon_main
from vp_recon.flight import CapturedViews, read_flight, write_flight
from vp_scene.flight_poses import POSES_FILE
from vp_recon.config import ReconConfig
from vp_recon.pipeline import reconstruct_views, render_flight
from vp_recon.registration import similarity_from_poses

#: The dev scan (README of ../shared/data/romi_real_plant): 60 real photographs of a plant.
ROMI = Path(__file__).resolve().parents[3].parent / "shared" / "data" / "romi_real_plant"
needs_romi = pytest.mark.skipif(not (ROMI / "metadata" / "images").is_dir(),
                                reason=f"the real scan {ROMI} is absent (../shared/data/romi_real_plant: "
                                       "the shared data folder beside the repository)")


def rolled(cameras: np.ndarray, degrees) -> np.ndarray:
    """Poses (N, 7) of levelled cameras turned about their optical axes by ``degrees`` (N,) or one value."""
    p = cameras_to_poses(cameras)
    deg = np.broadcast_to(np.asarray(degrees, dtype=np.float64), (len(p),))
    q = (Rotation.from_quat(p[:, 3:]) * Rotation.from_rotvec(np.radians(deg)[:, None] * [1.0, 0.0, 0.0])).as_quat()
    return np.hstack([p[:, :3], q])


def ring(n: int, radius: float = 1.6, height: float = 1.3, arc_deg: float = 150.0) -> np.ndarray:
    az = np.radians(np.linspace(0.0, arc_deg, n))
    c = np.stack([radius * np.cos(az), radius * np.sin(az), np.full(n, height)], axis=1)
    return look_at(c, [0.0, 0.0, 0.9])


def same_rotations(a: np.ndarray, b: np.ndarray, atol: float = 1e-9) -> None:
    np.testing.assert_allclose(a[:, :3], b[:, :3], atol=atol)
    np.testing.assert_allclose(world_to_camera(a)[0], world_to_camera(b)[0], atol=atol)  # q and -q: one rotation


def test_a_rolled_camera_round_trips_through_poses_csv_and_colmaps_model(tmp_path: Path) -> None:
    """Poses of any attitude (rolls of 5, -30 and 170 degrees, a camera looking straight down)
    go poses.csv -> CapturedViews -> write -> read and through COLMAP's images.txt alone with
    their roll (before: a roll over 2 degrees was refused and the suite's [c, v] dropped it)."""
    cams = np.vstack([ring(3), [[0.0, 0.0, 2.0, 0.0, 0.0, -1.0]]])
    poses = rolled(cams, [5.0, -30.0, 170.0, 12.0])
    rng = np.random.default_rng(0)
    views = CapturedViews(names=[f"im{i}.png" for i in range(4)],
                          images=[rng.integers(0, 255, (48, 64, 3), dtype=np.uint8) for _ in range(4)],
                          reported=poses, K=np.array([[32.0, 0, 31.5], [0, 32.0, 23.5], [0, 0, 1]]))
    folder = write_flight(views, tmp_path / "flight")
    back = read_flight(folder)
    same_rotations(back.reported, poses)
    np.testing.assert_allclose(np.degrees(roll_of(back.reported)), [5.0, -30.0, 170.0, 12.0], atol=1e-9)
    again = read_flight(write_flight(back, tmp_path / "again"))
    same_rotations(again.reported, poses)
    (folder / POSES_FILE).unlink()  # COLMAP's text model alone
    same_rotations(read_flight(folder).reported, poses)
    levelled = CapturedViews(names=views.names, images=views.images, reported=cams, K=views.K).validate()
    same_rotations(levelled.reported, cameras_to_poses(cams))  # a plan's [c, v] rows: their levelled poses


def _dots(K: np.ndarray, dist: np.ndarray, width: int = 320, height: int = 240,
          step: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """A lens's image of a grid of small white dots on black, and where a pinhole camera (K)
    puts them: each dot drawn where OpenCV's distortion model ``dist`` moves its centre
    (cv2.projectPoints, the forward model; a dot of 3 px keeps its shape)."""
    ys, xs = np.mgrid[step // 2:height:step, step // 2:width:step]
    pinhole = np.stack([xs.ravel(), ys.ravel()], axis=1).astype(np.float64)
    rays = np.hstack([pinhole, np.ones((len(pinhole), 1))]) @ np.linalg.inv(K).T
    seen = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), K, dist)[0].reshape(-1, 2)
    im = np.zeros((height, width, 3), np.uint8)
    for x, y in seen:  # cv2.circle's fixed point (shift 4): centres to 1/16 px
        cv2.circle(im, (int(round(x * 16)), int(round(y * 16))), 3 * 16, (255, 255, 255), -1, cv2.LINE_AA, 4)
    return im, pinhole


def _blobs(image: np.ndarray) -> np.ndarray:
    """Intensity-weighted centroids of the bright blobs of an image."""
    n, labels, stats, _ = cv2.connectedComponentsWithStats((image[..., 0] > 30).astype(np.uint8))
    g = image[..., 0].astype(np.float64)
    ys, xs = np.mgrid[:g.shape[0], :g.shape[1]]
    out = []
    for i in range(1, n):
        if stats[i, cv2.CC_STAT_AREA] >= 8:
            w = np.where(labels == i, g, 0.0)
            out.append([(w * xs).sum() / w.sum(), (w * ys).sum() / w.sum()])
    return np.array(out).reshape(-1, 2)


@pytest.mark.parametrize("model, params, dist", [
    ("SIMPLE_RADIAL", [200.0, 160.0, 120.0, -0.15], [-0.15, 0, 0, 0, 0]),
    ("RADIAL", [200.0, 160.0, 120.0, -0.2, 0.05], [-0.2, 0.05, 0, 0, 0]),
    ("OPENCV", [200.0, 205.0, 160.0, 120.0, -0.2, 0.04, 0.004, -0.003], [-0.2, 0.04, 0.004, -0.003, 0]),
    ("poses.csv", None, [-0.22, 0.03, 0.0, 0.002, 0.01]),
])
def test_a_distorted_camera_is_undistorted_as_its_folder_is_read(tmp_path: Path, model, params, dist) -> None:
    """A lens with known distortion (COLMAP's SIMPLE_RADIAL, RADIAL, OPENCV in cameras.txt, or
    OpenCV's k1 k2 p1 p2 k3 in poses.csv) photographs a grid of dots: read back, the images are
    pinhole again: every dot lies where the pinhole camera of the folder puts it (0.5 px), where
    the distorted image had it up to several pixels off (before: refused, 'only PINHOLE')."""
    fx, fy = (200.0, 205.0) if model == "OPENCV" else (200.0, 200.0)
    K = np.array([[fx, 0.0, 159.5], [0.0, fy, 119.5], [0.0, 0.0, 1.0]])  # COLMAP's cx, cy = 160, 120
    distorted, centres = _dots(K, np.array(dist, dtype=np.float64))
    seen = _blobs(distorted)
    assert np.linalg.norm(seen[:, None] - centres[None], axis=2).min(axis=1).max() > 3.0  # the lens bends the grid
    views = CapturedViews(names=["a.png", "b.png"], images=[distorted, distorted], reported=ring(2), K=K)
    folder = write_flight(views, tmp_path / "f")
    if model == "poses.csv":
        rows = list(csv.reader(open(folder / POSES_FILE)))
        rows[0] += ["k1", "k2", "p1", "p2", "k3"]
        for r in rows[1:]:
            r += [repr(v) for v in dist]
        with open(folder / POSES_FILE, "w", newline="") as f:
            csv.writer(f).writerows(rows)
    else:
        (folder / POSES_FILE).unlink()
        (folder / "cameras.txt").write_text(f"1 {model} 320 240 " + " ".join(map(repr, params)) + "\n")
    back = read_flight(folder)
    assert back.seconds["undistort"] > 0
    K2 = back.K
    expected = (K2 @ np.linalg.inv(K) @ np.hstack([centres, np.ones((len(centres), 1))]).T).T[:, :2]
    found = _blobs(back.images[0])
    w, h = back.size
    inner = expected[(expected[:, 0] > 8) & (expected[:, 0] < w - 9) & (expected[:, 1] > 8) & (expected[:, 1] < h - 9)]
    d = np.linalg.norm(found[:, None] - inner[None], axis=2).min(axis=0)
    assert len(inner) > 60 and np.median(d) < 0.25 and d.max() < 0.6, (np.median(d), d.max())
    assert w >= 320 and h >= 240  # COLMAP's undistorter keeps every pixel of a barrel lens's image (no blank pixels)


def test_bad_distortion_columns_are_refused(tmp_path: Path, capsys) -> None:
    rng = np.random.default_rng(0)
    views = CapturedViews(names=["a.png", "b.png"], images=[rng.integers(0, 255, (48, 64, 3), np.uint8)] * 2,
                          reported=ring(2), K=np.array([[32.0, 0, 31.5], [0, 32.0, 23.5], [0, 0, 1]]))
    folder = write_flight(views, tmp_path / "f")
    rows = list(csv.reader(open(folder / POSES_FILE)))
    rows[0].append("k7")
    for r in rows[1:]:
        r.append("0.1")
    with open(folder / POSES_FILE, "w", newline="") as f:
        csv.writer(f).writerows(rows)
    assert recon_main(["--images", str(folder), "--out", str(tmp_path / "never"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("recon: error:") and "k1,k2,p1,p2,k3" in err and err.count("\n") == 1, err


def _rolled_flight(scene, degrees: float, size=(640, 480)) -> tuple[CapturedViews, np.ndarray]:
    """An ideal render of 6 cameras on a 75-degree arc whose cameras are then turned ``degrees`` about their
    optical axes (alternating sign): each image warped by the rotation's homography K R' R^T K^-1,
    the poses reported with that roll (a 2 cm / 0.3 degree report error on top)."""
    cams = ring(6, radius=1.2, arc_deg=75.0)
    views = render_flight(scene, 0, cams, ReconConfig(width=size[0], height=size[1], num_threads=1, capture=IDEAL))
    truth = rolled(cams, degrees * np.array([1, -1, 1, -1, 1, -1]))
    K = views.K
    R0, R1 = world_to_camera(cams)[0], world_to_camera(truth)[0]
    images = [cv2.warpPerspective(im, K @ r1 @ r0.T @ np.linalg.inv(K), size, borderValue=(0, 0, 255))
              for im, r0, r1 in zip(views.images, R0, R1)]
    rng = np.random.default_rng(3)
    turn = Rotation.from_rotvec(np.radians(0.3) * rng.standard_normal((6, 3)))
    reported = np.hstack([truth[:, :3] + 0.02 * rng.standard_normal((6, 3)),
                          (turn * Rotation.from_quat(truth[:, 3:])).as_quat()])
    return CapturedViews(names=views.names, images=images, reported=reported, K=K, realization=0), truth


@pytest.fixture(scope="module")
def rolled_flight(noisy_scene):
    return _rolled_flight(noisy_scene, 5.0)


@pytest.mark.parametrize("mode", ["anchored", "incremental"])
def test_a_flight_of_rolled_cameras_reconstructs_where_the_plant_is(noisy_scene, rolled_flight, tmp_path: Path,
                                                                    mode) -> None:
    """6 cameras rolled +-5 degrees about their optical axes (a drone without a roll gimbal),
    reported with that roll: every image registers, the model's cameras keep the roll (within 1
    degree) and lie within centimetres of the truth, and the sparse cloud lies on the plant
    (median distance to the true points under 2.5 cm: the reports' 2 cm). With the roll dropped (the old [c, v]
    cameras) the triangulation sees 5-degree errors: about 30 px at these images' edges."""
    from scipy.spatial import cKDTree

    views, truth = rolled_flight
    capture = CaptureModel.named("realistic", report_position_sigma=0.02, report_attitude_sigma=0.5, gcp_markers=0)
    cfg = ReconConfig(width=640, height=480, num_threads=1, capture=capture, dense=False, sparse_mode=mode,
                      ground=False)
    vr = reconstruct_views(views, cfg, tmp_path / "w")
    sp = vr.sparse
    assert sp.registered == 6 and sp.mode == mode, (sp.registered, sp.mode, sp.fallback)
    np.testing.assert_allclose(np.degrees(roll_of(sp.cameras)), np.degrees(roll_of(truth)), atol=1.0)
    assert np.linalg.norm(sp.cameras[:, :3] - truth[:, :3], axis=1).max() < 0.06
    d, _ = cKDTree(noisy_scene.points[0]).query(vr.points)
    assert len(vr.points) > 100 and np.median(d) < 0.025, (len(vr.points), np.median(d))


def test_rough_attitudes_leave_a_failed_structure_from_motion_failed(rolled_flight, tmp_path: Path,
                                                                    monkeypatch) -> None:
    """Reported attitudes rougher than 2 degrees are weighed against the centres by their sigma
    (the registration gets (position, attitude) sigmas; good ones alone give its rotation, as
    before), and when COLMAP's SfM fails, the model anchored on the reported poses takes its place
    only when they are good: with a 30-degree sigma it would triangulate at attitudes that far off
    and 'register' every image (the dev scan's 10 views: 10 of 10, 8 points kept); the SfM's
    failure is the reconstruction's instead."""
    from vp_recon import sparse_modes
    from vp_recon.errors import RECONSTRUCTION_FAILED, ReconError, SparseError

    weights = []

    def two_of_six(matched, options, anchor, *args):
        weights.append(anchor.sigmas)  # the registration's sigmas: (position m, attitude rad) or None
        raise SparseError("incremental mapping registered 2 of 6 images in its largest model")

    monkeypatch.setattr(sparse_modes, "incremental_model", two_of_six)
    views, _ = rolled_flight
    for sigma in (30.0, 0.5):
        capture = CaptureModel.named("realistic", report_attitude_sigma=sigma, gcp_markers=0)
        cfg = ReconConfig(width=640, height=480, num_threads=1, capture=capture, dense=False,
                          sparse_mode="incremental", ground=False)
        if sigma > 2:
            with pytest.raises(ReconError, match="registered 2 of 6 images") as err:
                reconstruct_views(views, cfg, tmp_path / "rough")
            assert err.value.code == RECONSTRUCTION_FAILED and "anchored" not in str(err.value)
        else:
            sp = reconstruct_views(views, cfg, tmp_path / "good").sparse
            assert sp.mode == "anchored" and "2 of 6" in sp.fallback and sp.registered == 6
    assert weights[0] == pytest.approx((0.02, math.radians(30.0))) and weights[1] is None


def test_a_rough_attitude_prior_registers_on_the_centres() -> None:
    """A rig whose reported attitudes are all 20 degrees off (a camera mount looking down while
    the robot reports level) on an arc of 12 centres (150 degrees) known to 5 mm: with the
    attitudes trusted (sigma None, as before) the model is turned by degrees (on a whole
    circle the offsets would cancel); with their sigma (30 degrees) against the centres' (5 mm)
    it is registered on the centres (Umeyama's rotation within 0.5 degree, the truth within 1);
    a small attitude sigma keeps the attitudes' chordal mean."""
    rng = np.random.default_rng(1)
    az = np.radians(np.linspace(0.0, 150.0, 12))
    c = np.stack([0.375 + 0.3 * np.cos(az), 0.375 + 0.3 * np.sin(az), np.full(12, 0.08)], axis=1)
    true_cams = look_at(c, [0.375, 0.375, -0.03])
    R_true = world_to_camera(true_cams)[0]
    s, R, t = 2.5, Rotation.from_euler("xyz", [30, -10, 80], degrees=True).as_matrix(), np.array([1.0, 2.0, 3.0])
    model_c = (c - t) @ R / s
    model_R = np.einsum("nij,jk->nik", R_true, R)
    level = np.hstack([[0.375, 0.375] - c[:, :2], np.zeros((12, 1))])
    reported_R = world_to_camera(np.hstack([c, level]))[0]  # the robot says level: 20 degrees above the true axes
    reported_c = c + 0.005 * rng.standard_normal(c.shape)

    def turn(M):
        Rm = M[:, :3] / np.cbrt(np.linalg.det(M[:, :3]))
        return np.degrees(Rotation.from_matrix(Rm @ R.T).magnitude())

    trusted = similarity_from_poses(model_c, model_R, reported_c, reported_R)
    rough = similarity_from_poses(model_c, model_R, reported_c, reported_R, sigmas=(0.005, math.radians(30.0)))
    a, b = model_c - model_c.mean(axis=0), reported_c - reported_c.mean(axis=0)
    U, _, Vt = np.linalg.svd(b.T @ a)  # the centres alone: Umeyama's rotation
    Ru = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt
    off = np.degrees(Rotation.from_matrix(rough[:, :3] / np.cbrt(np.linalg.det(rough[:, :3])) @ Ru.T).magnitude())
    assert turn(trusted) > 5.0 and off < 0.5 and turn(rough) < 1.0, (turn(trusted), off, turn(rough))
    assert np.cbrt(np.linalg.det(rough[:, :3])) == pytest.approx(s, rel=0.03)
    tight = similarity_from_poses(model_c, model_R, reported_c, reported_R, sigmas=(0.005, math.radians(0.01)))
    np.testing.assert_allclose(tight, trusted, atol=1e-3)
    # the capture model takes such a sigma (it was capped at 10 degrees), and 'auto' leaves the poses to the images
    cap = CaptureModel.named("realistic", report_attitude_sigma=30.0)
    assert ReconConfig(capture=cap).sparse_mode_used == "incremental"
    with pytest.raises(ValueError, match="at most 180"):
        CaptureModel.named("realistic", report_attitude_sigma=200.0)


def test_a_rolled_pose_is_drawn_rolled_in_the_viewer() -> None:
    from vp_recon.viewer import frustum_poses

    poses = rolled(ring(3), [0.0, 20.0, -45.0])
    wxyz, pos = frustum_poses(poses)
    R_wc = Rotation.from_quat(wxyz[:, [1, 2, 3, 0]]).as_matrix()  # viser's OpenCV frame in the world
    np.testing.assert_allclose(np.swapaxes(R_wc, 1, 2), world_to_camera(poses)[0], atol=1e-9)
    np.testing.assert_allclose(pos, poses[:, :3])


def _fake_romi(folder: Path, n: int = 3) -> Path:
    """A ROMI scan folder of n small images on a circle (the layout of plant-3d-vision's scans)."""
    (folder / "images").mkdir(parents=True)
    (folder / "metadata" / "images").mkdir(parents=True)
    rng = np.random.default_rng(0)
    for i in range(n):
        cv2.imwrite(str(folder / "images" / f"{i:05d}_rgb.jpg"), rng.integers(0, 255, (48, 64, 3), dtype=np.uint8))
        pan = 270.0 + 360.0 * i / n
        x, y = 375 - 300 * math.cos(math.radians(pan - 270)), 375 - 300 * math.sin(math.radians(pan - 270))
        c = np.array([x, y, 80.0]) / 1000.0
        R_cw = world_to_camera(look_at(c, [0.375, 0.375, -0.03]))[0]
        (folder / "metadata" / "images" / f"{i:05d}_rgb.json").write_text(json.dumps({
            "approximate_pose": [x, y, 80, pan, 0],
            "colmap_camera": {"camera_model": {"model": "OPENCV", "width": 64, "height": 48,
                                               "params": [50.0, 50.0, 32.0, 24.0, -0.05, 0.01, 0.0, 0.0]},
                              "rotmat": R_cw.tolist(), "tvec": (-R_cw @ c * 1000.0).tolist()}}))
    return folder


def test_the_romi_importer_writes_a_flight_folder_in_metres(tmp_path: Path, capsys) -> None:
    """The importer on a scan folder of ROMI's layout: the images copied byte for byte, poses.csv
    in metres in the rig's frame with the scan's OPENCV camera (OpenCV's convention: cx - 0.5)
    and distortion; the approximate poses levelled and looking at the circle's centre (pan + 90
    degrees), the COLMAP ones as given (roll kept); bad input one line, exit 2, nothing written."""
    from vp_recon.importers import import_romi, main as import_main

    scan = _fake_romi(tmp_path / "scan")
    out = import_romi(scan, tmp_path / "flight")
    assert (out / "00001_rgb.jpg").read_bytes() == (scan / "images" / "00001_rgb.jpg").read_bytes()
    rows = list(csv.DictReader(open(out / POSES_FILE)))
    assert [r["image"] for r in rows] == ["00000_rgb.jpg", "00001_rgb.jpg", "00002_rgb.jpg"]
    assert (float(rows[0]["cx"]), float(rows[0]["k1"]), float(rows[0]["k3"])) == (31.5, -0.05, 0.0)
    views = read_flight(out)
    cams = poses_to_cameras(views.reported)
    np.testing.assert_allclose(np.hypot(cams[:, 0] - 0.375, cams[:, 1] - 0.375), 0.3, atol=1e-9)
    to_centre = np.array([0.375, 0.375]) - cams[:, :2]
    np.testing.assert_allclose(cams[:, 3:5] / np.linalg.norm(cams[:, 3:5], axis=1, keepdims=True),
                               to_centre / np.linalg.norm(to_centre, axis=1, keepdims=True), atol=1e-9)
    np.testing.assert_allclose(cams[:, 5], 0.0, atol=1e-12)  # tilt 0 reported: levelled
    ref = read_flight(import_romi(scan, tmp_path / "reference", pose="colmap"))
    np.testing.assert_allclose(ref.reported[:, :3], views.reported[:, :3], atol=1e-9)
    assert np.all(poses_to_cameras(ref.reported)[:, 5] < -0.3)  # the refined axes look down
    assert json.loads((out / "flight.json").read_text())["pose"] == "approximate"
    sparse = import_romi(scan, tmp_path / "every2", every=2)
    assert sorted(p.name for p in sparse.glob("*.jpg")) == ["00000_rgb.jpg", "00002_rgb.jpg"]

    for args, text in ((["romi", str(scan), str(out)], "exists"),
                       (["romi", str(tmp_path / "flight"), str(tmp_path / "x")], "not a ROMI scan folder")):
        assert import_main(args) == 2
        err = capsys.readouterr().err
        assert err.startswith("import: error:") and text in err and err.count("\n") == 1, err
    (scan / "metadata" / "images" / "00002_rgb.json").write_text("{}")
    assert import_main(["romi", str(scan), str(tmp_path / "y")]) == 2
    err = capsys.readouterr().err
    assert "00002_rgb.json: no camera model" in err and not (tmp_path / "y").exists()
    assert not list(tmp_path.glob(".y-*"))  # no staging folder left


@needs_romi
def test_the_dev_scan_imports_and_reads_as_four_undistorted_views(tmp_path: Path) -> None:
    """The real scan: 4 of its 60 images (every 15th) imported with the robot's poses: centres
    on its 0.3 m circle about (0.375, 0.375) within 7 mm of COLMAP's refined ones, which look
    about 20 degrees down with a roll of a few degrees (the camera is not level); read back,
    the OPENCV camera (k1 = -0.007) is undistorted to a pinhole one of about the same size."""
    from vp_recon.importers import import_romi

    flight = import_romi(ROMI, tmp_path / "approximate", every=15)
    ref = import_romi(ROMI, tmp_path / "colmap", pose="colmap", every=15)
    views, colmap = read_flight(flight), read_flight(ref)
    assert views.names == ["00000_rgb.jpg", "00015_rgb.jpg", "00030_rgb.jpg", "00045_rgb.jpg"]
    c = views.reported[:, :3]
    np.testing.assert_allclose(np.hypot(c[:, 0] - 0.375, c[:, 1] - 0.375), 0.3, atol=1e-6)
    assert np.linalg.norm(colmap.reported[:, :3] - c, axis=1).max() < 0.007
    tilt = np.degrees(np.arcsin(-poses_to_cameras(colmap.reported)[:, 5]))
    assert np.all((tilt > 17) & (tilt < 23)) and np.abs(np.degrees(roll_of(colmap.reported))).max() > 1.0
    w, h = views.size
    assert abs(w - 1440) <= 10 and abs(h - 1080) <= 10 and views.seconds["undistort"] > 0
    assert views.K[0, 0] == pytest.approx(1158.76, abs=1.0)
