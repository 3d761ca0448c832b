"""Camera convention of vp_scene.render: projection matches what pyrender draws."""
from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from vp_scene.camera import check_cameras, intrinsics, project, rotation_matrix, world_to_camera
from vp_scene.render import SKY_COLOR, Renderer, foreground_mask

W, H = 320, 240


def test_intrinsics_from_horizontal_fov() -> None:
    K = intrinsics(640, 480, math.pi / 2)
    assert K[0, 0] == pytest.approx(320.0) and K[1, 1] == pytest.approx(320.0)
    assert K[0, 2] == pytest.approx(319.5) and K[1, 2] == pytest.approx(239.5)
    K60 = intrinsics(1000, 750, math.radians(60))
    assert 2 * math.degrees(math.atan(500 / K60[0, 0])) == pytest.approx(60.0)
    with pytest.raises(ValueError):
        intrinsics(640, 480, 0.0)


def test_world_to_camera_axes() -> None:
    cam = np.array([1.0, 2.0, 1.5, -1.0, 0.3, -0.4])
    R, t = world_to_camera(cam)
    assert np.allclose(R @ R.T, np.eye(3)) and np.linalg.det(R) == pytest.approx(1.0)
    assert np.allclose(R @ cam[:3] + t, 0.0)                       # centre -> origin
    Rb = rotation_matrix(cam[3:])
    assert np.allclose(R @ Rb[:, 0], [0, 0, 1])                   # optical axis -> +z
    assert np.allclose(R @ Rb[:, 1], [-1, 0, 0])                  # body left -> image -x
    assert np.allclose(R @ Rb[:, 2], [0, -1, 0])                  # body up -> image -y
    # vectorized
    R2, t2 = world_to_camera(np.stack([cam, cam]))
    assert np.allclose(R2[1], R) and np.allclose(t2[1], t)


def test_project_directions() -> None:
    cam = np.array([0.0, 0.0, 1.0, 1.0, 0.0, 0.0])                # at height 1 looking along +x
    K = intrinsics(W, H)
    uv, vis = project([[2.0, 0.0, 1.0], [2.0, 0.5, 1.0], [2.0, 0.0, 1.5], [-2.0, 0.0, 1.0]], cam, W, H)
    assert np.allclose(uv[0], K[:2, 2])                            # optical axis -> principal point
    assert uv[1, 0] < K[0, 2] and uv[1, 1] == pytest.approx(K[1, 2])   # +y (left) -> smaller u
    assert uv[2, 1] < K[1, 2] and uv[2, 0] == pytest.approx(K[0, 2])   # +z (up) -> smaller v
    assert vis[:3].all() and not vis[3] and np.isnan(uv[3]).all()  # behind the camera


def _sphere(center, color, radius=0.04):
    s = trimesh.creation.icosphere(subdivisions=3, radius=radius)
    s.apply_translation(center)
    s.visual.vertex_colors = np.tile([*color, 255], (len(s.vertices), 1)).astype(np.uint8)
    return s


CAMERAS = np.array([
    [2.0, 0.0, 1.0, -1.0, 0.0, 0.0],            # level, looking along -x
    [0.5, -1.5, 1.8, -0.2, 1.0, -0.5],          # oblique, looking down
    [0.1, 0.2, 3.0, 0.0, 0.0, -1.0],            # straight down (vertical axis: y_b = world +y)
    [-1.0, 1.2, 0.4, 1.0, -1.1, 0.45],          # looking up
])
POINTS = np.array([[0.0, 0.0, 1.0], [0.3, 0.25, 1.2], [-0.25, -0.2, 0.8], [0.2, -0.3, 1.4]])
COLORS = [(255, 0, 0), (0, 255, 0), (255, 255, 0), (255, 0, 255)]


