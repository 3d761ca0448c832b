#!/usr/bin/env python3
"""A benchmark on real photographs (issue 41, part 4): the planner chooses among a scan's views.

Any flight folder (``--scan``: images + poses.csv or COLMAP's text model; README "From a real
flight") is a candidate set: a rig's stops, a gantry's positions, a flight's images.

1. The reference: the reconstruction of all its views (dense; no truth exists).
2. The prior: a first pass of 12 evenly spaced views (:func:`first_pass_views`: evenly spaced in
   azimuth about the point the views look at), reconstructed, its largest connected part kept
   (:func:`clean_prior`: a first pass keeps specks of background), written as ``prior.ply``: the
   planning cloud.
3. For every N of ``--ns`` (6, 8, 12): each method's plan among the views
   (``python -m vp_planner.cli --candidates``'s planning: :func:`vp_planner.optimizers.plan_views`
   with the candidates, on the prior, the default reward; a method with simulated flights, egp,
   flies them over the first pass as step 5 does, on ``--workers`` local Dask workers) and
   ``--random`` random subsets (20),
   each reconstructed with the prior (crop box, pairs, masks) and scored against the reference:
   Chamfer x100 in the folder's frame (``chamfer``) and after a rigid ICP onto the reference
   (``shape``); a failure is counted with its reason (ranked last).
4. Spearman's rho of the default reward against -Chamfer over all those plans (a failure ranks
   last), and the bars: egp's Chamfer at most the evenly spaced plan's (``circle``), and at most
   every other method's, for each N.
5. The simulated flight of every plan (:func:`flight_record`): the first pass's cloud meshed as the
   world meshes a scanned plant and photographed from the plan's candidate poses (the rig's
   camera, its backdrop a blue screen, no wind, no ground markers), reconstructed at the real
   reconstruction's setting and scored against that cloud: how well its map Chamfer ranks the
   real photographs' reconstructions of the same subsets (Spearman, failures last).

Records are cached under ``<out>/cache/real/<scan>/`` (one file a subset: a subset two methods chose
is reconstructed once); the report is ``<out>/real/<scan>.json`` and ``.md``.

    python -m bench.bench_real --scan FOLDER [--ns 6 8 12] [--methods egp circle arc sa random]
        [--random 20] [--evaluations 100] [--threads 2] [--workers 2] [--out results]
"""
from __future__ import annotations

import argparse
import math
import time
from contextlib import nullcontext
from pathlib import Path

import numpy as np

if not __package__:  # python bench/bench_real.py: as python -m bench.bench_real (bench/_script.py)
    import _script  # noqa: F401
from vp_scene.limits import seed_arg  # noqa: E402
from bench.cache import cached  # noqa: E402
from bench.options import parser  # noqa: E402
from bench.publish import machine, num, publish, table  # noqa: E402
from bench.stats import spearman, summary  # noqa: E402

NS = (6, 8, 12)
METHODS = ('egp', 'circle', 'arc', 'sa', 'random')
#: views of the first pass (the prior)
PRIOR_VIEWS = 12
#: the label of a plan drawn at random (not a planning method: none of the registry's entries)
RANDOM_SUBSET = 'random subset'


def parse_args(argv=None) -> argparse.Namespace:
    ap = parser(__doc__, 'threads', 'out', threads=2)
    ap.add_argument('--scan', type=Path, required=True, help='a flight folder (README "From a real flight")')
    ap.add_argument('--ns', type=int, nargs='+', default=list(NS), help='plan sizes N')
    ap.add_argument('--methods', nargs='+', default=list(METHODS))
    ap.add_argument('--random', type=int, default=20, help='random subsets a size')
    ap.add_argument('--evaluations', type=int, default=100, help='reward evaluations of a plan')
    ap.add_argument('--initial', type=int, default=50, help="egp's initial design")
    ap.add_argument('--seed', type=seed_arg, default=0)
    ap.add_argument('--workers', type=int, default=2, help="the local Dask workers egp's planning flights fly on")
    args = ap.parse_args(argv)
    if args.workers < 1:
        ap.error(f'--workers must be >= 1, got {args.workers}')
    from vp_planner.methods import BY_NAME

    bad = [m for m in args.methods if m not in BY_NAME or BY_NAME[m].candidates is None]
    if bad:
        ap.error(f'methods without a candidates mode: {bad}')
    if not args.scan.is_dir():
        ap.error(f'--scan {args.scan}: not a folder')
    return args


