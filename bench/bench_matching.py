#!/usr/bin/env python3
"""Benchmark of SIFT pair selection: exhaustive matching against pairs chosen from the known poses.

* field: three Corn50 plants in a row (``three_row``, 4000 points a plant, wind realization 0)
  seen by a ring of 12 cameras 30 degrees apart (:func:`vp_planner.patterns.ring`), full
  pipeline (render, sparse, dense, score) at each ``--sizes``, once with ``matching='exhaustive'``
  and once with ``matching='poses'`` (:func:`vp_recon.pairs.select_pairs`);
* threshold: the same row seen by an arc of N cameras 30 degrees apart on one side of it (N in
  ``--sweep``), full pipeline at 1000 x 750: where pose-based pairs start to pay
  (``vp_recon.config.MATCH_POSES_FROM``).

Per run: seconds choosing the pairs, extracting, matching, of the whole sparse stage and the
whole realization; pairs matched and verified (and how many verified pairs are over 90 degrees
apart); registered images; sparse points; Chamfer x 100 (paper Table I) of
the final cloud and of the cleaned sparse cloud. seconds_total: render + sparse + dense + score
(the plants' meshes are built once beforehand). Prints a table and writes JSON.

    python bench/bench_matching.py [--sizes 2000x1500,1000x750] [--sweep 4,6,8,10]
        [--models ../shared/data/corn50] [--threads 0] [--out results/bench_matching.json]
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

if not __package__:  # python bench/bench_matching.py: as python -m bench.bench_matching (bench/_script.py)
    import _script  # noqa: F401
from bench.common import default_models, machine, write_report  # noqa: E402
from vp_planner.patterns import ring  # noqa: E402
from vp_scene.meshing import scene_meshes  # noqa: E402
from vp_recon.pairs import in_view, pair_geometry, sample_points  # noqa: E402
from vp_recon.config import ReconConfig  # noqa: E402
from vp_recon.errors import ReconError  # noqa: E402
from vp_recon.pipeline import reconstruct_realization  # noqa: E402
from vp_recon.progress import STAGES  # noqa: E402
from vp_scene.build import build_noisy_scene  # noqa: E402
from vp_scene.camera import CameraModel  # noqa: E402

SPACING = math.radians(30.0)


def row_cameras(points: np.ndarray, n: int, full_ring: bool, standoff: float = 1.2, height: float = 1.5
                ) -> np.ndarray:
    """n cameras 30 degrees apart (a full ring when ``full_ring``, else an arc centred on the -y side),
    ``standoff`` metres outside the scene's half diagonal, at ``height``, looking at the scene's centre."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    centre = 0.5 * (lo + hi)
    radius = 0.5 * float(np.hypot(*(hi - lo)[:2])) + standoff
    if full_ring:
        return ring(centre[:2], centre, [radius], [height], n, phase=0.5 * SPACING)[0]
    return ring(centre[:2], centre, [radius], [height], n, spacing=SPACING, phase=-0.5 * math.pi)[0]


def median_angles(ns: object, cams: np.ndarray, cfg: ReconConfig) -> np.ndarray:
    """(N, N) median triangulation angle, degrees, of the pairs' shared points (vp_recon.pairs)."""
    model = CameraModel(cfg.width, cfg.height, cfg.fov)
    pts = sample_points(ns.points[0], 2000)
    return np.degrees(pair_geometry(cams, pts, in_view(cams, pts, model))[1])


