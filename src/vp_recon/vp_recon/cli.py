"""Command line reconstruction of a plan: render, reconstruct and score every wind realization.

    python -m vp_recon.cli --images DIR --out OUT [--overwrite] [--prior plan.json|PRIOR.ply] [--select plan.json]
        [--reference REF.ply] [--sparse-only] [--max-megapixels 768] [--mask auto|exg|background] [...]
    python -m vp_recon.cli --plan out/run/plan.json --out out/run [--overwrite] [--width 2000 --height 1500]
        [--realizations 0,1] [--sparse-only] [--sparse-mode known_poses|incremental]
        [--matching auto|exhaustive|poses]
        [--fscore-threshold 0.02] [--mesh-cache DIR] [--keep-workdir] [--[no-]ground] [--no-progress]
        [--scheduler local|tcp://HOST:8786|tls://HOST:8786 [--workers N] [--tls-ca-file --tls-cert --tls-key]]
        [--max-cameras 256]

Rebuilds the scene from plan.json's ``scene`` dict (vp_scene.build.build_noisy_scene) and writes

* ``OUT/recon.json``: chamfer_mean, chamfer_std (metres x 100, as paper Table I),
  per_realization [{chamfer, accuracy, completeness (x 100), fscore, points, images, matching,
  matched_pairs, and the metrics without a ground truth: registered_images,
  mean_reprojection_error (px), mean_track_length, coverage_of_prior (+ per plant, tau), ...}],
  no_truth (their aggregate), seconds, units, plan, method, reward, matching (as asked);
* ``OUT/recon_<k>.ply``: the reconstructed coloured cloud of realization k (metres);
* ``OUT/views.png``: contact sheet of the first realization's rendered views;
* ``OUT/uncovered_<k>.png``: the planning cloud's points the reconstruction of realization k
  does not cover (red; coverage_of_prior, no truth read).

``--images DIR`` reconstructs a flight folder instead (images + poses.csv or COLMAP's text model,
:mod:`vp_recon.flight`; README "From a real flight") on the same path
(:func:`vp_recon.pipeline.reconstruct_views`) and writes ``OUT/recon.json`` (the metrics without
a ground truth: registered images, mean reprojection error, mean track length, points and, with
``--prior plan.json``, coverage_of_prior per plant; Chamfer when the folder's flight.json names
the realization of the prior's scene it flew), ``OUT/recon.ply``, ``OUT/views.png`` and, with a
prior, ``OUT/uncovered.png``. Every input is checked before OUT is made. The prior may also be a
PLY (a first reconstruction in the folder's frame: crop box, pairs, coverage, masks).
``--select plan.json`` reconstructs only the images the plan names (``images``: a plan made
among the folder's views, ``python -m vp_planner.cli --candidates``), with the plan's ``prior``
PLY as the prior unless ``--prior`` is given; ``--reference REF.ply`` scores the reconstruction
against a reference cloud in the folder's frame (``chamfer_mean``, x100) and after a rigid ICP
onto it (``chamfer_shape_mean``: the shape), beside the metrics without a ground truth.

Nothing is lost or mixed: these files (:data:`RESULT`, with ``work/``) are written into a hidden
folder in OUT and moved into OUT together when the run ends; an error or an interrupt leaves OUT
as it was (and no OUT when there was none). An OUT that holds a reconstruction is refused (exit
2) unless ``--overwrite``, which replaces it as a whole when the run succeeds (a run that fails
keeps it and writes nothing). Other files in OUT (the plan) are never touched. A request refused
(exit 2: a realization the scene does not have, ...) writes nothing; a file that cannot be
written (a full disk) fails the run with ``[OUTPUT_NOT_WRITABLE]`` naming it. The stage and the
COLMAP workspaces name their owner's pid and hold its lock (:class:`vp_scene.folders.OwnedFolder`):
those a killed run left are removed by the next run.

With ``--scheduler`` the realizations reconstruct in parallel on a Dask cluster
(:mod:`vp_scene.cluster`; the same records as in this process). An address where no scheduler
answers is bad input (exit 2, within 10 s); a scheduler lost mid-run is a reconstruction failure
(``recon: error: [UNKNOWN] lost the Dask scheduler ADDRESS ...``, recon.json says so, exit 1).

Progress bars (one per stage) go to stderr. Exit codes: 0 ok, 2 bad input (``recon: error: ...``),
1 reconstruction failure (``recon: error: [CODE] ...``; OUT/recon.json holds the error), 130 interrupted.
"""
from __future__ import annotations

