"""Command line planner: plan views on a noisy scene (write plan.json), or score a plan.

    python -m vp_planner.cli [plan] --scenario one_plant --method egp --cameras 4 --evals 100 \\
        --init 50 --seed 0 --out out/run [--overwrite] [--reward coverage] [--models FOLDER] [...]
    python -m vp_planner.cli score --plan out/run/plan.json [--reward paper]
    python -m vp_planner.cli mission --plan out/run/plan.json --drones 2 --origin 47.3977,8.5456,488 \\
        --out out/run/missions [--map-yaw 0] [--cruise-speed 5 ...] [--homes X,Y;X,Y] [--overwrite]

A second sortie: ``--fixed PLAN.json`` (repeatable) gives the cameras already flown, which every
reward model counts with the plan, and ``--reconstructed PLY`` what they reconstructed (points of
the planning cloud within ``--tau`` of it weigh ``--reconstructed-weight``); plan.json records
them (``fixed_cameras``, ``fixed_from``, ``reconstructed``) and its ``reward`` is the plan's
together with the fixed cameras (README "A second sortie").

``plan`` (the default command) writes ``OUT/plan.json`` (scenario, method, reward_model,
cameras [[cx,cy,cz,vx,vy,vz], ...], poses [[x,y,z,qx,qy,qz,qw], ...], reward, trace,
evaluations, seed, seconds, scene (every argument needed to rebuild the identical scene), the
request as it records itself (:meth:`vp_planner.request.PlanRequest.record`: ``request``, every
field but the arrays, and fov, theta_match, image_size, ...), simple_regret, ...) and ``OUT/noisy_points.npy``
(the K x P x 3 realizations the reward was computed on), both together when the planning is done
(an interrupt or an error writes nothing). An OUT that holds a plan is refused (exit 2) unless
``--overwrite``; other files in OUT are not touched. A progress bar with the best reward goes to stderr.

``--scenario`` is a layout name or a layout file (.yaml, .yml, .json), read at once (a bad file:
one line, exit 2); plan.json's ``scene.scenario`` then holds the layout itself (its canonical
dict) and its top-level ``scenario`` the layout's name.

Among candidate views (README "From a real flight"): ``--candidates FOLDER --prior PRIOR.ply``
plans N of the flight folder's poses (poses.csv or COLMAP's text model; a rig's stops, a gantry,
the images of an earlier flight) on the prior cloud (a PLY in the folder's frame, e.g. a first
reconstruction), with every method but cmaes and lawnmower (:mod:`vp_planner.candidates`); the image size
and the field of view are the folder's camera's unless given. plan.json then names the chosen
images (``images``, ``selected``: their indices among the folder's poses), the folder
(``candidates``) and the prior (``prior``), and has no ``scene``; ``python -m vp_recon.cli
--images FOLDER --select plan.json`` reconstructs those images.

``score`` reads the plan file as every command does (:func:`vp_scene.planfile.load_plan`),
rebuilds its scene and prints the plan's reward under the chosen model as the last number on
stdout (a second sortie's with its recorded cameras already flown and reconstruction, as it was
planned). The scene is the file's ``scene``; a flight plan without one is scored only on a scene
named with ``--scenario`` (and the other scene options), which a plan with its own scene refuses:
no scene is guessed, none is silently replaced. A camera that breaks the planner's feasibility
rules (the plan's recorded minima, else the defaults: inside a plant, under the ground, two
cameras together) is named in a warning on stderr (:func:`vp_planner.fleet.plan_problems`).

``mission`` routes a plan's views over N drones (:mod:`vp_planner.routes`: the longest flight
minimized within the battery's budget, the drones kept ``--separation`` apart, the legs clear of
the plan's scene when it has one) and writes OUT/<drone>.plan for every drone with views (a
QGroundControl plan: take-off, a waypoint per view with its heading, the gimbal's pitch, a
photograph, return to launch; :mod:`vp_planner.missions`), OUT/fleet.kml and OUT/fleet.json,
together. The drones' homes are ``--homes`` (map x,y[,z] each) or a row 1 m apart, 5 m south of
the views. A plan whose routes cannot fit, a bad origin or a flight-model value out of its range is
one line with its code (``[DOES_NOT_FIT] ... s short``) and exit 2, nothing written.

Errors: one line on stderr and exit code 2.
"""
from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any, Optional, Sequence