@pytest.mark.parametrize("ci", range(len(CAMERAS)))
def test_spheres_drawn_where_projected(ci: int) -> None:
    """Each small sphere's pixel centroid lies within 2 px of project() of its centre."""
    cam = CAMERAS[ci]
    r = Renderer(W, H)
    images, masks, depths = r.render([_sphere(p, c) for p, c in zip(POINTS, COLORS)], cam[None], keep_depth=True)
    img, mask, depth = images[0], masks[0], depths[0]
    uv, vis = project(POINTS, cam, W, H)
    R, t = world_to_camera(cam)
    checked = 0
    for p, col, (u, v), ok in zip(POINTS, COLORS, uv, vis):
        if not ok:
            continue
        hit = np.all(np.abs(img.astype(int) - col) < 60, axis=-1)
        if hit.sum() < 5:                      # hidden behind another sphere
            continue
        ys, xs = np.nonzero(hit)
        assert abs(xs.mean() - u) < 2.0 and abs(ys.mean() - v) < 2.0, (p, xs.mean(), ys.mean(), u, v)
        z = (R @ p + t)[2]                     # the z-buffer (test only) agrees: depth along the axis
        d = depth[int(round(v)), int(round(u))]      # front surface of the sphere: z - radius
        assert z - 0.04 - 0.005 < d < z
        assert mask[int(round(v)), int(round(u))]
        checked += 1
    assert checked >= 2
    # background is exactly the sky colour and the mask is the colour key
    assert np.all(img[~mask].astype(int) - SKY_COLOR < 61)
    assert np.array_equal(mask, foreground_mask(img))
    assert mask.sum() < 0.05 * W * H


def test_optical_axis_hits_image_centre() -> None:
    cam = CAMERAS[1]
    target = cam[:3] + 1.5 * cam[3:] / np.linalg.norm(cam[3:])
    images, masks, _ = Renderer(W + 1, H + 1).render([_sphere(target, (255, 0, 0), 0.01)], cam[None])
    ys, xs = np.nonzero(masks[0])
    assert abs(xs.mean() - W / 2) < 1.0 and abs(ys.mean() - H / 2) < 1.0


def test_check_cameras_errors() -> None:
    with pytest.raises(ValueError, match="shape"):
        check_cameras(np.zeros((3, 5)))
    with pytest.raises(ValueError, match="zero viewing"):
        check_cameras([[0, 0, 1, 0, 0, 0]])
    with pytest.raises(ValueError, match="NaN"):
        check_cameras([[0, 0, np.nan, 1, 0, 0]])


def test_the_soil_does_not_repeat_and_renders_the_same_twice() -> None:
    """One soil texture tiled every 4.1 m gave views across a row's ends hundreds of
    false matches. Every square of the ground has its own texture: the soil photographed at x and
    at x + 4.1 m differs, and the same view renders the same twice (the squares are kept)."""
    from vp_scene.render import (SOIL_TEXELS, ground_meshes, make_soil_texture, soil_square_mesh, soil_squares,
                                 soil_texture, soil_tile_seed)

    period = 0.002 * SOIL_TEXELS
    plant = trimesh.creation.box((0.4, 0.4, 1.0))
    plant.apply_translation([6.0, 0.0, 0.5])  # a row's end: the ground spans x from -5.7 to 11.7
    squares = soil_squares([plant])
    assert len(set(squares)) == len(squares) and len({soil_tile_seed(i, j) for i, j in squares}) == len(squares)
    ground = ground_meshes([plant])
    lo = np.min([m.vertices.min(axis=0) for m in ground], axis=0)
    hi = np.max([m.vertices.max(axis=0) for m in ground], axis=0)
    assert lo[0] <= 5.8 - 5.5 and hi[0] >= 6.2 + 5.5 and lo[1] <= -5.7 and hi[1] >= 5.7  # the margin
    grey = [soil_texture(SOIL_TEXELS, soil_tile_seed(i, 0)).mean(axis=2).ravel() for i in range(3)]
    corr = np.corrcoef(grey)
    assert np.all(np.abs(corr[np.triu_indices(3, 1)]) < 0.2), corr  # distinct squares, not shifted copies
    first = soil_texture(SOIL_TEXELS, soil_tile_seed(1, 0)).copy()
    assert np.array_equal(make_soil_texture(SOIL_TEXELS, soil_tile_seed(1, 0)), first)  # seeded: every process agrees
    assert soil_square_mesh(1, 0).bounds[0, 0] == pytest.approx(0.5 * period)

    r = Renderer(W, H, math.radians(50))
    down = [0.0, 0.2, -1.0]
    cams = np.array([[0.7, 0.3, 1.0, *down], [0.7 + period, 0.3, 1.0, *down], [0.7, 0.3, 1.0, *down]])
    images, _, _ = r.render([plant], cams, ground=True)
    again, none, _ = r.render([plant], cams[:1], ground=True, masks=False)  # no segmentation pass
    assert np.array_equal(images[0], images[2]) and np.array_equal(images[0], again[0]) and none is None
    diff = np.abs(images[0].astype(np.int16) - images[1].astype(np.int16)).mean()
    assert diff > 3.0, diff  # the tiled soil: these two views were the same picture (0.02; distinct squares 5.6)


