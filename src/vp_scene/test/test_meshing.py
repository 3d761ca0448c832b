"""Poisson meshing of point-cloud plant models and its disk cache."""
from __future__ import annotations

import numpy as np

from vp_scene import meshing
from vp_scene.plants import PlantModel


def test_poisson_mesh_is_cached(tmp_path) -> None:
    rng = np.random.default_rng(0)
    d = rng.normal(size=(6000, 3))
    pts = 0.1 * d / np.linalg.norm(d, axis=1, keepdims=True)           # sphere of radius 0.1
    cols = np.tile(np.array([[40, 160, 40]], np.uint8), (len(pts), 1))
    model = PlantModel(name="ball", points=pts, colors=cols, mesh=None)
    mesh = meshing.model_mesh(model, tmp_path)
    assert len(mesh.faces) > 1000
    r = np.linalg.norm(np.asarray(mesh.vertices), axis=1)
    assert np.all(np.abs(r - 0.1) < meshing.MAX_DISTANCE + 1e-3)        # trimmed to the samples
    assert np.abs(np.asarray(mesh.visual.vertex_colors)[:, :3].astype(int) - [40, 160, 40]).max() <= 2
    files = list(tmp_path.glob("*.npz"))
    assert len(files) == 1
    meshing._MEMORY.clear()
    again = meshing.model_mesh(model, tmp_path)                           # from disk
    assert np.allclose(again.vertices, mesh.vertices) and np.array_equal(again.faces, mesh.faces)
    files[0].write_bytes(b"corrupt")                                      # a corrupt entry is rebuilt
    meshing._MEMORY.clear()
    rebuilt = meshing.model_mesh(model, tmp_path)                         # (Poisson is not bit-reproducible)
    assert abs(len(rebuilt.faces) - len(mesh.faces)) < 0.05 * len(mesh.faces)
    with np.load(files[0]) as z:
        assert len(z["faces"]) == len(rebuilt.faces)
