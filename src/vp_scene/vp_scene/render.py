"""Headless rendering of the simulated world with pyrender (camera geometry: :mod:`vp_scene.camera`).

:class:`Renderer` draws vertex-coloured triangle meshes without lighting (pyrender's FLAT flag,
double-sided materials) through the pinhole cameras of :mod:`vp_scene.camera` (intrinsics from
the image size and the horizontal field of view; OpenGL pose from :func:`camera_to_world_gl`).

Backgrounds and masks
---------------------
* Default: a uniform sky of :data:`SKY_COLOR`; the plant mask is a colour key on the rendered
  RGB image (any pixel farther than :data:`KEY_TOLERANCE` from the sky colour is plant).
* ``ground=True``: a textured soil plane at z = 0 under the plants (a real field is not a blue
  screen: SIFT then also finds features on the soil). The colour key no longer separates the
  plants; :meth:`Renderer.render` returns the mask of a second, segmentation pass
  (``RenderFlags.SEG``: plant meshes white, ground black), which knows the scene: an oracle that
  only the ideal capture and the tests use. A flight segments its images alone:
  :func:`vp_recon.segment.plant_mask` (excess green, the crop-segmentation index) is what the
  reconstruction of a realistic capture uses. Neither mode ever reads the depth buffer.
* ``markers``: ground-control markers (:mod:`vp_scene.ground_control`), printed squares lying
  2 mm above the soil (:func:`marker_meshes`); the segmentation pass counts them as ground.

The OpenGL platform must be chosen before pyrender (PyOpenGL) is imported: ``PYOPENGL_PLATFORM``
is used when set, else ``egl`` is tried and, when no EGL context can be created, ``osmesa``.
"""
from __future__ import annotations

import functools
import hashlib
import math
import os
import sys
import threading
from pathlib import Path
from typing import Optional, Sequence

import numpy as np
import trimesh
from numpy.typing import ArrayLike, NDArray

from vp_scene.camera import camera_to_world_gl, check_cameras, intrinsics, principal_point_gl
from vp_scene.folders import user_cache, write_atomic

__all__ = ["SKY_COLOR", "KEY_TOLERANCE", "RenderError", "default_soil_cache", "foreground_mask", "ground_meshes",
           "make_soil_texture", "marker_meshes", "soil_squares", "soil_square_mesh", "soil_texture", "soil_tile_seed",
           "Renderer", "release_contexts"]

#: Uniform background colour (pure blue: never a plant colour, corn is green / yellow / brown).
SKY_COLOR: tuple[int, int, int] = (0, 0, 255)
#: A pixel whose RGB Euclidean distance to the sky colour is at most this is background.
KEY_TOLERANCE: float = 60.0


class RenderError(RuntimeError):
    """No OpenGL context could be created, or rendering failed."""


def foreground_mask(image: NDArray[np.uint8], sky: Sequence[int] = SKY_COLOR,
                    tolerance: float = KEY_TOLERANCE) -> NDArray[np.bool_]:
    """Colour-key mask (H, W) of an RGB image: True where the colour is not the sky's."""
    d = image[..., :3].astype(np.int32) - np.asarray(sky, dtype=np.int32)
    return np.einsum("...i,...i->...", d, d) > tolerance * tolerance


_pyrender = None


