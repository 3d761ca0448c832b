"""Command line planner: build a noisy scene with vp_scene, plan views, write plan.json.

    python -m vp_planner.cli --scenario one_plant --method egp --cameras 4 --evals 100 \\
        --init 50 --seed 0 --out out/run [--models FOLDER] [--points-per-plant 4000 ...]

Writes ``OUT/plan.json`` (scenario, method, cameras [[cx,cy,cz,vx,vy,vz], ...], poses
[[x,y,z,qx,qy,qz,qw], ...], reward, trace, evaluations, seed, seconds, scene (every argument
needed to rebuild the identical scene), fov, theta_match, simple_regret, ...) and
``OUT/noisy_points.npy`` (the K x P x 3 realizations the reward was computed on). A progress bar
with the best reward goes to stderr. Errors: one line on stderr and exit code 2.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any, Optional, Sequence

import numpy as np

SCENARIO_NAMES = ("one_plant", "three_row", "six_rect")


class CliError(Exception):
    """A user-facing error: printed as one line, exit code 2."""


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (exit code 2)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def parse_args(argv: Optional[Sequence[str]] = None) -> argparse.Namespace:
    from .optimizers import METHODS

    p = _Parser(prog="plan", description="EGP-VP view planning on a noisy corn scene.")
    p.add_argument("--scenario", default="one_plant", choices=SCENARIO_NAMES)
    p.add_argument("--method", default="egp", choices=METHODS)
    p.add_argument("--cameras", type=int, default=4, help="number of cameras N (>= 2)")
    p.add_argument("--evals", type=int, default=100, help="reward evaluations (initial design included)")
    p.add_argument("--init", type=int, default=50, help="initial design size of egp/gp")
    p.add_argument("--seed", type=int, default=0, help="seed of the scene, the wind and the planner")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--models", default=None, help="folder of PLY plant models (default: procedural corn)")
    p.add_argument("--points-per-plant", type=int, default=4000)
    p.add_argument("--plant-spacing", type=float, default=0.6)
    p.add_argument("--row-spacing", type=float, default=0.76)
    p.add_argument("--levels", type=int, default=10, help="wind levels L")
    p.add_argument("--realizations", type=int, default=5, help="wind realizations K")
    p.add_argument("--wind-variance", type=float, default=0.002)
    p.add_argument("--wind-direction", type=float, default=0.0, help="rad from +x")
    p.add_argument("--min-standoff", type=float, default=0.5)
    p.add_argument("--min-altitude", type=float, default=0.3)
    p.add_argument("--min-separation", type=float, default=0.5)
    p.add_argument("--fov", type=float, default=math.pi / 2)
    p.add_argument("--theta-match", type=float, default=math.pi / 4)
    p.add_argument("--structured-init", type=int, default=4,
                   help="structured plans in the egp/gp initial design (0: purely random)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p.parse_args(argv)


def build_scene(args: argparse.Namespace) -> tuple[np.ndarray, dict]:
    """The noisy realizations (K, P, 3) and the scene dict that rebuilds them."""
    try:
        from vp_scene.scenario import make_scene
        from vp_scene.wind import WindConfig, make_noisy_scene
    except ImportError as exc:  # pragma: no cover - depends on the workspace
        raise CliError(f"vp_scene is not available: {exc}") from None
    models = None
    models_path = None
    if args.models:
        folder = Path(args.models)
        if not folder.is_dir():
            raise CliError(f"models folder not found: {folder}")
        from vp_scene.plants import load_models

        models_path = str(folder.resolve())
        models = load_models(folder)
        if not models:
            raise CliError(f"no plant models in {folder}")
    scene = make_scene(args.scenario, models=models, seed=args.seed, points_per_plant=args.points_per_plant,
                       plant_spacing=args.plant_spacing, row_spacing=args.row_spacing)
    config = WindConfig(levels=args.levels, realizations=args.realizations, variance=args.wind_variance,
                        direction=args.wind_direction)
    noisy = make_noisy_scene(scene, config, args.seed)
    desc = {
        "scenario": args.scenario,
        "models": models_path,
        "seed": args.seed,
        "points_per_plant": args.points_per_plant,
        "plant_spacing": args.plant_spacing,
        "row_spacing": args.row_spacing,
        "levels": args.levels,
        "realizations": args.realizations,
        "wind_variance": args.wind_variance,
        "wind_direction": args.wind_direction,
    }
    return np.asarray(noisy.points, dtype=np.float64), desc


def run(args: argparse.Namespace) -> dict:
    from .optimizers import plan_views, validate_request
    from .poses import cameras_to_poses

    validate_request(args.method, args.cameras, args.evals, args.init)  # fail before building the scene
    out = Path(args.out)
    realizations, scene_desc = build_scene(args)

    bar: Any = None
    if not args.no_progress:
        from tqdm import tqdm

        bar = tqdm(total=args.evals, desc=f"{args.method}", unit="eval", file=sys.stderr, dynamic_ncols=True)

    def progress(done: int, total: int, best: float, weights: Optional[list]) -> bool:
        if bar is not None:
            bar.update(done - bar.n)
            bar.set_postfix_str(f"best {best:.4f}", refresh=False)
        return True

    try:
        res = plan_views(args.method, realizations, args.cameras, evaluations=args.evals,
                         initial_evaluations=args.init, seed=args.seed, min_standoff=args.min_standoff,
                         min_altitude=args.min_altitude, min_separation=args.min_separation, fov=args.fov,
                         theta_match=args.theta_match, callback=progress, structured_init=args.structured_init)
    finally:
        if bar is not None:
            bar.close()
    poses = cameras_to_poses(res.cameras)
    plan = {
        "scenario": args.scenario,
        "method": args.method,
        "num_cameras": int(args.cameras),
        "cameras": [[float(x) for x in row] for row in res.cameras],
        "poses": [[float(x) for x in row] for row in poses],
        "reward": float(res.reward),
        "trace": [float(x) for x in res.trace],
        "simple_regret": [float(x) for x in res.simple_regret()],
        "evaluations": int(res.evaluations),
        "initial_evaluations": int(args.init) if args.method in ("egp", "gp") else None,
        "seed": int(args.seed),
        "seconds": float(res.seconds),
        "fov": float(args.fov),
        "theta_match": float(args.theta_match),
        "feasibility": {"min_standoff": args.min_standoff, "min_altitude": args.min_altitude,
                        "min_separation": args.min_separation},
        "ensemble_weights": res.ensemble_weights,
        "model_names": res.model_names,
        "scene": scene_desc,
    }
    out.mkdir(parents=True, exist_ok=True)
    np.save(out / "noisy_points.npy", realizations)
    tmp = out / "plan.json.tmp"
    tmp.write_text(json.dumps(plan, indent=1))
    tmp.replace(out / "plan.json")
    return plan


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = parse_args(argv)
    try:
        plan = run(args)
    except KeyboardInterrupt:
        print("plan: interrupted", file=sys.stderr)
        return 130
    except (CliError, ValueError, OSError) as exc:
        msg = " ".join(str(exc).split())
        print(f"plan: error: {msg}", file=sys.stderr)
        return 2
    print(f"plan: {plan['method']} reward {plan['reward']:.4f} after {plan['evaluations']} evaluations "
          f"({plan['seconds']:.1f} s) -> {Path(args.out) / 'plan.json'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