import argparse
import contextlib
import math
import os
import signal
import sys
from pathlib import Path
from typing import Any, Optional, Sequence

import numpy as np

PROG = "recon"

#: The entries of a reconstruction in OUT (--plan and --images); what --overwrite replaces, together.
RESULT = ("recon.json", "recon.ply", "recon_*.ply", "views.png", "uncovered.png", "uncovered_*.png", "work")


class CliError(Exception):
    """Bad user input: one line on stderr, exit code 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def add_capture_arguments(p: argparse.ArgumentParser) -> None:
    """``--capture realistic|ideal`` and one flag per figure of :class:`vp_scene.capture.
    CaptureModel` (default: the realistic model's; the CLI, the benchmarks)."""
    from vp_scene.capture import CAPTURES, REALISTIC
    from vp_scene.limits import MAX_SEED, seed_arg

    p.add_argument("--capture", default="realistic", choices=CAPTURES,
                   help="realistic: hover and localization errors and sensor noise of an RTK multirotor "
                        "(README 'Capture model'); ideal: planned poses flown and known exactly")
    for name, unit in (("hover_position_sigma", "m"), ("hover_attitude_sigma", "deg"),
                       ("report_position_sigma", "m"), ("report_attitude_sigma", "deg"),
                       ("sensor_noise", "of full scale")):
        p.add_argument("--" + name.replace("_", "-"), type=float, default=None,
                       help=f"capture figure, {unit} (default {getattr(REALISTIC, name):.4g}; ideal: 0)")
    p.add_argument("--capture-seed", type=seed_arg, default=None,
                   help=f"seed of the capture draws, 0 to {MAX_SEED} (default 0)")
    p.add_argument("--gcp-markers", type=int, default=None,
                   help=f"ground markers laid around the plants and surveyed (default {REALISTIC.gcp_markers}; "
                        "0: none, the drones' reported poses alone place the model; README 'Capture model')")
    p.add_argument("--gcp-sigma", type=float, default=None,
                   help=f"the markers' survey error, m per axis (default {REALISTIC.gcp_sigma:g})")


def capture_from_args(args: argparse.Namespace) -> object:
    """The CaptureModel the flags of :func:`add_capture_arguments` ask for; ValueError naming a bad one."""
    from vp_scene.capture import CaptureModel

    figures = {n: getattr(args, n) for n in ("hover_position_sigma", "hover_attitude_sigma",
                                             "report_position_sigma", "report_attitude_sigma", "sensor_noise",
                                             "gcp_markers", "gcp_sigma")}
    return CaptureModel.named(args.capture, seed=args.capture_seed, **figures)


def parse_args(argv: Optional[Sequence[str]] = None) -> argparse.Namespace:
    from vp_scene.camera import IMAGE_SIDE_RANGE, image_side_arg

    from .config import MATCH_POSES_FROM, MATCHINGS, MAX_CAMERAS, MAX_MEGAPIXELS, SPARSE_MODES, ReconConfig
    from .segment import MASK_METHODS

    p = _Parser(prog=PROG, description="Render, reconstruct (COLMAP on CPU + SGBM) and score a view plan.")
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--plan", help="plan.json written by the planner (make plan): render its flight and reconstruct")
    what.add_argument("--images", help="a flight folder: images + poses.csv or COLMAP cameras.txt/images.txt "
                                       "(README 'From a real flight')")
    p.add_argument("--prior", default=None,
                   help="with --images: plan.json whose scene is the planning cloud (coverage_of_prior, crop box, "
                        "pairs; Chamfer when flight.json names the realization), or a PLY in the folder's frame")
    p.add_argument("--select", default=None, metavar="PLAN.json",
                   help="with --images: reconstruct only the images this plan names (a plan among the folder's views: "
                        "vp_planner.cli --candidates); its prior PLY is the prior unless --prior is given")
    p.add_argument("--reference", default=None, metavar="PLY",
                   help="with --images: score against this reference cloud (folder's frame; and after ICP: shape)")
    p.add_argument("--out", required=True, help="output folder (its reconstruction files are written together at "
                                                  "the end; one that holds a reconstruction is refused)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the reconstruction OUT holds (when this run succeeds; a failed run keeps it)")
    p.add_argument("--width", type=image_side_arg, default=None,
                   help=f"--plan: rendered image width, pixels, {IMAGE_SIDE_RANGE[0]} to {IMAGE_SIDE_RANGE[1]} "
                        f"(default: the plan's image_size, else {ReconConfig.width}, the paper's)")
    p.add_argument("--height", type=image_side_arg, default=None,
                   help=f"--plan: rendered image height, pixels (default: the plan's, else {ReconConfig.height})")
    p.add_argument("--realizations", default=None, help="comma-separated realization indices (default: all)")
    p.add_argument("--sparse-only", action="store_true", help="score the sparse cloud (no dense stereo)")
    p.add_argument("--sparse-mode", default="auto", choices=("auto",) + SPARSE_MODES,
                   help="auto (default): anchored for a realistic capture whose attitudes are good to 2 degrees, "
                        "incremental for rougher ones, known_poses for the ideal one; anchored: triangulate at the "
                        "reported poses, bundle-adjust and register on them; incremental: COLMAP's SfM with the "
                        "reported centres as priors (anchored when it fails); known_poses: triangulate only")
    add_capture_arguments(p)
    p.add_argument("--matching", default="auto", choices=MATCHINGS,
                   help="image pairs SIFT matches: all of them (exhaustive), those chosen from the known poses "
                        f"and scene (poses), or auto: poses from {MATCH_POSES_FROM} cameras up (default)")
    p.add_argument("--fscore-threshold", type=float, default=0.02, help="F-score threshold, metres")
    p.add_argument("--voxel", type=float, default=0.002, help="dense voxel downsampling, metres (0: none)")
    p.add_argument("--dense-scale", type=float, default=1.0,
                   help="match the dense stereo pairs on the images resized by this factor, (0, 1] (default 1)")
    p.add_argument("--sift-first-octave", type=int, default=-1, choices=(-1, 0, 1),
                   help="SIFT's first octave: -1 (COLMAP's default) doubles the image first, 0 does not")
    p.add_argument("--mesh-cache", default=None, help="cache folder of Poisson meshes of PLY plant models")
    p.add_argument("--keep-workdir", action="store_true", help="keep the COLMAP workspaces in OUT/work")
    p.add_argument("--ground", action=argparse.BooleanOptionalAction, default=None,
                   help="render a textured soil plane under the plants (--no-ground: a blue screen); default: "
                        "soil for a realistic capture (plant masks from the images alone, by excess green), "
                        "the blue screen for --capture ideal")
    p.add_argument("--mask", default="auto", choices=MASK_METHODS,
                   help="plant masks of images over soil or a real background: auto (default: excess green for a "
                        "green plant, else the background model), exg or background (README 'From a real flight')")
    # as the recon node: the last core stays with a planner beside it (a reconstruction on all
    # cores slows a planner beside it down many times)
    p.add_argument("--threads", type=int, default=max(1, (os.cpu_count() or 2) - 1),
                   help="threads of COLMAP and OpenCV (default: cores - 1, leaving one to a planner; 0: all cores)")
    p.add_argument("--max-cameras", type=int, default=None,
                   help=f"--plan: a plan of more cameras is refused (exit 2; default {MAX_CAMERAS}: every image of a "
                        "realization is held at once, about 23 MB a camera at 2000 x 1500)")
    p.add_argument("--max-megapixels", type=float, default=None,
                   help=f"--images: a folder whose images have more megapixels together is refused before any is "
                        f"decoded (exit 2; default {MAX_MEGAPIXELS}: the memory of {MAX_CAMERAS} images of "
                        "2000 x 1500)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.add_argument("--scheduler", default="",
                   help="reconstruct the realizations in parallel on Dask: 'local' (a local cluster of --workers "
                        "processes, one thread each; 127.0.0.1, TLS with this run's credentials) or a running "
                        "scheduler's address (tls://host:8786 with --tls-*, or tcp://host:8786); "
                        "default: in this process, one after the other")
    p.add_argument("--workers", type=int, default=max(1, os.cpu_count() or 1),
                   help="worker processes of --scheduler local (default: the cores)")
    from vp_scene.cluster import TlsFiles, add_tls_args, check_cluster_args

    add_tls_args(p)
    args = p.parse_args(argv)
    if args.workers < 1:
        p.error(f"--workers must be >= 1, got {args.workers}")
    tls = TlsFiles.from_args(args)
    if tls != TlsFiles() and not args.scheduler:
        p.error("--tls-ca-file, --tls-cert and --tls-key go with --scheduler tls://HOST:PORT")
    if args.scheduler:
        try:
            check_cluster_args(args.scheduler, args.workers, tls)
        except ValueError as exc:
            p.error(str(exc))
    if args.max_cameras is not None and args.max_cameras < 2:
        p.error(f"--max-cameras must be >= 2, got {args.max_cameras}")
    if args.max_megapixels is not None and not args.max_megapixels > 0:
        p.error(f"--max-megapixels must be > 0, got {args.max_megapixels}")
    if args.plan and args.max_megapixels is not None:
        p.error("--max-megapixels goes with --images (a plan is bounded by --max-cameras)")
    if (args.prior or args.select or args.reference) and not args.images:
        p.error("--prior, --select and --reference go with --images (a plan brings its own scene)")
    if args.images:  # a flight folder has its own images: the options of rendering a plan do not apply
        given = [f for f, v in (("--width", args.width), ("--height", args.height),
                                ("--realizations", args.realizations),
                                ("--mesh-cache", args.mesh_cache), ("--scheduler", args.scheduler),
                                ("--max-cameras", args.max_cameras)) if v]
        if given:
            p.error(f"{', '.join(given)} go(es) with --plan, not --images (the folder's images are what they are)")
    return args


def parse_realizations(text: Optional[str]) -> Optional[list[int]]:
    if text is None or text.strip() in ("", "all"):
        return None
    try:
        return [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise CliError(f"--realizations must be comma-separated integers, got {text!r}") from None


def run(args: argparse.Namespace) -> dict:
    """Reconstruct the plan; returns the recon.json dict (also written)."""
    from vp_scene.build import build_noisy_scene
    from vp_scene.planfile import PlanFileError, load_plan

    from vp_scene.folders import ResultFolder
    from .config import MAX_CAMERAS, ReconConfig
    from .errors import ReconError, check_plan_size, check_realizations, ensure_writable_dir, validate_cameras

    result_dir = ResultFolder(args.out, RESULT, PROG, args.overwrite).check()
    try:
        plan = load_plan(args.plan)
    except PlanFileError as exc:
        raise CliError(str(exc)) from None
    ks = parse_realizations(args.realizations)
    max_cameras = MAX_CAMERAS if args.max_cameras is None else args.max_cameras
    try:
        cams = validate_cameras(plan.cameras)
        check_plan_size(len(cams), max_cameras, "--max-cameras")  # before the scene is built
    except ReconError as exc:
        raise CliError(f"{args.plan}: {exc}") from None
    try:
        size = plan.image_size or (ReconConfig.width, ReconConfig.height)  # the plan's cameras, as score has them
        config = ReconConfig(width=size[0] if args.width is None else args.width,
                             height=size[1] if args.height is None else args.height, fov=plan.fov,
                             dense=not args.sparse_only,
                             sparse_mode=args.sparse_mode, fscore_threshold=args.fscore_threshold,
                             voxel=args.voxel, mesh_cache=args.mesh_cache, keep_workdir=args.keep_workdir,
                             ground=args.ground, num_threads=args.threads, matching=args.matching,
                             dense_scale=args.dense_scale, sift_first_octave=args.sift_first_octave,
                             capture=capture_from_args(args), max_cameras=max_cameras, mask=args.mask).validate()
    except ValueError as exc:
        raise CliError(str(exc)) from None
    try:  # before the output folder is made: a bad scene leaves nothing behind
        noisy, _ = build_noisy_scene(**plan.scene)
    except (TypeError, ValueError, OSError) as exc:
        raise CliError(f"cannot rebuild the scene of {args.plan}: {exc}") from None
    try:  # the realizations asked for, against the scene: the request is whole before OUT is touched
        check_realizations(ks, noisy.points.shape[0])
    except ReconError as exc:
        raise CliError(f"--realizations: {exc}") from None
    ensure_writable_dir(args.out)
    with result_dir:  # an error or an interrupt leaves OUT as it was
        return _reconstruct_plan(args, result_dir, plan, noisy, cams, config, ks)


def _reconstruct_plan(args: argparse.Namespace, result_dir: Any, plan: Any, noisy: Any, cams: Any, config: Any,
                      ks: Optional[list]) -> dict:
    """:func:`run` once the inputs are checked: the reconstruction into ``result_dir``'s stage."""
    from .outputs import contact_sheet, summary, uncovered_image, write_image, write_json, write_ply
    from .pipeline import reconstruct_plan
    from .progress import STAGES

    out = result_dir.stage
    K = noisy.points.shape[0]
    n_real = K if ks is None else len(ks)

    bars: dict[str, Any] = {}
    if not args.no_progress:
        from tqdm import tqdm

        bars = {s: tqdm(total=n_real, desc=f"{s:>6}", unit="real", file=sys.stderr, position=i, leave=True,
                        dynamic_ncols=True) for i, s in enumerate(STAGES)}

    def progress(stage: str, k: int) -> bool:
        if stage in bars:
            bars[stage].update(1)
        return True

    info = {"plan": str(Path(args.plan).resolve()), "method": plan.data.get("method"),
            "scenario": noisy.scene.scenario, "reward": plan.data.get("reward"),
            "reward_model": plan.data.get("reward_model"), "num_cameras": int(len(cams)),
            "width": config.width, "height": config.height, "fov": config.fov, "dense": config.dense, "ground": config.ground_used,
            "sparse_mode": config.sparse_mode_used, "matching": config.matching,
            "capture": config.capture.to_dict()}
    info["scheduler"] = args.scheduler or "in-process"
    try:
        with contextlib.ExitStack() as stack:
            client = None
            if args.scheduler:
                from vp_scene.cluster import TlsFiles, open_client

                client = stack.enter_context(open_client(args.scheduler, args.workers, quiet=args.no_progress,
                                                         tls=TlsFiles.from_args(args)))
            result = reconstruct_plan(noisy, cams, config, out_dir=out, realizations=ks, progress=progress,
                                      client=client)
    except Exception as exc:
        failure = _record_failure(result_dir, info, exc)
        if failure is exc:
            raise
        raise failure from None
    finally:
        for b in bars.values():
            b.close()
    prior = None
    for r in result.realizations:
        write_ply(out / f"recon_{r.realization}.ply", r.points, r.colors)
        if r.coverage is not None:
            prior = noisy.points.reshape(-1, 3) if prior is None else prior
            write_image(out / f"uncovered_{r.realization}.png", uncovered_image(prior, r.coverage))
    first = result.realizations[0]
    if first.rendered:
        write_image(out / "views.png", contact_sheet(first.rendered))
    data = summary(result, extra=info)
    write_json(out / "recon.json", data)
    result_dir.commit()
    return data


def _record_failure(result_dir: Any, info: dict, exc: Exception) -> Exception:
    """The exception to raise for ``exc``, which stopped a reconstruction: a ReconError (the Dask
    scheduler lost, :class:`vp_scene.cluster.SchedulerLost`, becomes one, ``UNKNOWN``, naming it)
    is recorded in a recon.json that says what failed (batch tools: Table I counts failed plans),
    which becomes OUT's result; with --overwrite over an earlier result that one is kept and the
    failure only reported. A request error (:data:`vp_recon.errors.REQUEST_ERRORS`: exit 2, an
    output folder that cannot be written among them) and any other exception are returned as
    they are, nothing recorded: OUT stays as it was."""
    from vp_scene.cluster import SchedulerLost

    from .errors import REQUEST_ERRORS, UNKNOWN, ReconError
    from .outputs import write_json

    if isinstance(exc, SchedulerLost):
        exc = ReconError(UNKNOWN, str(exc))
    if not isinstance(exc, ReconError) or exc.code in REQUEST_ERRORS:
        return exc
    if result_dir.earlier():
        return ReconError(exc.code, f"{exc} (nothing written: {result_dir.out} keeps its earlier result)",
                          exc.realization)
    write_json(result_dir.stage / "recon.json", {**info, "chamfer_mean": None,
                                                  "error": {"code": exc.code, "name": exc.name, "message": str(exc)}})
    result_dir.commit()
    return exc


def _prior_scene(path: str) -> object:
    """The noisy scene of a plan.json (CliError naming the file)."""
    from vp_scene.build import build_noisy_scene
    from vp_scene.planfile import PlanFileError, load_plan

    try:
        plan = load_plan(path)
        return build_noisy_scene(**plan.scene)[0]
    except PlanFileError as exc:
        raise CliError(str(exc)) from None
    except (TypeError, ValueError, OSError) as exc:
        raise CliError(f"cannot rebuild the scene of {path}: {exc}") from None


def _cloud(path: str, flag: str) -> np.ndarray:
    """The points (M, 3) of a PLY given with ``flag`` (CliError naming it)."""
    from vp_scene.plants import PlantModelError
    from vp_scene.ply import load_points

    try:
        points = load_points(path)
    except PlantModelError as exc:
        raise CliError(f"{flag}: {exc}") from None
    if len(points) == 0:
        raise CliError(f"{flag}: {path} has no points")
    return points


def _selection(path: str) -> tuple[list, Optional[str]]:
    """The image names a plan among a folder's views chose (``images``) and its prior PLY (the
    plan file read as every command reads it, :func:`vp_scene.planfile.load_plan`)."""
    from vp_scene.planfile import PlanFileError, load_plan

    try:
        data = load_plan(path, require_scene=False).data
    except PlanFileError as exc:
        raise CliError(f"--select: {exc}") from None
    names = data.get("images")
    if not isinstance(names, list) or len(names) < 2 or not all(isinstance(n, str) for n in names) \
            or len(set(names)) != len(names):
        raise CliError(f"--select: {path} names no list of 2 or more distinct images ('images': a plan made with "
                       "python -m vp_planner.cli --candidates)")
    prior = data.get("prior")
    return names, prior if isinstance(prior, str) else None


def select_views(views: Any, names: Sequence[str]) -> Any:
    """The capture set of the images ``names`` of ``views`` (in that order); CliError naming an
    image the folder does not hold."""
    import dataclasses

    index = {n: i for i, n in enumerate(views.names)}
    missing = [n for n in names if n not in index]
    if missing:
        raise CliError(f"--select: {len(missing)} image(s) the plan names are not in the folder: {missing[:3]}")
    idx = [index[n] for n in names]
    return dataclasses.replace(views, names=list(names), images=[views.images[i] for i in idx],
                               reported=np.asarray(views.reported)[idx],
                               masks=None if views.masks is None else [views.masks[i] for i in idx])


def run_images(args: argparse.Namespace) -> dict:
    """Reconstruct a flight folder (``--images``); returns the recon.json dict (also written)."""
    from vp_scene.folders import ResultFolder
    from .config import MAX_MEGAPIXELS, ReconConfig
    from .errors import ensure_writable_dir
    from vp_scene.flight_poses import FlightError
    from .flight import read_flight
    from .metrics import chamfer, chamfer_after_icp
    from .outputs import contact_sheet, no_truth_metrics, uncovered_image, write_image, write_json, write_ply
    from .pipeline import reconstruct_views
    from .results import Prior

    result_dir = ResultFolder(args.out, RESULT, PROG, args.overwrite).check()
    selected, plan_prior = _selection(args.select) if args.select else (None, None)
    try:  # every input checked before OUT is made: nothing half-written
        views = read_flight(args.images, MAX_MEGAPIXELS if args.max_megapixels is None else args.max_megapixels)
    except FlightError as exc:
        raise CliError(str(exc)) from None
    if selected is not None:
        views = select_views(views, selected)
    prior_path = args.prior or plan_prior
    prior_cloud = _cloud(prior_path, "--prior") if prior_path and prior_path.lower().endswith(".ply") else None
    noisy = _prior_scene(prior_path) if prior_path and prior_cloud is None else None
    reference = _cloud(args.reference, "--reference") if args.reference else None
    width, height = views.size
    try:
        config = ReconConfig(width=width, height=height, fov=views.horizontal_fov, dense=not args.sparse_only,
                             sparse_mode=args.sparse_mode, fscore_threshold=args.fscore_threshold,
                             voxel=args.voxel, keep_workdir=args.keep_workdir, ground=args.ground,
                             num_threads=args.threads, matching=args.matching,
                             dense_scale=args.dense_scale, sift_first_octave=args.sift_first_octave,
                             capture=capture_from_args(args), mask=args.mask).validate()
    except ValueError as exc:
        raise CliError(str(exc)) from None
    k = views.realization
    truth = None
    if noisy is not None and isinstance(k, int) and 0 <= k < noisy.points.shape[0]:
        truth = noisy.points[k]
    ensure_writable_dir(args.out)
    with result_dir:  # an error or an interrupt leaves OUT as it was
        out = result_dir.stage
        info = {"source": "images", "images": str(Path(args.images).resolve()), "num_images": len(views.images),
                "prior": str(Path(prior_path).resolve()) if prior_path else None, "realization": k,
                "select": str(Path(args.select).resolve()) if args.select else None,
                "selected": list(views.names) if selected is not None else None,
                "reference": str(Path(args.reference).resolve()) if args.reference else None,
                "width": width, "height": height, "fov": config.fov, "dense": config.dense, "ground": config.ground_used,
                "sparse_mode": config.sparse_mode_used, "matching": config.matching,
                "capture": config.capture.to_dict(),
                "units": "chamfer, chamfer_shape: metres x 100 (paper Table I); mean_reprojection_error: pixels; "
                         "coverage_tau: metres"}
        prior = Prior.of_scene(noisy) if noisy is not None else None
        if prior_cloud is not None:
            prior = Prior(points=prior_cloud, plant=np.zeros(len(prior_cloud), np.int64))
        try:
            vr = reconstruct_views(views, config, workdir=out / "work" if args.keep_workdir else None, prior=prior)
        except Exception as exc:
            failure = _record_failure(result_dir, info, exc)
            if failure is exc:
                raise
            raise failure from None
        control = vr.control.to_dict() if vr.control is not None else None
        if control is not None:  # what the ground control did, and what it refused and why
            from .gcp import describe

            print(f"{PROG}: {describe(control)}", file=sys.stderr)
        write_ply(out / "recon.ply", vr.points, vr.colors)
        write_image(out / "views.png", contact_sheet(views.images))
        sp = vr.sparse
        data = {**info, **no_truth_metrics(sp.registered, sp.mean_reprojection_error, sp.mean_track_length,
                                           len(vr.points), vr.coverage, sp.centre_residual),
                "cloud": vr.source, "chamfer_mean": None, "sparse_points": len(sp.points), "sparse_models": sp.models,
                "sparse_mode": sp.mode, "sparse_fallback": sp.fallback,  # the model kept (incremental may fall back)
                "mask": vr.mask.to_dict() if vr.mask is not None else None, "control": control,
                "seconds": {k: round(float(v), 3) for k, v in {**views.seconds, **vr.seconds}.items()}}
        if vr.coverage is not None:
            write_image(out / "uncovered.png", uncovered_image(prior.points if noisy is None else noisy.points,
                                                               vr.coverage))
        if reference is not None:
            truth = reference
        if truth is not None:
            data["chamfer_mean"] = chamfer(vr.points, truth, config.fscore_threshold).chamfer * 100.0
            data["chamfer_shape_mean"] = chamfer_after_icp(vr.points, truth, config.fscore_threshold).chamfer * 100.0
        write_json(out / "recon.json", data)
        result_dir.commit()
        return data


def _terminate(signum: int, _frame: object) -> None:
    raise KeyboardInterrupt


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = parse_args(argv)
    if args.threads > 0:  # Mesa's llvmpipe renderer reads its thread count at its first context
        os.environ.setdefault("LP_NUM_THREADS", str(args.threads))
    import pycolmap  # noqa: F401  (first: it installs glog's SIGTERM handler, replaced below)

    from vp_scene.folders import OutputError

    from .errors import OUTPUT_NOT_WRITABLE, REQUEST_ERRORS, ReconError

    signal.signal(signal.SIGTERM, _terminate)  # SIGTERM ends the run as Ctrl-C does: exit 130
    try:
        try:
            data = run_images(args) if args.images else run(args)
        except OutputError as exc:  # a result file not written (a full disk): the run failed, OUT as it was
            raise ReconError(OUTPUT_NOT_WRITABLE, str(exc)) from None
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    except CliError as exc:
        print(f"{PROG}: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    except ReconError as exc:
        print(f"{PROG}: error: [{exc.name}] {' '.join(str(exc).split())}", file=sys.stderr)
        return 2 if exc.code in REQUEST_ERRORS else 1
    except (ValueError, OSError) as exc:
        print(f"{PROG}: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    if args.images:
        cov = data.get("coverage_of_prior")
        print(f"{PROG}: {data['registered_images']} of {data['num_images']} images registered, {data['points']} points"
              + (f", coverage of the prior {cov:.3f}" if cov is not None else "")
              + (f", chamfer x100 {data['chamfer_mean']:.3f}" if data.get("chamfer_mean") is not None else "")
              + f" -> {Path(args.out) / 'recon.json'}", file=sys.stderr)
        return 0
    print(f"{PROG}: chamfer x100 {data['chamfer_mean']:.3f} +- {data['chamfer_std']:.3f} over "
          f"{data['realizations']} realization(s) ({data['seconds']['total']:.1f} s) -> "
          f"{Path(args.out) / 'recon.json'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
