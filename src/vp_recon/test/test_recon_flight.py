"""A flight folder (issue 20, part 3): write_flight / read_flight, ``--images DIR`` on the path of
rendered plans, one-line errors (exit 2, nothing written) for every bad input; the metrics
without a ground truth (part 4)."""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from vp_scene.camera import as_poses, poses_to_cameras, world_to_camera
from vp_scene.capture import IDEAL
from vp_scene.ground_control import GroundControl

from vp_recon.cli import main
from vp_recon.config import ReconConfig
from vp_recon.flight import CapturedViews, read_flight, write_flight
from vp_scene.flight_poses import POSES_FILE, FlightError
from vp_recon.metrics import coverage_of_prior
from vp_recon.pipeline import reconstruct_views, render_flight
from vp_recon.results import Prior

SCENE = {"scenario": "one_plant", "models": None, "seed": 0, "points_per_plant": 2000, "plant_spacing": 0.6,
         "row_spacing": 0.76, "levels": 10, "realizations": 2, "wind_variance": 0.002, "wind_direction": 0.0}


def ring(n: int = 6, radius: float = 1.6, height: float = 1.3, arc: float = math.radians(150)) -> np.ndarray:
    az = np.linspace(0.0, arc, n)
    c = np.stack([radius * np.cos(az), radius * np.sin(az), np.full(n, height)], axis=1)
    return np.concatenate([c, np.array([0.0, 0.0, 0.9]) - c], axis=1)


@pytest.fixture(scope="module")
def scene():
    from vp_scene.build import build_noisy_scene

    return build_noisy_scene(**SCENE)[0]


def _plan(tmp_path: Path) -> Path:
    p = tmp_path / "plan.json"
    p.write_text(json.dumps({"scenario": "one_plant", "method": "ring", "cameras": ring().tolist(),
                             "fov": math.pi / 2, "scene": SCENE}))
    return p


def test_a_rendered_flight_written_as_a_folder_reconstructs_again(scene, tmp_path: Path, capsys) -> None:
    """Round trip: write_flight of a rendered flight -> ``--images`` gives what the library path
    gives for the same views (same images, the poses through poses.csv), and COLMAP reads the
    text model it wrote."""
    import pycolmap

    cfg = ReconConfig(width=640, height=480, num_threads=1, capture=IDEAL)
    views = render_flight(scene, 1, ring(), cfg)
    folder = write_flight(views, tmp_path / "flight", meta={"capture": IDEAL.to_dict()})
    assert {p.name for p in folder.iterdir()} >= {POSES_FILE, "cameras.txt", "images.txt", "flight.json",
                                                   "view_000.png"}
    back = read_flight(folder)
    assert back.names == views.names and back.realization == 1
    assert all(np.array_equal(a, b) for a, b in zip(back.images, views.images))  # PNG: lossless
    np.testing.assert_allclose(back.K, views.K)
    np.testing.assert_allclose(back.reported, as_poses(views.reported), atol=1e-12)  # read as poses (N, 7)
    rec = pycolmap.Reconstruction()
    rec.read_text(str(folder))
    centres = {im.name: np.asarray(im.projection_center()) for im in rec.images.values()}
    for name, c in zip(views.names, views.reported[:, :3]):
        np.testing.assert_allclose(centres[name], c, atol=1e-9)

    direct = reconstruct_views(views, cfg, prior=Prior.of_scene(scene))
    out = tmp_path / "out"
    rc = main(["--images", str(folder), "--out", str(out), "--prior", str(_plan(tmp_path)), "--capture", "ideal",
               "--threads", "1", "--no-progress"])
    assert rc == 0, capsys.readouterr().err
    data = json.loads((out / "recon.json").read_text())
    assert data["source"] == "images" and data["registered_images"] == direct.sparse.registered == 6
    assert data["points"] == len(direct.points)
    assert data["coverage_of_prior"] == pytest.approx(direct.coverage.fraction)
    assert 0.2 < data["coverage_of_prior"] <= 1.0 and len(data["coverage_of_prior_per_plant"]) == 1
    assert 0 < data["mean_reprojection_error"] < 2.0 and data["mean_track_length"] >= 2.0
    assert data["realization"] == 1 and 0.1 < data["chamfer_mean"] < 10.0  # the prior's realization 1: scored
    assert (out / "recon.ply").is_file() and (out / "uncovered.png").stat().st_size > 1000

    # the same folder through COLMAP's text model alone
    (folder / POSES_FILE).unlink()
    back2 = read_flight(folder)
    for a, b in zip(world_to_camera(back2.reported), world_to_camera(back.reported)):  # q and -q: one rotation
        np.testing.assert_allclose(a, b, atol=1e-9)
    np.testing.assert_allclose(back2.K, back.K, atol=1e-9)


