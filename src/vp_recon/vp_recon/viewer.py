"""A plan in the browser (viser): the scene, the cameras, the drones and the reconstruction.

:class:`PlanViewer` is ROS-free: it takes numpy arrays and draws them in a
``viser.ViserServer`` bound to 127.0.0.1 only (viser serves its own web client from the wheel;
every browser that connects gets the same state). Only the printed URL opens it: it carries a
token made at start (``http://127.0.0.1:<port>/<token>/``; viser's page derives its WebSocket
address from the page's path, so the socket asks for ``/<token>`` too), and a WebSocket
handshake without it, or from a page of another origin (a web site open in a browser on this
machine), is refused with 403 before anything is sent (:func:`_guarded_serve`):

* ``/scene``: the noisy scene cloud, one wind realization at a time (GUI "realization");
* ``/plan/cam_<i>``: one frustum per camera, placed and shaped by :mod:`vp_scene.camera` (the
  REP-103 optical frame, z forward, is viser's OpenCV frustum frame; a pose's roll is drawn),
  coloured by the drone that flies it (grey when no fleet assigned it);
* ``/drones/<name>``: each drone where it last reported;
* ``/reconstruction``: the reconstructed points of the shown realization, coloured by their distance to
  the truth (the scene cloud of that realization; without it, all realizations: the prior), blue
  (0) to red (>= ``distance_scale``), and ``/uncovered``: the truth points farther than
  ``distance_scale`` from every reconstructed point (magenta).

Clouds larger than ``max_points`` are shown as a uniform random subset (the GUI says so).

Live: the ``viewer`` node (:mod:`vp_recon.viewer_node`) feeds it from the run's topics.
Offline (``make view RUN=out/...``): ``python -m vp_recon.viewer RUN_FOLDER --port 8080``
replays the latest message of each topic of ``RUN_FOLDER/run.mcap`` (``make run`` records it,
:mod:`vp_recon.recording`) and serves until Ctrl-C; a recording cut by a kill is shown up to
then, with a one-line note. Bad input (no recording, a file that is not a readable MCAP, a port
in use): one line, exit 2.
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import http
import math
import secrets
import sys
import threading
import time
from pathlib import Path
from typing import Dict, Optional, Sequence

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from vp_scene.camera import CameraModel, check_poses, world_to_camera

__all__ = ["PlanViewer", "ViewerError", "frustum_poses", "distance_colors", "load_run", "replay_recording", "show_message", "main"]

EXIT_OK, EXIT_USAGE = 0, 2

#: Drone colours (RGB), by the drone's position in the fleet assignment.
PALETTE = ((31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
           (140, 86, 75), (227, 119, 194), (188, 189, 34), (23, 190, 207), (127, 127, 127))
UNASSIGNED = (90, 90, 90)
UNCOVERED = (255, 0, 255)


class ViewerError(RuntimeError):
    """Bad input for the viewer: one line for the user."""


def frustum_poses(cameras: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(wxyz (M, 4), positions (M, 3)) of the optical frames of cameras (M, 6) [c, v] or poses
    (M, 7) (roll kept), for viser's frustums."""
    cams = check_poses(cameras) if np.size(cameras) else np.zeros((0, 7))
    R_cw, _t = world_to_camera(cams)
    xyzw = Rotation.from_matrix(np.swapaxes(R_cw, -1, -2)).as_quat().reshape(-1, 4)
    return xyzw[:, [3, 0, 1, 2]], cams[:, :3].copy()


