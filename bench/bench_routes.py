#!/usr/bin/env python3
"""Fleet routes on a field: D drones from a launch row through N views (vp_planner.routes).

The views are a real plan of the field (default: row_12's 60-camera oblique lawnmower survey,
planned once and cached), the obstacles its scene's points (every wind realization); the drones
stand on a launch row 5 m south of the field, 1 m apart. Each repeat routes the whole fleet
(`plan_routes`: the legs around the plants, the solver, the timing, the separation's waits) and is
timed; the record says every drone's flight time against the budget, the fleet's time on site,
the least distance between two drones over the timed routes against the separation asked, and
the same before the waits (the solver's orders timed without them).

    python -m bench.bench_routes [--scenario row_12 --variant lawnmower-oblique --cameras 60
        --drones 16 --separation 0.5 --repeats 3]

Writes results/bench_routes.{json,md}.
"""
from __future__ import annotations

import statistics
import time
from dataclasses import fields
from pathlib import Path

import numpy as np

if not __package__:  # python bench/bench_routes.py: as python -m bench.bench_routes (bench/_script.py)
    import _script  # noqa: F401
from bench.common import plan_cell, scene  # noqa: E402
from bench.options import parser  # noqa: E402
from bench.publish import publish  # noqa: E402

#: s: what routing the benchmark's fleet may take at most
LIMIT_S = 10.0


def parse_args(argv=None):
    from vp_planner.routes import FlightModel

    ap = parser(__doc__, 'out')
    ap.add_argument('--scenario', default='row_12')
    ap.add_argument('--variant', default='lawnmower-oblique', help='the plan of the views (bench.common.VARIANTS)')
    ap.add_argument('--cameras', type=int, default=60)
    ap.add_argument('--drones', type=int, default=16)
    ap.add_argument('--separation', type=float, default=0.5, help='m between two drones at every moment')
    ap.add_argument('--repeats', type=int, default=3)
    for f in fields(FlightModel):
        ap.add_argument(f'--{f.name.replace("_", "-")}', type=float, default=f.default,
                        help=f'{f.metadata["help"]}, {FlightModel.range_text(f.name)}')
    return ap.parse_args(argv)


def run(args) -> dict:
    from vp_planner.routes import FlightModel, closest_approach, launch_row, plan_routes, time_routes

    model = FlightModel(**{f.name: getattr(args, f.name) for f in fields(FlightModel)})
    noisy, _ = scene(args.scenario)
    plan = plan_cell(Path(args.out) / 'cache', args.scenario, args.variant, 0, evals=1, init=1,
                     num_cameras=args.cameras)
    views = np.asarray(plan['cameras'])
    lo, hi = views[:, :2].min(axis=0), views[:, :2].max(axis=0)
    homes = launch_row(args.drones, centre=(0.5 * (lo[0] + hi[0]), lo[1]), south=5.0)
    seconds, fleet = [], None
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        fleet = plan_routes(views, homes, model, args.separation, obstacles=noisy.points, standoff=0.5)
        seconds.append(time.perf_counter() - t0)
    naive = time_routes([r.views for r in fleet.routes], homes, views[:, :3], model)
    flights = [r.flight_time for r in fleet.routes]
    return {
        'scenario': args.scenario, 'variant': args.variant, 'views': len(views), 'drones': args.drones,
        'obstacle_points': int(np.asarray(noisy.points).reshape(-1, 3).shape[0]),
        'model': {f.name: getattr(model, f.name) for f in fields(model)}, 'budget_s': model.budget_s,
        'separation': args.separation, 'seconds': seconds, 'seconds_median': statistics.median(seconds),
        'limit_s': LIMIT_S, 'within_limit': max(seconds) <= LIMIT_S,
        'time_on_site_s': fleet.time_on_site, 'flight_times_s': flights, 'every_route_within_budget':
            max(flights) <= model.budget_s, 'views_per_drone': [len(r.views) for r in fleet.routes],
        'min_separation_m': fleet.min_separation,
        'min_separation_before_waits_m': closest_approach(naive)[0],
        'longest_before_waits_s': max(r.flight_time for r in naive),
        'machine': 'x86_64, 2 cores shared with other work',
    }


def markdown(data: dict) -> str:
    return '\n'.join([
        '# Fleet routes', '',
        f"{data['drones']} drones from a launch row through {data['views']} views ({data['scenario']}, "
        f"{data['variant']}), around {data['obstacle_points']} scene points; cruise {data['model']['cruise_speed']:g} "
        f"m/s, climb {data['model']['climb_rate']:g} m/s, hover {data['model']['hover_s']:g} s a view, budget "
        f"{data['budget_s']:.0f} s; {data['machine']}.", '',
        '| routed in, s | time on site, s | longest flight, s | every route in budget | views a drone | '
        'least distance, m (asked) | before the waits, m |',
        '|---|---|---|---|---|---|---|',
        f"| {', '.join(f'{s:.2f}' for s in data['seconds'])} | {data['time_on_site_s']:.1f} | "
        f"{max(data['flight_times_s']):.1f} | {'yes' if data['every_route_within_budget'] else 'no'} | "
        f"{min(data['views_per_drone'])}-{max(data['views_per_drone'])} | {data['min_separation_m']:.3f} "
        f"({data['separation']:g}) | {data['min_separation_before_waits_m']:.3f} |", ''])


def main(argv=None) -> int:
    args = parse_args(argv)
    data = run(args)
    publish(args.out, 'bench_routes', data, markdown(data))
    return 0 if data['within_limit'] and data['every_route_within_budget'] else 1


if __name__ == '__main__':
    raise SystemExit(main())