def test_a_drone_rendering_its_own_camera_sees_what_the_plan_render_gives_it(scene) -> None:
    """render_flight of camera i alone (indices=[i], as a simulated drone holding pose i would)
    gives the whole plan's image and reported pose of camera i bit for bit (realistic capture:
    hover and localization errors and sensor noise seeded by realization and camera index)."""
    cfg = ReconConfig(width=320, height=240, num_threads=1)
    cams = ring()
    full = render_flight(scene, 1, cams, cfg)
    one = render_flight(scene, 1, cams[[4]], cfg, indices=[4])
    assert one.names == ["view_004.png"] and np.array_equal(one.images[0], full.images[4])
    np.testing.assert_array_equal(one.reported[0], full.reported[4])
    other = render_flight(scene, 1, cams[[4]], cfg, indices=[0])  # another index: other draws
    assert not np.array_equal(other.reported[0], one.reported[0])
    from vp_recon.errors import ReconError

    with pytest.raises(ReconError, match="indices"):
        render_flight(scene, 1, cams[:2], cfg, indices=[3, 3])


def _small_flight(tmp_path: Path, n: int = 3) -> Path:
    rng = np.random.default_rng(0)
    views = CapturedViews(names=[f"im{i}.png" for i in range(n)],
                          images=[rng.integers(0, 255, (48, 64, 3), dtype=np.uint8) for _ in range(n)],
                          reported=ring(n), K=np.array([[32.0, 0, 31.5], [0, 32.0, 23.5], [0, 0, 1]]))
    folder = tmp_path / f"flight{len(list(tmp_path.glob('flight*')))}"  # a fresh folder each time
    return write_flight(views, folder)


def _edit_poses(folder: Path, row: int, column: str, value: str) -> None:
    rows = list(csv.reader(open(folder / POSES_FILE)))
    rows[row][rows[0].index(column)] = value
    with open(folder / POSES_FILE, "w", newline="") as f:
        csv.writer(f).writerows(rows)


def _refused(tmp_path: Path, folder: Path, capsys, *names: str, args: tuple = ()) -> str:
    out = tmp_path / "never"
    rc = main(["--images", str(folder), "--out", str(out), "--no-progress", *args])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert err.startswith("recon: error:") and err.count("\n") == 1, err
    for name in names:
        assert name in err, (name, err)
    assert not out.exists()  # nothing half-written
    return err