def _egl_or_osmesa():
    """Import pyrender with a working platform: PYOPENGL_PLATFORM if set, else EGL then OSMesa."""
    global _pyrender
    if _pyrender is not None:
        return _pyrender
    if not hasattr(np, "infty"):                     # pyrender's shadow code uses np.infty (gone in numpy 2)
        np.infty = np.inf                            # type: ignore[attr-defined]
    explicit = os.environ.get("PYOPENGL_PLATFORM")
    candidates = [explicit] if explicit else ["egl", "osmesa"]
    errors = []
    for platform in candidates:
        if "OpenGL" in sys.modules and not explicit and os.environ.get("PYOPENGL_PLATFORM") != platform:
            for name in [m for m in sys.modules if m.split(".")[0] in ("OpenGL", "pyrender")]:
                del sys.modules[name]
        os.environ["PYOPENGL_PLATFORM"] = platform
        try:
            import pyrender                           # noqa: WPS433 (platform must be set first)
            r = pyrender.OffscreenRenderer(8, 8)      # create (and drop) a context to test the platform
            r.delete()
        except Exception as exc:                      # noqa: BLE001 - report every platform's failure
            errors.append(f"{platform}: {type(exc).__name__}: {exc}")
            continue
        _pyrender = pyrender
        return pyrender
    if not explicit:
        os.environ.pop("PYOPENGL_PLATFORM", None)
    raise RenderError("cannot create an OpenGL context for headless rendering ("
                      + "; ".join(errors) + "). Install Mesa's EGL (libegl1) or OSMesa (libosmesa6 "
                      "with pyopengl>=3.1.10), or set PYOPENGL_PLATFORM.")


_CONTEXTS: dict = {}
_LOCK = threading.RLock()
#: pyrender meshes of the soil's squares per OpenGL context (image size): {(w, h): {(i, j): meshes}}
_SQUARES: dict = {}
#: squares kept per context (each holds a 12 MB texture; row_12 and grid_3x3 stand on 25, one_plant on 12)
_SQUARES_KEPT: int = 64


def _leave_current(renderer: object) -> None:
    """Leave ``renderer``'s OpenGL context current in no thread. EGL binds a context to one thread
    at a time and pyrender's EGL platform never lets go of it (its ``make_uncurrent`` does
    nothing), so a context last used by a thread that is still alive (a Dask worker's pool, a task
    that seceded to wait for others) could not be made current by any other thread
    (EGL_BAD_ACCESS). OSMesa's contexts are not bound to threads."""
    display = getattr(getattr(renderer, "_platform", None), "_egl_display", None)
    if display is None:
        return
    from OpenGL.EGL import EGL_NO_CONTEXT, EGL_NO_SURFACE, eglMakeCurrent

    eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT)


def release_contexts() -> None:
    """Delete every cached OpenGL context (the next :class:`Renderer` creates a new one)."""
    with _LOCK:
        for r in _CONTEXTS.values():
            try:
                r.delete()
                _leave_current(r)
            except Exception:  # noqa: BLE001 - best effort
                pass
        _CONTEXTS.clear()
        _SQUARES.clear()


