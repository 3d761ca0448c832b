#!/usr/bin/env python3
"""The reconstruction pipeline's speed (vp_recon): results/bench_recon.{json,md}.

* seconds per rendered frame at 2000 x 1500 (one procedural plant, context already created),
* seconds per stage (mesh, render, sparse, dense, score) of a realization for ring plans of 4 and
  6 views (30 degrees apart) on one_plant,
* points and Chamfer x 100 (paper Table I units) of the planner's circle plan (radius and altitude
  tuned on the reward, 100 evaluations) on each scenario: one_plant with 4 cameras, three_row and
  six_rect with 6.

    python -m bench.bench_recon [--quick] [--width 2000 --height 1500] [--realizations 1]
        [--models FOLDER] [--out results]

--quick: 1000 x 750 stages and scenarios, 5 timed frames, 2000 points per plant.
"""
from __future__ import annotations

import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

if not __package__:  # python bench/bench_recon.py: as python -m bench.bench_recon (bench/_script.py)
    import _script  # noqa: F401
from bench.options import parser  # noqa: E402
from bench.publish import num, publish, table  # noqa: E402
from vp_scene.build import build_noisy_scene  # noqa: E402
from vp_scene.capture import IDEAL, REALISTIC  # noqa: E402

from vp_planner.optimizers import plan_views  # noqa: E402
from vp_planner.request import PlanRequest  # noqa: E402
from vp_recon.config import ReconConfig  # noqa: E402
from vp_recon.errors import ReconError  # noqa: E402
from vp_recon.pipeline import reconstruct_plan  # noqa: E402
from vp_scene.meshing import scene_meshes  # noqa: E402
from vp_scene.render import Renderer  # noqa: E402

SCENARIO_CAMERAS = {"one_plant": 4, "three_row": 6, "six_rect": 6}