import numpy as np

from vp_scene.layout import BUILTIN_LAYOUTS, LayoutError, read_scenario
from vp_scene.limits import MAX_SEED, seed_arg

#: The entries of a plan in OUT: what --overwrite replaces, together.
RESULT = ("plan.json", "noisy_points.npy")

if TYPE_CHECKING:
    from .request import PlanRequest

SCENARIO_NAMES = tuple(BUILTIN_LAYOUTS)


class CliError(Exception):
    """A user-facing error: printed as one line, exit code 2."""


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (exit code 2)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def _scenario(text: str) -> Any:
    """``--scenario``: a built-in name (kept as it is) or a layout file, read at once into its
    canonical dict (:meth:`vp_scene.layout.Layout.to_dict`), which plan.json stores so that the
    plan file rebuilds its scene without the layout file."""
    try:
        layout = read_scenario(text)
    except LayoutError as exc:
        raise argparse.ArgumentTypeError(" ".join(str(exc).split())) from None
    return text if layout is None else layout.to_dict()


def _scene_args(p: argparse.ArgumentParser, given_only: bool = False) -> None:
    """The scene options: a flag for every argument of a scene (:class:`vp_scene.scene_spec.SceneSpec`:
    its default and help); ``given_only`` (score): an option not given is left out of the
    namespace, so that a scene named on the command line is told from the defaults."""
    from dataclasses import fields

    from vp_scene.scene_spec import SceneSpec

    special = {"scenario": dict(type=_scenario, metavar="NAME_OR_FILE",
                                help=f"a layout name ({', '.join(SCENARIO_NAMES)}) or a layout file (.yaml, .yml, "
                                     f".json; README 'Your own field')"),
               "seed": dict(type=seed_arg, help=f"seed of the scene, the wind and the planner (0 to {MAX_SEED})"),
               "models": dict(help="folder of PLY plant models (default: procedural corn)")}
    for f in fields(SceneSpec):
        how = special.get(f.name) or dict(type=type(f.default), help=f"{f.metadata['help']} ({f.default})")
        p.add_argument("--" + f.name.replace("_", "-"), default=argparse.SUPPRESS if given_only else f.default, **how)


def _reward_args(p: argparse.ArgumentParser, default: Optional[str]) -> None:
    from vp_scene.camera import IMAGE_SIZE

    from .reward_models import REGISTRY, REWARD_MODELS

    p.add_argument("--reward", default=default, choices=REWARD_MODELS,
                   help="reward model (" + "; ".join(f"{m.name}: {m.summary}" for m in REGISTRY) + ")")
    p.add_argument("--image-width", type=int, default=None,
                   help=f"image width of the cameras, pixels ({IMAGE_SIZE[0]})")
    p.add_argument("--image-height", type=int, default=None,
                   help=f"image height of the cameras, pixels ({IMAGE_SIZE[1]})")


