#!/usr/bin/env python3
"""Bring up the whole suite without ROS launch: scene, planner and recon nodes, one mission.

Starts the three nodes as separate processes (real ROS 2 nodes, DDS on loopback only), prefixes
and streams their logs, asks the planner for a plan through the ``/plan_views`` action (with a
progress bar from its feedback), waits for the recon node's aggregate score on
``/reconstruction/score`` and writes ``<out>/summary.json``. With ``--drones N`` it also starts
the dispatcher with drones d0..d<N-1> and N simulated drones (``vp_scene sim_drone``, on a
launch row 5 m south of the plot; any N >= 1 for any number of cameras) and prints each drone's
route (``/fleet/assignment``); with ``--source fleet`` (the default with drones) the dispatcher
flies the routes once per wind realization the recon node asks for (``fly_on: capture``), the
drones photograph each of their poses and the recon node reconstructs their images
(``--source render``: it renders the plan itself).
The planner's simulated flights (egp's, by default) fly through the recon node's ``/simulate_flights``
on its cluster (``--sim-flights 0``: none, the cheap reward chooses; ``--flight-*``: their setting, the
planner's parameters); summary.json says how the plan was chosen (``chosen_by``), its ``flight_score``
and every flight (``flights``: the plan's source, the draw, the score, seconds).
A ``recorder`` node (vp_recon) writes the run's topics to ``<out>/run.mcap`` (a ROS 2 bag that
``ros2 bag info``/``play`` and Foxglove open); it is started first and stopped last. Everything is shut down on success,
on Ctrl-C and when any node dies; the nodes die with this script even when it is killed with
SIGKILL (parent-death signal, tools/node_process.py). While the nodes are stopped their output
goes to ``<out>/<node>.log`` only, so the outcome (or the error, with the dead node's last line)
is the last thing printed.

With ``--rounds 2`` the mission flies a second sortie (README "A second sortie"): after the first
plan of ``--cameras`` N is reconstructed, the planner gets a goal for ``--cameras2`` M more with
the N cameras already flown (``fixed_cameras``) and their reconstruction (the last cloud on
``/reconstruction/points``); the recon then reconstructs from all N + M images (with the fleet:
the drones photograph the M new poses, the N flown ones' images are read back from the first
plan's capture sets). summary.json's
``rounds`` holds one record per sortie (its cameras, reward, the Chamfer distance of the
reconstruction after it, seconds); its top-level plan fields are the last sortie's.

Nothing of an earlier run is lost: an ``--out`` that holds one (``make run`` twice) is renamed to
``<out>-<YYYYmmdd-HHMMSS>`` (the time it was last written) before the run starts, and the run
writes into a new, empty ``<out>``; a folder of other files is refused (exit 2). The run holds
``<out>`` locked (:class:`vp_scene.folders.FolderLock`; its recorder and recon node hold it too,
until they end): a second run into it, or a CLI's ``--out`` there, is refused in one line (exit
2), and the folder is never moved aside under a live run. ``run.mcap`` reads with the standard MCAP readers
up to a few seconds before a kill, also a SIGKILL (:mod:`vp_recon.recording`; the recorder then
finishes it when it gets its parent-death signal).

Exit codes: 0 success, 1 the plan or the reconstruction failed, or its results are not all written
(the error is printed; ``OUTPUT_NOT_WRITABLE``, a full disk said so), 2 bad arguments (a
``--domain-id`` or ``$ROS_DOMAIN_ID`` outside 0-232 too), an ``--out`` of other files or in use by
another run, or missing build, 3 a node died, 4 timed out, 130 interrupted.

Run after ``make setup`` (``make run`` does both)::

    . .venv/bin/activate && . install/setup.bash
    python tools/run_suite.py --scenario one_plant --method egp --cameras 4 --out out/demo
    python tools/run_suite.py --scenario examples/field.yaml --cameras 6 --out out/field   # a layout file
"""
from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Dict, List, Optional

from node_process import NodeProcess, node_command
from vp_planner.methods import DEFAULT_METHOD, METHODS  # the registry (torch-free)
from vp_scene.camera import IMAGE_SIDE_RANGE, IMAGE_SIZE, image_side_arg
from vp_scene.flights import MAX_FLIGHTS, FlightSettings
from vp_scene.limits import MAX_SEED, seed_arg
from vp_scene.scene_spec import SCENE

#: s between the action server being ready and the goal: server_is_ready() sees the request side of
#: the action's services only; a goal response sent before its reply path is matched is dropped by
#: rmw_fastrtps ("failed to send response (timeout)", ros2/rmw_fastrtps#706), and the planner then
#: executes a goal whose acceptance never arrives (the script also recovers from that, by feedback).
SETTLE_S = 1.0


ROOT = Path(__file__).resolve().parent.parent

#: The run's topics as a ROS 2 bag (MCAP), in the output folder (README "Looking at a plan").
RECORDING = 'run.mcap'

#: m: the first sortie's reconstruction goes to the planner thinned to its mean point a voxel of this
#: edge (a field's clouds are millions of points, tens of MB in one goal; a point moves by at most
#: the voxel's diagonal, 8.7 mm, against the planner's tau of 30 mm).
RECONSTRUCTION_VOXEL = 0.005

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_NODE_DIED, EXIT_TIMEOUT, EXIT_INTERRUPTED = 0, 1, 2, 3, 4, 130