def look_at_point(cameras: np.ndarray) -> np.ndarray:
    """The point nearest to every camera's optical axis (least squares): what a scan looks at."""
    c, v = cameras[:, :3], cameras[:, 3:] / np.linalg.norm(cameras[:, 3:], axis=1, keepdims=True)
    P = np.eye(3)[None] - v[:, :, None] * v[:, None, :]          # projectors orthogonal to each axis
    return np.linalg.lstsq(P.sum(axis=0), np.einsum('nij,nj->i', P, c), rcond=None)[0]


def first_pass_views(cameras: np.ndarray, n: int = PRIOR_VIEWS) -> list[int]:
    """n of the views evenly spaced in azimuth about the point they look at (``circle``'s subset
    of the candidates, :func:`vp_planner.candidates.evenly_spaced`, its first phase)."""
    from vp_planner.candidates import CandidateSpace, evenly_spaced

    space = CandidateSpace(cameras, min(n, len(cameras)), look_at_point(cameras)[None, None])
    return [int(i) for i in evenly_spaced(space, 1)[0]]


def clean_prior(points: np.ndarray, k: int = 8) -> np.ndarray:
    """The indices of the largest connected part of a cloud: points joined when closer than 4
    times the median distance to their ``k``-th nearest neighbour (a first pass keeps specks of
    background, a cloth fold, a pot's rim, apart from the plant): Open3D's DBSCAN with one point a
    core (its clusters are the connected parts of that radius graph)."""
    import open3d as o3d
    from scipy.spatial import cKDTree

    if len(points) < k + 2:
        return np.arange(len(points))
    d, _ = cKDTree(points).query(points, k=k + 1)
    radius = 4.0 * float(np.median(d[:, -1]))
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, dtype=np.float64)))
    labels = np.asarray(cloud.cluster_dbscan(eps=radius, min_points=1))
    return np.flatnonzero(labels == np.argmax(np.bincount(labels)))


#: The rig's capture as a simulated flight flies it: the camera where the rig says (no hover
#: error), its poses refined to about 2 mm and 0.1 degree, the camera's sensor noise, no markers.
RIG_CAPTURE = dict(hover_position_sigma=0.0, hover_attitude_sigma=0.0, report_position_sigma=0.002,
                   report_attitude_sigma=0.1, gcp_markers=0)


def rig_flights(prior_model, size: tuple, fov: float, client=None):
    """The simulated flights of plans among the scan's views over its first pass (module docstring,
    step 5): a :class:`vp_recon.sim_flights.SceneFlights` of the first pass's cloud meshed as the
    world meshes a scanned plant, no wind, the rig's capture (:data:`RIG_CAPTURE`), its backdrop a
    blue screen, reconstructed at the real reconstruction's setting; ``client``: the Dask client
    egp's planning flies on (None: in this process)."""
    from vp_recon.sim_flights import SceneFlights
    from vp_scene.capture import CaptureModel
    from vp_scene.flights import FlightSettings
    from vp_scene.scenario import scene_of_cloud
    from vp_scene.wind import WindConfig

    settings = FlightSettings(width=int(size[0]), height=int(size[1]), sift_first_octave=-1, dense_scale=1.0)
    return SceneFlights(scene_of_cloud(prior_model.points, prior_model.colors), WindConfig(variance=0.0), settings,
                        CaptureModel.named('realistic', **RIG_CAPTURE), client=client, fov=fov, ground=False)


def flight_record(prior_model, cams: np.ndarray, idx: list, index: int, seed: int, size: tuple, fov: float) -> dict:
    """One plan's simulated flight over the first pass (:func:`rig_flights`): its
    :class:`vp_scene.flights.FlightScore` as a dict (map Chamfer x100 as ``chamfer``), flight
    ``index`` of a planning run of ``seed`` (the planner's draws)."""
    from vp_scene.flights import flight_draws

    draw = flight_draws(seed, 1, 0.0, start=index)[0]
    rec = rig_flights(prior_model, size, fov).fly([cams[sorted(idx)]], [draw])[0].to_dict()
    for key in ('chamfer', 'chamfer_shape'):
        rec[key] = None if rec[key] is None else 100.0 * rec[key]
    return rec


