#!/usr/bin/env python3
"""The viewer under load: 16 camera frustums and a 300k-point reconstruction in a real browser.

Issue "See it and keep it" asks the viewer to handle 16 frustums and a 300k-point reconstruction
smoothly. This benchmark starts :class:`vp_recon.viewer.PlanViewer` (viser, 127.0.0.1), gives it a
scene (the six_rect procedural scene: 6 plants, K = 5 wind realizations), a 16-camera plan and a
300,000-point reconstruction, and opens the page in Debian's headless chromium (selenium, software
WebGL: no GPU here, so every frame figure is a lower bound of what a desktop with a GPU draws).
For each display cap (``--caps``: points drawn per cloud, a random subset, said in the GUI) it
measures

- the server's seconds for ``show_scene``, ``show_plan`` (16 frustums) and ``show_reconstruction``
  (the colouring by distance to the truth and the uncovered points included),
- the page's seconds until the plan and the reconstruction are on it,
- frame intervals in the page (``requestAnimationFrame`` over ``--seconds`` s while the view
  orbits the scene: every frame draws the clouds and the frustums): median, 95th percentile, fps.

Writes ``results/bench_viewer.json`` and ``.md``. A cap that fails (page never shows the cloud,
browser error) is recorded with its error, never dropped. Needs /usr/bin/chromium + chromedriver.
"""
from __future__ import annotations

import argparse
import json
import os
import socket
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

if not __package__:  # python bench/bench_viewer.py: as python -m bench.bench_viewer (bench/_script.py)
    import _script  # noqa: F401
from bench.browser import CHROMIUM, headless_chromium, wait_page, wait_text  # noqa: E402
from bench.common import ROOT, machine, write_report  # noqa: E402

