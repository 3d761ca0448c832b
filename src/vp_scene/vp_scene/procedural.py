"""The built-in procedural corn plant: a coloured triangle mesh and its surface samples in the
Corn50 model frame, so that the suite runs without any data (:func:`procedural_corn`), and the
names and seeds that identify such a plant in a scene.

ROS-free: numpy and trimesh only.
"""
from __future__ import annotations

import math
import re
from typing import Optional

import numpy as np
import trimesh

from .plants import PlantModel

__all__ = ["procedural_corn", "procedural_name", "procedural_name_seed", "procedural_seed", "sample_surface"]

_PROCEDURAL_NAME = re.compile(r"procedural-(\d+)")


def procedural_name(seed: int) -> str:
    """The name of the procedural plant of ``seed``: ``procedural-<seed>``."""
    return f"procedural-{int(seed)}"


def procedural_name_seed(name: str) -> Optional[int]:
    """The seed of a procedural plant's name (:func:`procedural_name`), None for any other name."""
    m = _PROCEDURAL_NAME.fullmatch(name)
    return None if m is None else int(m.group(1))


def procedural_seed(seed: int, index: int) -> int:
    """Stable per-plant seed derived from a scene seed and a plant index ("hash of (seed, i)")."""
    return int(np.random.SeedSequence([int(seed), int(index)]).generate_state(1)[0] & 0x7FFFFFFF)


def _grid_faces(rows: int, cols: int, start: int, wrap: bool = False) -> np.ndarray:
    """Triangles of a rows x cols vertex grid (row-major), optionally closed around the columns."""
    c = cols if wrap else cols - 1
    r, k = np.meshgrid(np.arange(rows - 1), np.arange(c), indexing="ij")
    a = start + r * cols + k
    b = start + r * cols + (k + 1) % cols
    d = start + (r + 1) * cols + k
    e = start + (r + 1) * cols + (k + 1) % cols
    return np.concatenate([np.stack([a, b, e], -1).reshape(-1, 3), np.stack([a, e, d], -1).reshape(-1, 3)])


