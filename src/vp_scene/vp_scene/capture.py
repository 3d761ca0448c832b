"""The capture model: what becomes of a planned camera when a drone flies it (one home).

A camera of a plan, ``[c, v]`` (:mod:`vp_scene.camera`), is *flown*:

* **actual pose** = planned pose + hover error: the centre moves by a Gaussian offset of
  ``hover_position_sigma`` m per axis, and the optical axis turns by a small random rotation
  whose rotation vector is Gaussian with ``hover_attitude_sigma`` degrees per axis;
* the **image** is rendered from the actual pose, and sensor noise is added to it: Gaussian,
  ``sensor_noise`` of full scale (1.0 = 255), clipped to [0, 255] and rounded;
* the **reported pose** (what the drone says where it was) = actual pose + localization error:
  ``report_position_sigma`` m per axis and ``report_attitude_sigma`` degrees per axis, drawn the
  same way.

Roll: a camera here has no roll (the body convention of :mod:`vp_scene.camera`): the drone's
3-axis gimbal levels the camera, so an attitude error moves the optical axis (pitch and yaw);
the component of a rotation about the optical axis is dropped.

Defaults (:data:`REALISTIC`), from RTK multirotor spec sheets (DJI Matrice 350 RTK: hovering
accuracy with RTK +-0.1 m; DJI RTK positioning 1 cm + 1 ppm horizontal, 1.5 cm + 1 ppm
vertical; gimbal angular vibration range +-0.01 deg, attitude from the flight controller well
under a degree): hover position sigma 0.05 m (so that +-2 sigma = the spec's +-0.1 m),
attitude 0.5 deg; reported position sigma 0.02 m, attitude 0.5 deg; sensor noise 2/255.
:data:`IDEAL` has every figure 0: the planned pose is flown and reported exactly and the image
is the rendered one, bit for bit.

Ground control (``gcp_markers``, default 4; 0: none, the drones' reports alone): ArUco markers
of ``gcp_size`` m (0.3) lie on the soil around the plants, at least ``gcp_markers`` and more along
a long plot's edge so that neighbours are at most ``gcp_spacing`` m (3.5) apart, as a surveyor
spaces them (:meth:`CaptureModel.marker_count`; the paper's three scenes get 4, grid_3x3 5, row_12
7), rendered into the images (:func:`vp_scene.ground_control.marker_layout`); the user knows their
positions as surveyed, each ``gcp_sigma`` m (0.01: an RTK rover on a tripod) off per axis (one
survey of the field, the same in every realization: :meth:`CaptureModel.lay_markers`). Why by
default: a plot flown for centimetre-level 3D models is flown with ground control, and without it
the registration is most of a small plan's error (:mod:`vp_recon.gcp`).

Every draw is seeded by ``(seed, realization k, camera i, stream)`` (numpy's SeedSequence
entropy list), so a capture is reproducible, the same camera in another realization draws
again, and one drone's capture does not depend on the others (:meth:`CaptureModel.fly_camera`,
the per-camera API the simulated drones use).

ROS-free: numpy and scipy.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from .camera import check_cameras
from .limits import check_seed

__all__ = ["CAPTURES", "CaptureModel", "IDEAL", "REALISTIC", "Flight"]

#: The capture kinds: ``realistic`` (the defaults below) and ``ideal`` (no error at all).
CAPTURES = ("realistic", "ideal")

# streams of a camera's draws (the fourth entry of the seed); the markers' survey: (seed, 0, 0, _SURVEY)
_HOVER, _REPORT, _SENSOR, _SURVEY = 0, 1, 2, 3


@dataclass(frozen=True)
class Flight:
    """One capture of a plan in one realization: ``actual`` and ``reported`` cameras (N, 6)."""

    actual: NDArray[np.float64]
    reported: NDArray[np.float64]


@dataclass(frozen=True)
class CaptureModel:
    """What a flight does to a plan (module docstring). Distances m, angles degrees.

    Attributes:
        kind: ``'realistic'`` or ``'ideal'`` (every figure must then be 0).
        hover_position_sigma, hover_attitude_sigma: hover error, per axis.
        report_position_sigma, report_attitude_sigma: localization error, per axis (for a real
            flight: how well its reported poses are known; a rig whose attitude is known only
            roughly, a camera mount 20 degrees off, has a large attitude sigma, up to 180).
        sensor_noise: std of the image noise, fraction of full scale.
        seed: seeds every draw with the realization and the camera.
        gcp_markers: the fewest ground markers laid around the plants (0: none; at most 50).
        gcp_sigma: the markers' survey error, m per axis (> 0).
        gcp_size: a marker's printed side, m (its code square is half of it).
        gcp_spacing: the most metres between neighbouring markers along the plot's edge (more
            markers than ``gcp_markers`` on a long plot).
    """

    kind: str = "realistic"
    hover_position_sigma: float = 0.05
    hover_attitude_sigma: float = 0.5
    report_position_sigma: float = 0.02
    report_attitude_sigma: float = 0.5
    sensor_noise: float = 2.0 / 255.0
    seed: int = 0
    gcp_markers: int = 4
    gcp_sigma: float = 0.01
    gcp_size: float = 0.3
    gcp_spacing: float = 3.5

    _FIGURES = ("hover_position_sigma", "hover_attitude_sigma", "report_position_sigma",
                "report_attitude_sigma", "sensor_noise")

    @classmethod
    def named(cls, kind: str, **figures: Any) -> "CaptureModel":
        """The model of ``kind`` (:data:`CAPTURES`): realistic defaults, overridden by
        ``figures`` given (None: the default), or the ideal one; validated."""
        if kind not in CAPTURES:
            raise ValueError(f"capture must be one of {', '.join(CAPTURES)}, got {kind!r}")
        base = IDEAL if kind == "ideal" else REALISTIC
        return replace(base, **{k: v for k, v in figures.items() if v is not None}).validate()

    def validate(self) -> "CaptureModel":
        """Raise ValueError naming the first bad field; return self."""
        if self.kind not in CAPTURES:
            raise ValueError(f"capture must be one of {', '.join(CAPTURES)}, got {self.kind!r}")
        for name in self._FIGURES:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
                raise ValueError(f"capture {name} must be a finite number >= 0, got {v!r}")
        if self.hover_attitude_sigma > 10:
            raise ValueError("capture hover_attitude_sigma must be at most 10 degrees")
        if self.report_attitude_sigma > 180:  # a rig that reports its attitude only roughly: up to unknown
            raise ValueError("capture report_attitude_sigma must be at most 180 degrees")
        if self.sensor_noise > 0.5:
            raise ValueError(f"capture sensor_noise must be at most 0.5 of full scale, got {self.sensor_noise!r}")
        if self.kind == "ideal" and any(getattr(self, n) for n in self._FIGURES):
            raise ValueError("capture 'ideal' has no error: its figures must all be 0")
        check_seed("capture seed", self.seed)
        from .ground_control import MAX_MARKERS

        m = self.gcp_markers
        if isinstance(m, bool) or not isinstance(m, (int, np.integer)) or not 0 <= m <= MAX_MARKERS:
            raise ValueError(f"capture gcp_markers must be an integer in [0, {MAX_MARKERS}], got {m!r}")
        if self.kind == "ideal" and m:
            raise ValueError("capture 'ideal' has no ground markers: its poses are known exactly")
        for name, hi in (("gcp_sigma", 1.0), ("gcp_size", 2.0), ("gcp_spacing", 100.0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and 0 < v <= hi):
                raise ValueError(f"capture {name} must be a number in (0, {hi:g}] m, got {v!r}")
        return self

    @property
    def ideal(self) -> bool:
        return self.kind == "ideal"

    def to_dict(self) -> dict:
        """JSON form (recon.json, plan records): kind and every figure (records made before the
        ground markers have no ``gcp_*`` keys: their captures had none)."""
        return {k: (float(v) if k in self._FIGURES else v) for k, v in asdict(self).items()}

    def marker_count(self, points: ArrayLike) -> int:
        """How many markers a field of ``points`` gets: ``gcp_markers``, or more when its edge (the
        x-y box grown by :data:`~vp_scene.ground_control.MARKER_MARGIN`) is long, ceil(perimeter /
        ``gcp_spacing``), at most 50."""
        from .ground_control import MARKER_MARGIN, MAX_MARKERS

        if not self.gcp_markers:
            return 0
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        w, h = p[:, :2].max(axis=0) - p[:, :2].min(axis=0) + 2 * MARKER_MARGIN
        return int(min(MAX_MARKERS, max(self.gcp_markers, math.ceil(2 * (w + h) / self.gcp_spacing - 1e-9))))

    def lay_markers(self, points: ArrayLike) -> tuple[NDArray[np.float64], Any]:
        """The ground markers of a field whose plants are ``points`` (..., 3) (every realization's):
        their true centres (M, 3) (where they are rendered) and the
        :class:`vp_scene.ground_control.GroundControl` the user has (named by marker id, the
        surveyed centres: ``gcp_sigma`` m off per axis, one survey for every realization);
        (0, 3) and None without markers."""
        from .ground_control import GroundControl, marker_layout

        if not self.gcp_markers:
            return np.zeros((0, 3)), None
        true = marker_layout(points, self.marker_count(points))
        rng = np.random.default_rng([int(self.seed), 0, 0, _SURVEY])
        surveyed = true + self.gcp_sigma * rng.standard_normal(true.shape)
        control = GroundControl(positions={str(i): tuple(float(x) for x in p) for i, p in enumerate(surveyed)},
                                sigma=float(self.gcp_sigma))
        return true, control

    def _rng(self, k: int, i: int, stream: int) -> np.random.Generator:
        return np.random.default_rng([int(self.seed), int(k), int(i), stream])

    @staticmethod
    def _perturb(camera: NDArray[np.float64], rng: np.random.Generator, sigma_pos: float,
                 sigma_deg: float) -> NDArray[np.float64]:
        out = camera.copy()
        out[:3] = camera[:3] + sigma_pos * rng.standard_normal(3)
        turn = Rotation.from_rotvec(math.radians(sigma_deg) * rng.standard_normal(3))
        v = camera[3:] / np.linalg.norm(camera[3:])
        out[3:] = turn.apply(v)
        return out

    def fly_camera(self, camera: ArrayLike, k: int, i: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(actual, reported) 6-vectors of camera ``i`` of a plan flown in realization ``k``.
        Ideal: both are the planned camera itself (unchanged, not normalized)."""
        cam = check_cameras(np.asarray(camera, dtype=np.float64).reshape(1, 6))[0]
        if self.ideal:
            return cam.copy(), cam.copy()
        actual = self._perturb(cam, self._rng(k, i, _HOVER), self.hover_position_sigma, self.hover_attitude_sigma)
        reported = self._perturb(actual, self._rng(k, i, _REPORT), self.report_position_sigma,
                                 self.report_attitude_sigma)
        return actual, reported

    def fly(self, cameras: ArrayLike, k: int) -> Flight:
        """Every camera of a plan (N, 6) flown in realization ``k``."""
        cams = check_cameras(cameras)
        pairs = [self.fly_camera(c, k, i) for i, c in enumerate(cams)]
        return Flight(actual=np.array([a for a, _ in pairs]).reshape(-1, 6),
                      reported=np.array([r for _, r in pairs]).reshape(-1, 6))

    def expose(self, image: NDArray[np.uint8], k: int, i: int) -> NDArray[np.uint8]:
        """Camera ``i``'s image in realization ``k`` with the sensor noise (ideal: ``image``)."""
        if self.ideal or self.sensor_noise == 0:
            return image
        rng = self._rng(k, i, _SENSOR)
        noisy = image.astype(np.float32) + np.float32(255.0 * self.sensor_noise) * \
            rng.standard_normal(image.shape, dtype=np.float32)
        return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)


#: No error at all: the planned poses flown and known exactly, noise-free images.
IDEAL = CaptureModel("ideal", 0.0, 0.0, 0.0, 0.0, 0.0, gcp_markers=0)
#: The defaults of an RTK multirotor (module docstring).
REALISTIC = CaptureModel()