def parse_args(argv: Optional[Sequence[str]] = None) -> argparse.Namespace:
    """Arguments of ``plan`` (the default command) or ``score``; ``args.command`` says which.
    The plan flags' defaults are the request's (:data:`vp_planner.request.DEFAULTS`)."""
    from .request import DEFAULTS as D

    argv = list(sys.argv[1:] if argv is None else argv)
    command = argv.pop(0) if argv and argv[0] in ("plan", "score", "mission") else "plan"
    if command == "mission":
        p = _mission_parser()
    elif command == "score":
        p = _Parser(prog="plan score",
                    description="The reward of an existing plan on its scene (the last number on stdout).")
        p.add_argument("--plan", required=True, help="plan.json (cameras or poses; its scene, or the scene options)")
        _reward_args(p, None)
        p.add_argument("--fov", type=float, default=None, help="rad (default: the plan's, else pi/2)")
        p.add_argument("--theta-match", type=float, default=None, help="rad (default: the plan's, else pi/4)")
        _scene_args(p, given_only=True)  # the scene of a plan file without one, named (none is guessed)
    else:
        p = _Parser(prog="plan", description="EGP-VP view planning on a noisy corn scene.")
        _scene_args(p)
        p.add_argument("--out", required=True, help="output folder (one that holds a plan is refused)")
        p.add_argument("--overwrite", action="store_true", help="replace the plan OUT holds (when this run succeeds)")
        _reward_args(p, D["reward"])
        p.add_argument("--fov", type=float, default=None,
                       help=f"rad (default {D['fov']:.4g}; among --candidates: the folder's camera's)")
        _request_args(p)
        p.add_argument("--fixed", action="append", default=[], metavar="PLAN.json",
                       help="cameras already flown (a plan file; repeatable): the reward counts them with "
                            "the plan (README 'A second sortie')")
        p.add_argument("--reconstructed", default=None, metavar="PLY",
                       help="what an earlier sortie reconstructed (a PLY in the scene's frame): planning-cloud "
                            "points within --tau of it weigh --reconstructed-weight")
        p.add_argument("--candidates", dest="candidates_folder", default=None, metavar="FOLDER",
                       help="plan N of this flight folder's poses (poses.csv or COLMAP text; README 'From a real "
                            "flight'); needs --prior")
        p.add_argument("--prior", default=None, metavar="PLY",
                       help="with --candidates: the planning cloud, a PLY in the folder's frame (a first reconstruction)")
        p.add_argument("--threads", type=int, default=1,
                       help="torch threads (default 1: leaves the other cores to a reconstruction beside it)")
        p.add_argument("--scheduler", default="local",
                       help="where the simulated flights run, one a task: 'local' (a local Dask cluster of "
                            "--workers processes) or a scheduler's address (tls://host:8786 with --tls-*)")
        p.add_argument("--workers", type=int, default=max(1, os.cpu_count() or 1),
                       help="worker processes of --scheduler local (default: the cores)")
        from vp_scene.cluster import add_tls_args

        add_tls_args(p)
        p.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = p.parse_args(argv)
    if command == "plan":
        from vp_scene.cluster import TlsFiles, check_cluster_args

        args.tls = TlsFiles.from_args(args)
        try:
            check_cluster_args(args.scheduler, args.workers, args.tls)
        except ValueError as exc:
            p.error(str(exc))
    if command == "plan" and (args.candidates_folder is None) != (args.prior is None):
        p.error("--candidates and --prior go together (the poses to choose among and the cloud they are scored on)")
    args.command = command
    return args


#: Plan flags (argparse's names) that are settings of a request under another name; every other
#: setting of :data:`vp_planner.request.SETTINGS` (``--min-standoff``, ``--bo-mode``, ...) is the
#: flag of its name.
REQUEST_FLAGS = {"cameras": "num_cameras", "evals": "evaluations", "init": "initial_evaluations"}
#: The settings the plan command takes with other options: the seed with the scene's, the reward
#: and the image size with ``score``'s, the field of view with its default among candidates.
OTHER_FLAGS = ("seed", "reward", "image_width", "image_height", "fov")


def _request_args(p: argparse.ArgumentParser) -> None:
    """A flag for every setting of a request (:data:`vp_planner.request.SETTINGS`, but
    :data:`OTHER_FLAGS`): its type and default, its help and choices from the request's field."""
    from .request import SETTINGS

    names = {v: k for k, v in REQUEST_FLAGS.items()}
    for s in SETTINGS:
        if s.name in OTHER_FLAGS:
            continue
        flag = "--" + names.get(s.name, s.name).replace("_", "-")
        text = f"{s.help} ({s.default:.4g})" if isinstance(s.default, float) else f"{s.help} ({s.default})"
        if isinstance(s.default, bool):
            p.add_argument(flag, action=argparse.BooleanOptionalAction, default=s.default, help=text)
        else:
            p.add_argument(flag, type=type(s.default), default=s.default, choices=s.choices, help=text)