def _frames(path: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tangent and two normals along a polyline (a rotation-minimizing-ish frame)."""
    t = np.gradient(path, axis=0)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    ref = np.where(np.abs(t[:, 2:3]) < 0.9, np.array([[0.0, 0.0, 1.0]]), np.array([[1.0, 0.0, 0.0]]))
    n1 = np.cross(t, ref)
    n1 /= np.linalg.norm(n1, axis=1, keepdims=True)
    n2 = np.cross(t, n1)
    return t, n1, n2


def _tube(path: np.ndarray, radius: np.ndarray, sides: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A tube around a polyline: vertices (n*sides, 3), faces, and the angle of each vertex."""
    _t, n1, n2 = _frames(path)
    ang = np.linspace(0.0, 2 * np.pi, sides, endpoint=False)
    v = (path[:, None, :] + radius[:, None, None]
         * (np.cos(ang)[None, :, None] * n1[:, None, :] + np.sin(ang)[None, :, None] * n2[:, None, :]))
    return v.reshape(-1, 3), _grid_faces(len(path), sides, 0, wrap=True), np.tile(ang, len(path))


def _smooth_noise(rng: np.random.Generator, x: np.ndarray, terms: int = 4, scale: float = 1.0) -> np.ndarray:
    """Low-frequency pseudo-noise in [-1, 1]-ish: a few random sinusoids of x (x in [0, 1])."""
    out = np.zeros_like(x, dtype=np.float64)
    for j in range(terms):
        f = rng.uniform(1.0, 4.0) * (j + 1) * scale
        out += np.sin(2 * np.pi * f * x + rng.uniform(0, 2 * np.pi)) / (j + 1)
    return out / 1.6


def _stalk(rng: np.random.Generator, height: float, node_z: np.ndarray):
    """Tapered stalk (cylinder) from z = 0 to ``height``: vertices, faces, colours (float RGB)."""
    rows, sides = 64, 16
    z = np.linspace(0.0, height, rows)
    s = z / height
    r0 = rng.uniform(0.024, 0.032)
    radius = r0 * (1.0 - 0.6 * s) * (1.0 + 0.25 * np.exp(-s / 0.04))  # flared base (brace roots)
    path = np.stack([np.zeros(rows), np.zeros(rows), z], 1)
    v, f, ang = _tube(path, radius, sides)
    srow = np.repeat(s, sides)
    green = np.array([72.0, 118.0, 42.0]) * rng.uniform(0.9, 1.1, 3)
    dark = np.array([70.0, 62.0, 38.0])      # darker, brownish base
    col = green[None] * (0.8 + 0.2 * srow[:, None])
    w_base = np.exp(-srow / 0.08)[:, None]
    col = col * (1 - w_base) + dark[None] * w_base
    # nodes: pale rings where leaves insert; vertical stripes (vascular bundles) around
    zr = np.repeat(z, sides)
    ring = np.exp(-((zr[:, None] - node_z[None]) / 0.012) ** 2).max(axis=1)
    col = col * (1 - 0.45 * ring[:, None]) + np.array([175.0, 185.0, 110.0]) * 0.45 * ring[:, None]
    col *= (1.0 + 0.07 * np.cos(ang * 8))[:, None]
    return v, f, col


def _leaf(rng: np.random.Generator, z0: float, stalk_r: float, phi: float, length: float, width: float,
          theta0: float, droop: float, senescence: float):
    """One strap leaf: curved drooping midrib, width tapering to a tip, V fold, wavy margins."""
    rows, cols = 90, 11
    sig = np.linspace(0.0, 1.0, rows)          # position along the leaf (0 base, 1 tip)
    u = np.linspace(-1.0, 1.0, cols)           # across the leaf
    ds = length / (rows - 1)
    curl = rng.normal(0.0, 0.25)
    phis = phi + curl * sig ** 2               # slight sideways curve
    d = np.stack([np.cos(phis), np.sin(phis), np.zeros(rows)], 1)
    for _ in range(40):                        # low leaves: droop less rather than reach the ground
        theta = theta0 - droop * sig ** 1.4    # elevation of the midrib: rises, then droops
        tang = np.cos(theta)[:, None] * d + np.sin(theta)[:, None] * np.array([0.0, 0.0, 1.0])
        mid = np.cumsum(np.vstack([np.zeros((1, 3)), 0.5 * (tang[1:] + tang[:-1]) * ds]), axis=0)
        mid += np.array([stalk_r * math.cos(phi), stalk_r * math.sin(phi), z0])
        if mid[:, 2].min() >= 0.04:
            break
        droop *= 0.92
    lat = np.stack([-np.sin(phis), np.cos(phis), np.zeros(rows)], 1)
    nrm = np.cross(tang, lat)
    psi = rng.normal(0.0, 0.5) * sig ** 1.5    # twist towards the tip
    lat, nrm = (lat * np.cos(psi)[:, None] + nrm * np.sin(psi)[:, None],
                -lat * np.sin(psi)[:, None] + nrm * np.cos(psi)[:, None])
    half = 0.5 * width * np.sin(np.pi * (0.12 + 0.88 * sig)) ** 0.6
    half[-1] = 0.0
    fold = rng.uniform(0.15, 0.35)
    wave = 0.003 * np.sin(2 * np.pi * sig * length / rng.uniform(0.04, 0.07) + rng.uniform(0, 6.3))
    uu = u[None, :]
    off_n = half[:, None] * fold * np.abs(uu) + wave[:, None] * np.abs(uu) ** 3
    v = mid[:, None, :] + (half[:, None] * uu)[..., None] * lat[:, None, :] + off_n[..., None] * nrm[:, None, :]
    v[..., 2] = np.maximum(v[..., 2], 0.01)    # never below the stalk base (the ground)

    # colours: leaf green, veins/stripes across, pale midrib, darker base, yellowing tip, blotches
    base = np.array([58.0, 122.0, 36.0]) * rng.uniform(0.85, 1.15, 3)
    col = np.broadcast_to(base, (rows, cols, 3)).copy()
    col *= (1.0 + 0.10 * np.cos(np.pi * np.arange(cols)))[None, :, None]          # parallel veins
    col *= (1.0 + 0.12 * _smooth_noise(rng, sig, 5, 2.0))[:, None, None]         # blotches along
    midrib = np.exp(-(uu / 0.12) ** 2)[..., None]
    col = col * (1 - 0.5 * midrib) + np.array([165.0, 190.0, 115.0]) * 0.5 * midrib
    col *= (0.72 + 0.28 * np.clip(sig / 0.2, 0, 1))[:, None, None]                 # darker base
    tip = (senescence * np.clip((sig - 0.7) / 0.3, 0, 1) ** 1.5)[:, None, None]
    tip = tip * (1.0 + 0.3 * np.abs(uu)[..., None])                               # margins dry first
    tip = np.clip(tip, 0, 1)
    col = col * (1 - tip) + np.array([196.0, 172.0, 88.0]) * tip                  # yellowing tip
    col += rng.normal(0.0, 7.0, col.shape)                                       # fine texture
    return v.reshape(-1, 3), _grid_faces(rows, cols, 0), col.reshape(-1, 3)


def _tassel(rng: np.random.Generator, top: float, stalk_r: float):
    """Tassel: a central spike and drooping side branches, straw coloured with spikelet bands."""
    verts, faces, cols = [], [], []
    n_branch = int(rng.integers(5, 9))
    spec = [(0.0, math.radians(88), math.radians(5), rng.uniform(0.22, 0.3), 0.0)]
    for _ in range(n_branch):
        spec.append((rng.uniform(0.0, 2 * np.pi), math.radians(rng.uniform(40, 70)),
                     math.radians(rng.uniform(60, 110)), rng.uniform(0.13, 0.24), rng.uniform(0.0, 0.08)))
    for phi, th0, droop, length, dz in spec:
        rows = 24
        sig = np.linspace(0, 1, rows)
        th = th0 - droop * sig ** 1.3
        d = np.array([math.cos(phi), math.sin(phi), 0.0])
        tang = np.cos(th)[:, None] * d + np.sin(th)[:, None] * np.array([0.0, 0.0, 1.0])
        path = np.cumsum(tang * length / (rows - 1), axis=0) - tang[0] * length / (rows - 1)
        path += np.array([0.0, 0.0, top + dz])
        r = (stalk_r if dz == 0.0 else 0.0035) * (1.0 - 0.7 * sig) + 0.0015
        v, f, _ang = _tube(path, r, 6)
        band = np.repeat((np.arange(rows) % 2).astype(float), 6)
        straw = np.array([188.0, 158.0, 78.0]) * rng.uniform(0.9, 1.1, 3)
        c = straw[None] * (0.82 + 0.18 * band[:, None]) + rng.normal(0, 6.0, (len(v), 3))
        faces.append(f + sum(len(x) for x in verts))
        verts.append(v)
        cols.append(c)
    return np.concatenate(verts), np.concatenate(faces), np.concatenate(cols)


def sample_surface(mesh: trimesh.Trimesh, n_points: int,
                   rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Area-uniform samples of a vertex-coloured mesh: (n, 3) points and (n, 3) uint8 colours
    (barycentric interpolation of the vertex colours)."""
    v = np.asarray(mesh.vertices, dtype=np.float64)
    f = np.asarray(mesh.faces)
    vc = np.asarray(mesh.visual.vertex_colors)[:, :3].astype(np.float64)
    area = np.asarray(mesh.area_faces, dtype=np.float64)
    idx = rng.choice(len(f), size=n_points, p=area / area.sum())
    r1 = np.sqrt(rng.random(n_points))
    r2 = rng.random(n_points)
    w = np.stack([1.0 - r1, r1 * (1.0 - r2), r1 * r2], 1)          # uniform barycentric weights
    tri = f[idx]
    pts = np.einsum("nk,nkj->nj", w, v[tri])
    col = np.einsum("nk,nkj->nj", w, vc[tri])
    return pts, np.clip(np.rint(col), 0, 255).astype(np.uint8)


def procedural_corn(seed: int = 0, n_points: int = 20000) -> PlantModel:
    """A built-in, realistic corn plant (triangle mesh with vertex colours + surface samples).

    A tapered stalk about 1.6-1.9 m tall, 8-12 alternating leaves (phyllotaxy about 180 degrees
    with jitter; long, curved, drooping strap leaves whose width tapers to a tip) and, for most
    seeds, a tassel, giving a plant about 2 m tall. Colours are greens with veins/stripes, a pale
    midrib, darker bases, yellowing tips and per-vertex texture so that SIFT finds keypoints in
    renderings (render double-sided: ``mesh.metadata['double_sided']`` is True).

    The frame is Corn50's: stalk along +z through the origin, area-weighted centroid at z = 0.
    The geometry depends on ``seed`` only; ``points`` are ``n_points`` area-uniform samples
    (a separate random stream, so the mesh does not depend on ``n_points``).

    Args:
        seed: non-negative integer; equal seeds give identical plants.
        n_points: number of surface samples (>= 1).

    Returns:
        PlantModel named ``procedural-<seed>`` with ``mesh`` set.
    """
    if isinstance(seed, bool) or int(seed) != seed or seed < 0:
        raise ValueError(f"procedural_corn: seed must be a non-negative integer, got {seed!r}")
    if isinstance(n_points, bool) or int(n_points) != n_points or n_points < 1:
        raise ValueError(f"procedural_corn: n_points must be an integer >= 1, got {n_points!r}")
    seed, n_points = int(seed), int(n_points)
    g = np.random.default_rng([seed, 0])        # geometry and colours

    has_tassel = bool(g.random() < 0.7)
    stalk_h = g.uniform(1.62, 1.78) if has_tassel else g.uniform(1.8, 1.95)
    n_leaves = int(g.integers(8, 13))
    t = np.linspace(0.08, 0.86, n_leaves) + g.uniform(-0.015, 0.015, n_leaves)
    node_z = t * stalk_h
    phi0 = g.uniform(0, 2 * np.pi)
    lmax = g.uniform(0.8, 0.95)

    verts, faces, cols = [], [], []

    def add(v: np.ndarray, f: np.ndarray, c: np.ndarray) -> None:
        faces.append(f + sum(len(x) for x in verts))
        verts.append(v)
        cols.append(c)

    add(*_stalk(g, stalk_h, node_z))
    for i in range(n_leaves):
        u = i / max(n_leaves - 1, 1)                                       # 0 lowest, 1 highest leaf
        phi = phi0 + i * np.pi + g.normal(0.0, 0.2)                      # alternating phyllotaxy
        length = lmax * (0.45 + 0.55 * math.sin(math.pi * (0.15 + 0.75 * u))) * g.uniform(0.9, 1.1)
        width = g.uniform(0.07, 0.1) * (0.75 + 0.25 * math.sin(math.pi * u))
        theta0 = math.radians(30 + 35 * u + g.normal(0, 5))
        droop = math.radians(g.uniform(95, 135) * (1.0 - 0.35 * u))
        senescence = g.uniform(0.2, 0.5) + 0.5 * (1.0 - u)                # lower leaves yellower
        r_here = 0.028 * (1.0 - 0.6 * t[i])
        add(*_leaf(g, node_z[i], r_here, phi, length, width, theta0, droop, min(senescence, 1.0)))
    if has_tassel:
        add(*_tassel(g, stalk_h, 0.028 * 0.4))

    v = np.concatenate(verts)
    f = np.concatenate(faces).astype(np.int64)
    c = np.clip(np.rint(np.concatenate(cols)), 0, 255).astype(np.uint8)
    rgba = np.concatenate([c, np.full((len(c), 1), 255, np.uint8)], axis=1)
    mesh = trimesh.Trimesh(vertices=v, faces=f, vertex_colors=rgba, process=False)
    # Corn50 frame: centroid at z = 0 (area-weighted centroid of the surface, independent of n_points)
    area = mesh.area_faces
    zc = float((area * mesh.triangles_center[:, 2]).sum() / area.sum())
    mesh.apply_translation([0.0, 0.0, -zc])
    mesh.metadata["double_sided"] = True
    mesh.metadata["name"] = procedural_name(seed)
    pts, pcol = sample_surface(mesh, n_points, np.random.default_rng([seed, 1]))
    return PlantModel(name=procedural_name(seed), points=pts, colors=pcol, mesh=mesh)
