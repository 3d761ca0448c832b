"""Flights that reconstruct (issue 40): the model anchored on the reported poses, the choice of it
when the structure from motion fails, and ground control (markers found, triangulated, and the
model placed on them and the reported centres together)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vp_scene.camera import poses_to_cameras
from vp_scene.capture import REALISTIC, CaptureModel
from vp_scene.ground_control import GroundControl, GroundControlError, marker_layout, read_gcp_list, \
    read_markers_csv, write_markers_csv

from vp_recon import sparse_modes
from vp_recon.config import ReconConfig, SparseOptions
from vp_recon.errors import SparseError
from vp_recon.gcp import register
from vp_recon.pipeline import reconstruct_captured, render_flight
from vp_recon.segment import image_mask
from vp_recon.sparse import sparse_reconstruct


@pytest.fixture(scope="module")
def scene():
    from vp_scene.build import build_noisy_scene

    ns, _ = build_noisy_scene(scenario="one_plant", points_per_plant=3000, realizations=2, levels=5, seed=2)
    return ns


def arc(n: int = 4, radius: float = 1.6, height: float = 1.5, span: float = math.radians(90)) -> np.ndarray:
    az = np.linspace(0.0, span, n)
    c = np.stack([radius * np.cos(az), radius * np.sin(az), np.full(n, height)], axis=1)
    return np.concatenate([c, np.array([0.0, 0.0, 0.7]) - c], axis=1)


# The sparse steps below run SIFT on the images as they are (first octave 0, as make run does): the
# tests check the anchoring, the fallbacks and the markers, not the feature count of a doubled image.


@pytest.fixture(scope="module")
def flown(scene):
    """Realization 1 of a 4-camera arc flown under the realistic capture (4 ground markers)."""
    cfg = ReconConfig(width=1600, height=1200, num_threads=1)
    return cfg, render_flight(scene, 1, arc(), cfg)


def angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a = a / np.linalg.norm(a, axis=1, keepdims=True)
    b = b / np.linalg.norm(b, axis=1, keepdims=True)
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=1), -1.0, 1.0)))


def test_the_anchored_model_stays_on_the_reported_poses_and_corrects_their_attitudes(flown, tmp_path) -> None:
    """Triangulated at the reported poses (half a degree off), adjusted and registered back on
    them: every image registered, the cameras within centimetres of where they really were and
    their optical axes closer to the true ones than the reports."""
    cfg, views = flown
    masks = [image_mask(im, True) for im in views.images]
    sp = sparse_reconstruct(views.images, views.reported, views.K, tmp_path,
                            SparseOptions(mode="anchored", num_threads=1, sift_first_octave=0))
    assert sp.mode == "anchored" and sp.fallback == "" and sp.registered == 4 and len(sp.points) > 300
    actual = REALISTIC.fly(arc(), 1).actual
    assert np.all(np.linalg.norm(sp.cameras[:, :3] - actual[:, :3], axis=1) < 0.08)
    axes = poses_to_cameras(sp.cameras)[:, 3:]  # the model's poses (N, 7); the reports are the plan's [c, v]
    assert angle_deg(axes, actual[:, 3:]).mean() < angle_deg(views.reported[:, 3:], actual[:, 3:]).mean()
    assert 0.0 < sp.centre_residual < 0.08
    assert masks  # the images are a plant on soil: the pipeline's own masks find it


def test_a_structure_from_motion_that_fails_falls_back_to_the_anchored_model(flown, tmp_path, monkeypatch) -> None:
    """Choose, don't fail: the incremental mode keeps the SfM's reason and makes the anchored model
    of the same matches; with ``fallback=None`` the SfM's failure is the sparse step's. One step
    further: when the anchored model's adjustment then slides a camera further from its report
    than the self-check allows (here: one camera pushed 1 m after the last registration), the
    tracks triangulated at the reported poses are kept, the slide named too."""
    cfg, views = flown

    def no_model(*args, **kwargs):
        raise SparseError("the model of 4 registered images is inconsistent: its camera centres lie 0.42 m (RMS) "
                          "from the reported ones")

    import pycolmap

    register_parts = sparse_modes.register_parts
    calls = []

    def drift(rec, *args, **kwargs):  # the last registration (after the last adjustment) slides
        register_parts(rec, *args, **kwargs)
        calls.append(1)
        if len(calls) == sparse_modes.ANCHOR_ROUNDS + 1:
            im = rec.images[min(rec.images)]
            pose = im.cam_from_world()
            im.frame.rig_from_world = pycolmap.Rigid3d(pose.rotation, (np.asarray(pose.translation).reshape(3)
                                                                       + [1.0, 0.0, 0.0]).reshape(3, 1))

    monkeypatch.setattr(sparse_modes, "incremental_model", no_model)
    monkeypatch.setattr(sparse_modes, "register_parts", drift)
    sp = sparse_reconstruct(views.images, views.reported, views.K, tmp_path / "a",
                            SparseOptions(mode="incremental", num_threads=1, sift_first_octave=0),
                            prior_centres=views.reported[:, :3])
    assert sp.mode == "anchored" and sp.registered == 4 and "0.42 m" in sp.fallback, sp.fallback
    assert "kept the points triangulated at the reported poses" in sp.fallback, sp.fallback
    assert "from the reported ones (more than 0.20 m" in sp.fallback and sp.centre_residual == 0.0
    kept = np.isfinite(sp.cameras[:, 0])
    assert kept.sum() == 4 and len(sp.points) > 100
    np.testing.assert_allclose(sp.cameras[kept, :3], views.reported[kept, :3])
    with pytest.raises(SparseError, match="0.42 m"):
        sparse_reconstruct(views.images, views.reported, views.K, tmp_path / "b",
                           SparseOptions(mode="incremental", num_threads=1, fallback=None, sift_first_octave=0),
                           prior_centres=views.reported[:, :3])


def test_ground_markers_are_found_and_place_the_model(scene, flown) -> None:
    """The realistic capture's 4 markers are rendered, found in the images, triangulated, and the
    reconstruction is placed on them and the reported centres: the map Chamfer moves towards the
    shape Chamfer (registration error taken out), and the record says what was used."""
    cfg, views = flown
    assert views.control is not None and len(views.control.positions) == 4
    # the sparse cloud: quicker
    sparse_cfg = ReconConfig(width=1600, height=1200, num_threads=1, dense=False, sift_first_octave=0)
    with_gcp = reconstruct_captured(scene, views, sparse_cfg)
    ctl = with_gcp.control
    assert ctl["applied"] and ctl["used"] >= 3 and ctl["reprojection_px"] < 3.0, ctl
    no_cfg = ReconConfig(width=1600, height=1200, num_threads=1, dense=False, sift_first_octave=0,
                         capture=CaptureModel(gcp_markers=0))
    without = reconstruct_captured(scene, render_flight(scene, 1, arc(), no_cfg), no_cfg)
    assert without.control is None
    gap = lambda r: r.chamfer - r.chamfer_shape  # noqa: E731  (the registration's part)
    assert gap(with_gcp) < gap(without), (with_gcp.chamfer, with_gcp.chamfer_shape, without.chamfer,
                                          without.chamfer_shape)


def test_register_recovers_a_model_displaced_from_map_from_single_views() -> None:
    """A model off map by a known similarity (1 % of scale, 0.5 degree, 3 cm): markers each seen in
    ONE image only (a circle of cameras 90 degrees apart), exact pixels, reported centres 2 cm off:
    the registration brings the points back to map within millimetres (40 -> 5 mm), where triangulating the
    markers first could place none."""
    from scipy.spatial.transform import Rotation

    from vp_scene.camera import intrinsics, world_to_camera
    from vp_scene.ground_control import GcpObservation

    rng = np.random.default_rng(3)
    az = np.radians([0.0, 90.0, 180.0, 270.0])
    c = np.stack([1.8 * np.cos(az), 1.8 * np.sin(az), np.full(4, 1.6)], axis=1)
    truth_cams = np.concatenate([c, np.array([0.0, 0.0, 0.3]) - c], axis=1)
    markers = np.array([[1.1, 0.0, 0.0], [0.0, 1.1, 0.0], [-1.1, 0.0, 0.0], [0.0, -1.1, 0.0]])
    K = intrinsics(1000, 750, math.pi / 2)
    R, _ = world_to_camera(truth_cams)
    obs = []
    for i in range(4):  # camera i sees marker i alone
        y = R[i] @ (markers[i] - c[i])
        u, v = (K @ (y / y[2]))[:2]
        obs.append(GcpObservation(name=str(i), image=f"im{i}", u=float(u), v=float(v)))
    plant = rng.normal(scale=0.2, size=(200, 3)) + [0.0, 0.0, 0.6]
    s, Rm, t = 1.01, Rotation.from_rotvec(np.radians([0.3, -0.2, 0.3])).as_matrix(), np.array([0.03, -0.02, 0.01])
    off = lambda x: x @ (s * Rm).T + t  # noqa: E731  (map -> the displaced model)
    model_cams = truth_cams.copy()
    model_cams[:, :3] = off(c)
    model_cams[:, 3:] = truth_cams[:, 3:] @ Rm.T
    reported = truth_cams.copy()
    reported[:, :3] += rng.normal(scale=0.02, size=(4, 3))
    control = GroundControl(positions={str(i): tuple(m) for i, m in enumerate(markers)}, sigma=0.001,
                            observations=tuple(obs))
    pts, cams, reg = register(off(plant), model_cams, [f"im{i}" for i in range(4)], [], K, reported, control, 0.02)
    assert reg.applied and (reg.used, reg.observations) == (4, 4) and reg.reprojection_px < 2.0, reg
    before = np.linalg.norm(off(plant) - plant, axis=1).mean()
    after = np.linalg.norm(pts - plant, axis=1).mean()
    assert before > 0.02 and after < 0.008, (before, after)  # measured 0.040 -> 0.0052 (the 2 cm reports pull)


def _ring_of_markers(n: int = 6):
    """n cameras on a circle, each seeing the n markers around the plant (exact pixels): the
    cameras, their names, K and the observations."""
    from vp_scene.camera import intrinsics, project

    az = np.radians(np.arange(n) * 360.0 / n)
    c = np.stack([1.8 * np.cos(az), 1.8 * np.sin(az), np.full(n, 1.6)], axis=1)
    cams = np.concatenate([c, np.array([0.0, 0.0, 0.0]) - c], axis=1)
    markers = np.stack([1.1 * np.cos(az + 0.3), 1.1 * np.sin(az + 0.3), np.zeros(n)], axis=1)
    K = intrinsics(1000, 750, math.pi / 2)
    from vp_scene.ground_control import GcpObservation

    obs = []
    for i in range(n):
        uv, inside = project(markers, cams[i], 1000, 750)
        obs += [GcpObservation(name=str(j), image=f"im{i}", u=float(uv[j, 0]), v=float(uv[j, 1]))
                for j in np.flatnonzero(inside)]
    return cams, [f"im{i}" for i in range(n)], K, markers, tuple(obs)


def test_control_points_that_do_not_fit_the_reported_poses_are_rejected_and_named() -> None:
    """Control points far off (a file in another frame, a wrong survey) were
    fitted silently. The gate rejects a point whose rays miss it by more than what the poses and
    the survey explain, names it with its distance; the others place the model. When none fits,
    the model stays where the poses put it and the record says why."""
    import re

    from vp_recon.gcp import describe

    cams, names, K, markers, obs = _ring_of_markers()
    pts = np.random.default_rng(0).normal(scale=0.2, size=(100, 3)) + [0.0, 0.0, 0.6]
    positions = {str(j): tuple(m) for j, m in enumerate(markers)}
    positions["2"] = (markers[2][0] + 1000.0, markers[2][1], 0.0)  # 1 km off
    positions["4"] = (markers[4][0], markers[4][1] + 0.05, 0.0)  # 5 cm off: a survey error, kept
    control = GroundControl(positions=positions, sigma=0.01, observations=obs)
    out, _, reg = register(pts, cams, names, [], K, cams, control, 0.02)
    assert reg.applied and reg.listed == 6 and reg.used == 5 and list(reg.rejected) == ["2"], reg
    assert re.fullmatch(r"lies 998 m from the rays of the 6 image\(s\) that see it \(the gate: [\d.]+ m; its survey, "
                        r"id or frame is not the flight's\)", reg.rejected["2"]), reg.rejected
    assert np.abs(out - pts).max() < 0.05  # the 1 km point did not drag the model
    line = describe(reg.to_dict())
    assert line.startswith("ground control: 5 of 6 control points placed the model") and "rejected: 2 lies" in line
    for shift, kept in ((0.15, True), (0.6, False)):  # the gate at 2 m deep: 10 x 2.2 cm + 2 degrees, 0.29 m
        moved = dict(positions, **{"2": (markers[2][0], markers[2][1] + shift, 0.0)})
        reg_moved = register(pts, cams, names, [], K, cams, GroundControl(moved, 0.01, obs), 0.02)[2]
        assert ("2" not in reg_moved.rejected) == kept, (shift, reg_moved)

    far = GroundControl(positions={k: (x + 1000.0, y, z) for k, (x, y, z) in positions.items()}, observations=obs)
    out, _, reg = register(pts, cams, names, [], K, cams, far, 0.02)
    assert not reg.applied and out is pts and sorted(reg.rejected) == [str(j) for j in range(6)], reg
    assert reg.reason == ("0 of the 6 control points seen in the registered images fit the reported poses "
                          "(3 are needed)")
    assert describe(reg.to_dict()).startswith("ground control not used: 0 of the 6 control points")
    assert reg.to_dict()["rejected"] == reg.rejected


def test_a_flight_folders_ground_control_is_reported_in_recon_json_and_the_log(flown, tmp_path, capsys) -> None:
    """``--images`` with a markers.csv one marker of which is listed 1 km from where it lies:
    recon.json's ``control`` (there was none) and the log say what placed the model and which
    marker was rejected and why; exit 0, the others used."""
    import json

    from vp_recon.cli import main
    from vp_recon.flight import write_flight

    cfg, views = flown
    folder = write_flight(views, tmp_path / "flight")
    rows = (folder / "markers.csv").read_text().splitlines()
    cells = rows[1].split(",")
    cells[1] = repr(float(cells[1]) + 1000.0)
    rows[1] = ",".join(cells)
    (folder / "markers.csv").write_text("\n".join(rows) + "\n")
    capsys.readouterr()
    rc = main(["--images", str(folder), "--out", str(tmp_path / "out"), "--sparse-only", "--sift-first-octave", "0",
               "--threads", "1", "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 0, err
    ctl = json.loads((tmp_path / "out" / "recon.json").read_text())["control"]
    assert ctl["listed"] == 4 and list(ctl["rejected"]) == [cells[0]], ctl
    assert ctl["rejected"][cells[0]].startswith("lies ") and ctl["applied"] and ctl["used"] == 3, ctl
    line = next(t for t in err.splitlines() if t.startswith("recon: ground control"))
    assert "3 of 4 control points placed the model" in line and f"rejected: {cells[0]} lies" in line, err


def test_register_leaves_the_model_when_too_few_control_points_are_seen() -> None:
    pts = np.zeros((5, 3))
    cams = arc(3)
    control = GroundControl(positions={"0": (0.0, 0.0, 0.0)})
    out_pts, out_cams, reg = register(pts, cams, ["a", "b", "c"], [np.zeros((8, 8, 3), np.uint8)] * 3,
                                      np.eye(3), cams, control, 0.02)
    assert not reg.applied and "3 are needed" in reg.reason and out_pts is pts


def test_marker_layout_and_control_files(tmp_path) -> None:
    pts = np.array([[-0.5, -0.2, 0.0], [0.5, 0.2, 1.5]])
    lay = marker_layout(pts, 4, margin=0.3)
    np.testing.assert_allclose(lay, [[-0.8, -0.5, 0], [0.8, 0.5, 0], [0.8, -0.5, 0], [-0.8, 0.5, 0]])
    six = marker_layout(pts, 6, margin=0.3)  # the corners, then 2 at half the 5.2 m perimeter apart
    np.testing.assert_allclose(six[4:], [[0.5, -0.5, 0], [-0.5, 0.5, 0]], atol=1e-12)
    control = GroundControl(positions={"0": (1.0, 2.0, 0.0), "7": (-1.0, 0.5, 0.01)}, sigma=0.005)
    back = read_markers_csv(write_markers_csv(control, tmp_path / "markers.csv"))
    assert back == control
    (tmp_path / "bad.csv").write_text("id,x,y,z\n60,0,0,0\n")
    with pytest.raises(GroundControlError, match="line 2: marker id 60 is not in DICT_4X4_50"):
        read_markers_csv(tmp_path / "bad.csv")
    (tmp_path / "gcp_list.txt").write_text("+proj=utm +zone=15 +datum=WGS84\n"
                                           "1.0 2.0 0.0 100.5 200.25 im0.jpg gcp1\n"
                                           "1.0 2.0 0.0 300 400 im1.jpg gcp1\n")
    g = read_gcp_list(tmp_path / "gcp_list.txt")
    assert g.positions == {"gcp1": (1.0, 2.0, 0.0)} and len(g.observations) == 2
    assert (g.observations[0].u, g.observations[0].v, g.observations[0].image) == (100.5, 200.25, "im0.jpg")
    (tmp_path / "gcp_list.txt").write_text("EPSG:4326\n1.0 2.0 x 1 1 im0.jpg\n")
    with pytest.raises(GroundControlError, match="line 2: geo_z is not a number"):
        read_gcp_list(tmp_path / "gcp_list.txt")
    with pytest.raises(ValueError, match="gcp_markers"):
        CaptureModel(gcp_markers=51).validate()
    # a long plot gets more than the 4: neighbours at most gcp_spacing apart along its edge
    row = np.array([[-4.0, -0.5, 0.0], [4.0, 0.5, 1.5]])  # 8.7 x 1.7 m with the margins: 20.8 m of edge
    assert REALISTIC.marker_count(row) == 6 and REALISTIC.marker_count(pts) == 4
    assert len(REALISTIC.lay_markers(row)[1].positions) == 6 and CaptureModel(gcp_markers=0).marker_count(row) == 0