def _mission_parser() -> argparse.ArgumentParser:
    from dataclasses import fields

    from .feasibility import Feasibility
    from .routes import FlightModel

    p = _Parser(prog="plan mission", description="Each drone's route through a plan's views, as QGroundControl "
                                                 "missions and KML.")
    p.add_argument("--plan", required=True, help="plan.json (cameras or poses; its scene, when it has one, is avoided)")
    p.add_argument("--drones", type=int, required=True, help="number of drones, 1 to 100")
    p.add_argument("--origin", required=True, metavar="LAT,LON,HEIGHT",
                   help="the map origin: WGS84 latitude and longitude (degrees), ellipsoidal height (m)")
    p.add_argument("--map-yaw", type=float, default=0.0, help="rad: the map's x axis from east, counter-clockwise")
    p.add_argument("--out", required=True, help="output folder (one that holds missions is refused)")
    p.add_argument("--overwrite", action="store_true", help="replace the missions OUT holds (when this run succeeds)")
    p.add_argument("--homes", default=None, metavar="X,Y[,Z];...",
                   help="the drones' homes in map, one per drone (default: a row 1 m apart, 5 m south of the views)")
    p.add_argument("--separation", type=float, default=Feasibility.min_separation,
                   help="m between two drones at every moment (%(default)s)")
    p.add_argument("--standoff", type=float, default=Feasibility.min_standoff,
                   help="m the legs keep from the plan's scene (%(default)s)")
    for f in fields(FlightModel):
        p.add_argument(f"--{f.name.replace('_', '-')}", type=float, default=f.default,
                       help=f"{f.metadata['help']}, {FlightModel.range_text(f.name)} (%(default)s)")
    return p


def _homes(text: Optional[str], n: int, views: np.ndarray) -> np.ndarray:
    from .routes import launch_row

    if text is None:
        c = views[:, :2]
        return launch_row(n, centre=(0.5 * (c[:, 0].min() + c[:, 0].max()), c[:, 1].min()), south=5.0)
    try:
        rows = [[float(x) for x in part.split(",")] for part in text.split(";") if part.strip()]
    except ValueError:
        raise CliError(f"--homes must be X,Y[,Z] numbers separated by ';', got {text!r}") from None
    if len(rows) != n or any(len(r) not in (2, 3) for r in rows):
        raise CliError(f"--homes must give {n} homes of 2 or 3 numbers (one per drone), got {text!r}")
    return np.array([r + [0.0] * (3 - len(r)) for r in rows])


def mission(args: argparse.Namespace) -> list:
    """``mission``: the routes and their files (module docstring); the files written."""
    from dataclasses import fields

    from vp_scene.folders import ResultFolder
    from vp_scene.geo import GeoOrigin
    from vp_scene.planfile import PlanFileError, load_plan

    from .missions import MISSION_FILES, write_missions
    from .routes import FlightModel, plan_routes

    origin = GeoOrigin.parse(args.origin, yaw=args.map_yaw)
    model = FlightModel(**{f.name: getattr(args, f.name) for f in fields(FlightModel)})
    if not 1 <= args.drones <= 100:
        raise CliError(f"--drones must be 1 to 100, got {args.drones}")
    try:
        pf = load_plan(args.plan, require_scene=False)
    except PlanFileError as exc:
        raise CliError(str(exc)) from None
    homes = _homes(args.homes, args.drones, pf.cameras)
    result_dir = ResultFolder(args.out, MISSION_FILES, "mission", args.overwrite).check()
    obstacles = build_scene(pf.scene)[0] if pf.scene is not None else None
    fleet = plan_routes(pf.cameras, homes, model, args.separation, obstacles=obstacles, standoff=args.standoff)
    names = [f"d{k}" for k in range(args.drones)]
    with result_dir:
        written = write_missions(result_dir.stage, fleet, pf.cameras, names, origin)
        result_dir.commit()
    for r in fleet.routes:
        if len(r.views):
            print(f"plan mission: {names[r.drone]}: {len(r.views)} views, {r.flight_time:.1f} s flight "
                  f"(budget {model.budget_s:.0f} s), {r.distance:.1f} m -> {Path(args.out) / (names[r.drone] + '.plan')}",
                  file=sys.stderr)
    print(f"plan mission: time on site {fleet.time_on_site:.1f} s, drones at least {fleet.min_separation:.2f} m apart "
          f"(separation {fleet.separation:g} m){'' if obstacles is not None else ', the plan has no scene to avoid'}"
          f" -> {Path(args.out) / 'fleet.kml'}", file=sys.stderr)
    return [Path(args.out) / p.name for p in written]