def test_a_soil_texture_is_built_once_per_machine_and_a_corrupt_entry_again(tmp_path, monkeypatch) -> None:
    """soil_texture keeps what make_soil_texture makes on disk: another process reads the same
    bytes back; a truncated or foreign entry is built again; an unwritable folder only costs time."""
    from vp_scene import render
    from vp_scene.render import make_soil_texture, soil_texture

    monkeypatch.setenv("VP_SOIL_CACHE", str(tmp_path / "soil"))
    monkeypatch.setattr(render, "_SOIL", {})
    made = make_soil_texture(256, (7, 3, 4))
    assert np.array_equal(soil_texture(256, (7, 3, 4)), made)
    (entry,) = (tmp_path / "soil").glob("*.npy")
    assert entry.name.endswith("-256-7-3-4.npy") and np.array_equal(np.load(entry), made)
    calls = []
    monkeypatch.setattr(render, "make_soil_texture", lambda *a: calls.append(a) or made)
    monkeypatch.setattr(render, "_soil_recipe", lambda: entry.name.split("-")[0])
    render._SOIL.clear()  # a new process: read from disk, nothing built
    assert np.array_equal(soil_texture(256, (7, 3, 4)), made) and calls == []
    for spoil in (lambda: entry.write_bytes(entry.read_bytes()[:1000]),  # truncated
                  lambda: np.save(entry, np.zeros((2, 2), np.float64))):  # a foreign array
        spoil()
        render._SOIL.clear()
        assert np.array_equal(soil_texture(256, (7, 3, 4)), made)
    assert len(calls) == 2 and np.array_equal(np.load(entry), made)  # built again, and kept again
    monkeypatch.setenv("VP_SOIL_CACHE", "/proc/no-such-folder")
    render._SOIL.clear()
    assert np.array_equal(soil_texture(256, (7, 3, 4)), made)


def test_a_thread_renders_while_the_thread_that_rendered_before_is_still_alive() -> None:
    """The shared context is current in no thread between renders: a Dask worker's task renders
    in a thread of its pool while the thread that rendered last still lives (a task that seceded
    to wait for its flights); before, eglMakeCurrent failed there with EGL_BAD_ACCESS."""
    import threading

    sphere = trimesh.creation.icosphere(radius=0.3)
    sphere.visual.vertex_colors = [30, 160, 40, 255]
    cam = np.array([[2.0, 0.0, 0.5, -1.0, 0.0, -0.2]])
    drawn: dict = {}
    first_done, release = threading.Event(), threading.Event()

    def render(k: int, linger: bool) -> None:
        try:
            images, _, _ = Renderer(72, 54).render([sphere], cam)
            drawn[k] = int(np.count_nonzero(foreground_mask(images[0])))
        except Exception as exc:  # noqa: BLE001 - reported by the assertion below
            drawn[k] = repr(exc)
        first_done.set()
        if linger:
            release.wait(60.0)

    first = threading.Thread(target=render, args=(0, True))
    first.start()
    try:
        assert first_done.wait(60.0)
        second = threading.Thread(target=render, args=(1, False))
        second.start()
        second.join(60.0)
    finally:
        release.set()
        first.join(60.0)
    assert isinstance(drawn[0], int) and drawn[0] > 0, drawn
    assert drawn[1] == drawn[0], drawn