def test_bad_flight_folders_are_refused_naming_the_file(tmp_path: Path, capsys) -> None:
    f = _small_flight(tmp_path)
    assert read_flight(f).size == (64, 48)
    (f / "im1.png").write_bytes(b"not a png at all")
    _refused(tmp_path, f, capsys, "im1.png", "corrupt")

    f = _small_flight(tmp_path)
    cv2.imwrite(str(f / "im2.png"), np.zeros((40, 60, 3), np.uint8))
    _refused(tmp_path, f, capsys, "im2.png", "60x40", "64x48")

    f = _small_flight(tmp_path)
    _edit_poses(f, 2, "qz", "nan")
    _refused(tmp_path, f, capsys, "poses.csv line 3", "im1.png", "NaN")

    f = _small_flight(tmp_path)
    _edit_poses(f, 1, "x", "")
    _refused(tmp_path, f, capsys, "poses.csv line 2", "im0.png", "missing pose")

    f = _small_flight(tmp_path)
    cv2.imwrite(str(f / "extra.jpg"), np.zeros((48, 64, 3), np.uint8))  # an image without a pose
    _refused(tmp_path, f, capsys, "extra.jpg", "missing pose")

    f = _small_flight(tmp_path)
    _edit_poses(f, 3, "image", "im0.png")
    (f / "im2.png").unlink()
    _refused(tmp_path, f, capsys, "poses.csv line 4", "duplicate", "im0.png")

    f = _small_flight(tmp_path)
    (f / "im2.png").unlink()
    _refused(tmp_path, f, capsys, "im2.png", "missing")

    f = _small_flight(tmp_path)
    _edit_poses(f, 1, "frame", "odom")
    _refused(tmp_path, f, capsys, "im0.png", "odom")

    f = _small_flight(tmp_path, n=2)
    (f / POSES_FILE).write_text("".join((f / POSES_FILE).read_text().splitlines(keepends=True)[:2]))
    (f / "im1.png").unlink()
    _refused(tmp_path, f, capsys, "poses.csv", "at least 2")

    f = _small_flight(tmp_path)
    (f / POSES_FILE).unlink()
    (f / "cameras.txt").write_text("1 OPENCV_FISHEYE 64 48 32 32 31.5 23.5 0.1 0 0 0\n")
    _refused(tmp_path, f, capsys, "cameras.txt line 1", "'OPENCV_FISHEYE' is not read", "SIMPLE_RADIAL, RADIAL, OPENCV")
    (f / "cameras.txt").write_text("1 OPENCV 64 48 32 32 31.5 23.5 0.1 0\n")
    _refused(tmp_path, f, capsys, "cameras.txt line 1", "OPENCV has 8 parameters", "got 6")
    (f / "cameras.txt").unlink()
    _refused(tmp_path, f, capsys, "no poses.csv")
    with pytest.raises(SystemExit) as ei:  # the options of rendering a plan do not apply to a folder
        main(["--images", str(f), "--out", str(tmp_path / "never"), "--width", "640", "--realizations", "0"])
    err = capsys.readouterr().err
    assert ei.value.code == 2 and "--width, --realizations go(es) with --plan" in err and err.count("\n") == 1
    assert not (tmp_path / "never").exists()
    with pytest.raises(FlightError, match="not a folder"):
        read_flight(tmp_path / "nowhere")