def set_threads(n: int) -> None:
    """Use ``n`` threads for torch and OpenCV in this process (BLAS pools of numpy follow
    OMP_NUM_THREADS, which the Makefile and the entry script set per process)."""
    import torch

    torch.set_num_threads(int(n))
    try:
        import cv2

        cv2.setNumThreads(int(n))
    except ImportError:  # pragma: no cover - OpenCV is a dependency
        pass


def scene_of(args: argparse.Namespace) -> dict:
    """The scene dict (build_noisy_scene's keyword arguments) of the command line options;
    ``scenario`` is a layout name or a layout file's canonical dict (see :func:`_scenario`)."""
    from vp_scene.scene_spec import SCENE_KEYS

    models = None
    if args.models:
        folder = Path(args.models)
        if not folder.is_dir():
            raise CliError(f"models folder not found: {folder}")
        models = str(folder.resolve())
    return {**{k: getattr(args, k) for k in SCENE_KEYS}, "models": models}


def build_scene(scene: dict) -> tuple[np.ndarray, str]:
    """The noisy realizations (K, P, 3) of a scene dict and its layout's name (the layout
    resolved once, by the scene's build)."""
    noisy = build_noisy(scene)
    return np.asarray(noisy.points, dtype=np.float64), noisy.scene.scenario


def build_noisy(scene: dict) -> Any:
    """The :class:`vp_scene.wind.NoisyScene` of a scene dict."""
    from vp_scene.build import build_noisy_scene

    return build_noisy_scene(**scene)[0]


def flight_capture(request: "PlanRequest") -> Any:
    """The capture model the planner's simulated flights fly: the realistic one, with the request's
    reported-pose errors and, with ground control, the markers (without: none):
    :func:`vp_scene.flights.flight_capture`."""
    from vp_scene.flights import flight_capture as capture

    rs = request.reward
    return capture(rs.position_sigma, rs.attitude_sigma, rs.ground_control)


@contextlib.contextmanager
def flight_simulator(args: argparse.Namespace, request: "PlanRequest", noisy: Any):
    """The simulated flights of the scene ``noisy`` (the installed simulator,
    :func:`vp_scene.flights.load_simulator`) on the Dask cluster of ``--scheduler``; None when the
    request makes no flights. CliError when no simulator is installed."""
    from vp_scene.flights import FlightSimulatorMissing, load_simulator

    if not request.flights.flights_of(request.method):
        yield None
        return
    try:
        simulator = load_simulator()
    except FlightSimulatorMissing as exc:
        raise CliError(str(exc)) from None
    from vp_scene.cluster import open_client

    with open_client(args.scheduler, args.workers, quiet=True, tls=args.tls) as client:
        yield simulator(scene=noisy.scene, wind=noisy.config, settings=request.flights.settings(),
                        capture=flight_capture(request), client=client, fov=request.cameras.fov)


def memory_beside(shape: Sequence[int]) -> Optional[int]:
    """Bytes of memory available beside a scene of realizations ``shape`` (K, P) once it is built
    (:func:`vp_scene.limits.scene_memory`); None where unknown."""
    from vp_scene.limits import available_memory, scene_memory

    have = available_memory()
    return None if have is None else max(0, have - scene_memory(shape[1], shape[0]))


def _image_size(args: argparse.Namespace, default: Sequence[int]) -> tuple[int, int]:
    """(--image-width, --image-height), each ``default``'s where not given (the request checks them)."""
    w = args.image_width if args.image_width is not None else default[0]
    h = args.image_height if args.image_height is not None else default[1]
    return w, h


def candidates_of(folder: str, prior: str) -> dict:
    """The candidate poses of a flight folder (no image decoded) and the prior they are scored
    on: names, poses (M, 7, roll kept), cameras (M, 6), the camera's field of view and image size,
    the prior's points as one realization (1, P, 3); CliError naming a bad file."""
    from vp_scene.flight_poses import FlightError, read_poses
    from vp_scene.camera import poses_to_cameras

    try:
        names, poses, K, size = read_poses(folder)
    except FlightError as exc:
        raise CliError(f"--candidates: {exc}") from None
    points = reconstruction_of(prior, "--prior")
    if len(points) == 0:
        raise CliError(f"--prior: {prior} has no points")
    return {"names": names, "poses": poses, "cameras": poses_to_cameras(poses), "size": size,
            "fov": 2.0 * math.atan(0.5 * size[0] / float(K[0, 0])), "realizations": points[None]}