def run_one(ns: object, cams: np.ndarray, cfg: ReconConfig) -> dict:
    """One realization; the numbers of the table (failures recorded, not raised). ``verified``:
    [i, j, inliers, median triangulation angle in degrees] of each verified pair; ``wide_verified``:
    how many of them are over 90 degrees apart (seen from the plants: almost surely false matches)."""
    try:
        r = reconstruct_realization(ns, 0, cams, cfg)
    except ReconError as exc:
        return {"matching": cfg.matching, "error": f"[{exc.name}] {exc}"}
    angle = median_angles(ns, cams, cfg)
    verified = [[int(i), int(j), int(n), round(float(angle[i, j]), 1)] for (i, j), n in sorted(r.pair_inliers.items())]
    return {
        "matching": r.matching, "cameras": int(r.num_images), "pairs_matched": int(r.matched_pairs),
        "pairs_verified": len(r.pair_inliers), "wide_verified": sum(v[3] > 90.0 for v in verified),
        "verified": verified, "sparse_points": int(r.sparse_points), "images": int(r.images),
        "chamfer_x100": 100.0 * r.chamfer, "source": r.source,
        "sparse_chamfer_x100": 100.0 * r.sparse_score.chamfer if r.sparse_score is not None else None,
        "seconds_pairs": r.sparse_seconds.get("pairs", 0.0), "seconds_extract": r.sparse_seconds.get("extract"),
        "seconds_match": r.sparse_seconds.get("match"), "seconds_sparse": r.seconds["sparse"],
        "seconds_dense": r.seconds["dense"], "seconds_total": sum(r.seconds[s] for s in STAGES),
        "dense_pairs": [[int(i), int(j), round(float(angle[i, j]), 1)] for i, j in r.dense_pairs],
    }


def _fmt(v: object) -> str:
    return f"{v:.2f}" if isinstance(v, float) else str(v)


COLUMNS = ("size", "cameras", "matching", "pairs_matched", "pairs_verified", "wide_verified", "seconds_pairs",
           "seconds_extract", "seconds_match", "seconds_sparse", "seconds_dense", "seconds_total", "images",
           "sparse_points", "sparse_chamfer_x100", "chamfer_x100")


def table(rows: list) -> str:
    """A markdown table of the rows; a failed run shows its error in the last column."""
    lines = [" | ".join(COLUMNS), " | ".join("---" for _ in COLUMNS)]
    for r in rows:
        cells = [_fmt(r.get(c, "")) for c in COLUMNS]
        if "error" in r:
            cells[-1] = r["error"][:80]
        lines.append(" | ".join(cells))
    return "\n".join(lines)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", default="2000x1500,1000x750", help="image sizes of the field runs, WxH,...")
    p.add_argument("--cameras", type=int, default=12, help="cameras of the field ring")
    p.add_argument("--sweep", default="4,6,8,10", help="camera counts of the threshold runs ('' skips them)")
    p.add_argument("--models", default=default_models(), help="folder of PLY plants ('': procedural)")
    p.add_argument("--threads", type=int, default=0, help="COLMAP / OpenCV threads (0: all cores)")
    p.add_argument("--out", default=str(ROOT / "results" / "bench_matching.json"))
    args = p.parse_args()

    ns, _ = build_noisy_scene("three_row", models=args.models or None, points_per_plant=4000, realizations=1)
    pts = ns.points[0]
    scene_meshes(ns, 0)                      # Poisson meshes cached once, outside the timings
    out: dict = {"machine": machine(), "scene": "three_row", "models": Path(args.models).name if args.models else
                 "procedural", "points_per_plant": 4000, "field": [], "threshold": []}
    for size in args.sizes.split(","):
        w, h = (int(x) for x in size.lower().split("x"))
        cams = row_cameras(pts, args.cameras, full_ring=True)
        for matching in ("exhaustive", "poses"):
            cfg = ReconConfig(width=w, height=h, matching=matching, keep_images=False, num_threads=args.threads)
            row = {"size": size, "cameras": len(cams), **run_one(ns, cams, cfg)}
            out["field"].append(row)
            print(json.dumps({k: v for k, v in row.items() if k not in ("dense_pairs", "verified")}), flush=True)
    for n in [int(x) for x in args.sweep.split(",") if x.strip()]:
        cams = row_cameras(pts, n, full_ring=False)
        for matching in ("exhaustive", "poses"):
            cfg = ReconConfig(width=1000, height=750, matching=matching, keep_images=False,
                              num_threads=args.threads)
            row = {"size": "1000x750", "cameras": n, **run_one(ns, cams, cfg)}
            out["threshold"].append(row)
            print(json.dumps({k: v for k, v in row.items() if k not in ("dense_pairs", "verified")}), flush=True)
    print("\nfield (ring of %d, full pipeline)\n%s" % (args.cameras, table(out["field"])))
    if out["threshold"]:
        print("\nthreshold (arc on one side, full pipeline, 1000x750)\n%s" % table(out["threshold"]))
    path = Path(args.out)
    write_report(path, out)
    print(f"-> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