def spearman_of(rewards: list, chamfers: list) -> float:
    """Spearman's rho of the rewards against -Chamfer (a failure, None: Chamfer inf, ranked last)."""
    return spearman([float(r) for r in rewards], [-(math.inf if c is None else float(c)) for c in chamfers])


def reconstruct(views, config, prior=None, reference=None) -> dict:
    """One subset's reconstruction record: no-truth metrics, and with a reference the Chamfer
    x100 in the folder's frame and after ICP; a failure: its code name and message."""
    from vp_recon.metrics import chamfer, chamfer_after_icp
    from vp_recon.pipeline import ReconError, reconstruct_views

    t0 = time.perf_counter()
    try:
        vr = reconstruct_views(views, config, prior=prior)
    except ReconError as exc:
        return {'error': exc.name, 'error_msg': str(exc), 'seconds': time.perf_counter() - t0}
    rec = {'registered': int(vr.sparse.registered), 'images': len(views.names), 'points': len(vr.points),
           'sparse_points': len(vr.sparse.points), 'cloud': vr.source,
           'mean_reprojection_error': vr.sparse.mean_reprojection_error,
           'mean_track_length': vr.sparse.mean_track_length,
           'coverage_of_prior': vr.coverage.fraction if vr.coverage is not None else None,
           'mask': vr.mask.method if vr.mask is not None else None, 'seconds': time.perf_counter() - t0}
    if reference is not None:
        if len(vr.points) == 0:
            return {**rec, 'error': 'RECONSTRUCTION_FAILED', 'error_msg': 'the reconstruction is empty'}
        rec['chamfer'] = chamfer(vr.points, reference).chamfer * 100.0
        rec['shape'] = chamfer_after_icp(vr.points, reference).chamfer * 100.0
    rec['_cloud'] = (vr.points, vr.colors)
    return rec