class Renderer:
    """Offscreen renderer of coloured meshes.

    One pyrender ``OffscreenRenderer`` (OpenGL context) per image size is created on first use
    and shared by every Renderer of that size (creating a context is slow); rendering
    is serialized with a lock, and the context is current in no thread between renders, so any
    thread may render. :func:`release_contexts` frees them.

    Args:
        width, height: image size in pixels.
        fov: horizontal field of view, rad.

    Raises:
        ValueError: bad size or fov. RenderError: no OpenGL platform works.
    """

    def __init__(self, width: int, height: int, fov: float = math.pi / 2) -> None:
        self.K = intrinsics(width, height, fov)  # ValueError for a bad size or fov
        self.width, self.height, self.fov = int(width), int(height), float(fov)
        with _LOCK:
            self._pr = _egl_or_osmesa()
            key = (self.width, self.height)
            if key not in _CONTEXTS:
                try:
                    _CONTEXTS[key] = self._pr.OffscreenRenderer(self.width, self.height)
                    _leave_current(_CONTEXTS[key])
                except Exception as exc:  # noqa: BLE001
                    raise RenderError(f"cannot create a {self.width}x{self.height} offscreen renderer: "
                                      f"{type(exc).__name__}: {exc}") from exc
            self._renderer = _CONTEXTS[key]

    def _scene(self, meshes: Sequence, ground: bool, markers: Sequence = (), segment: bool = True
               ) -> tuple[object, dict]:
        """The pyrender scene, and the segmentation map of the ``ground`` mode with ``segment``
        (else empty); ``markers``: textured meshes of the ground (:func:`marker_meshes`), segmented
        as ground.

        pyrender culls back faces in its segmentation pass whatever the flags, so that pass draws
        its own two-sided copies of the meshes (hidden in the colour pass)."""
        pr = self._pr
        bg = np.array([*SKY_COLOR, 255], dtype=np.float64) / 255.0
        scene = pr.Scene(bg_color=bg, ambient_light=np.ones(3))
        items = [(m, (255, 255, 255)) for m in meshes] + [(m, (0, 0, 0)) for m in markers]
        seg_map: dict = {}
        for m, seg_color in items:
            pm, two_sided = self._pyrender_mesh(m, with_segmentation=ground and segment)
            scene.add(pm)
            if two_sided is not None:
                seg_map[scene.add(two_sided)] = seg_color
        if ground:
            for square in soil_squares(meshes):
                pm, two_sided = self._soil_square(*square)
                scene.add(pm)
                if segment:
                    seg_map[scene.add(two_sided)] = (0, 0, 0)
        return scene, seg_map

    def _pyrender_mesh(self, m: object, with_segmentation: bool) -> tuple[object, Optional[object]]:
        """pyrender's double-sided mesh of trimesh ``m``, and (``with_segmentation``) its hidden
        two-sided copy for the segmentation pass."""
        pr = self._pr
        pm = pr.Mesh.from_trimesh(m, smooth=False)
        for prim in pm.primitives:
            prim.material.doubleSided = True
        if not with_segmentation:
            return pm, None
        faces = np.asarray(m.faces)
        two_sided = pr.Mesh.from_trimesh(
            trimesh.Trimesh(vertices=np.asarray(m.vertices), faces=np.concatenate([faces, faces[:, ::-1]]),
                            process=False), smooth=False)
        two_sided.is_visible = False
        return pm, two_sided

    def _soil_square(self, i: int, j: int) -> tuple[object, object]:
        """The pyrender meshes of soil square (i, j) in this renderer's OpenGL context, kept
        between renders (:data:`_SQUARES`): pyrender uploads a mesh and its 12 MB texture once
        per context while the same mesh object is in every scene (building them again for every
        render would cost seconds). At most :data:`_SQUARES_KEPT` per context."""
        with _LOCK:
            kept = _SQUARES.setdefault((self.width, self.height), {})
            if (i, j) not in kept:
                if len(kept) >= _SQUARES_KEPT:
                    kept.clear()
                kept[(i, j)] = self._pyrender_mesh(soil_square_mesh(i, j), with_segmentation=True)
            return kept[(i, j)]

    def render(self, meshes: Sequence, cameras: ArrayLike, keep_depth: bool = False, ground: bool = False,
               markers: Sequence = (), masks: bool = True
               ) -> tuple[list[NDArray[np.uint8]], Optional[list[NDArray[np.bool_]]],
                          Optional[list[NDArray[np.float32]]]]:
        """Render ``meshes`` (trimesh.Trimesh with vertex colours) from every camera (N, 6).

        Args:
            ground: draw a textured soil plane at z = 0 (masks from a segmentation pass).
            markers: ground-control markers to draw (:func:`marker_meshes`; ground in the masks).
            masks: False: no plant masks (None), and over the ground no segmentation pass (a
                second render of every view); the images are the same.

        Returns:
            (images: N RGB uint8 (H, W, 3), masks: N bool (H, W) plant pixels (None without ``masks``),
            depths: N float32 (H, W) z-buffer depths (0 = nothing) if ``keep_depth`` else None).
            The depth is for tests only; reconstruction never uses it.
        """
        cams = check_cameras(cameras)
        pr = self._pr
        scene, seg_map = self._scene(meshes, ground, markers, segment=masks)
        K = self.K
        cx, cy = principal_point_gl(K)
        cam = pr.IntrinsicsCamera(fx=K[0, 0], fy=K[1, 1], cx=cx, cy=cy, znear=0.01, zfar=1000.0)
        node = scene.add(cam, pose=np.eye(4))
        images, plant, depths = [], [], []
        flags = pr.RenderFlags.FLAT | pr.RenderFlags.SKIP_CULL_FACES
        for c in cams:
            scene.set_pose(node, camera_to_world_gl(c))
            try:
                with _LOCK:
                    try:
                        color, depth = self._renderer.render(scene, flags=flags)
                        if seg_map:
                            for n in seg_map:
                                n.mesh.is_visible = True
                            seg, _ = self._renderer.render(scene, flags=pr.RenderFlags.SEG, seg_node_map=seg_map)
                            for n in seg_map:
                                n.mesh.is_visible = False
                    finally:  # any thread may render next (:func:`_leave_current`)
                        _leave_current(self._renderer)
            except Exception as exc:  # noqa: BLE001
                raise RenderError(f"rendering failed: {type(exc).__name__}: {exc}") from exc
            color = np.ascontiguousarray(color[..., :3], dtype=np.uint8)
            images.append(color)
            if masks:
                plant.append(np.asarray(seg)[..., 0] > 127 if seg_map else foreground_mask(color))
            if keep_depth:
                depths.append(np.asarray(depth, dtype=np.float32))
        return images, (plant if masks else None), (depths if keep_depth else None)