#: Counts requestAnimationFrame callbacks for ``seconds`` and returns the intervals (ms).
FRAME_PROBE = """
const seconds = arguments[0], done = arguments[arguments.length - 1];
const stamps = [];
function tick(t) { stamps.push(t); if (t - stamps[0] < seconds * 1000) requestAnimationFrame(tick);
                   else done(stamps.slice(1).map((s, i) => s - stamps[i])); }
requestAnimationFrame(tick);
"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_data(num_cameras: int, num_points: int, seed: int = 0):
    """(scene points, colors, realization index, cameras (M, 6), reconstruction (R, 3)): the
    six_rect procedural scene, ``num_cameras`` on a ring around it, and a reconstruction of
    realization 0 with ``num_points`` points (the truth resampled with 5 mm noise)."""
    from vp_scene.build import build_noisy_scene
    from vp_scene.camera import look_at

    ns, _ = build_noisy_scene(scenario="six_rect", seed=seed)
    K, P, _ = ns.points.shape
    pts = ns.points.reshape(-1, 3)
    real = np.repeat(np.arange(K), P)
    colors = np.tile(np.array([[60, 150, 60]], np.uint8), (len(pts), 1))
    centre = ns.points[0].mean(axis=0)
    a = np.linspace(0.0, 2 * np.pi, num_cameras, endpoint=False)
    ring = np.stack([centre[0] + 2.5 * np.cos(a), centre[1] + 2.5 * np.sin(a), np.full(num_cameras, 1.8)], -1)
    cams = look_at(ring, centre)
    rng = np.random.default_rng(seed)
    recon = ns.points[0][rng.integers(0, P, num_points)] + rng.normal(0.0, 0.005, (num_points, 3))
    return pts, colors, real, cams, recon


def measure(cap: int, data, seconds: float, timeout: float) -> dict:
    from vp_recon.viewer import PlanViewer

    pts, colors, real, cams, recon = data
    rec: dict = {'cap': cap, 'frustums': len(cams), 'reconstruction_points': len(recon),
                 'load_average_1min': round(os.getloadavg()[0], 2)}  # the machine is shared: say how busy
    viewer = PlanViewer(port=free_port(), max_points=cap)
    try:
        t = time.perf_counter()
        viewer.show_scene(pts, colors, real)
        rec['server_scene_s'] = time.perf_counter() - t
        t = time.perf_counter()
        viewer.show_plan(cams)
        rec['server_plan_s'] = time.perf_counter() - t
        t = time.perf_counter()
        viewer.show_reconstruction(recon, np.zeros(len(recon), np.int64))
        rec['server_reconstruction_s'] = time.perf_counter() - t
        with headless_chromium() as driver:
            driver.set_script_timeout(seconds + 60)
            t = time.monotonic()
            wait_page(driver, viewer.url, timeout)
            wait_text(driver, f"plan: {len(cams)} cameras", timeout)
            shown = min(cap, len(recon))
            wait_text(driver, f"reconstruction: {shown} of {len(recon)} points", timeout)
            rec['page_ready_s'] = time.monotonic() - t
            time.sleep(2.0)  # the clouds' first upload to the GPU (software WebGL) is not a frame of use
            # orbit the view from the server while the page counts its frames
            centre = pts.mean(axis=0)
            clients = list(viewer.server.get_clients().values())
            stop = time.monotonic() + seconds + 5
            import threading

            def orbit() -> None:
                phi = 0.0
                while time.monotonic() < stop:
                    phi += 0.05
                    for c in clients:
                        c.camera.position = (centre[0] + 5 * np.cos(phi), centre[1] + 5 * np.sin(phi), 3.0)
                        c.camera.look_at = tuple(centre)
                    time.sleep(1 / 30)
            mover = threading.Thread(target=orbit, daemon=True)
            mover.start()
            intervals = np.asarray(driver.execute_async_script(FRAME_PROBE, seconds), float)
            stop = 0.0
            mover.join(5)
        rec.update(frames=int(len(intervals)), frame_ms_median=float(np.median(intervals)),
                   frame_ms_p95=float(np.percentile(intervals, 95)),
                   fps=float(1000.0 * len(intervals) / max(intervals.sum(), 1e-9)))
    except Exception as exc:  # noqa: BLE001 - a failed cap is a result, recorded with its error
        rec.update(error=type(exc).__name__, error_msg=str(exc).splitlines()[0][:300])
    finally:
        viewer.close()
    return rec


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--cameras', type=int, default=16)
    ap.add_argument('--points', type=int, default=300_000)
    ap.add_argument('--caps', type=int, nargs='+', default=[60_000, 300_000],
                    help='points drawn per cloud (the viewer default is 60000)')
    ap.add_argument('--seconds', type=float, default=8.0, help='frame-counting window')
    ap.add_argument('--timeout', type=float, default=180.0)
    ap.add_argument('--out', default=str(ROOT / 'results'))
    args = ap.parse_args(argv)
    if not CHROMIUM.exists():
        raise SystemExit(f'{CHROMIUM} is absent (Debian package chromium): nothing measured')
    data = test_data(args.cameras, args.points)
    runs = []
    for cap in args.caps:
        rec = measure(cap, data, args.seconds, args.timeout)
        runs.append(rec)
        print(json.dumps(rec), flush=True)
    stamp = datetime.now(timezone.utc).strftime('%Y-%m-%d')
    failed = sum(1 for r in runs if 'error' in r)
    result = {'date': stamp, 'machine': machine(), 'browser': 'chromium headless, software WebGL (no GPU)',
              'scene_points': int(len(data[0])), 'cameras': args.cameras, 'reconstruction_points': args.points,
              'failed': failed, 'runs': runs}
    out = Path(args.out)
    write_report(out / 'bench_viewer.json', result)
    lines = [f'# Viewer under load, measured {stamp} ({machine()})', '',
             f'{args.cameras} frustums, scene {len(data[0])} points (6 plants x K realizations), reconstruction '
             f'{args.points} points; headless chromium with software WebGL (no GPU: a lower bound). '
             f'Failed: {failed} of {len(runs)}.', '',
             '| points drawn per cloud | server: scene / plan / reconstruction (s) | page ready (s) | '
             'frame median / p95 (ms) | fps | load average |', '|---|---|---|---|---|---|']
    for r in runs:
        if 'error' in r:
            lines.append(f"| {r['cap']} | failed: {r['error']}: {r['error_msg']} | | | | {r['load_average_1min']} |")
            continue
        lines.append(f"| {r['cap']} | {r['server_scene_s']:.2f} / {r['server_plan_s']:.2f} / "
                     f"{r['server_reconstruction_s']:.2f} | {r['page_ready_s']:.1f} | "
                     f"{r['frame_ms_median']:.1f} / {r['frame_ms_p95']:.1f} | {r['fps']:.1f} | "
                     f"{r['load_average_1min']} |")
    (out / 'bench_viewer.md').write_text('\n'.join(lines) + '\n')
    print('\n'.join(lines))
    return 0


if __name__ == '__main__':
    sys.exit(main())