def fixed_cameras_of(paths: Sequence[str]) -> np.ndarray:
    """The cameras (M, 6) of the plan files given with ``--fixed`` (in order), CliError naming a
    bad file."""
    from vp_scene.planfile import PlanFileError, load_plan

    cams = [np.zeros((0, 6))]
    for path in paths:
        try:
            cams.append(load_plan(path, require_scene=False).cameras)
        except PlanFileError as exc:
            raise CliError(f"--fixed: {exc}") from None
    return np.concatenate(cams)


def reconstruction_of(path: Optional[str], flag: str = "--reconstructed") -> Optional[np.ndarray]:
    """The points (Q, 3) of the PLY given with ``flag`` (None without one), CliError naming a bad
    file."""
    if path is None:
        return None
    from vp_scene.plants import PlantModelError
    from vp_scene.ply import load_points

    try:
        return load_points(path)
    except PlantModelError as exc:
        raise CliError(f"{flag}: {exc}") from None




def request_of(args: argparse.Namespace) -> "PlanRequest":
    """The :class:`~vp_planner.request.PlanRequest` of the plan flags, built and validated in one
    place (the cameras already flown and the reconstruction are read from their files later)."""
    from .request import SETTINGS, PlanRequest, values_of_settings

    names = {v: k for k, v in REQUEST_FLAGS.items()}
    given = {s.name: getattr(args, names.get(s.name, s.name)) for s in SETTINGS}
    return PlanRequest.from_dict(values_of_settings({k: v for k, v in given.items() if v is not None}))