def run(args: argparse.Namespace) -> dict:
    from vp_planner.optimizers import plan_views
    from vp_planner.request import PlanRequest
    from vp_planner.reward_models import DEFAULT_REWARD_MODEL, REWARD_MODELS, make_reward
    from vp_recon.cli import select_views
    from vp_recon.flight import read_flight
    from vp_recon.outputs import write_ply
    from vp_recon.pipeline import Prior, ReconConfig
    from vp_scene.camera import CameraModel, poses_to_cameras
    from vp_scene.cluster import open_client
    from vp_scene.ply import load_ply, load_points

    def flown(done: int, total: int, score) -> None:
        print(f'planning flight {done}/{total}: ' + (f'failed ({score.reason[:80]})' if score.failed else
                                                         f'chamfer x100 {100 * score.chamfer:.3f}, '
                                                         f'{score.seconds:.0f} s'), flush=True)

    scan = args.scan.resolve()
    cache = Path(args.out) / 'cache' / 'real' / scan.name
    cache.mkdir(parents=True, exist_ok=True)
    views = read_flight(scan, max_megapixels=math.inf)
    names = list(views.names)
    rep = np.asarray(views.reported, dtype=np.float64)
    cams = poses_to_cameras(rep) if rep.shape[1] == 7 else rep
    config = ReconConfig(width=views.size[0], height=views.size[1], fov=views.horizontal_fov, num_threads=args.threads)

    def subset_record(idx: list, kind: str, prior=None, reference=None) -> dict:
        idx = sorted(int(i) for i in idx)
        path = cache / f'{kind}-{"-".join(map(str, idx))}.json'
        ply = path.with_suffix('.ply')

        def compute() -> dict:
            rec = reconstruct(select_views(views, [names[i] for i in idx]), config, prior, reference)
            cloud = rec.pop('_cloud', None)
            if cloud is not None and kind != 'subset':
                write_ply(ply, *cloud)
            return {**rec, 'indices': idx}
        rec = cached(path, compute)
        print(f'{kind} {len(idx)} views: ' + (rec.get('error') or f'{rec["registered"]} registered, '
                                              f'{rec["points"]} points, chamfer {rec.get("chamfer")}'), flush=True)
        return rec

    t_all = time.perf_counter()
    ref_rec = subset_record(list(range(len(names))), 'reference')
    if 'error' in ref_rec:
        raise SystemExit(f'{scan}: the reference (all {len(names)} views) failed: {ref_rec["error_msg"]}')
    reference = load_points(cache / f'reference-{"-".join(map(str, range(len(names))))}.ply')
    first = first_pass_views(cams)
    prior_rec = subset_record(first, 'prior')
    if 'error' in prior_rec:
        raise SystemExit(f'{scan}: the first pass ({len(first)} views) failed: {prior_rec["error_msg"]}')
    raw = load_points(cache / f'prior-{"-".join(map(str, sorted(first)))}.ply')
    keep = clean_prior(raw)
    prior_points = raw[keep]
    write_ply(cache / 'prior.ply', prior_points)
    prior = Prior(points=prior_points, plant=np.zeros(len(prior_points), np.int64))
    fov, size = views.horizontal_fov, views.size

    first_pass = load_ply(cache / f'prior-{"-".join(map(str, sorted(first)))}.ply')
    prior_model = type(first_pass)('prior', first_pass.points[keep], first_pass.colors[keep])

    plans = []
    for n in args.ns:
        for method in args.methods:
            q = PlanRequest.of(method, n, evaluations=args.evaluations,
                               initial_evaluations=min(args.initial, args.evaluations), seed=args.seed,
                               candidates=cams, fov=fov, image_size=size)
            n_flights = q.flights.flights_of(method)

            def plan(q=q, n_flights=n_flights) -> dict:
                with open_client('local', args.workers, quiet=True) if n_flights else nullcontext() as client:
                    sim = rig_flights(prior_model, size, fov, client) if n_flights else None
                    res = plan_views(q, prior_points[None], simulator=sim, on_flight=flown)
                return {'selected': res.selected, 'reward': res.reward, 'evaluations': res.evaluations,
                        'seconds': res.seconds, 'chosen_by': res.chosen_by, 'flight_score': res.flight_score,
                        'flights': res.flights, 'flights_note': res.flights_note}
            tag = f'-f{n_flights}' if n_flights else ''
            p = cached(cache / f'plan-{method}-n{n}-e{args.evaluations}-s{args.seed}{tag}.json', plan)
            plans.append({'n': n, 'method': method, 'selected': p['selected'], 'reward': p['reward'],
                          'planning_seconds': p['seconds'], 'chosen_by': p.get('chosen_by'),
                          'planning_flights': len(p.get('flights') or [])})
        rng = np.random.default_rng([args.seed, n])
        reward = make_reward(DEFAULT_REWARD_MODEL, prior_points[None], fov, image=CameraModel(*size, fov))
        for j in range(args.random):
            sel = sorted(int(i) for i in rng.choice(len(names), n, replace=False))
            plans.append({'n': n, 'method': RANDOM_SUBSET, 'draw': j, 'selected': sel,
                          'reward': float(reward(cams[sel][None])[0])})
    gaps = wide_gaps(cams, prior_points, fov, size)
    for model in REWARD_MODELS:  # every reward model's value of every plan (the variants of the Spearman bar)
        score = make_reward(model, prior_points[None], fov, image=CameraModel(*size, fov))
        for p in plans:
            p.setdefault('rewards', {})[model] = float(score(cams[sorted(p['selected'])][None])[0])
    for j, p in enumerate(plans):
        rec = subset_record(p['selected'], 'subset', prior, reference)
        p.update({k: rec.get(k) for k in ('registered', 'points', 'chamfer', 'shape', 'coverage_of_prior', 'error',
                                          'error_msg', 'seconds', 'mask')})
        p['images'] = [names[i] for i in sorted(p['selected'])]
        sel = sorted(int(i) for i in p['selected'])
        p['flight'] = cached(cache / f'flight-{"-".join(map(str, sel))}.json',
                             lambda: flight_record(prior_model, cams, sel, j, args.seed, size, fov))
        print(f'flight of {len(sel)} views: ' + (p['flight']['reason'][:80] if p['flight']['failed'] else
                                                 f'chamfer {p["flight"]["chamfer"]:.3f}'), flush=True)
    return {'scan': scan.name, 'folder': str(scan), 'views': len(names), 'image_size': list(size), 'fov': fov,
            'reward_model': DEFAULT_REWARD_MODEL, 'ns': args.ns, 'methods': args.methods, 'random': args.random,
            'evaluations': args.evaluations, 'seed': args.seed, 'machine': machine(),
            'date': time.strftime('%Y-%m-%d'),
            'reference': {k: v for k, v in ref_rec.items() if k != 'indices'},
            'prior': {**{k: v for k, v in prior_rec.items() if k != 'indices'}, 'views': [names[i] for i in first],
                      'points_kept': int(len(prior_points)), 'points_first_pass': int(len(raw))},
            'plans': plans, 'analysis': analyse(plans, args.ns), 'wide_gaps': gaps,
            'seconds': time.perf_counter() - t_all}


