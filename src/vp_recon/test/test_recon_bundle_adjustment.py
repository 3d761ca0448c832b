"""vp_recon.sparse_modes._adjust is pycolmap.bundle_adjustment to the last bit, from pycolmap's own
parts, without the INFO lines pycolmap's call prints on every use whatever the log level."""
from __future__ import annotations

import subprocess
import sys

import numpy as np

NOISY = ("import vp_recon.sparse_modes as sm, pycolmap\n"
         "o = pycolmap.SyntheticDatasetOptions(num_rigs=1, num_frames_per_rig=6, num_points3D=150)\n"
         "rec = pycolmap.synthesize_dataset(o)\n"
         "pycolmap.synthesize_noise(pycolmap.SyntheticNoiseOptions(rig_from_world_translation_stddev=0.05, "
         "rig_from_world_rotation_stddev=0.5, point3D_stddev=0.05, point2D_stddev=0.5), rec)\n")


def state(rec) -> tuple[np.ndarray, np.ndarray]:
    pts = np.array([[*p.xyz, p.error] for _, p in sorted(rec.points3D.items())])
    poses = np.array([np.r_[im.cam_from_world().rotation.quat, im.cam_from_world().translation]
                      for _, im in sorted(rec.images.items()) if im.has_pose])
    return pts, poses


def test_the_adjustment_is_pycolmaps_to_the_last_bit() -> None:
    scope: dict = {}
    exec(NOISY, scope)  # noqa: S102 - the same scene the subprocess below adjusts
    pycolmap, rec = scope["pycolmap"], scope["rec"]
    twin = pycolmap.Reconstruction(rec)
    before = state(rec)
    scope["sm"]._adjust(rec, pycolmap.BundleAdjustmentOptions())
    pycolmap.bundle_adjustment(twin, pycolmap.BundleAdjustmentOptions())
    (pts, poses), (pts_twin, poses_twin) = state(rec), state(twin)
    assert not np.array_equal(pts, before[0])  # it adjusted something
    assert np.array_equal(pts, pts_twin) and np.array_equal(poses, poses_twin)


def test_the_adjustment_prints_nothing() -> None:
    """COLMAP's INFO lines go to the process's stderr (C level): looked at in a process of its own,
    at the log level the reconstruction keeps (2: errors only)."""
    quiet = NOISY + "pycolmap.logging.minloglevel = 2\n"
    out = subprocess.run([sys.executable, "-c", quiet + "sm._adjust(rec, pycolmap.BundleAdjustmentOptions())\n"
                          "print('adjusted')\n"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "adjusted", out.stderr[-2000:]
    assert "bundle_adjustment" not in out.stderr and "Elapsed time" not in out.stderr, out.stderr[-2000:]
    call = "pycolmap.bundle_adjustment(rec, pycolmap.BundleAdjustmentOptions())\n"
    loud = subprocess.run([sys.executable, "-c", quiet + call], capture_output=True, text=True, timeout=120)
    assert loud.returncode == 0 and "Global bundle adjustment" in loud.stderr  # what pycolmap's call prints