def test_an_oversize_or_truncated_image_is_refused_before_anything_is_decoded(tmp_path: Path, capsys,
                                                                               monkeypatch) -> None:
    """Hardening III, items 4-6: a 30000 x 30000 PNG (0.1 MB here, 2.7 GB decoded) was decoded in
    full before its size was refused (34 s, 5.4 GB) and, with that size in poses.csv, ended in a
    cv2 allocation traceback (exit 1); a truncated JPEG was read with its lower half grey and
    reconstructed (exit 0); a folder's images are held at once, whatever their pixels. Now: exit
    2, one line naming the file, and nothing is decoded of a folder whose headers are refused."""
    from PIL import Image

    f = _small_flight(tmp_path)
    Image.new("1", (30000, 30000)).save(f / "im1.png")
    with monkeypatch.context() as tripwire:  # OpenCV's decoders must not run
        tripwire.setattr(cv2, "imdecode", lambda *a, **k: pytest.fail("an image was decoded"))
        tripwire.setattr(cv2, "imread", lambda *a, **k: pytest.fail("an image was decoded"))
        _refused(tmp_path, f, capsys, "im1.png", "30000x30000 pixels (900 MP); an image may have at most 150 MP")
        for row in (1, 2, 3):  # the size declared in poses.csv as well: beyond any image's side
            _edit_poses(f, row, "width", "30000")
            _edit_poses(f, row, "height", "30000")
        _refused(tmp_path, f, capsys, "poses.csv", "the image width must be an integer of 16 to 16384 pixels, "
                 "got 30000")
        f = _small_flight(tmp_path)  # 3 images of 64 x 48
        _refused(tmp_path, f, capsys, f"{f}: its 3 images have 0.009216 megapixels; at most 0.009 are reconstructed "
                 "at once (--max-megapixels", args=("--max-megapixels", "0.009"))

    rng = np.random.default_rng(2)
    views = CapturedViews(names=[f"im{i}.jpg" for i in range(3)],
                          images=[cv2.GaussianBlur(rng.integers(0, 255, (48, 64, 3), dtype=np.uint8), (5, 5), 2)
                                  for _ in range(3)],
                          reported=ring(3), K=np.array([[32.0, 0, 31.5], [0, 32.0, 23.5], [0, 0, 1]]))
    f = write_flight(views, tmp_path / "jpeg_flight")
    whole = (f / "im1.jpg").read_bytes()
    (f / "im1.jpg").write_bytes(whole[: len(whole) * 2 // 3])
    _refused(tmp_path, f, capsys, "im1.jpg", "corrupt or truncated JPEG")
    with pytest.raises(FlightError, match=r"im1.jpg: corrupt or truncated JPEG"):
        read_flight(f)


def test_a_pose_file_is_bounded_its_byte_order_mark_read_and_its_rows_counted_as_read(tmp_path: Path,
                                                                                         capsys) -> None:
    """A poses.csv coordinate of 1e300 ended in an OverflowError traceback of the
    dense step; a UTF-8 byte-order mark (a spreadsheet's CSV) made the header wrong while the error
    printed one that looked the same; a 400,000-row poses.csv was read whole, each name looked up
    in a list (20,000 rows: 5 s). Now: every position and quaternion within MAX_COORDINATE (exit 2,
    the line named), the mark read as one, at most MAX_POSES rows counted as they are read."""
    from vp_scene.flight_poses import MAX_POSES, read_pose_files

    f = _small_flight(tmp_path)
    _edit_poses(f, 1, "x", "1e300")
    _refused(tmp_path, f, capsys, "poses.csv line 2 (im0.png): the pose holds 1e+300, outside [-10000, 10000]")
    f = _small_flight(tmp_path)
    _edit_poses(f, 2, "qw", "-2e4")
    _refused(tmp_path, f, capsys, "poses.csv line 3 (im1.png): the pose holds -20000")
    f = _small_flight(tmp_path)  # COLMAP's text model: the centre -R^T t of a translation 1e300
    (f / POSES_FILE).unlink()
    lines = (f / "images.txt").read_text().splitlines()
    i = next(n for n, t in enumerate(lines) if t.endswith(" im1.png"))
    lines[i] = " ".join(lines[i].split()[:5] + ["1e300"] + lines[i].split()[6:])
    (f / "images.txt").write_text("\n".join(lines) + "\n")
    _refused(tmp_path, f, capsys, f"images.txt line {i + 1} (im1.png): the pose holds 1e+300")

    f = _small_flight(tmp_path)
    (f / POSES_FILE).write_bytes(b"\xef\xbb\xbf" + (f / POSES_FILE).read_bytes())
    assert read_flight(f).names == ["im0.png", "im1.png", "im2.png"]
    text = (f / POSES_FILE).read_text(encoding="utf-8-sig")
    (f / POSES_FILE).write_text(text.replace("image,", "image\u200b,", 1))  # a header that looks the same
    _refused(tmp_path, f, capsys, "the first line must be the header", "got 'image\\u200b,x,y,z")

    # rows past MAX_POSES are not read: what follows the limit (here: no row at all) is never parsed
    rows = text.splitlines()
    big = tmp_path / "big"
    big.mkdir()
    (big / POSES_FILE).write_text("\n".join([rows[0]] + [rows[1].replace("im0.png", f"v{i}.png")
                                                          for i in range(MAX_POSES + 1)]
                                            + ["not a row"] * 1000) + "\n")
    with pytest.raises(FlightError, match=rf"poses.csv: more than {MAX_POSES} images; a pose file lists at most "
                                          rf"{MAX_POSES} \(the rest of the file was not read\)"):
        read_pose_files(big)
    (big / POSES_FILE).write_text("\n".join([rows[0]] + [rows[1].replace("im0.png", f"v{i}.png")
                                                          for i in range(MAX_POSES)]) + "\n")
    names, poses, cams, _ = read_pose_files(big)  # the limit itself: read
    assert len(names) == len(set(names)) == MAX_POSES and poses.shape == (MAX_POSES, 7)
    _refused(tmp_path, big, capsys, "v0.png: missing (listed in poses.csv)")


def test_ground_control_in_another_frame_is_refused_naming_the_line(tmp_path: Path, capsys) -> None:
    """A gcp_list.txt in UTM (its points 500 km from the flight's poses, in
    map) was taken and gave nothing in recon.json. A control point is in the poses' frame, within
    MAX_COORDINATE of map's origin: refused before anything is read, naming the line and the
    coordinate system the file gives (not converted). Nearer ones that do not fit the poses are
    rejected by the registration (test_recon_anchored)."""
    f = _small_flight(tmp_path)
    (f / "gcp_list.txt").write_text("+proj=utm +zone=15 +datum=WGS84 +units=m +no_defs\n"
                                    "500123.5 4980456.25 280.0 31.5 23.5 im0.png gcp1\n")
    _refused(tmp_path, f, capsys, "gcp_list.txt, line 2: geo_x, geo_y, geo_z holds 500124, outside [-10000, 10000]",
             "(the poses' frame, metres; the coordinate system '+proj=utm +zone=15")
    (f / "gcp_list.txt").unlink()
    (f / "markers.csv").write_text("id,x,y,z\n0,1.0,2.0,0.0\n3,0.5,-20000,0.0\n")
    _refused(tmp_path, f, capsys, "markers.csv, line 3: marker 3 holds -20000", "(markers.csv is in the poses' frame)")


def test_a_truncated_png_is_refused_in_one_line(tmp_path: Path, capfd) -> None:
    """Hardening III, item 11: a flight folder with a truncated PNG is refused with exit 2 and one
    line on the process's stderr (capfd: the file descriptor, where libpng printed its own
    'libpng error: Read Error' before the CLI's line), and no OUT."""
    rng = np.random.default_rng(1)
    views = CapturedViews(names=["im0.png", "im1.png"],
                          images=[rng.integers(0, 255, (240, 320, 3), dtype=np.uint8) for _ in range(2)],
                          reported=ring(2), K=np.array([[160.0, 0, 159.5], [0, 160.0, 119.5], [0, 0, 1]]))
    folder = write_flight(views, tmp_path / "flight")
    data = (folder / "im1.png").read_bytes()
    (folder / "im1.png").write_bytes(data[:len(data) // 2])
    out = tmp_path / "never"
    assert main(["--images", str(folder), "--out", str(out), "--no-progress"]) == 2
    err = capfd.readouterr().err
    assert err.startswith("recon: error:") and "im1.png" in err and err.count("\n") == 1, err
    assert not out.exists()


def test_coverage_of_prior_per_plant_in_the_best_covered_realization() -> None:
    """Two plants, two realizations of the prior: in realization 1 half of plant 0 is within tau
    and all of plant 1 (0.75); realization 0 is covered less (0.25): the wind of the moment is
    unknown, the coverage is the best realization's; per plant each plant's best."""
    base = np.array([[0, 0, 0], [1, 0, 0], [5, 0, 0], [6, 0, 0]], float)
    plant = np.array([0, 0, 1, 1])
    prior = np.stack([base + [0, 0.5, 0], base])  # realization 0 blown 0.5 m off, then the one flown
    recon = np.array([[0, 0, 0.01], [5, 0, 0], [6.0, 0.015, 0], [1, 0.5, 0]])
    c = coverage_of_prior(recon, prior, plant, tau=0.02, realizations=2)
    assert (c.fraction, c.realization, c.block) == (0.75, 1, (4, 8))
    assert c.per_plant == (0.5, 1.0)
    assert c.covered.tolist() == [False, True, False, False, True, False, True, True]
    whole = coverage_of_prior(recon, prior.reshape(-1, 3), np.tile(plant, 2), tau=0.02)  # one block
    assert whole.fraction == 0.5 and whole.realization == 0
    with pytest.raises(ValueError, match="plant index"):
        coverage_of_prior(recon, base, plant[:2])
    with pytest.raises(ValueError, match="realizations"):
        coverage_of_prior(recon, base, plant, realizations=3)


def test_a_second_sortie_reads_the_flown_cameras_images_back_from_the_first_plans_capture_sets(tmp_path) -> None:
    """With the fleet: the cameras a second sortie names as flown are found in the capture sets
    of the earlier plan that flew them (newest first, to 1e-6), read back for realization k in
    the order named, with the field's ground markers their capture sets kept, and put before the
    new images (the new sortie photographs the same markers: one set); a camera no sortie flew,
    a realization not kept, a capture set of another camera and one of other ground control
    (other markers, or none) are named errors."""
    from vp_recon.flight import capture_folder, flown_views, join_views, locate_flown
    from vp_scene.capture import REALISTIC

    rng = np.random.default_rng(1)
    K = np.array([[32.0, 0, 31.5], [0, 32.0, 23.5], [0, 0, 1]])
    markers = REALISTIC.lay_markers(ring(6)[:, :3] * 0.3)[1]  # as the capture model surveys them

    def views(cams, k, size=(48, 64), control=markers):
        return CapturedViews(names=[f"view_{i:03d}.png" for i in range(len(cams))],
                             images=[rng.integers(0, 255, (*size, 3), dtype=np.uint8) for _ in cams],
                             reported=cams + rng.normal(0.0, 0.01, cams.shape), K=K, realization=k, control=control)

    first, other = ring(4), ring(6)[4:]
    plans = {"plan-a": first, "plan-b": other}
    kept = {}
    for name, cams in plans.items():
        for k in range(2):
            kept[(name, k)] = views(cams, k)
            write_flight(kept[(name, k)], capture_folder(tmp_path / name, k))
    flown = [(cams, tmp_path / name) for name, cams in plans.items()]
    fixed = np.vstack([first[2], other[1], first[0] + 1e-8])  # as a planner names them: any order, float noise
    located = locate_flown(flown, fixed)
    assert located == [(tmp_path / "plan-a", 2), (tmp_path / "plan-b", 1), (tmp_path / "plan-a", 0)]
    old = flown_views(located, 1)
    for got, (name, j) in zip(old.images, [("plan-a", 2), ("plan-b", 1), ("plan-a", 0)]):
        np.testing.assert_array_equal(got, kept[(name, 1)].images[j])  # PNG: lossless
    v = kept[("plan-a", 1)].reported[2]
    np.testing.assert_allclose(poses_to_cameras(old.reported[0]), np.r_[v[:3], v[3:] / np.linalg.norm(v[3:])],
                               atol=1e-9)  # read back as a pose
    new = views(ring(6)[:2], 1)
    assert old.control == markers  # read back from each capture set's markers.csv
    both = join_views([old, new]).validate()
    assert both.names == [f"view_{i:03d}.png" for i in range(5)] and both.realization == 1
    assert both.control == markers
    np.testing.assert_array_equal(both.images[3], new.images[0])
    np.testing.assert_allclose(both.reported[3:], as_poses(new.reported), atol=1e-12)  # one set: all poses

    with pytest.raises(FlightError, match=r"1 of the 2 cameras already flown \(indices \[1\]\)"):
        locate_flown(flown, np.vstack([first[1], first[1] + [0.01, 0, 0, 0, 0, 0]]))
    with pytest.raises(FlightError, match="no capture set of realization 2 kept"):
        flown_views(located, 2)
    with pytest.raises(FlightError, match="cannot be reconstructed together"):
        join_views([old, views(ring(6)[:2], 1, size=(60, 80))])
    with pytest.raises(FlightError, match="realizations 1 and 0"):
        join_views([old, views(ring(6)[:2], 0)])
    moved = GroundControl(positions={**markers.positions, "0": (9.0, 9.0, 0.0)}, sigma=markers.sigma)
    for other, words in ((moved, "4 points, sigma 0.01 m and 4 points"), (None, "4 points, sigma 0.01 m and none")):
        with pytest.raises(FlightError, match=rf"different ground control \({words}.*cannot be reconstructed together"):
            join_views([old, views(ring(6)[:2], 1, control=other)])


def test_a_capture_set_is_written_with_its_ground_control(tmp_path) -> None:
    """write_flight keeps a set's ground control, read back equal: ArUco markers as markers.csv,
    control points with their observations (a user's gcp_list.txt) as gcp_list.txt."""
    from vp_scene.ground_control import GcpObservation
    from vp_recon.flight import GCP_LIST_FILE, MARKERS_FILE

    rng = np.random.default_rng(2)
    cams = ring(3)
    K = np.array([[32.0, 0, 31.5], [0, 32.0, 23.5], [0, 0, 1]])
    names = [f"view_{i:03d}.png" for i in range(3)]
    markers = GroundControl(positions={"0": (0.1, -0.7, 0.0), "7": (1.25, 0.3, 0.001)}, sigma=0.02)
    points = GroundControl(positions={"a": (0.1, -0.7, 0.0), "b": (1.25, 0.3, 0.001)},
                           observations=(GcpObservation("a", names[0], 10.5, 20.25),
                                         GcpObservation("b", names[2], 3.0, 4.0)))
    for control, written in ((markers, MARKERS_FILE), (points, GCP_LIST_FILE)):
        views = CapturedViews(names=names, images=[rng.integers(0, 255, (48, 64, 3), dtype=np.uint8) for _ in names],
                              reported=cams, K=K, realization=0, control=control)
        folder = write_flight(views, tmp_path / written)
        assert (folder / written).is_file() and not (folder / ({MARKERS_FILE, GCP_LIST_FILE} - {written}).pop()).exists()
        assert read_flight(folder).control == control