def wide_gaps(cams: np.ndarray, prior_points: np.ndarray, fov: float, size: tuple) -> dict:
    """The default reward of the evenly spaced plans of 6 to 30 views and of 10 neighbouring ones
    (few views far apart can fail where more work: does the reward know?); not reconstructed."""
    from vp_planner.candidates import CandidateSpace, evenly_spaced, neighbours
    from vp_planner.reward_models import DEFAULT_REWARD_MODEL, make_reward
    from vp_scene.camera import CameraModel

    reward = make_reward(DEFAULT_REWARD_MODEL, prior_points[None], fov, image=CameraModel(*size, fov))
    out = {}
    for n in (6, 8, 10, 12, 20, 30):
        if n <= len(cams):
            space = CandidateSpace(cams, n, prior_points[None])
            out[f'evenly {n}'] = float(reward(cams[evenly_spaced(space, 1)[0]][None])[0])
            if n == 10:
                out['neighbours 10'] = max(float(reward(cams[s][None])[0]) for s in neighbours(space, len(cams)))
    return out


def analyse(plans: list, ns: list) -> dict:
    """Spearman over all plans, and per N: each method's Chamfer and the random subsets' summary,
    the bar egp <= circle."""
    out = {'spearman_reward_vs_minus_chamfer': spearman_of([p['reward'] for p in plans],
                                                           [p.get('chamfer') for p in plans]),
           'spearman_reward_vs_minus_shape': spearman_of([p['reward'] for p in plans],
                                                         [p.get('shape') for p in plans]),
           'plans': len(plans), 'failed': sum(1 for p in plans if p.get('error')), 'by_n': {},
           'spearman_by_reward_model': {m: spearman_of([p['rewards'][m] for p in plans], [p.get('chamfer') for p in plans])
                                        for m in (plans[0].get('rewards') or {}) if plans}}
    flown = [p for p in plans if p.get('flight')]
    if flown:  # the simulated flight's map Chamfer as a predictor (a failed flight ranks last)
        def minus_flight(p: dict) -> float:
            return -math.inf if p['flight']['failed'] else -float(p['flight']['chamfer'])
        out['spearman_flight_vs_minus_chamfer'] = spearman_of([minus_flight(p) for p in flown],
                                                              [p.get('chamfer') for p in flown])
        out['spearman_flight_vs_minus_shape'] = spearman_of([minus_flight(p) for p in flown],
                                                            [p.get('shape') for p in flown])
        out['flights'] = len(flown)
        out['flights_failed'] = sum(1 for p in flown if p['flight']['failed'])
    for n in ns:
        here = [p for p in plans if p['n'] == n]
        rand = [p for p in here if p['method'] == RANDOM_SUBSET]
        by = {p['method']: p for p in here if p['method'] != RANDOM_SUBSET}
        egp, circle = by.get('egp'), by.get('circle')
        bar = None
        if egp is not None and circle is not None:
            ce, cc = egp.get('chamfer'), circle.get('chamfer')
            bar = ce is not None and (cc is None or ce <= cc)
        others = [p.get('chamfer') for m, p in by.items() if m != 'egp']
        lowest = None
        if egp is not None and others:  # a failed plan (None) is beaten by any reconstruction
            ce = egp.get('chamfer')
            lowest = ce is not None and all(c is None or ce <= c for c in others)
        out['by_n'][str(n)] = {
            'random': {'chamfer': summary({i: p.get('chamfer') for i, p in enumerate(rand)}),
                       'shape': summary({i: p.get('shape') for i, p in enumerate(rand)}),
                       'failures': sorted({p['error'] for p in rand if p.get('error')})},
            'spearman': spearman_of([p['reward'] for p in here], [p.get('chamfer') for p in here]),
            'egp_at_most_circle': bar, 'egp_lowest': lowest}
    return out


def _yes(b) -> str:
    return "yes" if b else "no" if b is not None else "-"


