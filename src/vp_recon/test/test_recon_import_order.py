"""vp_recon loads OpenCV before pycolmap: with pycolmap's libraries loaded first, OpenCV's PNG
writer aborts the process; a process that loaded pycolmap first is refused with one line."""
from __future__ import annotations

import subprocess
import sys

WRITE = ("import cv2, numpy as np, tempfile, os\n"
         "path = os.path.join(tempfile.mkdtemp(), 'x.png')\n"
         "assert cv2.imwrite(path, np.zeros((64, 64, 3), np.uint8))\n"
         "print('written')\n")


def run(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)


def test_the_hazard_is_real_pycolmap_first_aborts_a_png_write() -> None:
    out = run("import pycolmap\n" + WRITE)
    assert out.returncode != 0 and "written" not in out.stdout  # the abort the package guards against


def test_a_module_that_loads_pycolmap_loads_opencv_first() -> None:
    for module in ("vp_recon.registration", "vp_recon.sparse_modes"):  # pycolmap at their top, no cv2 of their own
        out = run(f"import {module}, pycolmap\n" + WRITE)
        assert out.returncode == 0 and "written" in out.stdout, (module, out.stderr[-2000:])


def test_pycolmap_imported_before_vp_recon_is_one_clear_error() -> None:
    out = run("import pycolmap\nimport vp_recon.sparse\n")
    assert out.returncode == 1
    assert out.stderr.strip().splitlines()[-1] == (
        "ImportError: import vp_recon (or cv2) before pycolmap: with pycolmap loaded first, OpenCV's PNG writer "
        "aborts the process (double free)")
