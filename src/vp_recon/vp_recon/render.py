"""Pinhole camera model of the suite's cameras and headless rendering with pyrender.

Conventions
-----------
A camera is ``[cx, cy, cz, vx, vy, vz]`` (docs/CONTRACTS.md): centre c, optical axis v.
:func:`vp_planner.poses.rotation_matrix` gives the body-to-world rotation ``[x_b y_b z_b]``
(x_b = v/|v| forward, y_b left and horizontal, z_b up-ish). The OpenCV / COLMAP camera frame
(x right, y down, z forward) has, in world coordinates, the axes

    x_c = -y_b,   y_c = -z_b,   z_c = x_b,

so the world-to-camera transform is ``X_c = R_cw X_w + t`` with ``R_cw = [-y_b, -z_b, x_b]^T``
and ``t = -R_cw c`` (Hartley & Zisserman, Multiple View Geometry, eq. 6.8).

Pixels follow OpenCV: pixel centres at integer coordinates, u to the right (column), v down
(row). With a horizontal field of view ``fov`` and square pixels (Hartley & Zisserman eq. 6.4)

    f = (W / 2) / tan(fov / 2),   K = [[f, 0, (W-1)/2], [0, f, (H-1)/2], [0, 0, 1]],
    (u, v, 1)^T ~ K X_c.

COLMAP and OpenGL put pixel centres at +0.5 (the image corner is (0, 0)); their principal point
is therefore ``(W/2, H/2)``: see :func:`principal_point_gl`.

Rendering
---------
:class:`Renderer` draws vertex-coloured triangle meshes without lighting (pyrender's FLAT flag,
double-sided materials) over a uniform sky of :data:`SKY_COLOR`. The foreground mask is a colour
key on the rendered RGB image (any pixel farther than :data:`KEY_TOLERANCE` from the sky colour
is plant): it never reads the depth buffer, so downstream reconstruction sees only the images.

The OpenGL platform must be chosen before pyrender (PyOpenGL) is imported: ``PYOPENGL_PLATFORM``
is used when set, else ``egl`` is tried and, when no EGL context can be created, ``osmesa``.
"""
from __future__ import annotations

import math
import os
import sys
import threading
from typing import Optional, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vp_planner.poses import rotation_matrix

__all__ = [
    "SKY_COLOR", "KEY_TOLERANCE", "RenderError", "intrinsics", "principal_point_gl",
    "world_to_camera", "camera_to_world_gl", "project", "foreground_mask", "Renderer",
    "check_cameras", "release_contexts",
]

#: Uniform background colour (pure blue: never a plant colour, corn is green / yellow / brown).
SKY_COLOR: tuple[int, int, int] = (0, 0, 255)
#: A pixel whose RGB Euclidean distance to the sky colour is at most this is background.
KEY_TOLERANCE: float = 60.0


class RenderError(RuntimeError):
    """No OpenGL context could be created, or rendering failed."""


def check_cameras(cameras: ArrayLike) -> NDArray[np.float64]:
    """Cameras as an (N, 6) float64 array; ValueError naming the problem otherwise."""
    cams = np.asarray(cameras, dtype=np.float64)
    if cams.ndim == 1 and cams.size == 6:
        cams = cams[None]
    if cams.ndim != 2 or cams.shape[1] != 6:
        raise ValueError(f"cameras must have shape (N, 6) = [cx, cy, cz, vx, vy, vz], got {cams.shape}")
    if not np.all(np.isfinite(cams)):
        raise ValueError("cameras contain NaN or infinite values")
    if np.any(np.linalg.norm(cams[:, 3:], axis=1) <= 0):
        raise ValueError("a camera has a zero viewing direction")
    return cams


def _check_size(width: int, height: int, fov: float) -> None:
    if int(width) < 2 or int(height) < 2:
        raise ValueError(f"image size must be at least 2 x 2, got {width} x {height}")
    if not (0 < fov < math.pi):
        raise ValueError(f"fov must be in (0, pi) rad, got {fov}")


def intrinsics(width: int, height: int, fov: float = math.pi / 2) -> NDArray[np.float64]:
    """3x3 calibration K (OpenCV pixel centres) from the horizontal field of view, square pixels.

    f = (W/2) / tan(fov/2); principal point at the image centre ((W-1)/2, (H-1)/2).
    """
    _check_size(width, height, fov)
    f = 0.5 * width / math.tan(0.5 * fov)
    return np.array([[f, 0.0, 0.5 * (width - 1)], [0.0, f, 0.5 * (height - 1)], [0.0, 0.0, 1.0]])


def principal_point_gl(K: ArrayLike) -> tuple[float, float]:
    """Principal point in the OpenGL / COLMAP pixel convention (pixel centres at +0.5)."""
    K = np.asarray(K, dtype=np.float64)
    return float(K[0, 2] + 0.5), float(K[1, 2] + 0.5)