def markdown(data: dict) -> str:
    a = data['analysis']
    lines = [f'# Real photographs: {data["scan"]}', '',
             f'{data["views"]} views ({data["image_size"][0]} x {data["image_size"][1]}) of `{data["scan"]}`. Reference: '
             f'the reconstruction of all of them ({data["reference"].get("registered")} registered, '
             f'{data["reference"].get("points")} points); prior: a first pass of {len(data["prior"]["views"])} evenly '
             f'spaced views ({data["prior"].get("registered")} registered, {data["prior"]["points_kept"]} of '
             f'{data["prior"]["points_first_pass"]} points kept as its largest connected part). Each plan chooses N of '
             f'the views ({data["evaluations"]} reward evaluations, {data["reward_model"]} reward), is reconstructed '
             'with the prior and scored against the reference: Chamfer x100 in the folder\'s frame and after ICP '
             '(shape); a failure is counted with its reason.', '']
    body = []
    for n in data['ns']:
        for p in [p for p in data['plans'] if p['n'] == n and p['method'] != RANDOM_SUBSET]:
            body.append([str(n), p['method'], num(p['reward'], 3), p.get('error') or f'{p["registered"]} / {n}',
                         num(p.get('chamfer')), num(p.get('shape'))])
        r = a['by_n'][str(n)]['random']
        fails = r['chamfer']['failed']
        body.append([str(n), f'{data["random"]} random subsets', '-', f'{fails} failed' if fails else 'all',
                     f'{num(r["chamfer"]["mean"])} +- {num(r["chamfer"]["std"])} (n={r["chamfer"]["n"]})',
                     f'{num(r["shape"]["mean"])} +- {num(r["shape"]["std"])}'])
    lines += table(['N', 'method', 'reward', 'registered', 'Chamfer x100', 'shape x100'], body)
    bars = {n: a['by_n'][str(n)]['egp_at_most_circle'] for n in data['ns']}
    lines += ['', f'Spearman of the {data["reward_model"]} reward against -Chamfer over all {a["plans"]} plans '
              f'(failures ranked last): **{num(a["spearman_reward_vs_minus_chamfer"], 3)}** (against -shape: '
              f'{num(a["spearman_reward_vs_minus_shape"], 3)}); per N: '
              + ', '.join(f'{n}: {num(a["by_n"][str(n)]["spearman"], 3)}' for n in data['ns'])
              + f'. Failed plans: {a["failed"]}. egp\'s Chamfer at most the evenly spaced plan\'s: '
              + ', '.join(f'N={n} {"yes" if b else "no" if b is not None else "-"}' for n, b in bars.items())
              + '; at most every other method\'s: '
              + ', '.join(f'N={n} {_yes(a["by_n"][str(n)].get("egp_lowest"))}' for n in data['ns']) + '.']
    chosen = [p for p in data['plans'] if p.get('planning_flights')]
    if chosen:
        lines += ['', 'Planned with simulated flights over the first pass (the same flight as below, under '
                  'the planner\'s draws): ' + ', '.join(f'{p["method"]} N={p["n"]} {p["planning_flights"]} flights, '
                                                       f'chosen by {p["chosen_by"]}, {num(p["planning_seconds"], 0)} s'
                                                       for p in chosen) + '.']
    if a.get('flights'):
        lines += ['', f'The simulated flight of every plan over the first pass (step 5), its map Chamfer against '
                  f'the real reconstruction\'s: Spearman **{num(a["spearman_flight_vs_minus_chamfer"], 3)}** over '
                  f'{a["flights"]} plans (against -shape: {num(a["spearman_flight_vs_minus_shape"], 3)}; '
                  f'{a["flights_failed"]} flights failed, ranked last).']
    if a.get('spearman_by_reward_model'):
        lines += ['', 'Spearman against -Chamfer over the same plans of each reward model\'s value: '
                  + ', '.join(f'{m} {num(v, 3)}' for m, v in a['spearman_by_reward_model'].items()) + '.']
    if data.get('wide_gaps'):
        lines += ['', f'The {data["reward_model"]} reward of evenly spaced plans (not reconstructed): '
                  + ', '.join(f'{k} views {num(v, 3)}' for k, v in data['wide_gaps'].items()) + '.']
    failures = sorted({(p['error'], (p.get('error_msg') or '')[:120]) for p in data['plans'] if p.get('error')})
    if failures:
        lines += ['', 'Failures and their reasons:', ''] + [f'- {e}: {m}' for e, m in failures[:10]]
    return '\n'.join(lines) + '\n'


def main(argv=None) -> int:
    args = parse_args(argv)
    data = run(args)
    publish(Path(args.out) / 'real', data['scan'], data, markdown(data))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
