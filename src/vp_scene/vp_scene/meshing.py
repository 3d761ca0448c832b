"""Triangle meshes of a scene's plants for rendering, one wind realization at a time.

A plant model either carries its own coloured mesh (procedural corn) or only a coloured point
cloud (Corn50 PLY scans). Point clouds are meshed once with screened Poisson surface
reconstruction (Kazhdan & Hoppe, "Screened Poisson Surface Reconstruction", ACM TOG 2013) in
Open3D, then trimmed:

* vertices of the lowest ``DENSITY_QUANTILE`` (8%) octree density (extrapolated surface),
* vertices farther than ``MAX_DISTANCE`` (0.008 model units) from every input point,

and cached on disk under a hash of the point cloud and the recipe (seconds per plant).

A placed mesh follows its points exactly: :func:`vp_scene.scenario.place_mesh` (yaw, scale,
translation), then :func:`vp_scene.wind.displace` with the plant's ``z_range`` and the
realization's ``n_wind``: a vertex of level l moves by l * n_wind along the wind direction,
the same displacement as the realization's points (paper Sec. V-A).
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Optional, Union

import numpy as np
import trimesh

from vp_scene.folders import user_cache, write_atomic
from vp_scene.scenario import place_mesh
from vp_scene.wind import displace

__all__ = ["POISSON_DEPTH", "DENSITY_QUANTILE", "MAX_DISTANCE", "default_mesh_cache", "model_mesh",
           "poisson_mesh", "scene_meshes"]

POISSON_DEPTH = 10
DENSITY_QUANTILE = 0.08
MAX_DISTANCE = 0.008
_RECIPE = f"poisson-v1-d{POISSON_DEPTH}-q{DENSITY_QUANTILE}-r{MAX_DISTANCE}"

#: In-process cache: content hash -> mesh (model-frame).
_MEMORY: dict[str, trimesh.Trimesh] = {}

PathLike = Union[str, os.PathLike]


def default_mesh_cache() -> Path:
    """``$VP_MESH_CACHE`` or ``$XDG_CACHE_HOME/vp_suite/meshes`` (default ``~/.cache/vp_suite/meshes``)."""
    return user_cache("meshes", "VP_MESH_CACHE")


def _content_hash(points: np.ndarray, colors: np.ndarray) -> str:
    h = hashlib.sha256(_RECIPE.encode())
    h.update(np.ascontiguousarray(points, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(colors, dtype=np.uint8).tobytes())
    return h.hexdigest()[:32]


def poisson_mesh(points: np.ndarray, colors: np.ndarray) -> trimesh.Trimesh:
    """Screened Poisson mesh (Open3D) of a coloured point cloud, trimmed as in the module doc.

    Normals: PCA of the 30 nearest neighbours, oriented consistently over a tangent-plane graph
    (Hoppe et al. 1992). Raises RuntimeError when Open3D is missing.
    """
    try:
        import open3d as o3d
    except ImportError as exc:
        raise RuntimeError("meshing a point-cloud plant model (a PLY scan without faces) needs open3d: "
                           "pip install open3d") from exc
    pts = np.asarray(points, dtype=np.float64)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    pcd.colors = o3d.utility.Vector3dVector(np.asarray(colors, dtype=np.float64) / 255.0)
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn=30))
    try:
        pcd.orient_normals_consistent_tangent_plane(15)
    except RuntimeError:                                   # degenerate graph: keep PCA normals
        pass
    mesh, density = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(pcd, depth=POISSON_DEPTH)
    density = np.asarray(density)
    mesh.remove_vertices_by_mask(density < np.quantile(density, DENSITY_QUANTILE))
    v = np.asarray(mesh.vertices)
    from scipy.spatial import cKDTree
    dist, _ = cKDTree(pts).query(v, k=1, workers=-1)
    mesh.remove_vertices_by_mask(dist > MAX_DISTANCE)
    mesh.remove_unreferenced_vertices()
    v = np.asarray(mesh.vertices)
    f = np.asarray(mesh.triangles)
    c = np.clip(np.asarray(mesh.vertex_colors) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    if len(f) == 0:
        raise RuntimeError("Poisson meshing produced no triangles")
    rgba = np.concatenate([c, np.full((len(c), 1), 255, np.uint8)], axis=1)
    out = trimesh.Trimesh(vertices=v, faces=f, vertex_colors=rgba, process=False)
    out.metadata["double_sided"] = True
    return out


def model_mesh(model: object, mesh_cache: Optional[PathLike] = None) -> trimesh.Trimesh:
    """The model-frame mesh of a :class:`vp_scene.plants.PlantModel`: its own, or a cached Poisson mesh.

    ``mesh_cache``: folder of ``<hash>.npz`` meshes (None: :func:`default_mesh_cache`). An
    unreadable cache entry is recomputed; an unwritable cache folder is ignored.
    """
    own = getattr(model, "mesh", None)
    if own is not None:
        return own
    key = _content_hash(model.points, model.colors)
    if key in _MEMORY:
        return _MEMORY[key]
    folder = Path(mesh_cache) if mesh_cache is not None else default_mesh_cache()
    path = folder / f"{key}.npz"
    mesh = None
    if path.is_file():
        try:
            with np.load(path) as z:
                mesh = trimesh.Trimesh(vertices=z["vertices"], faces=z["faces"], vertex_colors=z["colors"],
                                       process=False)
            mesh.metadata["double_sided"] = True
        except Exception:  # noqa: BLE001 - corrupt cache entry: rebuild it
            mesh = None
    if mesh is None:
        mesh = poisson_mesh(model.points, model.colors)
        def write(tmp: Path) -> None:
            with open(tmp, "wb") as fh:
                np.savez(fh, vertices=np.asarray(mesh.vertices), faces=np.asarray(mesh.faces),
                         colors=np.asarray(mesh.visual.vertex_colors))
        try:
            folder.mkdir(parents=True, exist_ok=True)
            write_atomic(path, write)
        except OSError:  # an unwritable cache (OutputError included): the mesh is rebuilt next time
            pass
    _MEMORY[key] = mesh
    return mesh


def scene_meshes(noisy_scene: object, k: int, mesh_cache: Optional[PathLike] = None) -> list[trimesh.Trimesh]:
    """World-frame meshes of every plant of wind realization ``k`` of a :class:`vp_scene.wind.NoisyScene`.

    Each model mesh is placed like its plant (``place_mesh``), then every vertex is displaced
    with ``displace(vertices, plant.z_range, n_wind[k], levels, direction)``.
    """
    n_wind = np.asarray(noisy_scene.n_wind)
    if not (0 <= int(k) < len(n_wind)):
        raise IndexError(f"realization {k} out of range 0..{len(n_wind) - 1}")
    cfg = noisy_scene.config
    scene = noisy_scene.scene
    out = []
    for plant in scene.plants:
        placed = place_mesh(model_mesh(scene.models[plant.model_index], mesh_cache), plant)
        placed.vertices = displace(np.asarray(placed.vertices), plant.z_range, float(n_wind[int(k)]),
                                   cfg.levels, cfg.direction)
        out.append(placed)
    return out