def world_to_camera(camera6: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(R_cw (..., 3, 3), t (..., 3)): X_c = R_cw X_w + t in the OpenCV / COLMAP camera frame.

    R_cw has rows (-y_b, -z_b, x_b) of the body frame of :func:`vp_planner.poses.rotation_matrix`;
    t = -R_cw c. Vectorized over leading dimensions of ``camera6`` (..., 6).
    """
    cam = np.asarray(camera6, dtype=np.float64)
    if cam.shape[-1] != 6:
        raise ValueError(f"camera must have shape (..., 6), got {cam.shape}")
    R_bw = rotation_matrix(cam[..., 3:])                       # columns x_b, y_b, z_b
    R_wc = np.stack([-R_bw[..., :, 1], -R_bw[..., :, 2], R_bw[..., :, 0]], axis=-1)
    R_cw = np.swapaxes(R_wc, -1, -2)
    t = -np.einsum("...ij,...j->...i", R_cw, cam[..., :3])
    return R_cw, t


def camera_to_world_gl(camera6: ArrayLike) -> NDArray[np.float64]:
    """4x4 OpenGL camera-to-world pose (x right, y up, z backward) for pyrender."""
    cam = np.asarray(camera6, dtype=np.float64)
    R_bw = rotation_matrix(cam[3:])
    T = np.eye(4)
    T[:3, :3] = np.stack([-R_bw[:, 1], R_bw[:, 2], -R_bw[:, 0]], axis=-1)
    T[:3, 3] = cam[:3]
    return T


def project(points: ArrayLike, camera6: ArrayLike, width: int, height: int,
            fov: float = math.pi / 2) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Pixels (M, 2) = (u, v) of world points (M, 3) and whether each is in front and in the image.

    (u, v, 1)^T ~ K (R_cw X + t); a point is ``visible`` when its depth is > 0 and
    -0.5 <= u < W - 0.5, -0.5 <= v < H - 0.5 (no occlusion test). Points behind the camera get NaN.
    """
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    K = intrinsics(width, height, fov)
    R, t = world_to_camera(camera6)
    Xc = P @ R.T + t
    z = Xc[:, 2]
    front = z > 1e-9
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = (Xc[:, :2] / np.where(front, z, np.nan)[:, None]) * K[[0, 1], [0, 1]] + K[:2, 2]
    inside = front & (uv[:, 0] >= -0.5) & (uv[:, 0] < width - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] < height - 0.5)
    return uv, inside


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


def release_contexts() -> None:
    """Delete every cached OpenGL context (the next :class:`Renderer` creates a new one)."""
    with _LOCK:
        for r in _CONTEXTS.values():
            try:
                r.delete()
            except Exception:  # noqa: BLE001 - best effort
                pass
        _CONTEXTS.clear()


class Renderer:
    """Offscreen renderer of coloured meshes.

    One pyrender ``OffscreenRenderer`` (OpenGL context) per image size is created on first use
    and shared by every Renderer of that size (creating a context costs about 0.5 s); rendering
    is serialized with a lock. :func:`release_contexts` frees them.

    Args:
        width, height: image size in pixels.
        fov: horizontal field of view, rad.

    Raises:
        ValueError: bad size or fov. RenderError: no OpenGL platform works.
    """

    def __init__(self, width: int, height: int, fov: float = math.pi / 2) -> None:
        _check_size(width, height, fov)
        self.width, self.height, self.fov = int(width), int(height), float(fov)
        self.K = intrinsics(self.width, self.height, self.fov)
        with _LOCK:
            self._pr = _egl_or_osmesa()
            key = (self.width, self.height)
            if key not in _CONTEXTS:
                try:
                    _CONTEXTS[key] = self._pr.OffscreenRenderer(self.width, self.height)
                except Exception as exc:  # noqa: BLE001
                    raise RenderError(f"cannot create a {self.width}x{self.height} offscreen renderer: "
                                      f"{type(exc).__name__}: {exc}") from exc
            self._renderer = _CONTEXTS[key]

    def _scene(self, meshes: Sequence) -> object:
        pr = self._pr
        bg = np.array([*SKY_COLOR, 255], dtype=np.float64) / 255.0
        scene = pr.Scene(bg_color=bg, ambient_light=np.ones(3))
        for m in meshes:
            pm = pr.Mesh.from_trimesh(m, smooth=False)
            for prim in pm.primitives:
                prim.material.doubleSided = True
            scene.add(pm)
        return scene

    def render(self, meshes: Sequence, cameras: ArrayLike, keep_depth: bool = False
               ) -> tuple[list[NDArray[np.uint8]], list[NDArray[np.bool_]], Optional[list[NDArray[np.float32]]]]:
        """Render ``meshes`` (trimesh.Trimesh with vertex colours) from every camera (N, 6).

        Returns:
            (images: N RGB uint8 (H, W, 3), masks: N bool (H, W) colour-key foreground,
            depths: N float32 (H, W) z-buffer depths (0 = nothing) if ``keep_depth`` else None).
            The depth is for tests only; reconstruction never uses it.
        """
        cams = check_cameras(cameras)
        pr = self._pr
        scene = self._scene(meshes)
        K = self.K
        cx, cy = principal_point_gl(K)
        cam = pr.IntrinsicsCamera(fx=K[0, 0], fy=K[1, 1], cx=cx, cy=cy, znear=0.01, zfar=1000.0)
        node = scene.add(cam, pose=np.eye(4))
        images, masks, depths = [], [], []
        flags = pr.RenderFlags.FLAT | pr.RenderFlags.SKIP_CULL_FACES
        for c in cams:
            scene.set_pose(node, camera_to_world_gl(c))
            try:
                with _LOCK:
                    color, depth = self._renderer.render(scene, flags=flags)
            except Exception as exc:  # noqa: BLE001
                raise RenderError(f"rendering failed: {type(exc).__name__}: {exc}") from exc
            color = np.ascontiguousarray(color[..., :3], dtype=np.uint8)
            images.append(color)
            masks.append(foreground_mask(color))
            if keep_depth:
                depths.append(np.asarray(depth, dtype=np.float32))
        return images, masks, (depths if keep_depth else None)