def distance_colors(points: np.ndarray, reference: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """(colours (N, 3) uint8 from blue at 0 to red at >= ``scale``, distances (N,)) of ``points`` to
    their nearest ``reference`` point."""
    d, _ = cKDTree(reference).query(points, k=1)
    t = np.clip(d / scale, 0.0, 1.0)[:, None]
    colors = (1 - t) * np.array([30, 80, 255]) + t * np.array([230, 30, 30])
    return colors.astype(np.uint8), d


def _subsample(n: int, max_points: int, seed: int = 0) -> np.ndarray:
    if n <= max_points:
        return np.arange(n)
    return np.sort(np.random.default_rng(seed).choice(n, max_points, replace=False))


HOST = "127.0.0.1"
_SERVE_LOCK = threading.Lock()


@contextlib.contextmanager
def _guarded_serve(token: str, port: int):
    """While a ``viser.ViserServer`` starts in this block, its WebSocket server refuses (403) a
    handshake whose path is not ``/<token>`` or whose ``Origin`` is not this viewer's page
    (http://127.0.0.1:<port> or http://localhost:<port>; a client without an Origin, not a
    browser, needs the token alone), and serves its page only under ``/<token>/``.

    Why a hook: viser (1.1.1) offers neither an origin check nor a token and calls websockets'
    ``serve`` itself with its own ``process_request`` (which serves the page); websockets' own
    ``origins=`` cannot be passed through it. So ``websockets.asyncio.server.serve`` is wrapped for
    the time viser's constructor takes (it returns once its server listens, and calls ``serve``
    only then): our check runs first, viser's handler after it, unchanged."""
    import websockets.asyncio.server as ws_server

    origins = {f"http://{HOST}:{port}", f"http://localhost:{port}"}
    prefix = f"/{token}"
    original = ws_server.serve

    def guard(connection, request, viser_process_request):
        path = request.path.partition("?")[0]
        if request.headers.get("Upgrade", "").lower() == "websocket":
            origin = request.headers.get("Origin")
            asked = path.rstrip("/").encode("utf-8", "surrogateescape")
            if not secrets.compare_digest(asked, prefix.encode()) or (origin is not None and origin not in origins):
                return connection.respond(http.HTTPStatus.FORBIDDEN, "403: open the URL this viewer printed\n")
            return viser_process_request(connection, request) if viser_process_request else None
        if not (path == prefix or path.startswith(prefix + "/")):
            return connection.respond(http.HTTPStatus.FORBIDDEN, "403: open the URL this viewer printed "
                                                                 "(it carries the viewer's token)\n")
        request = dataclasses.replace(request, path=request.path[len(prefix):] or "/")
        return viser_process_request(connection, request) if viser_process_request else None

    def serve(*args, process_request=None, **kwargs):
        return original(*args, process_request=lambda c, r: guard(c, r, process_request), **kwargs)

    with _SERVE_LOCK:
        ws_server.serve = serve
        try:
            yield
        finally:
            ws_server.serve = original


class PlanViewer:
    """The viewer's scene on a viser server at 127.0.0.1:``port``, open at :attr:`url` only (its
    token: ``token``, else a new random one); ViewerError when the port is taken."""

    def __init__(self, port: int = 8080, max_points: int = 60000, distance_scale: float = 0.02,
                 model: CameraModel = CameraModel(), token: Optional[str] = None):
        import viser

        self.token = token or secrets.token_urlsafe(16)
        with _guarded_serve(self.token, port):
            self.server = viser.ViserServer(host=HOST, port=port, verbose=False)
        if self.server.get_port() != port:  # viser moves on to the next free port; we do not
            self.server.stop()
            raise ViewerError(f"port {port} on {HOST} is in use (try --port / make view PORT=...)")
        self.port, self.max_points, self.distance_scale, self.model = port, max_points, distance_scale, model
        self.server.scene.set_up_direction("+z")  # REP-103: z up
        self._scene: Optional[tuple] = None  # points, colors, realization
        self._recon: Optional[tuple] = None
        self._drone_colors: Dict[str, tuple] = {}
        self.frustums: list = []
        self.drones: Dict[str, object] = {}
        self._lock = threading.RLock()  # the GUI's callbacks run in viser's thread, updates in the caller's
        self._cameras = np.zeros((0, 7))
        self._assigned = {}
        gui = self.server.gui
        self.realization = gui.add_dropdown("realization", ("0",), initial_value="0")
        self.realization.on_update(lambda _e: self._redraw_clouds())
        # the display cap, changeable in the page: a browser without a GPU (software WebGL) slows
        # down with tens of thousands of points; a GPU draws the slider's maximum with ease
        self.points_shown = gui.add_slider("points shown", min=min(1000, int(max_points)),
                                           max=max(300_000, int(max_points)), step=1000, initial_value=int(max_points),
                                           hint="points drawn per cloud (a random subset of bigger clouds)")
        self.points_shown.on_update(lambda _e: self._set_max_points(self.points_shown.value))
        self.status = gui.add_markdown("waiting for the scene")
        self.plan_info = gui.add_markdown("no plan yet")

    def _set_max_points(self, value) -> None:
        self.max_points = max(1, int(value))
        self._redraw_clouds()

    @property
    def url(self) -> str:
        """The page, with the token that opens it."""
        return f"http://{HOST}:{self.port}/{self.token}/"

    # -------------------------------------------------------------- inputs
    def show_scene(self, points: np.ndarray, colors: Optional[np.ndarray], realization: Optional[np.ndarray]) -> None:
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        real = np.zeros(len(pts), np.int64) if realization is None else np.asarray(realization, np.int64)
        cols = np.full((len(pts), 3), 60, np.uint8) if colors is None else np.asarray(colors, np.uint8)
        self._scene = (pts, cols, real)
        options = tuple(str(k) for k in np.unique(real)) or ("0",)
        self.realization.options = options
        if self.realization.value not in options:
            self.realization.value = options[0]
        self._redraw_clouds()

    def show_plan(self, cameras: np.ndarray) -> None:
        """One frustum per camera (M, 6) [c, v] or pose (M, 7), grey until :meth:`assign` names their drones."""
        self._cameras = check_poses(cameras) if np.size(cameras) else np.zeros((0, 7))
        self._assigned: Dict[int, str] = {}
        self._draw_plan()

    def assign(self, drone_of_camera: Dict[int, str]) -> None:
        """Colour camera i by the drone ``drone_of_camera[i]`` that flies it."""
        self._assigned = dict(drone_of_camera)
        self._draw_plan()

    def _draw_plan(self) -> None:
        with self._lock:
            self._draw_plan_locked()

    def _draw_plan_locked(self) -> None:
        for handle in self.frustums:
            handle.remove()
        cams = self._cameras
        wxyz, pos = frustum_poses(cams)
        fov = 2.0 * self.model.half_fov_vertical
        self.frustums = []
        for i in range(len(cams)):
            drone = self._assigned.get(i, "")
            self.frustums.append(self.server.scene.add_camera_frustum(
                f"/plan/cam_{i}", fov=fov, aspect=self.model.width / self.model.height, scale=0.25,
                color=self._color_of(drone) if drone else UNASSIGNED, wxyz=wxyz[i], position=pos[i]))
        flown = ", ".join(f"cam {i}: {d}" for i, d in sorted(self._assigned.items()))
        self.plan_info.content = f"**plan**: {len(cams)} cameras" + (f" ({flown})" if flown else "")

    def show_drone(self, name: str, position: Sequence[float]) -> None:
        xyz = tuple(float(c) for c in position)
        with self._lock:
            if name in self.drones:
                self.drones[name].position = xyz
            else:
                self.drones[name] = self.server.scene.add_icosphere(
                    f"/drones/{name}", radius=0.08, color=self._color_of(name), position=xyz)

    def show_reconstruction(self, points: np.ndarray, realization: Optional[np.ndarray]) -> None:
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        real = np.zeros(len(pts), np.int64) if realization is None else np.asarray(realization, np.int64)
        self._recon = (pts, real)
        self._redraw_clouds()

    # -------------------------------------------------------------- drawing
    def _color_of(self, drone: str) -> tuple:
        if drone not in self._drone_colors:
            self._drone_colors[drone] = PALETTE[len(self._drone_colors) % len(PALETTE)]
        return self._drone_colors[drone]

    def _redraw_clouds(self) -> None:
        with self._lock:
            self._redraw_clouds_locked()

    def _redraw_clouds_locked(self) -> None:
        k = int(self.realization.value)
        notes = []
        truth = None
        if self._scene is not None:
            pts, cols, real = self._scene
            sel = real == k
            truth = pts[sel]
            idx = _subsample(len(truth), self.max_points)
            self.server.scene.add_point_cloud("/scene", truth[idx], cols[sel][idx], point_size=0.004)
            notes.append(f"scene: realization {k}, {len(idx)} of {len(truth)} points shown"
                         + (" (downsampled)" if len(idx) < len(truth) else ""))
        if self._recon is not None:
            pts, real = self._recon
            mine = pts[real == k]
            reference, against = (truth, "the truth") if truth is not None and len(truth) else (None, "")
            if reference is None and self._scene is not None:
                reference, against = self._scene[0], "the prior (all realizations)"
            if len(mine):
                idx = _subsample(len(mine), self.max_points)
                if reference is not None and len(reference):
                    colors, d = distance_colors(mine[idx], reference, self.distance_scale)
                    notes.append(f"reconstruction: {len(idx)} of {len(mine)} points"
                                 + (" (downsampled)" if len(idx) < len(mine) else "") + ", coloured by distance to "
                                 f"{against} (blue 0 to red >= {self.distance_scale * 100:g} cm), median "
                                 f"{np.median(d) * 100:.2f} cm")
                else:
                    colors = np.tile(np.array(PALETTE[0], np.uint8), (len(idx), 1))
                    notes.append(f"reconstruction: {len(idx)} of {len(mine)} points")
                self.server.scene.add_point_cloud("/reconstruction", mine[idx], colors, point_size=0.005)
                if reference is not None and len(reference):
                    far, _ = cKDTree(mine).query(reference, k=1)
                    gap = reference[far > self.distance_scale]
                    gidx = _subsample(len(gap), self.max_points)
                    self.server.scene.add_point_cloud("/uncovered", gap[gidx], np.array(UNCOVERED, np.uint8),
                                                      point_size=0.006)
                    notes.append(f"uncovered (magenta): {len(gap)} of {len(reference)} truth points "
                                 f"farther than {self.distance_scale * 100:g} cm")
            else:
                notes.append(f"reconstruction: none for realization {k}")
        self.status.content = "\n\n".join(notes) or "waiting for the scene"

    def close(self) -> None:
        self.server.stop()


# ------------------------------------------------------------------ offline: a run folder
def _last_messages(path: Path) -> tuple[Dict[str, object], bool]:
    """(topic -> its latest decoded message in an MCAP file, whether the file was cut: its writer
    killed before it closed; :func:`vp_recon.recording.read_messages` reads it up to then);
    ViewerError when unreadable."""
    from mcap.exceptions import EndOfFile, McapError
    from mcap_ros2.decoder import DecoderFactory

    from .recording import is_closed, read_messages

    last: Dict[str, object] = {}
    try:
        for _schema, channel, _message, decoded in read_messages(path, [DecoderFactory()]):
            last[channel.topic] = decoded
    except EndOfFile:
        if last:
            return last, True
        raise ViewerError(f"{path}: not a readable MCAP recording (it ends before its first message)") from None
    except (McapError, EOFError, ValueError, KeyError, OSError) as exc:
        raise ViewerError(f"{path}: not a readable MCAP recording ({type(exc).__name__}: {exc})") from exc
    except Exception as exc:  # noqa: BLE001 - a corrupt file can fail anywhere in the decoders
        raise ViewerError(f"{path}: not a readable MCAP recording ({type(exc).__name__}: {exc})") from exc
    return last, not is_closed(path)


def _poses(msg) -> np.ndarray:
    return np.array([[p.position.x, p.position.y, p.position.z, p.orientation.x, p.orientation.y,
                      p.orientation.z, p.orientation.w] for p in msg.poses], dtype=np.float64).reshape(-1, 7)


def load_run(run_folder: Path) -> Dict[str, object]:
    """topic -> latest message of a run folder's recording; ViewerError (one line) when it has none
    or it cannot be read; a recording cut by a kill is read up to then, with a one-line note on
    stderr."""
    path = Path(run_folder) / "run.mcap"
    if not Path(run_folder).is_dir():
        raise ViewerError(f"{run_folder}: no such run folder")
    if not path.is_file():
        raise ViewerError(f"{run_folder}: no recording (run.mcap); make run writes one")
    last, cut = _last_messages(path)
    if not last:
        raise ViewerError(f"{path}: the recording holds no messages")
    if cut:
        print(f"viewer: note: {path} was cut (its recorder was killed): what it holds up to then is shown",
              file=sys.stderr, flush=True)
    return last


#: The order in which a recording's latest messages are shown (the plan before its assignment).
_ORDER = ("/scene/noisy_points", "/camera_plan", "/fleet/assignment", "/reconstruction/points")


def show_message(viewer: PlanViewer, topic: str, msg) -> bool:
    """Show one message of the run (a ROS message, or one decoded from MCAP: same fields) on
    ``viewer``; False for a topic the viewer does not draw. One home for the live node and replay."""
    from vp_scene.cloud import pointcloud2_to_numpy

    if topic == "/scene/noisy_points":
        viewer.show_scene(*pointcloud2_to_numpy(msg))
    elif topic == "/camera_plan":
        viewer.show_plan(_poses(msg))  # poses: a camera's roll is drawn
    elif topic == "/fleet/assignment":
        if getattr(msg, "error_code", 0) == 0:
            viewer.assign({int(e.pose_index): e.drone for e in msg.entries})
    elif topic == "/reconstruction/points":
        pts, _cols, real = pointcloud2_to_numpy(msg)
        viewer.show_reconstruction(pts, real)
    elif topic.endswith("/pose") and topic.count("/") == 2:
        pose = msg.pose.pose if hasattr(msg.pose, "pose") else msg.pose  # Odometry or PoseStamped
        viewer.show_drone(topic.split("/")[1], (pose.position.x, pose.position.y, pose.position.z))
    else:
        return False
    return True


def replay_recording(viewer: PlanViewer, last: Dict[str, object]) -> None:
    """Show the latest state of a recorded run (topic -> message, :func:`load_run`)."""
    for topic in sorted(last, key=lambda t: (_ORDER.index(t) if t in _ORDER else len(_ORDER), t)):
        show_message(viewer, topic, last[topic])


def main(argv: Optional[list] = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m vp_recon.viewer",
                                 description="Show a recorded run (its run.mcap) in the browser (viser, 127.0.0.1).")
    ap.add_argument("run_folder", help="a make run output folder (holds run.mcap)")
    ap.add_argument("--port", type=int, default=8080)
    ap.add_argument("--max-points", type=int, default=60000, help="points shown per cloud (random subset)")
    ap.add_argument("--seconds", type=float, default=math.inf, help="serve this long, then exit (default: until Ctrl-C)")
    args = ap.parse_args(argv)
    if not 1 <= args.port <= 65535 or args.max_points < 1:
        ap.error("--port must be in 1..65535 and --max-points >= 1")
    viewer = None
    try:
        last = load_run(Path(args.run_folder))  # bad input is reported before any server starts
        viewer = PlanViewer(port=args.port, max_points=args.max_points)
        replay_recording(viewer, last)
        print(f"viewer: {viewer.url} (Ctrl-C to stop)", flush=True)
        end = time.monotonic() + args.seconds
        while time.monotonic() < end:
            time.sleep(min(0.5, max(0.0, end - time.monotonic())))
        return EXIT_OK
    except ViewerError as exc:
        print(f"error: {exc}", file=sys.stderr, flush=True)
        return EXIT_USAGE
    except KeyboardInterrupt:
        return EXIT_OK
    finally:
        if viewer is not None:
            viewer.close()


if __name__ == "__main__":
    sys.exit(main())