#: Soil textures (RGB uint8) of this process, by :func:`soil_texture`.
_SOIL: dict = {}
#: Texels across one soil texture (a square of ``SOIL_TEXELS * texel`` metres of ground).
SOIL_TEXELS: int = 2048
#: Soil beyond the plants' x-y box, metres (at least; :func:`soil_squares`).
GROUND_MARGIN: float = 5.5


def default_soil_cache() -> Path:
    """``$VP_SOIL_CACHE`` or ``$XDG_CACHE_HOME/vp_suite/soil`` (default ``~/.cache/vp_suite/soil``)."""
    return user_cache("soil", "VP_SOIL_CACHE")


@functools.cache
def _soil_recipe() -> str:
    """A digest of :func:`make_soil_texture`'s code and constants: a cached texture made by other
    code is never read back."""
    h = hashlib.sha256()

    def add(code) -> None:  # nested code objects by their own bytes (their repr holds an address)
        h.update(code.co_code)
        for c in code.co_consts:
            add(c) if hasattr(c, "co_code") else h.update(repr(c).encode())
    add(make_soil_texture.__code__)
    return h.hexdigest()[:16]


def soil_texture(size: int = SOIL_TEXELS, seed: int | Sequence[int] = 7) -> NDArray[np.uint8]:
    """:func:`make_soil_texture`, built once per machine: kept in this process and on disk under
    :func:`default_soil_cache` (``<recipe>-<size>-<seed>.npy``, 12.6 MB a 2048-texel square), as
    every process that renders a ground (a node, a Dask worker, a flight) would otherwise build
    each square's texture again. The bytes are :func:`make_soil_texture`'s: an entry that does not
    load as a (size, size, 3) uint8 array is built again; an unwritable folder is ignored."""
    key = (int(size), tuple(np.atleast_1d(seed).tolist()))
    if key in _SOIL:
        return _SOIL[key]
    folder = default_soil_cache()
    path = folder / f"{_soil_recipe()}-{key[0]}-{'-'.join(map(str, key[1]))}.npy"
    out = None
    if path.is_file():
        try:
            out = np.load(path, allow_pickle=False)
        except (OSError, ValueError):  # a corrupt or truncated entry: built again below
            out = None
        if out is not None and (out.shape != (key[0], key[0], 3) or out.dtype != np.uint8):
            out = None
    if out is None:
        out = make_soil_texture(size, seed)

        def write(tmp: Path) -> None:
            with open(tmp, "wb") as fh:
                np.save(fh, out)
        try:
            folder.mkdir(parents=True, exist_ok=True)
            write_atomic(path, write)
        except OSError:  # an unwritable cache (OutputError included): built again by the next process
            pass
    _SOIL[key] = out
    return out