#: ROS_DOMAIN_ID's range (ROS 2's "The ROS_DOMAIN_ID" concept page: Fast DDS's ports overflow above 232)
DOMAIN_IDS = (0, 232)

#: Entries that make a folder an earlier output of the suite (a run, a plan, a reconstruction): a
#: run never writes into one (its files would mix), it moves it aside first (:func:`prepare_out`).
EARLIER_OUTPUT = (RECORDING, 'summary.json', 'recorder.log', 'plan.json', 'recon.json', 'plan-*')


#: image width (pixels) from which make run's SIFT starts at the image's own resolution: below it, too
#: few keypoints are left without the doubled octave (800 x 600 views of one plant: 59-115 per image,
#: no point triangulated; at 2000 x 1500 the Chamfer is unchanged, results/bench_recon_speed.md)
SIFT_OCTAVE0_FROM = 1600


def parse_args(argv: Optional[List[str]] = None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0],
                                 formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    ap.add_argument('--scenario', default=SCENE.scenario, metavar='NAME_OR_FILE',
                    help='a layout name (one_plant, three_row, six_rect, grid_3x3, row_12) or a layout file '
                         "(.yaml, .yml, .json; README 'Your own field')")
    ap.add_argument('--method', default=DEFAULT_METHOD, choices=METHODS)
    ap.add_argument('--cameras', type=int, default=4)
    ap.add_argument('--evals', type=int, default=100, help='reward evaluations')
    ap.add_argument('--init', type=int, default=50, help='initial random design (egp, gp)')
    ap.add_argument('--seed', type=seed_arg, default=SCENE.seed, help=f'seed of the scene, the wind and the planner (0 to {MAX_SEED})')
    ap.add_argument('--reward', default='', help="reward model: paper | coverage | coverage-graph ('': the planner's default)")
    ap.add_argument('--models', default='', help='folder of PLY plant models (default: procedural)')
    ap.add_argument('--realizations', type=int, default=SCENE.realizations, help='K wind realizations')
    ap.add_argument('--points-per-plant', type=int, default=SCENE.points_per_plant)
    ap.add_argument('--width', type=image_side_arg, default=IMAGE_SIZE[0],
                    help=f'rendered image width, pixels ({IMAGE_SIDE_RANGE[0]} to {IMAGE_SIDE_RANGE[1]})')
    ap.add_argument('--height', type=image_side_arg, default=IMAGE_SIZE[1], help='rendered image height, pixels')
    ap.add_argument('--capture', default='realistic', choices=['realistic', 'ideal'],
                    help="the recon node's capture model (README 'Capture model'): realistic (hover and "
                         "localization errors, sensor noise, SfM with the reported poses) or ideal")
    ap.add_argument('--out', default='out/run', help='output folder')
    ap.add_argument('--drones', type=int, default=0,
                    help='start the dispatcher and this many simulated drones (0: none; any number for any cameras)')
    ap.add_argument('--source', choices=('render', 'fleet'), default=None,
                    help='what the recon node reconstructs: fleet (the simulated drones photograph the plan; the '
                         'default with --drones) or render (it renders the plan itself; the default without)')
    ap.add_argument('--assignment', default='min_max', choices=['min_max', 'min_total'],
                    help="the dispatcher's routes' objective: the longest flight or the total")
    ap.add_argument('--rounds', type=int, default=1, choices=(1, 2),
                    help="sorties: 2 plans a second one given the first one's cameras and reconstruction")
    ap.add_argument('--cameras2', type=int, default=0,
                    help='cameras M of the second sortie (0: half of --cameras, at least 2)')
    ap.add_argument('--recon-workers', type=int, default=os.cpu_count() or 1,
                    help='the recon node reconstructs the wind realizations on a local Dask cluster of this many '
                         'one-thread workers (the planner is idle by then; 1: in the node, on the cores the '
                         'planner leaves)')
    # make run's reconstruction settings: about 2x faster per realization than the recon node's defaults
    # (the benchmarks' settings) at the same Chamfer within noise (README "Speed of a flight's
    # reconstruction", results/bench_make_run.md); -1 and 1.0 give the benchmarks' settings
    ap.add_argument('--sift-first-octave', type=int, default=None, choices=(-1, 0, 1),
                    help="recon: SIFT's first octave (-1, COLMAP's default and the benchmarks': each image doubled "
                         f"first; 0: the image as it is; default: 0 from {SIFT_OCTAVE0_FROM} pixels wide, else -1)")
    ap.add_argument('--dense-scale', type=float, default=0.7,
                    help='recon: dense stereo on the images resized by this factor, (0, 1] (default 0.7; '
                         'the benchmarks: 1)')
    flight = FlightSettings()  # the planner's defaults (vp_planner.request's, from vp_scene.flights)
    ap.add_argument('--sim-flights', type=int, default=None,
                    help="simulated flights that check the cheap reward's plans, flown by the recon node (-1: the "
                         "method's default, egp 12; 0: none, the cheap reward chooses; default: the planner's, -1)")
    ap.add_argument('--flight-width', type=image_side_arg, default=None,
                    help=f"the simulated flights' image width, pixels (default: the planner's, {flight.width})")
    ap.add_argument('--flight-height', type=image_side_arg, default=None,
                    help=f"the simulated flights' image height, pixels (default: the planner's, {flight.height})")
    ap.add_argument('--flight-sift-octave', type=int, default=None, choices=(-1, 0),
                    help=f"the simulated flights' SIFT first octave (default: the planner's, {flight.sift_first_octave})")
    ap.add_argument('--flight-dense-scale', type=float, default=None,
                    help=f"the simulated flights' dense step on the images resized by this factor, 0.1..1 (default: "
                         f"the planner's, {flight.dense_scale:g})")
    ap.add_argument('--managed', action='store_true',
                    help='start the planner and the dispatcher as managed lifecycle nodes (managed:=true) and drive '
                         'their transitions here (configure, activate), as a lifecycle manager does')
    ap.add_argument('--timeout', type=float, default=3600.0, help='seconds for the whole mission')
    ap.add_argument('--domain-id', type=int, default=None,
                    help=f'ROS_DOMAIN_ID of this run, {DOMAIN_IDS[0]}-{DOMAIN_IDS[1]} (default: $ROS_DOMAIN_ID, else '
                         'derived from the process id)')
    args = ap.parse_args(argv)
    args.domain_id = domain_id(ap, args.domain_id)
    if args.cameras < 2:
        ap.error('--cameras must be >= 2')
    if args.recon_workers < 1:
        ap.error('--recon-workers must be >= 1')
    if args.evals < 1:
        ap.error('--evals must be >= 1')
    if not 0 < args.dense_scale <= 1:
        ap.error('--dense-scale must be in (0, 1]')
    if args.sim_flights is not None and not -1 <= args.sim_flights <= MAX_FLIGHTS:
        ap.error(f'--sim-flights must be in [-1, {MAX_FLIGHTS}], got {args.sim_flights}')
    try:  # the flights' setting: the planner's own checks, here before anything starts
        FlightSettings(**{k: v for k, v in zip(('width', 'height', 'sift_first_octave', 'dense_scale'), (
            args.flight_width, args.flight_height, args.flight_sift_octave, args.flight_dense_scale)) if v is not None})
    except ValueError as exc:
        ap.error(f'--flight-*: {exc}')
    if args.sift_first_octave is None:
        args.sift_first_octave = 0 if args.width >= SIFT_OCTAVE0_FROM else -1
    if args.cameras2 < 0 or args.cameras2 == 1:
        ap.error('--cameras2 must be 0 (half of --cameras) or >= 2')
    args.cameras2 = args.cameras2 or max(2, args.cameras // 2)
    if args.drones < 0:
        ap.error('--drones must be >= 0')
    if args.source is None:
        args.source = 'fleet' if args.drones else 'render'
    if args.source == 'fleet' and not args.drones:
        ap.error('--source fleet needs --drones (the drones take the pictures)')
    if args.models:
        if not Path(args.models).is_dir():
            ap.error(f'--models: no such folder: {args.models}')
        args.models = str(Path(args.models).resolve())
    args.scenario_name, args.scenario_file = check_scenario(ap, args.scenario)
    if args.scenario_file is not None:  # the scene node gets the file, wherever it runs from
        args.scenario = args.scenario_file
    return args


def domain_id(ap: argparse.ArgumentParser, given: Optional[int]) -> int:
    """The run's ROS_DOMAIN_ID: ``--domain-id``, else ``$ROS_DOMAIN_ID``, else one derived from the
    process id; one outside :data:`DOMAIN_IDS` (or a ``$ROS_DOMAIN_ID`` that is not an integer) is
    a usage error, before anything starts (Fast DDS would fail at its first participant)."""
    low, high = DOMAIN_IDS
    if given is not None:
        if not low <= given <= high:
            ap.error(f'--domain-id must be in {low}-{high}, got {given}')
        return given
    env = os.environ.get('ROS_DOMAIN_ID', '').strip()
    if not env:
        return 10 + os.getpid() % 200
    if not (env.isdigit() and low <= int(env) <= high):
        ap.error(f'ROS_DOMAIN_ID (environment) must be an integer in {low}-{high}, got {env!r}')
    return int(env)


def prepare_out(out: Path):
    """Make ``out`` the run's folder, empty and locked: (its :class:`vp_scene.folders.FolderLock`,
    held for the run; the earlier output's new path or None). Made when missing; one that another
    live run holds is refused (FolderInUse) and never moved; one holding an earlier output
    (:data:`EARLIER_OUTPUT`: ``make run`` twice) is renamed, locked, to ``<out>-<the time it was last
    written>`` (nothing is deleted); a folder of other files is refused with FileExistsError (the
    run's files would mix with them, and a later run would move them aside)."""
    from vp_scene.folders import FolderLock, move_aside

    out.mkdir(parents=True, exist_ok=True)
    lock = FolderLock(out)
    if not any(out.iterdir()):
        return lock, None
    with lock:  # held while the earlier output is looked at and moved: no other run starts in it meanwhile
        if not any(any(out.glob(name)) for name in EARLIER_OUTPUT):
            raise FileExistsError(f'--out {out} holds other files, not an output of the suite: give a new or an '
                                  'empty folder')
        moved = move_aside(out)
        out.mkdir(parents=True, exist_ok=True)
        return FolderLock(out), moved


def check_scenario(ap: argparse.ArgumentParser, scenario: str) -> tuple:
    """(the layout's name, its file as an absolute path or None for a built-in layout); a layout
    file is read and checked now (a bad one is a usage error: exit 2, the file and field named)."""
    try:
        from vp_scene.layout import LayoutError, read_scenario
    except ImportError as exc:
        ap.error(f'cannot import vp_scene ({exc}): run make setup and source install/setup.bash')
    try:
        layout = read_scenario(scenario)
    except LayoutError as exc:
        ap.error(f'--scenario: {exc}')
    return (scenario, None) if layout is None else (layout.name, str(Path(scenario).resolve()))


class LifecycleRefused(RuntimeError):
    """A lifecycle node (``--managed``) refused a transition."""


class Mission:
    """The test-side ROS node: action client of the planner, listener of the scores."""

    def __init__(self, args: argparse.Namespace):
        import rclpy
        from rclpy.action import ActionClient
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import PointCloud2
        from vp_interfaces.action import PlanViews
        from vp_interfaces.msg import FleetAssignment, ReconstructionScore

        self.rclpy, self.PlanViews, self.Score = rclpy, PlanViews, ReconstructionScore
        self.args = args
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('vp_mission', context=self.context)
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.scene_ready = threading.Event()
        self.scores: List[object] = []
        self.clouds: List[object] = []  # /reconstruction/points, one a realization done
        self.node.create_subscription(PointCloud2, '/reconstruction/points', self.clouds.append, latched)
        self.aggregate = threading.Event()
        self.node.create_subscription(PointCloud2, '/scene/noisy_points',
                                      lambda _m: self.scene_ready.set(), latched)
        # as the recon node offers it (vp_recon.recon_node.SCORES): a score sent before this
        # subscription matched (an immediate error) still arrives
        self.node.create_subscription(ReconstructionScore, '/reconstruction/score', self._on_score,
                                      QoSProfile(depth=64, reliability=ReliabilityPolicy.RELIABLE,
                                                 durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self.assignments: List[object] = []
        self.node.create_subscription(FleetAssignment, '/fleet/assignment', self.assignments.append,
                                      QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                                                 durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self.client = ActionClient(self.node, PlanViews, '/plan_views')
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._spin = threading.Thread(target=self._spin_forever, daemon=True)
        self._spin.start()
        self.progress = None
        self.flights_bar = None
        self.feedback_seen = False

    def _spin_forever(self) -> None:
        try:
            self.executor.spin()
        except Exception:
            pass

    def _on_score(self, msg) -> None:
        self.scores.append(msg)
        if msg.realization == self.Score.AGGREGATE:
            self.aggregate.set()

    def on_feedback(self, fb_msg) -> None:
        self.feedback_seen = True
        fb = fb_msg.feedback
        if fb.flights_total:  # the simulated flights, after the evaluations
            from tqdm import tqdm
            if self.flights_bar is None:
                self.close_bars()
                self.flights_bar = tqdm(total=fb.flights_total, desc='simulated flights', unit='flight',
                                        file=sys.stdout, dynamic_ncols=True)
            self.flights_bar.n = fb.flights_done
            last = fb.last_flight_chamfer
            self.flights_bar.set_postfix({'last map Chamfer': 'failed' if math.isnan(last) else f'{last:.4f} m'},
                                         refresh=True)
            return
        if self.progress is None:
            from tqdm import tqdm
            self.progress = tqdm(total=fb.evaluations_total, desc=f'planning ({self.args.method})',
                                 unit='eval', file=sys.stdout, dynamic_ncols=True)
        self.progress.n = fb.evaluations_done
        post = {'best reward': f'{fb.best_reward:.4f}'}
        if fb.ensemble_weights:
            post['w'] = ' '.join(f'{m}:{w:.2f}' for m, w in zip(fb.ensemble_models, fb.ensemble_weights))
        self.progress.set_postfix(post, refresh=True)

    def send_goal(self, num_cameras: int = 0, fixed=None, reconstruction=None):
        """Send the goal for ``num_cameras`` (0: ``--cameras``; a second sortie's with the PoseArray of the cameras
        already flown and the PointCloud2 of their reconstruction); (the future of its goal handle,
        its goal id)."""
        from unique_identifier_msgs.msg import UUID
        import uuid

        goal = self.PlanViews.Goal()
        goal.num_cameras = num_cameras or self.args.cameras
        if fixed is not None:
            goal.fixed_cameras = fixed
        if reconstruction is not None:
            goal.reconstruction = reconstruction
        goal.method = self.args.method
        goal.evaluations = self.args.evals
        goal.initial_evaluations = min(self.args.init, self.args.evals)
        goal.seed = self.args.seed
        goal.reward = self.args.reward
        goal_id = UUID(uuid=list(uuid.uuid4().bytes))
        return self.client.send_goal_async(goal, feedback_callback=self.on_feedback, goal_uuid=goal_id), goal_id

    def activate(self, name: str, nodes: List[NodeProcess], deadline: float) -> None:
        """Drive the lifecycle node ``name`` from unconfigured to active (configure, then activate),
        as a lifecycle manager does; a transition whose answer is lost in DDS discovery
        (ros2/rmw_fastrtps#390) is read back from the node's state. LifecycleRefused when it refuses."""
        from lifecycle_msgs.msg import State, Transition
        from lifecycle_msgs.srv import ChangeState, GetState

        change = self.node.create_client(ChangeState, f'/{name}/change_state')
        get = self.node.create_client(GetState, f'/{name}/get_state')
        wait_for(lambda: change.service_is_ready() and get.service_is_ready(), nodes, deadline,
                 f'the lifecycle services of {name}')
        for transition, label, target in ((Transition.TRANSITION_CONFIGURE, 'configure', State.PRIMARY_STATE_INACTIVE),
                                          (Transition.TRANSITION_ACTIVATE, 'activate', State.PRIMARY_STATE_ACTIVE)):
            asked = change.call_async(ChangeState.Request(transition=Transition(id=transition)))
            answer_by = min(deadline, time.monotonic() + 5.0)
            wait_for(lambda: asked.done() or time.monotonic() > answer_by, nodes, deadline, f'{name} to {label}')
            if asked.done() and not asked.result().success:
                raise LifecycleRefused(f'the {name} node refused to {label}')
            if not asked.done():  # the answer was lost: the node's state says whether it happened
                state = get.call_async(GetState.Request())
                wait_for(state.done, nodes, deadline, f'the lifecycle state of {name}')
                if state.result().current_state.id != target:
                    raise LifecycleRefused(f'the {name} node did not {label}')
        print(f'{name}: configured and activated (lifecycle)', flush=True)

    def accepted_handle(self, goal_id):
        """A handle for a goal the planner accepted (its feedback arrives) whose acceptance never
        reached us, so that its result can be asked for."""
        from rclpy.action.client import ClientGoalHandle

        return ClientGoalHandle(self.client, goal_id, self.PlanViews.Impl.SendGoalService.Response(accepted=True))

    def close_bars(self) -> None:
        for bar in (self.progress, self.flights_bar):
            if bar is not None:
                bar.close()
        self.progress = self.flights_bar = None

    def close(self) -> None:
        self.close_bars()
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        self.rclpy.try_shutdown(context=self.context)


def start_node(name: str, pkg: str, exe: str, params: Dict[str, object], env, log_dir: Path,
               lock=None) -> NodeProcess:
    """One node as a child process named ``name``, its output streamed with a ``[name]`` prefix;
    it holds the run's folder ``lock`` too (a FolderLock: the folder stays locked until it ends)."""
    node = NodeProcess(node_command(pkg, exe, params, name=name), env, log_dir / f'{name}.log', echo=name,
                       pass_fds=() if lock is None else (lock.fd,))
    print(f'started {name} (pid {node.pid}): {exe}', flush=True)
    return node


def assignment_lines(msg) -> List[str]:
    """What /fleet/assignment says, for the terminal: one line per drone."""
    lines = [f'fleet ({msg.assignment}): {len(msg.routes)} drones to {msg.num_poses} poses, time on site '
             f'{msg.time_on_site:.1f} s, total {msg.total_distance:.2f} m, '
             + (f'drones at least {msg.min_separation:.2f} m apart (separation {msg.separation:g} m)'
                if math.isfinite(msg.min_separation) else 'one drone')]
    for r in msg.routes:
        lines.append(f'  {r.drone} -> cams {", ".join(str(i) for i in r.pose_indices)}: {r.flight_time:.1f} s flight '
                     f'(budget {msg.budget:.0f} s), {r.distance:.2f} m')
    if msg.spare_drones:
        lines.append(f'  spare: {", ".join(msg.spare_drones)}')
    return lines


def wait_for(predicate, nodes: List[NodeProcess], deadline: float, what: str) -> None:
    """Poll ``predicate`` while watching the nodes; raise on a dead node or the deadline."""
    while not predicate():
        for n in nodes:
            code = n.poll()
            if code is not None:
                n.wait(1.0)  # its last lines
                raise NodeDied(n.echo, code, n.last_line(), n.log_path)
        if time.monotonic() > deadline:
            raise TimeoutError(f'timed out waiting for {what}')
        time.sleep(0.1)


class NodeDied(RuntimeError):
    def __init__(self, name: str, code: int, last_line: str = '', log: Optional[Path] = None):
        said = f': {last_line}' if last_line else ''
        where = f' (log: {log})' if log is not None else ''
        super().__init__(f'node "{name}" died (exit code {code}){said}{where}')
        self.node_name, self.code = name, code


def thinned_cloud(msg, voxel: float = RECONSTRUCTION_VOXEL):
    """A PointCloud2 of the mean point (and colour) of every occupied voxel of ``msg``'s cloud, in
    its frame (:func:`vp_recon.dense.voxel_downsample`)."""
    import numpy as np
    from vp_recon.dense import voxel_downsample
    from vp_scene.cloud import numpy_to_pointcloud2, pointcloud2_to_numpy

    points, colors, _ = pointcloud2_to_numpy(msg)
    colors = np.zeros((len(points), 3), np.uint8) if colors is None else colors
    points, colors = voxel_downsample(points, colors, voxel)
    return numpy_to_pointcloud2(points, colors, frame_id=msg.header.frame_id, stamp=msg.header.stamp)


def fly_sortie(mission: Mission, nodes: List[NodeProcess], deadline: float, args: argparse.Namespace,
               num_cameras: int, outcome: List[str], fixed=None, reconstruction=None) -> Optional[dict]:
    """One sortie: the goal (a second one's with the cameras already flown and their
    reconstruction), the plan printed, the fleet's assignment (with drones), the reconstruction's
    aggregate score and the last cloud on /reconstruction/points. A dict (result, fleet, agg, per,
    cloud, record: the summary's ``rounds`` entry), or None with the error in ``outcome``."""
    from vp_scene.messages import msgs_to_poses

    started = time.monotonic()
    first_score, first_cloud = len(mission.scores), len(mission.clouds)
    mission.aggregate.clear()
    mission.feedback_seen = False
    goal_future, goal_id = mission.send_goal(num_cameras, fixed, reconstruction)
    wait_for(lambda: goal_future.done() or mission.feedback_seen, nodes, deadline,
             'the planner to accept the goal')
    if goal_future.done():
        handle = goal_future.result()
    else:  # executing (its feedback arrives), but the goal response was lost: ask for the result
        print('note: the planner accepted the goal but its answer was lost in DDS discovery; '
              'asking for the result directly', flush=True)
        handle = mission.accepted_handle(goal_id)
    if not handle.accepted:
        outcome.append('error: the planner rejected the goal')
        return None
    result_future = handle.get_result_async()
    wait_for(result_future.done, nodes, deadline, 'the plan')
    result = result_future.result().result
    mission.close_bars()
    if result.error_code != 0:
        outcome.append(f'error: planning failed (error_code {result.error_code}): {result.error_msg}')
        return None
    poses = msgs_to_poses(result.plan.poses).tolist()
    cameras = [list(result.cameras[i:i + 6]) for i in range(0, len(result.cameras), 6)]
    print(f'plan: {result.reward_model} reward {result.reward:.4f} after {result.evaluations} evaluations'
          + (f', chosen by {len(result.flights)} simulated flights (map Chamfer {result.flight_score:.4f} m)'
             if result.chosen_by == 'flights' else '')
          + f' ({result.planning_time:.1f} s)' + (f'; {result.flights_note}' if result.flights_note else ''), flush=True)
    for i, pose in enumerate(poses):
        print(f'  cam {i}: position ({pose[0]:+.3f}, {pose[1]:+.3f}, {pose[2]:+.3f}) m  '
              f'quaternion ({pose[3]:+.3f}, {pose[4]:+.3f}, {pose[5]:+.3f}, {pose[6]:+.3f})',
              flush=True)

    fleet = None
    if args.drones:
        stamp = result.plan.header.stamp

        def dispatched():
            return [a for a in mission.assignments if a.plan_stamp == stamp]
        wait_for(dispatched, nodes, deadline, 'the dispatcher\'s answer on /fleet/assignment')
        fleet = dispatched()[-1]
        if fleet.error_code != 0:
            outcome.append(f'error: the dispatcher refused the plan (error_code {fleet.error_code}): '
                           f'{fleet.error_msg}')
            return None
        for line in assignment_lines(fleet):
            print(line, flush=True)

    def aggregate_now():
        return [s for s in mission.scores[first_score:] if s.realization == mission.Score.AGGREGATE]
    wait_for(aggregate_now, nodes, deadline, 'the aggregate reconstruction score')
    agg = aggregate_now()[-1]
    per = [s for s in mission.scores[first_score:] if s.realization != mission.Score.AGGREGATE]
    cloud = None
    if agg.error_code == 0:  # one cloud a realization done, the last holds them all
        wait_for(lambda: len(mission.clouds) - first_cloud >= agg.realizations, nodes, deadline,
                 'the reconstruction on /reconstruction/points')
        cloud = mission.clouds[-1]
    record = {'cameras': cameras, 'num_cameras': len(result.plan.poses), 'fixed_cameras': 0 if fixed is None else len(fixed.poses),
              'images': agg.num_images, 'reward': result.reward,
              'chamfer_mean': None if agg.error_code else agg.chamfer,
              'chamfer_std': None if agg.error_code else agg.chamfer_std,
              'error_code': agg.error_code, 'chosen_by': result.chosen_by, 'seconds': time.monotonic() - started}
    return {'result': result, 'fleet': fleet, 'agg': agg, 'per': per, 'cloud': cloud, 'record': record}


def run(args: argparse.Namespace) -> int:
    from vp_planner.routes import FlightModel, launch_row
    from vp_recon.errors import ERROR_NAMES
    from vp_scene.folders import write_atomic
    from vp_scene.messages import (flight_record, msgs_to_poses, path_poses, point_array, pose_array,  # conversions'
                                   score_record)  # one home

    out = Path(args.out).resolve()
    try:
        lock, moved = prepare_out(out)  # held until this process and its nodes end
    except OSError as exc:
        print(f'error: {exc}', flush=True)
        return EXIT_USAGE
    if moved is not None:
        print(f'vp-suite: the earlier output in {out} was moved to {moved}', flush=True)
    env = dict(os.environ)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    domain = args.domain_id
    env['ROS_DOMAIN_ID'] = str(domain)
    os.environ.update({k: env[k] for k in ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'ROS_DOMAIN_ID')})
    env.setdefault('PYOPENGL_PLATFORM', 'egl')
    env['PYTHONUNBUFFERED'] = '1'
    if not env.get('FASTRTPS_DEFAULT_PROFILES_FILE'):  # the images' heartbeat (vp_scene/config/fastdds.xml)
        from ament_index_python.packages import get_package_share_directory
        env['FASTRTPS_DEFAULT_PROFILES_FILE'] = str(Path(get_package_share_directory('vp_scene')) / 'config' / 'fastdds.xml')
    start = time.monotonic()
    deadline = start + args.timeout
    print(f'vp-suite: {args.scenario_name}, {args.cameras} cameras, {args.method}, {args.evals} evaluations, '
          f'seed {args.seed}{f", {args.drones} drones" if args.drones else ""}; ROS_DOMAIN_ID={domain} '
          f'(localhost only); output {out}', flush=True)

    scene_params = {'scenario': args.scenario, 'models_folder': args.models, 'seed': args.seed,
                    'realizations': args.realizations, 'points_per_plant': args.points_per_plant}
    nodes: List[NodeProcess] = []
    mission: Optional[Mission] = None
    outcome: List[str] = []  # printed after the nodes are stopped, so that it is the last line

    def on_signal(signum, _frame):
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, on_signal)
    # SIGINT stops the mission also when a non-interactive shell started the script with `&`
    # (which starts it with SIGINT ignored: `kill -INT` then did nothing, and the test failed)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        # the planner and the recon share the cores: 1 thread for the planner, the rest for the recon
        recon_threads = max(1, (os.cpu_count() or 2) - 1)
        # first, so that it sees every topic from its start; stopped last (the nodes stop in
        # reverse order), which closes <out>/run.mcap (vp_recon.recording). The recorder and the
        # recon write into <out>: they hold its lock too, so that it outlives a SIGKILL of this script
        # until they have finished their files
        nodes.append(start_node('recorder', 'vp_recon', 'recorder', {'output': str(out / RECORDING)},
                                {**env, 'OMP_NUM_THREADS': '1'}, out, lock))
        nodes.append(start_node('scene', 'vp_scene', 'scene', scene_params, {**env, 'OMP_NUM_THREADS': '1'}, out))
        flights = {k: v for k, v in (('sim_flights', args.sim_flights), ('flight_width', args.flight_width),
                                     ('flight_height', args.flight_height), ('flight_sift_octave', args.flight_sift_octave),
                                     ('flight_dense_scale', args.flight_dense_scale)) if v is not None}
        nodes.append(start_node('planner', 'vp_planner', 'planner', {
            'num_cameras': args.cameras, 'method': args.method, 'evaluations': args.evals,
            'initial_evaluations': min(args.init, args.evals), 'seed': args.seed, 'num_threads': 1,
            'managed': args.managed, **flights},
            {**env, 'OMP_NUM_THREADS': '1'}, out))
        # the realizations reconstruct after the plan is made (the planner idle): on a local Dask
        # cluster of one-thread workers, all cores (issue 18, part 4: make run's time)
        # (each worker one thread; in the node: every core but the planner's)
        on_cluster = {'scheduler': 'local', 'workers': args.recon_workers} if args.recon_workers > 1 else {}
        recon_threads = 1 if on_cluster else recon_threads
        nodes.append(start_node('recon', 'vp_recon', 'recon', {
            'output_folder': str(out), 'width': args.width, 'height': args.height,
            'method': args.method, 'num_threads': recon_threads, 'capture': args.capture, 'source': args.source,
            'sift_first_octave': args.sift_first_octave, 'dense_scale': args.dense_scale, **on_cluster},
            {**env, 'OMP_NUM_THREADS': str(recon_threads)}, out, lock))
        if args.drones:
            drones = [f'd{k}' for k in range(args.drones)]
            # with the fleet's images: one sortie a wind realization the recon node asks for
            nodes.append(start_node('dispatcher', 'vp_planner', 'dispatcher', {
                'drones': drones, 'assignment': args.assignment, 'managed': args.managed,
                'fly_on': 'capture' if args.source == 'fleet' else 'plan'}, {**env, 'OMP_NUM_THREADS': '1'}, out))
            model = FlightModel()  # the dispatcher's: the simulated drones fly as its routes are timed
            for name, (x, y, z) in zip(drones, launch_row(args.drones).tolist()):
                camera = {'camera': True, 'width': args.width, 'height': args.height, 'capture': args.capture} \
                    if args.source == 'fleet' else {}
                nodes.append(start_node(f'sim_{name}', 'vp_scene', 'sim_drone', {
                    'drone': name, 'x': x, 'y': y, 'z': z, 'speed': model.cruise_speed, 'climb_rate': model.climb_rate,
                    **camera}, {**env, 'OMP_NUM_THREADS': '1'}, out))
        mission = Mission(args)
        if args.managed:
            for name in ('planner', 'dispatcher')[:2 if args.drones else 1]:
                mission.activate(name, nodes, deadline)

        wait_for(mission.scene_ready.is_set, nodes, deadline, 'the scene on /scene/noisy_points')
        wait_for(lambda: mission.client.server_is_ready(), nodes, deadline, 'the /plan_views server')
        settled = time.monotonic() + SETTLE_S
        wait_for(lambda: time.monotonic() > settled, nodes, deadline, 'the action\'s reply paths')
        rounds: List[dict] = []
        sortie = fly_sortie(mission, nodes, deadline, args, args.cameras, outcome)
        if sortie is None:
            return EXIT_FAILED
        rounds.append(sortie)
        if args.rounds == 2 and sortie['agg'].error_code == 0:
            flown = sortie['result'].plan
            reconstruction = thinned_cloud(sortie['cloud'])
            print(f'second sortie: {args.cameras2} cameras given the {len(flown.poses)} flown and their '
                  f'reconstruction ({reconstruction.width * reconstruction.height} points, one a '
                  f'{1000 * RECONSTRUCTION_VOXEL:g} mm voxel)', flush=True)
            sortie = fly_sortie(mission, nodes, deadline, args, args.cameras2, outcome, flown, reconstruction)
            if sortie is None:
                return EXIT_FAILED
            rounds.append(sortie)
        result, fleet, agg, per = sortie['result'], sortie['fleet'], sortie['agg'], sortie['per']
        poses = msgs_to_poses(result.plan.poses).tolist()
        cameras = [list(result.cameras[i:i + 6]) for i in range(0, len(result.cameras), 6)]
        summary = {
            'scenario': args.scenario_name, 'scenario_file': args.scenario_file,
            'method': args.method, 'cameras': cameras,
            'reward': result.reward, 'reward_model': result.reward_model,
            'chamfer_mean': None if agg.error_code else agg.chamfer,
            'chamfer_std': None if agg.error_code else agg.chamfer_std,
            'chamfer_shape_mean': None if agg.error_code else agg.chamfer_shape,
            'capture': agg.capture or args.capture, 'source': agg.source or args.source,
            'recon_settings': {'sift_first_octave': args.sift_first_octave, 'dense_scale': args.dense_scale},
            'registered_images': agg.registered_images,
            'poses': poses, 'seconds': time.monotonic() - start,
            'evaluations': result.evaluations, 'trace': list(result.trace), 'seed': args.seed,
            # how the plan was chosen: by the simulated flights (each flight: the plan's source, draw, score, seconds)
            'chosen_by': result.chosen_by,
            'flight_score': result.flight_score if math.isfinite(result.flight_score) else None,
            'flights_note': result.flights_note, 'flights': [flight_record(f) for f in result.flights],
            'error_code': agg.error_code, 'error_msg': agg.error_msg,
            'per_realization': [score_record(s) for s in per],
            'rounds': [r['record'] for r in rounds],
            # what a real flight can check (README "From a real flight"): the aggregate's metrics without a truth
            'no_truth': {k: v for k, v in score_record(agg).items()
                         if k in ('registered_images', 'mean_reprojection_error', 'mean_track_length', 'points',
                                  'centre_residual', 'coverage_of_prior', 'coverage_of_prior_per_plant',
                                  'coverage_tau')},
        }
        if fleet is not None:
            def finite(x):
                return x if math.isfinite(x) else None
            summary['fleet'] = {
                'assignment': fleet.assignment, 'time_on_site': fleet.time_on_site, 'budget': fleet.budget,
                'separation': fleet.separation, 'min_separation': finite(fleet.min_separation),
                'total_distance': fleet.total_distance, 'max_distance': fleet.max_distance,
                'spare_drones': list(fleet.spare_drones),
                'routes': [{'drone': r.drone, 'poses': list(r.pose_indices), 'flight_time': r.flight_time,
                            'distance': r.distance, 'path': path_poses(r.path).tolist(), 'arrival': list(r.arrival),
                            'departure': list(r.departure)} for r in fleet.routes],
                'drones': [{'drone': e.drone, 'pose_index': e.pose_index, 'order': e.order, 'eta': e.eta,
                            'distance': e.distance, 'start': point_array(e.start).tolist(),
                            'goal': pose_array(e.goal).tolist()} for e in fleet.entries]}
        text = json.dumps(summary, indent=2)
        try:
            write_atomic(out / 'summary.json', lambda tmp: tmp.write_text(text))
        except OSError as exc:  # a run whose results are not all written failed (a full disk: said so)
            outcome.append(f'error: [OUTPUT_NOT_WRITABLE] {exc}')
            return EXIT_FAILED
        if agg.error_code != 0:
            outcome.append(f'error: reconstruction failed (error_code {agg.error_code} '
                           f'{ERROR_NAMES.get(agg.error_code, "UNKNOWN")}): {agg.error_msg}')
            return EXIT_FAILED
        outcome.append(f'Chamfer distance x100: {agg.chamfer:.3f} +- {agg.chamfer_std:.3f} over '
                       f'{agg.realizations} wind realizations; summary: {out / "summary.json"}')
        return EXIT_OK
    except NodeDied as exc:
        print(f'node "{exc.node_name}" died: stopping the other nodes', flush=True)
        outcome.append(f'error: {exc}')
        return EXIT_NODE_DIED
    except TimeoutError as exc:
        outcome.append(f'error: {exc}')
        return EXIT_TIMEOUT
    except LifecycleRefused as exc:
        outcome.append(f'error: {exc}')
        return EXIT_FAILED
    except FileNotFoundError as exc:
        outcome.append(f'error: {exc}')
        return EXIT_USAGE
    except KeyboardInterrupt:
        print('interrupted: stopping the nodes', flush=True)
        outcome.append('interrupted')
        return EXIT_INTERRUPTED
    finally:
        if mission is not None:
            mission.close()
        for n in nodes:  # their shutdown lines go to <out>/<node>.log only
            n.mute()
        for n in reversed(nodes):
            n.stop()
        lock.release()
        for line in outcome:
            print(line, flush=True)


def main(argv: Optional[List[str]] = None) -> int:
    return run(parse_args(argv))


if __name__ == '__main__':
    sys.exit(main())
