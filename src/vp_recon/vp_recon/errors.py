"""The reconstruction's refusals: the error codes (identical to the ``vp_interfaces/ReconstructionScore``
constants), :class:`ReconError` (a failure with its code) and the checks of what a reconstruction
is given that answer with them: the plan (EMPTY_PLAN, PLAN_TOO_LARGE), the scene (NO_SCENE) and
the output folder (OUTPUT_NOT_WRITABLE); :class:`SparseError`, the sparse step's failure, which
the pipeline reports as RECONSTRUCTION_FAILED.
Writers (the CLI, the recon node) turn a ReconError into an exit code or a score message."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Optional, Sequence, Union

import numpy as np
from numpy.typing import NDArray

from .config import MAX_CAMERAS

__all__ = ["NONE", "UNKNOWN", "EMPTY_PLAN", "NO_SCENE", "NOTHING_VISIBLE", "RECONSTRUCTION_FAILED",
           "OUTPUT_NOT_WRITABLE", "WRONG_FRAME", "CAPTURE_MISSING", "PLAN_TOO_LARGE", "ERROR_NAMES", "ReconError",
           "SparseError", "REQUEST_ERRORS", "validate_cameras", "check_plan_size", "check_scene", "check_realizations",
           "ensure_writable_dir"]

NONE = 0
UNKNOWN = 1
EMPTY_PLAN = 2
NO_SCENE = 3
NOTHING_VISIBLE = 4
RECONSTRUCTION_FAILED = 5
OUTPUT_NOT_WRITABLE = 6
WRONG_FRAME = 7
CAPTURE_MISSING = 8
PLAN_TOO_LARGE = 9
ERROR_NAMES = {NONE: "NONE", UNKNOWN: "UNKNOWN", EMPTY_PLAN: "EMPTY_PLAN", NO_SCENE: "NO_SCENE",
               NOTHING_VISIBLE: "NOTHING_VISIBLE", RECONSTRUCTION_FAILED: "RECONSTRUCTION_FAILED",
               OUTPUT_NOT_WRITABLE: "OUTPUT_NOT_WRITABLE", WRONG_FRAME: "WRONG_FRAME",
               CAPTURE_MISSING: "CAPTURE_MISSING", PLAN_TOO_LARGE: "PLAN_TOO_LARGE"}

#: The codes of a request that cannot be run as given (the plan, the scene, the output folder, the
#: size): the CLI's usage errors (exit 2), which leave its output folder as it was.
REQUEST_ERRORS = (EMPTY_PLAN, NO_SCENE, OUTPUT_NOT_WRITABLE, PLAN_TOO_LARGE)


class ReconError(Exception):
    """A reconstruction failure with a ``ReconstructionScore`` error code (``.code``) and message;
    ``.realization`` is the wind realization that failed (None: the plan as a whole)."""

    def __init__(self, code: int, message: str, realization: Optional[int] = None) -> None:
        super().__init__(message)
        self.code = int(code)
        self.message = message
        self.realization = realization

    @property
    def name(self) -> str:
        """The code's constant name, e.g. ``'NOTHING_VISIBLE'``."""
        return ERROR_NAMES.get(self.code, "UNKNOWN")


class SparseError(RuntimeError):
    """The sparse step made no model: no features, no matches, no triangulated point, or a
    structure from motion that registered too little or could not be placed in the world."""


def validate_cameras(cameras: object) -> NDArray[np.float64]:
    """The plan as an (N, 6) array with N >= 2; ReconError(EMPTY_PLAN) naming the problem otherwise."""
    try:
        cams = np.asarray(cameras, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ReconError(EMPTY_PLAN, f"cameras are not a numeric (N, 6) array: {exc}") from None
    if cams.size == 0:
        raise ReconError(EMPTY_PLAN, "the plan has no cameras")
    if cams.ndim == 1 and cams.size % 6 == 0:
        cams = cams.reshape(-1, 6)
    if cams.ndim != 2 or cams.shape[1] != 6:
        raise ReconError(EMPTY_PLAN, f"cameras must have shape (N, 6) = [cx, cy, cz, vx, vy, vz], got {cams.shape}")
    if not np.all(np.isfinite(cams)):
        raise ReconError(EMPTY_PLAN, "cameras contain NaN or infinite values")
    bad = np.flatnonzero(np.linalg.norm(cams[:, 3:], axis=1) <= 1e-12)
    if len(bad):
        raise ReconError(EMPTY_PLAN, f"camera(s) {bad.tolist()} have a zero viewing direction")
    if len(cams) < 2:
        raise ReconError(EMPTY_PLAN, f"a reconstruction needs at least 2 cameras, the plan has {len(cams)}")
    return cams


def check_plan_size(num_cameras: int, max_cameras: int = MAX_CAMERAS, setting: str = "max_cameras") -> None:
    """ReconError(PLAN_TOO_LARGE) for a plan of more than ``max_cameras`` cameras (``setting``:
    the name the user knows the cap by, in the message)."""
    if num_cameras > max_cameras:
        raise ReconError(PLAN_TOO_LARGE, f"the plan has {num_cameras} cameras; at most {max_cameras} are "
                         f"reconstructed ({setting}: every image of a realization is held at once)")


def check_scene(noisy_scene: object) -> NDArray[np.float64]:
    """The (K, P, 3) realizations of a :class:`vp_scene.wind.NoisyScene`; ReconError(NO_SCENE) naming the
    problem otherwise."""
    pts = getattr(noisy_scene, "points", None)
    if noisy_scene is None or pts is None or getattr(noisy_scene, "scene", None) is None:
        raise ReconError(NO_SCENE, "no scene: give a vp_scene NoisyScene")
    pts = np.asarray(pts)
    if pts.ndim != 3 or pts.shape[0] == 0 or pts.shape[1] == 0 or pts.shape[2] != 3:
        raise ReconError(NO_SCENE, f"the scene has no points (realizations array of shape {pts.shape})")
    return pts


def check_realizations(realizations: Optional[Sequence[int]], count: int) -> list[int]:
    """The wind realizations to reconstruct of a scene of ``count`` (None: all of them), in the
    order given; ReconError(NO_SCENE) for none, one the scene does not have, or a duplicate."""
    ks = list(range(count)) if realizations is None else [int(x) for x in realizations]
    if not ks:
        raise ReconError(NO_SCENE, "no realization selected")
    bad = [x for x in ks if not 0 <= x < count]
    if bad:
        raise ReconError(NO_SCENE, f"realization(s) {bad} do not exist (the scene has {count}: 0..{count - 1})")
    if len(set(ks)) != len(ks):
        raise ReconError(NO_SCENE, f"duplicate realizations in {ks}")
    return ks


def ensure_writable_dir(path: Union[str, os.PathLike]) -> Path:
    """Create ``path`` if needed and check it is a writable folder; ReconError(OUTPUT_NOT_WRITABLE)."""
    p = Path(path)
    try:
        p.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=p, prefix=".write-test-"):
            pass
    except OSError as exc:
        raise ReconError(OUTPUT_NOT_WRITABLE, f"output folder {p} is not writable: {exc.strerror or exc}") from None
    return p