def make_soil_texture(size: int = SOIL_TEXELS, seed: int | Sequence[int] = 7) -> NDArray[np.uint8]:
    """A seeded soil texture: brown multi-scale value noise with clods, stones and straw.

    Built from the sum of upsampled random grids (periodic: each grid is wrapped by two cells
    before its cubic upsampling) at cell sizes 4-256 texels, then one clod or stone (a darker or
    lighter disc of 1-5 texels, 2-10 mm on the 2 mm texels of :func:`ground_meshes`) per 600
    texels and a thin straw stroke per 8000. A field's soil is that rough; the clods are what SIFT
    finds on it at a few metres, and the ground does not move in the wind: it anchors a flight's
    structure from motion (a smoother soil gives too few keypoints to register a ring of a few
    views). Straw stays one texel wide: its excess green (about 0.09) is above the plant mask's
    threshold, the mask's opening removes it. ``seed``: an int or a sequence of non-negative ints
    (numpy's ``default_rng``), one texture per seed.
    """
    import cv2

    rng = np.random.default_rng(seed)
    field = np.zeros((size, size), np.float32)
    for cell, amp in ((256, 0.3), (64, 0.25), (16, 0.25), (4, 0.2)):
        n = max(2, size // cell)
        g = np.pad(rng.random((n, n), np.float32), 2, mode="wrap")  # periodic: the cubic kernel sees wrapped cells
        c = size / n
        up = cv2.resize(g, (round((n + 4) * c), round((n + 4) * c)), interpolation=cv2.INTER_CUBIC)
        o = round(2 * c)
        field += amp * up[o:o + size, o:o + size]
    field = (field - field.min()) / max(1e-9, float(np.ptp(field)))
    dark = np.array([55, 40, 28], np.float32)
    light = np.array([165, 130, 95], np.float32)
    img = dark + field[..., None] * (light - dark)
    n = size * size // 600
    centres, radii, tones = rng.integers(0, size, (n, 2)), rng.integers(1, 6, n), rng.uniform(0.35, 1.6, n)
    colours = np.clip(img[centres[:, 1], centres[:, 0]] * tones[:, None], 0, 235).tolist()
    for (x, y), r, colour in zip(centres.tolist(), radii.tolist(), colours):  # clods (darker), stones (lighter)
        cv2.circle(img, (x, y), r, colour, -1)
    for _ in range(size * size // 8000):
        x, y = rng.integers(0, size, 2)
        a = rng.uniform(0, np.pi)
        length = rng.uniform(8, 30)
        p2 = (int(x + length * np.cos(a)), int(y + length * np.sin(a)))
        cv2.line(img, (int(x), int(y)), p2, (190.0, 165.0, 100.0), 1)
    return np.clip(img, 0, 255).astype(np.uint8)


def soil_tile_seed(i: int, j: int, seed: int = 7) -> tuple[int, int, int]:
    """The texture seed of soil square (``i``, ``j``) (:func:`ground_meshes`): distinct for every
    square of the plane (a bijection of the integers onto the naturals per axis)."""
    def natural(k: int) -> int:
        return 2 * k if k >= 0 else -2 * k - 1
    return int(seed), natural(int(i)), natural(int(j))


def soil_squares(meshes: Sequence, margin: float = GROUND_MARGIN, texel: float = 0.002) -> list[tuple[int, int]]:
    """The squares (i, j) of soil under ``meshes`` (:func:`ground_meshes`): every square of the
    grid that meets their x-y box grown by ``margin`` metres (a box of +- ``margin`` when empty)."""
    if len(meshes):
        v = np.concatenate([np.asarray(m.vertices) for m in meshes])
        lo, hi = v[:, :2].min(axis=0) - margin, v[:, :2].max(axis=0) + margin
    else:
        lo, hi = np.full(2, -margin), np.full(2, margin)
    period = texel * SOIL_TEXELS
    first, last = np.floor(lo / period + 0.5).astype(int), np.floor(hi / period + 0.5).astype(int)
    return [(i, j) for i in range(first[0], last[0] + 1) for j in range(first[1], last[1] + 1)]


def soil_square_mesh(i: int, j: int, texel: float = 0.002, seed: int = 7) -> object:
    """Soil square (``i``, ``j``) at z = 0: a textured quad of ``SOIL_TEXELS * texel`` m a side
    centred on (i, j) times that, its own texture (:func:`soil_tile_seed`)."""
    from PIL import Image

    period = texel * SOIL_TEXELS
    x0, y0 = (i - 0.5) * period, (j - 0.5) * period
    corners = np.array([[x0, y0, 0.0], [x0 + period, y0, 0.0], [x0 + period, y0 + period, 0.0],
                        [x0, y0 + period, 0.0]])
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    image = Image.fromarray(soil_texture(SOIL_TEXELS, soil_tile_seed(i, j, seed)))
    material = trimesh.visual.material.SimpleMaterial(image=image)
    visual = trimesh.visual.TextureVisuals(uv=uv, image=image, material=material)
    return trimesh.Trimesh(vertices=corners, faces=np.array([[0, 1, 2], [0, 2, 3]]), visual=visual, process=False)


def ground_meshes(meshes: Sequence, margin: float = GROUND_MARGIN, texel: float = 0.002, seed: int = 7) -> list:
    """The soil at z = 0 under ``meshes``: square quads of ``SOIL_TEXELS * texel`` m (4.1 m at 2 mm
    texels: about a pixel of a 2000-pixel image at the plants' distance), square (0, 0) centred on
    the origin, every square that meets the meshes' x-y box grown by ``margin`` metres
    (:func:`soil_squares`; a plant under 1 m across at the origin stands on 3 x 3 squares, 12.3 m a side).

    The soil does not repeat: square (i, j) has its own texture (:func:`soil_tile_seed`), so no
    two places of a field look alike (one texture tiled over a field makes views across a row's
    ends match soil with its repeat, and bends the row's model). Where two squares meet the soil's
    tone steps, as it does between real patches of soil. A texture is built once per process and
    :class:`Renderer` keeps each square's OpenGL mesh between renders.
    """
    return [soil_square_mesh(i, j, texel, seed) for i, j in soil_squares(meshes, margin, texel)]


def marker_meshes(centres: ArrayLike, size: float, texels: int = 240) -> list:
    """Ground-control markers as meshes: marker i of :data:`vp_scene.ground_control.ARUCO_DICTIONARY`
    (its printed image, :func:`vp_scene.ground_control.marker_image`, grey on white) as a
    ``size`` m square centred on ``centres[i]`` (M, 3), lying flat 2 mm above it (clear of the
    soil plane's depth), its image x along world x and image y along world -y (read from above
    as printed: a mirror image would not decode)."""
    from PIL import Image

    from vp_scene.ground_control import marker_image

    out = []
    h = 0.5 * float(size)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])  # texture v up: row 0 is the top
    for i, (x, y, z) in enumerate(np.asarray(centres, dtype=np.float64).reshape(-1, 3)):
        corners = np.array([[x - h, y - h, z + 0.002], [x + h, y - h, z + 0.002], [x + h, y + h, z + 0.002],
                            [x - h, y + h, z + 0.002]])
        img = Image.fromarray(np.repeat(marker_image(i, texels)[..., None], 3, axis=2))
        material = trimesh.visual.material.SimpleMaterial(image=img)
        visual = trimesh.visual.TextureVisuals(uv=uv, image=img, material=material)
        out.append(trimesh.Trimesh(vertices=corners, faces=faces, visual=visual, process=False))
    return out
