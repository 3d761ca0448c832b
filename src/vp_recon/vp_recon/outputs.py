"""Writers: coloured PLY clouds, a contact sheet of views, the recon.json summary (folders:
:mod:`vp_scene.folders`).

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

from vp_scene.folders import write_atomic

__all__ = ["TABLE_SCALE", "write_ply", "contact_sheet", "write_image", "summary", "write_json",
           "no_truth_metrics", "uncovered_image"]

#: Table I reports distances in metres x 100.
TABLE_SCALE = 100.0

PathLike = Union[str, os.PathLike]


def write_ply(path: PathLike, points: NDArray[np.float64], colors: Optional[NDArray[np.uint8]] = None) -> None:
    """Binary PLY (trimesh's writer: float32 x, y, z; uchar red, green, blue, alpha when coloured),
    written whole or not at all (:func:`vp_scene.folders.write_atomic`: OutputError naming the
    file). Read it back with ``vp_scene.ply.load_ply`` or ``trimesh.load``."""
    import trimesh

    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(p) == 0:
        raise ValueError(f"no points to write to {path}")
    if colors is not None:
        c = np.asarray(colors, dtype=np.uint8).reshape(-1, 3)
        if len(c) != len(p):
            raise ValueError(f"{len(c)} colours for {len(p)} points")
        cloud = trimesh.PointCloud(p, colors=c)
    else:
        cloud = trimesh.PointCloud(p)
    data = trimesh.exchange.ply.export_ply(cloud, encoding="binary")
    write_atomic(path, lambda tmp: tmp.write_bytes(data))


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
    """Write an RGB image (PNG/JPEG by extension), whole or not at all (encoded in memory, then
    :func:`vp_scene.folders.write_atomic`: OutputError naming the file)."""
    ok, data = cv2.imencode(Path(path).suffix or ".png", cv2.cvtColor(np.asarray(rgb, np.uint8), cv2.COLOR_RGB2BGR))
    if not ok:
        raise ValueError(f"cannot encode the image {path}")
    write_atomic(path, lambda tmp: tmp.write_bytes(data.tobytes()))


def no_truth_metrics(registered: int, mean_reprojection_error: float, mean_track_length: float, points: int,
                     coverage: Any = None, centre_residual: float = float("nan")) -> dict:
    """The metrics a practitioner can check after a real flight (no ground truth): registered
    images, mean reprojection error (pixels), mean track length (images a sparse point is seen
    in), points of the cloud, the RMS distance (m) of the registered cameras from the reported
    poses (``centre_residual``, null without SfM: the sparse step's self-check,
    :mod:`vp_recon.sparse_modes`) and, with a prior, coverage_of_prior (overall and per plant, at
    coverage_tau metres; :func:`vp_recon.metrics.coverage_of_prior`)."""
    residual = float(centre_residual)
    out = {"registered_images": int(registered), "mean_reprojection_error": float(mean_reprojection_error),
           "mean_track_length": float(mean_track_length), "points": int(points),
           "centre_residual": residual if np.isfinite(residual) else None,
           "coverage_of_prior": None, "coverage_of_prior_per_plant": None, "coverage_tau": None}
    if coverage is not None:
        out.update(coverage_of_prior=coverage.fraction, coverage_of_prior_per_plant=list(coverage.per_plant),
                   coverage_tau=coverage.tau)
    return out


def uncovered_image(prior: NDArray[np.float64], coverage: Any, size: int = 600,
                    margin: int = 20) -> NDArray[np.uint8]:
    """A picture (RGB) of the uncovered points of the prior's best-covered realization
    (``coverage``: :class:`vp_recon.metrics.Coverage` of ``prior``, (K P, 3) or (K, P, 3)): a top
    view (x right, y up) beside a side view (x right, z up), same scale; covered points grey,
    uncovered red (drawn last)."""
    allp = np.asarray(prior, dtype=np.float64).reshape(-1, 3)
    flags = np.asarray(coverage.covered, dtype=bool).reshape(-1)
    if len(flags) != len(allp):
        raise ValueError(f"{len(flags)} coverage flags for {len(allp)} prior points")
    lo_i, hi_i = coverage.block
    p, cov = allp[lo_i:hi_i], flags[lo_i:hi_i]
    lo, hi = p.min(axis=0), p.max(axis=0)
    scale = (size - 2 * margin) / max(float(np.max(hi - lo)), 1e-9)
    panels = []
    for a, b, title in ((0, 1, "top (x, y)"), (0, 2, "side (x, z)")):
        img = np.full((size, size, 3), 255, np.uint8)
        u = (margin + (p[:, a] - lo[a]) * scale).astype(int)
        v = (size - margin - (p[:, b] - lo[b]) * scale).astype(int)
        for sel, colour in ((cov, (190, 190, 190)), (~cov, (220, 30, 30))):
            img[np.clip(v[sel], 0, size - 1), np.clip(u[sel], 0, size - 1)] = colour
        cv2.putText(img, f"{title}, prior realization {coverage.realization}: {int((~cov).sum())} of {len(cov)} "
                    "uncovered", (8, 16),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
        panels.append(img)
    return np.concatenate(panels, axis=1)


def summary(result: Any, extra: Optional[dict] = None) -> dict:
    """The recon.json dict of a :class:`vp_recon.results.PlanReconResult` (distances x 100)."""
    s = TABLE_SCALE
    per = []
    for r in result.realizations:
        per.append({
            "realization": r.realization,
            "chamfer": r.chamfer * s, "chamfer_shape": r.chamfer_shape * s, "accuracy": r.accuracy * s,
            "completeness": r.completeness * s, "fscore": r.fscore, "precision": r.precision, "recall": r.recall,
            "points": int(len(r.points)), "images": int(r.images), "num_images": int(r.num_images),
            "visible_images": int(r.visible_images), "source": r.source, "sparse_points": int(r.sparse_points),
            "matching": r.matching, "matched_pairs": int(r.matched_pairs), "sparse_models": int(r.sparse_models),
            "sparse_mode": r.sparse_mode, "sparse_fallback": r.sparse_fallback or None,
            "control": r.control,
            "mask": r.mask,
            "seconds": {k: float(v) for k, v in r.seconds.items()},
            **no_truth_metrics(r.images, r.mean_reprojection_error, r.mean_track_length, len(r.points), r.coverage,
                               r.centre_residual),
        })
    out = {
        "units": "chamfer, chamfer_std, chamfer_shape, accuracy, completeness: metres x 100 (paper Table I); "
                 "fscore, precision, recall: fraction in [0, 1] at fscore_threshold metres",
        "chamfer_mean": result.chamfer_mean * s,
        "chamfer_std": result.chamfer_std * s,
        "chamfer_shape_mean": result.chamfer_shape_mean * s,
        "fscore_threshold": result.realizations[0].fscore_threshold if result.realizations else None,
        "realizations": len(result.realizations),
        "per_realization": per,
        "seconds": {k: float(v) for k, v in result.seconds.items()},
        "no_truth": _mean_no_truth(per),
    }
    if extra:
        out.update(extra)
    return out


def _mean_no_truth(per: Sequence[dict]) -> dict:
    """The no-truth metrics over the realizations: registered images the fewest, the rest means."""
    if not per:
        return {}
    out = {"registered_images": min(r["registered_images"] for r in per)}
    for key in ("mean_reprojection_error", "mean_track_length", "points", "centre_residual", "coverage_of_prior"):
        vals = [r[key] for r in per if r[key] is not None]
        out[key] = float(np.mean(vals)) if vals else None
    return out


def write_json(path: PathLike, data: dict) -> None:
    """Write JSON whole or not at all (:func:`vp_scene.folders.write_atomic`)."""
    text = json.dumps(data, indent=1)
    write_atomic(path, lambda tmp: tmp.write_text(text))