def plan(args: argparse.Namespace) -> dict:
    """Plan views; write OUT/plan.json and OUT/noisy_points.npy; return the plan dict."""
    from vp_scene.camera import cameras_to_poses
    from vp_scene.build import scene_shape
    from vp_scene.folders import ResultFolder, write_atomic
    from vp_scene.planfile import write_plan

    from .optimizers import plan_views
    from .request import check_plan_memory

    request = request_of(args)  # fail before reading files or building the scene
    if args.threads < 1:
        raise CliError(f"--threads must be >= 1, got {args.threads}")
    scene = None if args.candidates_folder else scene_of(args)
    shape = None if scene is None else scene_shape(scene)  # the scene's bounds and memory, nothing built
    request = request.replace(fixed_cameras=fixed_cameras_of(args.fixed),
                              reconstruction=reconstruction_of(args.reconstructed))
    if shape is not None:  # what the plan's cameras multiply, in the memory the scene leaves
        check_plan_memory(request, shape, memory_beside(shape))
    result_dir = ResultFolder(args.out, RESULT, "plan", args.overwrite).check()  # before the planning
    set_threads(args.threads)
    among = None
    if args.candidates_folder:
        among = candidates_of(args.candidates_folder, args.prior)
        realizations, scene, layout_name = among["realizations"], None, None
        request = request.replace(candidates=among["cameras"], fov=args.fov if args.fov is not None else among["fov"],
                                  image_size=_image_size(args, among["size"]))
        noisy = None
    else:
        noisy = build_noisy(scene)
        realizations, layout_name = np.asarray(noisy.points, dtype=np.float64), noisy.scene.scenario

    bar: Any = None
    if not args.no_progress:
        from tqdm import tqdm

        bar = tqdm(total=request.evaluations, desc=request.method, unit="eval", file=sys.stderr, dynamic_ncols=True)

    def progress(done: int, total: int, best: float, weights: Optional[list]) -> bool:
        if bar is not None:
            bar.total = total  # by parts the run makes more evaluations than --evals, a survey one
            bar.update(done - bar.n)
            bar.set_postfix_str(f"best {best:.4f}", refresh=False)
        return True

    def flown(done: int, total: int, score: Any) -> None:
        text = f"flight {done}/{total}: " + (f"failed ({score.reason})" if score.failed else
                                             f"map Chamfer x100 {100 * score.chamfer:.3f}, {score.seconds:.0f} s")
        if bar is not None:
            bar.write(text, file=sys.stderr)
        else:
            print(text, file=sys.stderr, flush=True)

    try:
        with flight_simulator(args, request, noisy) if noisy is not None else contextlib.nullcontext() as sim:
            res = plan_views(request, realizations, callback=progress, simulator=sim, on_flight=flown)
    finally:
        if bar is not None:
            bar.close()
    poses = cameras_to_poses(res.cameras) if among is None else among["poses"][res.selected]
    sortie = request.sortie
    data = {
        "scenario": layout_name,
        **request.record(),  # the request, written by itself
        "reward_model": res.reward_model,
        "cameras": [[float(x) for x in row] for row in res.cameras],
        "poses": [[float(x) for x in row] for row in poses],
        "reward": float(res.reward),
        "trace": [float(x) for x in res.trace],
        "simple_regret": [float(x) for x in res.simple_regret()],
        "evaluations": int(res.evaluations),
        "initial_best": res.initial_best,
        "parts": res.parts,
        "steps": res.steps,
        "seconds": float(res.seconds),
        "ensemble_weights": res.ensemble_weights,
        "model_names": res.model_names,
        "fixed_from": [str(Path(f).resolve()) for f in args.fixed],
        "reconstructed": None if sortie.reconstruction is None else {
            "path": str(Path(args.reconstructed).resolve()), "points": int(len(sortie.reconstruction)),
            "tau": sortie.tau,
            "reconstructed_weight": sortie.reconstructed_weight, "fraction": res.reconstructed_fraction},
        "scene": scene,
        "chosen_by": res.chosen_by,
        "sim_flights": request.flights.flights_of(request.method),
        "flight_settings": request.flights.settings().to_dict(),
        "flight_score": res.flight_score,
        "flights_note": res.flights_note,
        "flights": res.flights,
        "flight_plans": res.flight_plans,
    }
    if among is not None:
        data.pop("scene")
        data.update({"candidates": str(Path(args.candidates_folder).resolve()), "num_candidates": len(among["names"]),
                     "selected": [int(i) for i in res.selected], "images": [among["names"][i] for i in res.selected],
                     "prior": str(Path(args.prior).resolve()), "prior_points": int(realizations.shape[1])})
    def save_realizations(tmp: Path) -> None:
        with open(tmp, "wb") as f:
            np.save(f, realizations)

    with result_dir:  # both files, together, whole (OutputError naming the one that cannot be written)
        write_atomic(result_dir.stage / "noisy_points.npy", save_realizations)
        write_plan(result_dir.stage / "plan.json", data)
        result_dir.commit()
    return data


def _reconstructed_weights(data: dict, realizations: np.ndarray) -> Optional[np.ndarray]:
    """A second sortie's plan file: the point weights of its recorded reconstruction (read again
    from its PLY), as it was planned; None without one."""
    from .reward_models import reconstructed_weights

    rec = data.get("reconstructed")
    if not rec:
        return None
    try:
        points = reconstruction_of(rec["path"])
        return reconstructed_weights(realizations, points, float(rec["tau"]), float(rec["reconstructed_weight"]))
    except (KeyError, TypeError) as exc:
        raise CliError(f"the plan's 'reconstructed' record is malformed ({exc})") from None


def _score_scene(args: argparse.Namespace, pf: Any) -> dict:
    """The scene a plan is scored on: its own (scene options refused beside it), else the one the
    options name (``--scenario`` required: no scene is guessed)."""
    from vp_scene.scene_spec import SCENE, SCENE_KEYS

    given = {k: v for k, v in vars(args).items() if k in SCENE_KEYS}
    flags = ", ".join("--" + k.replace("_", "-") for k in given)
    if pf.scene is not None:
        if given:
            raise CliError(f"{args.plan} names its scene ('scene'): {flags} are for a plan without one")
        return pf.scene
    if "scenario" not in given:
        raise CliError(f"{args.plan} has no 'scene': name the scene it was planned for with --scenario (and its "
                       "other scene options); no scene is guessed (vp_recon.cli refuses such a plan)")
    return scene_of(argparse.Namespace(**{**SCENE.as_dict(), **given}))


