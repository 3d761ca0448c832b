"""vp_recon does not depend on vp_planner: the plan's reward reaches the recon node in a message
(vp_interfaces/CameraPlan on /camera_plan/info), camera geometry comes from vp_scene.camera."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

PKG = Path(__file__).resolve().parents[1]
IMPORT = re.compile(r"^\s*(from\s+vp_planner[\s.]|import\s+vp_planner\b)", re.M)


def test_no_source_file_imports_vp_planner() -> None:
    files = sorted((PKG / "vp_recon").glob("*.py"))
    assert files
    offenders = [f.name for f in files if IMPORT.search(f.read_text())]
    assert not offenders, f"vp_recon modules importing vp_planner: {offenders}"
    assert "vp_planner" not in (PKG / "package.xml").read_text()


def test_importing_every_module_loads_no_vp_planner() -> None:
    """In a fresh interpreter: import all of vp_recon (the node included), then look."""
    code = ("import importlib, pkgutil, sys, vp_recon\n"
            "for m in pkgutil.iter_modules(vp_recon.__path__):\n"
            "    importlib.import_module('vp_recon.' + m.name)\n"
            "print(sorted(n for n in sys.modules if n.split('.')[0] == 'vp_planner'))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.strip().splitlines()[-1] == "[]", out.stdout
