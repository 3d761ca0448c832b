"""Plant models: Corn50 PLY loading, the PLY parser's error cases, procedural corn."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from vp_scene.plants import PlantModel, PlantModelError
from vp_scene.ply import load_models, load_ply
from vp_scene.procedural import procedural_corn

CORN50 = Path(__file__).resolve().parents[3].parent / "shared" / "data" / "corn50"


@pytest.fixture(scope="module")
def corn50() -> Path:
    if not CORN50.is_dir() or not list(CORN50.glob("*.ply")):
        pytest.skip(f"Corn50 data not found at {CORN50} (<repo>/../shared/data/corn50): real-model tests skipped")
    return CORN50


def write_ply(path: Path, points: np.ndarray, colors=None, fmt: str = "binary_little_endian",
              xyz: str = "double", color_type: str = "uchar", declared=None, cut: int = 0) -> Path:
    """A small PLY writer for the tests (``declared`` overrides the vertex count in the header,
    ``cut`` drops bytes from the end)."""
    n = len(points) if declared is None else declared
    head = ["ply", f"format {fmt} 1.0", "comment test", f"element vertex {n}"]
    head += [f"property {xyz} {a}" for a in "xyz"]
    if colors is not None:
        head += [f"property {color_type} {c}" for c in ("red", "green", "blue")]
    head.append("end_header")
    header = ("\n".join(head) + "\n").encode()
    if fmt == "ascii":
        rows = []
        for i, p in enumerate(points):
            vals = [repr(float(v)) for v in p] + ([str(c) for c in colors[i]] if colors is not None else [])
            rows.append(" ".join(vals))
        body = ("\n".join(rows) + ("\n" if rows else "")).encode()
    else:
        e = "<" if fmt == "binary_little_endian" else ">"
        fields = [(a, e + ("f8" if xyz == "double" else "f4")) for a in "xyz"]
        if colors is not None:
            fields += [(c, e + ("u1" if color_type == "uchar" else "f4")) for c in ("r", "g", "b")]
        arr = np.zeros(len(points), dtype=fields)
        for i, a in enumerate("xyz"):
            arr[a] = points[:, i]
        if colors is not None:
            for i, c in enumerate("rgb"):
                arr[c] = colors[:, i]
        body = arr.tobytes()
    data = header + body
    path.write_bytes(data[:len(data) - cut] if cut else data)
    return path


def _cloud(n: int = 50, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.normal(size=(n, 3)), rng.integers(0, 256, size=(n, 3)).astype(np.uint8)


# ----------------------------------------------------------------------------- Corn50

def test_corn50_models_load(corn50: Path) -> None:
    models = load_models(corn50)
    files = sorted(corn50.glob("*.ply"), key=lambda p: p.name)
    assert [m.name for m in models] == [p.stem for p in files]
    for path, m in zip(files, models):
        header = path.read_bytes()[:1024].decode("ascii", errors="replace")
        declared = int(re.search(r"element vertex (\d+)", header).group(1))
        assert m.points.shape == (declared, 3) and m.points.dtype == np.float64
        assert m.colors.shape == (declared, 3) and m.colors.dtype == np.uint8
        assert len(np.unique(m.colors, axis=0)) > 100, "colours look constant"
        z = m.points[:, 2]
        assert -1.05 <= z.min() < -0.6 and 0.8 < z.max() <= 1.0        # README: z roughly [-1, 0.95]
        assert 1.5 < z.max() - z.min() < 2.1                            # about 2 units tall
        assert abs(z.mean()) < 1e-3                                     # centroid at z = 0
        assert np.abs(m.points[:, :2]).max() < 1.0
        assert np.median(np.hypot(m.points[:, 0], m.points[:, 1])) < 0.3  # stalk through the origin
        assert m.mesh is None


# ----------------------------------------------------------------------------- PLY parser

@pytest.mark.parametrize("fmt,xyz", [("binary_little_endian", "double"), ("binary_little_endian", "float"),
                                     ("binary_big_endian", "double"), ("ascii", "double"), ("ascii", "float")])
def test_ply_formats_round_trip(tmp_path: Path, fmt: str, xyz: str) -> None:
    pts, cols = _cloud()
    m = load_ply(write_ply(tmp_path / "plant.ply", pts, cols, fmt=fmt, xyz=xyz))
    assert m.name == "plant"
    np.testing.assert_allclose(m.points, pts, rtol=1e-6 if xyz == "float" else 1e-12)
    np.testing.assert_array_equal(m.colors, cols)


def test_ply_float_colours_scaled(tmp_path: Path) -> None:
    pts, cols = _cloud()
    m = load_ply(write_ply(tmp_path / "f.ply", pts, cols / 255.0, color_type="float"))
    np.testing.assert_array_equal(m.colors, cols)


def test_load_models_sorted_and_ply_only(tmp_path: Path) -> None:
    for name in ("b", "a", "c"):
        write_ply(tmp_path / f"{name}.ply", *_cloud())
    (tmp_path / "notes.txt").write_text("not a model")
    assert [m.name for m in load_models(tmp_path)] == ["a", "b", "c"]


@pytest.mark.parametrize("case,expected", [
    ("truncated", "truncated"),
    ("no_colour", "no per-vertex colour"),
    ("empty", "empty"),
    ("nan", "NaN"),
    ("garbage", "not a PLY"),
    ("no_end_header", "end_header"),
    ("bad_header_line", "corrupt PLY header"),
    ("ascii_short", "truncated"),
    ("ascii_text", "corrupt PLY"),
    ("absurd_coordinates", "implausible plant size"),
    ("millimetres", "implausible plant size"),
    ("flat", "implausible plant size"),
    ("ushort_colour", "colour channels must be uchar"),
])
def test_bad_ply_raises_naming_file_and_problem(tmp_path: Path, case: str, expected: str) -> None:
    pts, cols = _cloud()
    path = tmp_path / f"{case}.ply"
    if case == "truncated":
        write_ply(path, pts, cols, cut=7)
    elif case == "no_colour":
        write_ply(path, pts, None)
    elif case == "empty":
        write_ply(path, pts[:0], cols[:0])
    elif case == "nan":
        pts[3, 1] = np.nan
        write_ply(path, pts, cols)
    elif case == "garbage":
        path.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(256)))
    elif case == "no_end_header":
        path.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n")
    elif case == "bad_header_line":
        path.write_bytes(b"ply\nformat ascii 1.0\nelement vertex many\nend_header\n")
    elif case == "absurd_coordinates":  # was accepted, planned with cameras at 3e9 m
        write_ply(path, pts + 1e9, cols)
    elif case == "millimetres":
        write_ply(path, pts * 1000.0, cols)
    elif case == "flat":
        pts[:, 2] = 0.0
        write_ply(path, pts, cols)
    elif case == "ushort_colour":  # trimesh would keep only the low byte of each channel
        path.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                         b"property float z\nproperty ushort red\nproperty ushort green\nproperty ushort blue\n"
                         b"end_header\n0 0 0 65535 32768 0\n")
    elif case == "ascii_short":
        write_ply(path, pts, cols, fmt="ascii", declared=len(pts) + 5)
    elif case == "ascii_text":
        path.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                         b"property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
                         b"end_header\n1 2 three 4 5 6\n")
    with pytest.raises(PlantModelError) as err:
        load_ply(path)
    assert path.name in str(err.value) and expected in str(err.value), str(err.value)
    with pytest.raises(PlantModelError):   # the folder loader refuses it as well
        load_models(tmp_path)


def test_bad_folders(tmp_path: Path) -> None:
    with pytest.raises(PlantModelError, match="not found.*missing_dir"):
        load_models(tmp_path / "missing_dir")
    (tmp_path / "empty_dir").mkdir()
    (tmp_path / "empty_dir" / "readme.txt").write_text("x")
    with pytest.raises(PlantModelError, match="no .ply files.*empty_dir"):
        load_models(tmp_path / "empty_dir")
    (tmp_path / "a_file").write_text("x")
    with pytest.raises(PlantModelError, match="not a folder"):
        load_models(tmp_path / "a_file")
    with pytest.raises(PlantModelError, match="not found"):
        load_ply(tmp_path / "nope.ply")
    assert issubclass(PlantModelError, ValueError)


def test_plant_model_validates() -> None:
    with pytest.raises(PlantModelError, match="empty"):
        PlantModel("x", np.zeros((0, 3)), np.zeros((0, 3), np.uint8))
    with pytest.raises(PlantModelError, match="uint8"):
        PlantModel("x", np.zeros((2, 3)), np.zeros((2, 3), np.int64))


# ----------------------------------------------------------------------------- procedural corn

@pytest.fixture(scope="module")
def corn() -> PlantModel:
    return procedural_corn(seed=1)


def test_procedural_corn_shape(corn: PlantModel) -> None:
    p = corn.points
    assert corn.name == "procedural-1" and p.shape == (20000, 3) and corn.colors.shape == (20000, 3)
    height = p[:, 2].max() - p[:, 2].min()
    assert 1.8 < height < 2.2
    assert -1.15 < p[:, 2].min() < -0.85 and 0.85 < p[:, 2].max() < 1.15
    assert abs(p[:, 2].mean()) < 0.03                       # centroid at z = 0 (Corn50 frame)
    r = np.hypot(p[:, 0], p[:, 1])
    assert np.median(r) < 0.3 and np.percentile(r, 99) < 1.0  # leaves reach out, not far
    # the stalk: points close to the z axis at every height of its lower 80 %
    z0 = p[:, 2].min()
    near = p[r < 0.04]
    bins = np.histogram(near[:, 2], bins=10, range=(z0 + 0.02, z0 + 0.8 * height))[0]
    assert (bins > 0).all(), bins
    # leaves on both sides (alternating phyllotaxy): points in opposite half-planes
    far = p[r > 0.2]
    ang = np.arctan2(far[:, 1], far[:, 0])
    hist = np.histogram(ang, bins=4, range=(-np.pi, np.pi))[0]
    assert (hist > 0).sum() >= 2


def test_procedural_corn_colours(corn: PlantModel) -> None:
    c = corn.colors.astype(float)
    assert corn.colors.dtype == np.uint8
    mean = c.mean(axis=0)
    assert mean[1] > mean[0] and mean[1] > mean[2]                       # green dominant
    assert np.mean((c[:, 1] > c[:, 0]) & (c[:, 1] > c[:, 2])) > 0.7
    assert (c.std(axis=0) > 8).all()                                     # texture, not flat
    assert len(np.unique(corn.colors, axis=0)) > 1000
    top = corn.points[:, 2] > np.percentile(corn.points[:, 2], 99)
    assert not np.array_equal(c[top].mean(0), mean)


def test_procedural_corn_mesh(corn: PlantModel) -> None:
    mesh = corn.mesh
    assert mesh is not None and len(mesh.faces) > 5000 and len(mesh.vertices) > 3000
    vc = np.asarray(mesh.visual.vertex_colors)
    assert vc.shape == (len(mesh.vertices), 4) and len(np.unique(vc[:, :3], axis=0)) > 100
    assert mesh.metadata.get("double_sided") is True
    lo, hi = mesh.bounds
    assert (corn.points.min(0) >= lo - 1e-9).all() and (corn.points.max(0) <= hi + 1e-9).all()
    assert np.allclose(lo, corn.points.min(0), atol=0.05) and np.allclose(hi, corn.points.max(0), atol=0.05)


def test_procedural_corn_deterministic() -> None:
    a, b = procedural_corn(5, 2000), procedural_corn(5, 2000)
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.colors, b.colors)
    np.testing.assert_array_equal(a.mesh.vertices, b.mesh.vertices)
    c = procedural_corn(6, 2000)
    assert c.points.shape == a.points.shape and not np.allclose(c.points, a.points)
    assert len(c.mesh.vertices) != len(a.mesh.vertices) or not np.allclose(c.mesh.vertices, a.mesh.vertices)
    # the mesh depends on the seed only, not on how many points are sampled
    np.testing.assert_array_equal(procedural_corn(5, 10).mesh.vertices, a.mesh.vertices)


@pytest.mark.parametrize("kwargs", [{"seed": -1}, {"n_points": 0}, {"seed": 1.5}])
def test_procedural_corn_bad_args(kwargs: dict) -> None:
    with pytest.raises(ValueError, match="seed|n_points"):
        procedural_corn(**kwargs)