def ring_plan(points: np.ndarray, n: int, step_deg: float = 30.0, standoff: float = 1.2,
              height: float = 1.2) -> np.ndarray:
    """n cameras ``step_deg`` apart on a circle around the scene, ``standoff`` metres outside its
    horizontal extent, looking at the scene centre at half height (a circle-like plan)."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    center = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2])
    radius = 0.5 * float(np.hypot(hi[0] - lo[0], hi[1] - lo[1])) + standoff
    a = np.deg2rad(-90.0 + step_deg * (np.arange(n) - (n - 1) / 2))     # centred on the -y side
    c = np.stack([center[0] + radius * np.cos(a), center[1] + radius * np.sin(a), np.full(n, height)], axis=1)
    return np.concatenate([c, center - c], axis=1)


def time_frames(width: int, height: int, frames: int, ns) -> float:
    r = Renderer(width, height)
    cams = ring_plan(ns.points[0], frames, step_deg=360.0 / frames)
    meshes = scene_meshes(ns, 0)
    r.render(meshes, cams[:1])                                  # warm-up (scene upload, shaders)
    t = time.perf_counter()
    r.render(meshes, cams)
    return (time.perf_counter() - t) / frames


def main(argv=None) -> int:
    from vp_scene.camera import image_side_arg

    p = parser(__doc__, "models", "out", models="")
    p.add_argument("--quick", action="store_true", help="1000 x 750, 5 timed frames, 2000 points a plant")
    p.add_argument("--width", type=image_side_arg, default=None, help="image width (default 2000; --quick 1000)")
    p.add_argument("--height", type=image_side_arg, default=None, help="image height (default 1500; --quick 750)")
    p.add_argument("--realizations", type=int, default=1)
    a = p.parse_args(argv)
    width = a.width or (1000 if a.quick else ReconConfig.width)
    height = a.height or (750 if a.quick else ReconConfig.height)
    ppp = 2000 if a.quick else 4000
    frames = 5 if a.quick else 20
    ks = list(range(a.realizations))
    out: dict = {"machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                             "platform": platform.platform(), "gl": os.environ.get("PYOPENGL_PLATFORM")},
                 "quick": a.quick, "width": width, "height": height, "realizations": len(ks),
                 "models": a.models, "points_per_plant": ppp}

    ns, _ = build_noisy_scene("one_plant", models=a.models or None, seed=0, points_per_plant=ppp,
                              realizations=max(1, len(ks)))
    out["seconds_per_frame_2000x1500"] = time_frames(2000, 1500, frames, ns)
    print(f"render 2000x1500: {out['seconds_per_frame_2000x1500']:.3f} s/frame", file=sys.stderr)

    stages = {}
    for capture in (REALISTIC, IDEAL):  # the default capture (a flight), and the ideal one (before issue 18)
        cfg = ReconConfig(width=width, height=height, keep_images=False, capture=capture)
        for n in (4, 6):
            key = f"{n}_views" + ("" if capture is REALISTIC else "_ideal")
            try:
                res = reconstruct_plan(ns, ring_plan(ns.points[0], n), cfg, realizations=ks)
            except ReconError as exc:  # counted, never dropped
                stages[key] = {"capture": capture.kind, "error": exc.name, "message": str(exc)}
                print(f"{key}: {exc.name} {exc}", file=sys.stderr)
                continue
            per = {k: v / len(ks) for k, v in res.seconds.items()}
            stages[key] = {"capture": capture.kind, "sparse_mode": res.realizations[0].sparse_mode,
                           "seconds": per, "chamfer_x100": res.chamfer_mean * 100,
                           "chamfer_shape_x100": res.chamfer_shape_mean * 100,
                           "registered_images": [r.images for r in res.realizations],
                           "points": int(np.mean([len(r.points) for r in res.realizations]))}
            print(f"{key}: " + ", ".join(f"{k} {v:.2f}" for k, v in per.items()), file=sys.stderr)
    out["stages_one_plant"] = stages
    cfg = ReconConfig(width=width, height=height, keep_images=False)

    scen = {}
    for name, n in SCENARIO_CAMERAS.items():
        sc, _ = build_noisy_scene(name, models=a.models or None, seed=0, points_per_plant=ppp,
                                  realizations=max(1, len(ks)))
        # the tuned circle baseline
        cams = plan_views(PlanRequest.of("circle", n, evaluations=100, seed=0), sc.points).cameras
        try:
            res = reconstruct_plan(sc, cams, cfg, realizations=ks)
            r0 = res.realizations
            scen[name] = {"cameras": n, "chamfer_x100": res.chamfer_mean * 100,
                          "chamfer_std_x100": res.chamfer_std * 100,
                          "accuracy_x100": float(np.mean([r.accuracy for r in r0])) * 100,
                          "completeness_x100": float(np.mean([r.completeness for r in r0])) * 100,
                          "fscore": float(np.mean([r.fscore for r in r0])),
                          "points": int(np.mean([len(r.points) for r in r0])),
                          "registered_images": int(np.min([r.images for r in r0])),
                          "seconds": res.seconds["total"] / len(ks)}
        except ReconError as exc:
            scen[name] = {"cameras": n, "error": exc.name, "message": str(exc)}
        print(f"{name}: {scen[name]}", file=sys.stderr)
    out["scenarios"] = scen
    publish(a.out, "bench_recon", out, markdown(out))
    return 0


def markdown(data: dict) -> str:
    """The seconds per stage of the ring plans on one plant, with their registered images and Chamfer."""
    body = [[name.replace("_", " "), s["capture"], "/".join(map(str, s.get("registered_images") or [])),
             *(num((s.get("seconds") or {}).get(k), 1) for k in ("render", "sparse", "dense", "score", "total")),
             num(s.get("chamfer_x100")), num(s.get("chamfer_shape_x100"))]
            for name, s in data["stages_one_plant"].items()]
    lines = ["# Reconstruction stages", "", f"One plant ({Path(data.get('models') or '').name or 'procedural'}), "
             f"{data['width']} x {data['height']}, a ring of views 30 degrees apart, one realization, seconds per "
             "stage with the reconstruction on the machine's cores.", ""]
    lines += table(["views", "capture", "registered", "render s", "sparse s", "dense s", "score s", "total s",
                    "Chamfer x100", "shape x100"], body)
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
