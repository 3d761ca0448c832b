"""Writers: coloured PLY clouds, a contact sheet of views, and the recon.json summary.

recon.json reports distances x 100 (metres x 100, as paper Table I); the library's results are
in metres and are scaled here, in :func:`summary`, only.
"""
from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any, Optional, Sequence, Union

import cv2
import numpy as np
from numpy.typing import NDArray

__all__ = ["TABLE_SCALE", "write_ply", "read_ply_points", "contact_sheet", "write_image", "summary", "write_json"]

#: Table I reports distances in metres x 100.
TABLE_SCALE = 100.0

PathLike = Union[str, os.PathLike]


def write_ply(path: PathLike, points: NDArray[np.float64], colors: Optional[NDArray[np.uint8]] = None) -> None:
    """Binary little-endian PLY with float32 x, y, z and (optional) uchar red, green, blue."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    props = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if colors is not None:
        props += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    rec = np.empty(len(p), dtype=props)
    rec["x"], rec["y"], rec["z"] = p[:, 0], p[:, 1], p[:, 2]
    if colors is not None:
        c = np.asarray(colors, dtype=np.uint8).reshape(-1, 3)
        if len(c) != len(p):
            raise ValueError(f"{len(c)} colours for {len(p)} points")
        rec["red"], rec["green"], rec["blue"] = c[:, 0], c[:, 1], c[:, 2]
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {len(p)}"]
    header += [f"property {'float' if t == '<f4' else 'uchar'} {n}" for n, t in props]
    header += ["end_header"]
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        f.write(("\n".join(header) + "\n").encode("ascii"))
        f.write(rec.tobytes())
    tmp.replace(path)


def read_ply_points(path: PathLike) -> NDArray[np.float64]:
    """Points of a PLY written by :func:`write_ply` (for tests and quick checks)."""
    raw = Path(path).read_bytes()
    end = raw.index(b"end_header\n") + len(b"end_header\n")
    header = raw[:end].decode("ascii").splitlines()
    n = int(next(h for h in header if h.startswith("element vertex")).split()[-1])
    has_color = any(h.endswith(" red") for h in header)
    dt = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")] + ([("r", "u1"), ("g", "u1"), ("b", "u1")] if has_color else [])
    rec = np.frombuffer(raw[end:], dtype=dt, count=n)
    return np.stack([rec["x"], rec["y"], rec["z"]], axis=1).astype(np.float64)


def contact_sheet(images: Sequence[NDArray[np.uint8]], thumb_width: int = 480, columns: int = 0,
                  labels: bool = True) -> NDArray[np.uint8]:
    """A grid of RGB thumbnails (``columns`` 0: about square), labelled with the view index."""
    if not images:
        raise ValueError("no images for the contact sheet")
    h0, w0 = images[0].shape[:2]
    tw = int(min(thumb_width, w0))
    th = max(1, int(round(h0 * tw / w0)))
    n = len(images)
    cols = columns or int(math.ceil(math.sqrt(n)))
    rows = int(math.ceil(n / cols))
    sheet = np.full((rows * th, cols * tw, 3), 255, np.uint8)
    for i, img in enumerate(images):
        t = cv2.resize(np.asarray(img, np.uint8), (tw, th), interpolation=cv2.INTER_AREA)
        if labels:
            t = np.ascontiguousarray(t)
            cv2.putText(t, str(i), (8, 28), cv2.FONT_HERSHEY_SIMPLEX, 0.9, (255, 255, 255), 2, cv2.LINE_AA)
        r, c = divmod(i, cols)
        sheet[r * th:(r + 1) * th, c * tw:(c + 1) * tw] = t
    return sheet


def write_image(path: PathLike, rgb: NDArray[np.uint8]) -> None:
    """Write an RGB image (PNG/JPEG by extension); OSError when it cannot be written."""
    if not cv2.imwrite(str(path), cv2.cvtColor(np.asarray(rgb, np.uint8), cv2.COLOR_RGB2BGR)):
        raise OSError(f"cannot write image {path}")


def summary(result: Any, extra: Optional[dict] = None) -> dict:
    """The recon.json dict of a :class:`vp_recon.pipeline.PlanReconResult` (distances x 100)."""
    s = TABLE_SCALE
    per = []
    for r in result.realizations:
        per.append({
            "realization": r.realization,
            "chamfer": r.chamfer * s, "accuracy": r.accuracy * s, "completeness": r.completeness * s,
            "fscore": r.fscore, "precision": r.precision, "recall": r.recall,
            "points": int(len(r.points)), "images": int(r.images), "num_images": int(r.num_images),
            "visible_images": int(r.visible_images), "source": r.source, "sparse_points": int(r.sparse_points),
            "seconds": {k: float(v) for k, v in r.seconds.items()},
        })
    out = {
        "units": "chamfer, chamfer_std, accuracy, completeness: metres x 100 (paper Table I); "
                 "fscore, precision, recall: fraction in [0, 1] at fscore_threshold metres",
        "chamfer_mean": result.chamfer_mean * s,
        "chamfer_std": result.chamfer_std * s,
        "fscore_threshold": result.realizations[0].fscore_threshold if result.realizations else None,
        "realizations": len(result.realizations),
        "per_realization": per,
        "seconds": {k: float(v) for k, v in result.seconds.items()},
    }
    if extra:
        out.update(extra)
    return out


def write_json(path: PathLike, data: dict) -> None:
    """Atomically write JSON (tmp file + rename)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=1))
    tmp.replace(path)
