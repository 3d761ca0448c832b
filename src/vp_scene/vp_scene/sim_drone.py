"""The simulated drones (ROS-free; :mod:`vp_scene.sim_drone_node` is their ROS adapter): a drone's
step toward its goal (:func:`fly_toward`) and cameras flown under the capture model and
photographed (:func:`photograph`).

:func:`photograph` is the world's side of a flight: the plants' meshes displaced by realization
k's wind (:mod:`vp_scene.meshing`), every camera flown under the capture model
(:mod:`vp_scene.capture`: its ACTUAL pose, planned + hover error, and the pose the drone REPORTS,
with a localization error), the field's ground markers laid, one image per camera rendered from
its actual pose (:mod:`vp_scene.render`) and exposed with sensor noise. A camera's draws are
seeded by its index i in the plan: a simulated drone holding camera i photographs exactly what
the whole plan's flight gives camera i. The reconstruction's :func:`vp_recon.pipeline.render_flight`
and the ``sim_drone`` node both call it.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Optional, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .camera import check_cameras
from .capture import CaptureModel
from .ground_control import GroundControl

__all__ = ["fly_toward", "ground_under", "Photographs", "photograph", "warm_up"]


def fly_toward(position: ArrayLike, goal: ArrayLike, speed: float, dt: float,
               climb_rate: Optional[float] = None) -> NDArray[np.float64]:
    """One step of a simulated drone straight toward ``goal``, arriving exactly when it is nearer
    than a step: ``speed * dt`` metres, or with a ``climb_rate`` (m/s) the drone flies the line at
    the constant velocity whose horizontal part is at most ``speed`` and vertical part at most
    ``climb_rate`` (the line takes max(horizontal / speed, vertical / climb_rate) seconds, as
    :func:`vp_planner.routes.leg_times` times it)."""
    p, g = np.asarray(position, dtype=np.float64), np.asarray(goal, dtype=np.float64)
    gap = g - p
    if climb_rate is None:
        need = float(np.linalg.norm(gap)) / float(speed)
    else:
        need = max(float(np.linalg.norm(gap[:2])) / float(speed), abs(float(gap[2])) / float(climb_rate))
    step = max(0.0, float(dt))
    if need <= step:
        return g.copy()
    return p + gap * (step / need)


def ground_under(capture: CaptureModel, ground: Optional[bool] = None) -> bool:
    """Whether the soil is rendered under the plants: ``ground``, or by the capture when None (a
    textured soil plane for a realistic flight, the blue screen for the ideal capture)."""
    return (not capture.ideal) if ground is None else bool(ground)


@dataclass
class Photographs:
    """What :func:`photograph` gives, camera by camera in the order asked.

    Attributes:
        images: N RGB uint8 (H, W, 3), rendered from the actual poses, with sensor noise.
        masks: N bool (H, W): the renderer's plant masks (an oracle that knows the scene), or None.
        reported: (N, 6) the cameras [c, v] the drones report (:mod:`vp_scene.camera`).
        K: 3x3 intrinsics, OpenCV pixel convention.
        control: the ground control of the markers laid (:class:`vp_scene.ground_control.GroundControl`),
            None without markers.
        seconds: wall time of ``mesh`` and ``render``.
    """

    images: list
    masks: Optional[list]
    reported: NDArray[np.float64]
    K: NDArray[np.float64]
    control: Optional[GroundControl] = None
    seconds: dict = field(default_factory=dict)


def photograph(noisy_scene: object, k: int, cameras: ArrayLike, capture: CaptureModel, width: int, height: int,
               fov: float, ground: Optional[bool] = None, mesh_cache: Optional[str] = None,
               indices: Optional[Sequence[int]] = None, masks: bool = True) -> Photographs:
    """Realization ``k`` of ``noisy_scene`` (a :class:`vp_scene.wind.NoisyScene`) photographed by
    ``cameras`` (N, 6) flown under ``capture`` (module docstring), ``width`` x ``height`` pixels,
    horizontal field of view ``fov``; ``ground``: the soil plane (:func:`ground_under`);
    ``mesh_cache``: :func:`vp_scene.meshing.scene_meshes`'s.

    ``indices``: the cameras' indices i in their plan (default 0..N-1), which seed their capture
    draws: ``photograph(scene, k, [camera_i], ..., indices=[i])`` gives exactly the image and
    reported pose the whole plan's photographs give camera i. ``masks``: False: no renderer masks
    (``Photographs.masks`` None; the renderer's segmentation pass skipped), the same images.

    Raises:
        ValueError: bad cameras or indices. RenderError: meshing or rendering failed.
    """
    from .meshing import scene_meshes
    from .render import RenderError, Renderer, marker_meshes

    cams = check_cameras(cameras)  # one camera is a capture too (a drone's own)
    seconds = {}
    t0 = time.perf_counter()
    try:
        meshes = scene_meshes(noisy_scene, k, mesh_cache)
    except (RuntimeError, ValueError) as exc:
        raise RenderError(f"cannot mesh the plants: {exc}") from exc
    seconds["mesh"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    ids = list(range(len(cams))) if indices is None else [int(i) for i in indices]
    if len(ids) != len(cams) or len(set(ids)) != len(ids) or min(ids) < 0:
        raise ValueError(f"indices must be {len(cams)} distinct camera indices >= 0, got {ids}")
    # ideal: the planned cameras, flown and reported exactly
    flown = [capture.fly_camera(c, k, i) for c, i in zip(cams, ids)]
    actual = np.array([a for a, _ in flown]).reshape(-1, 6)
    reported = np.array([r for _, r in flown]).reshape(-1, 6)
    # the field's ground markers (capture.gcp_markers), around every realization's plants: one layout
    markers, control = capture.lay_markers(noisy_scene.points)
    renderer = Renderer(width, height, fov)
    images, plant, _ = renderer.render(meshes, actual, ground=ground_under(capture, ground),
                                       markers=marker_meshes(markers, capture.gcp_size), masks=masks)
    images = [capture.expose(im, k, i) for i, im in zip(ids, images)]
    seconds["render"] = time.perf_counter() - t0
    return Photographs(images=images, masks=plant, reported=reported, K=renderer.K, control=control, seconds=seconds)


def warm_up(noisy_scene: object, capture: CaptureModel, width: int, height: int, fov: float) -> float:
    """Photograph realization 0 of ``noisy_scene`` once, from 3 m south of and 2 m above its centre,
    and forget the picture: the process's OpenGL context, its shaders and the soil's texture are
    set up (seconds of CPU the first time), so that the first
    photograph a drone takes costs what the later ones do. Without masks, as the drones and the
    realistic flights photograph. Seconds it took."""
    t0 = time.perf_counter()
    centre = np.asarray(noisy_scene.points, dtype=np.float64).reshape(-1, 3).mean(axis=0)
    camera = np.concatenate([centre + [0.0, -3.0, 2.0], [0.0, 3.0, -2.0]])
    photograph(noisy_scene, 0, camera[None], capture, width, height, fov, indices=[0], masks=False)
    return time.perf_counter() - t0
