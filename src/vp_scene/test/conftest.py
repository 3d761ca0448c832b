"""The vp_scene tests render headless (vp_scene.render): EGL unless the environment chooses."""
from __future__ import annotations

import os

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