def _feasibility_warning(pf: Any, realizations: np.ndarray) -> Optional[str]:
    """The planner's feasibility rules broken by the plan's cameras (its recorded minima, else the
    defaults), as one line; None when it keeps them."""
    from .feasibility import Feasibility
    from .fleet import plan_problems

    record = pf.data.get("feasibility") or {}
    try:
        rules = Feasibility(**record)
    except (TypeError, ValueError) as exc:
        raise CliError(f"{pf.path}: its 'feasibility' record is malformed ({exc})") from None
    problems = plan_problems(pf.cameras, realizations, rules.min_standoff, rules.min_altitude, rules.min_separation)
    if not problems:
        return None
    return f"{pf.path} breaks the planner's feasibility rules (scored all the same): " + "; ".join(problems)


def score(args: argparse.Namespace) -> float:
    """The reward of the plan file under ``--reward`` (default: the file's reward_model, else
    the default model) on the plan's scene (:func:`_score_scene`)."""
    from vp_scene.planfile import PlanFileError, load_plan

    from vp_scene.build import scene_shape
    from vp_scene.camera import IMAGE_SIZE, CameraModel

    from .request import FLAT, REGISTRATION, CameraSpec, InvalidRequestError, RewardSpec, check_memory
    from .reward_models import DEFAULT_REWARD_MODEL, check_reward_model, make_reward

    try:
        pf = load_plan(args.plan, require_scene=False)
    except PlanFileError as exc:
        raise CliError(str(exc)) from None
    if len(pf.cameras) < 2:
        raise CliError(f"{args.plan}: a reward needs at least 2 cameras, the plan has {len(pf.cameras)}")
    scene = _score_scene(args, pf)
    model = check_reward_model(args.reward or pf.data.get("reward_model") or DEFAULT_REWARD_MODEL)
    fov = args.fov if args.fov is not None else pf.fov
    theta = args.theta_match if args.theta_match is not None else pf.theta_match
    spec = CameraSpec(fov=fov, image_size=_image_size(args, pf.image_size or IMAGE_SIZE))  # its checks
    image = CameraModel(*spec.image_size, spec.fov)
    # the flight's reported-pose errors: the plan's (a plan from before they were recorded: the defaults)
    registration = pf.data.get("registration") or {}
    if not isinstance(registration, dict):
        raise CliError(f"{args.plan}: its 'registration' record is not an object")
    try:
        reward = RewardSpec(name=model, theta_match=theta,
                            **{FLAT[k][1]: registration[k] for k in REGISTRATION if k in registration})
    except InvalidRequestError as exc:
        raise CliError(f"{args.plan}: {exc}") from None
    shape = scene_shape(scene)  # the scene's bounds and memory, then what the cameras multiply
    check_memory(len(pf.cameras) + len(pf.fixed_cameras), shape, model, memory_beside(shape))
    realizations, layout_name = build_scene(scene)
    weights = _reconstructed_weights(pf.data, realizations)
    warning = _feasibility_warning(pf, realizations)
    if warning:
        print(f"plan score: warning: {warning}", file=sys.stderr)
    value = float(np.asarray(make_reward(reward.model_spec(), realizations, fov, theta, image,
                                         fixed_cameras=pf.fixed_cameras, point_weights=weights)(pf.cameras[None]))[0])
    print(f"plan score: {model} reward of {args.plan} ({len(pf.cameras)} cameras, "
          f"{layout_name}):",
          file=sys.stderr)
    print(f"{value:.6f}")
    return value


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = parse_args(argv)
    try:
        if args.command == "score":
            score(args)
            return 0
        if args.command == "mission":
            mission(args)
            return 0
        data = plan(args)
    except KeyboardInterrupt:
        print("plan: interrupted", file=sys.stderr)
        return 130
    except (CliError, ValueError, OSError) as exc:
        msg = " ".join(str(exc).split())
        print(f"plan: error: {msg}", file=sys.stderr)
        return 2
    print(f"plan: {data['method']} ({data['reward_model']} reward) {data['reward']:.4f} after "
          f"{data['evaluations']} evaluations ({data['seconds']:.1f} s) -> {Path(args.out) / 'plan.json'}",
          file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
