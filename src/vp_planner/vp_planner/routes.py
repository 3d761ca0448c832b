"""From views to flights: each drone's timed route through the views, kept apart from the others
(ROS-free; the dispatcher node and ``vp_planner.cli mission`` are its callers).

Flights
-------
D drones stand at homes h_1..h_D (on the ground) and N views (cameras ``[c, v]``) are to be
photographed. Drone d flies one sortie: it takes off vertically above its home, visits its views
in order (hovering ``hover_s`` at each: settling under wind, then the photograph) and comes back
to above its home and down. A leg is a polyline; each straight piece from p to q takes

    tau(p, q) = max(|q_xy - p_xy| / cruise_speed, |q_z - p_z| / climb_rate)

(the drone flies the line at a constant velocity whose horizontal and vertical parts stay within
both limits). From a home the drone climbs to the first view's altitude and flies level to it;
to a home it flies level above it and descends. With obstacles (the scene's points) a leg whose
line comes nearer than ``standoff`` to a point (checked by sphere tracing on a KD-tree: the ball
free of points around a sample is skipped at once, so a leg costs a few queries) climbs instead
to the transit altitude (the highest point plus ``standoff``), crosses and descends; a leg clear
neither way is refused (``NO_CLEAR_LEG``).

Routing
-------
The order is a multi-depot vehicle routing problem with a duration dimension (OR-Tools' routing
solver): vehicle d starts and ends at node d (its home), the views are the other nodes, the
transit of arc (i, j) is tau(i, j) plus the hover at i, and each vehicle's cumulated duration is
at most a capacity C (hard). The objective is the longest flight (the fleet's time on site):
C starts at the usable budget B = flight_time_s (1 - reserve) and is bisected down to the least
C for which the solver's first-solution heuristic (parallel cheapest insertion, which spreads the
views over the drones when C is tight; a C it cannot fill counts as too small) still fits every
view, down to the lower bound max_v min_d (a sortie to view v alone); the solver's local search (greedy descent on
SPAN_WEIGHT max_d T_d + sum_d T_d) then improves the routes under that C. No step stops on the
clock, so the routes are the same on every machine. ``objective="min_total"`` minimizes the total
flight time instead (the local search on the arc costs alone, under B). A view no drone reaches and returns from
within B, or views that do not fit under B, are refused with ``DOES_NOT_FIT`` and the shortfall
in seconds (the routes solved without the budget tell how long the longest would be).

Separation
----------
A timed route is piecewise linear in time: at rest at each waypoint from its arrival to its
departure, moving at a constant velocity in between; before its departure from home and after
its landing a drone stands at its home. Between two consecutive instants of the union of every
drone's arrivals and departures every drone moves linearly, so the distance of two drones there
is the distance of a segment to the origin (the closest approach, in closed form): the minimum
over every pair and every moment is exact, computed for all pairs at once in chunks of instants
(at most ``PAIR_ELEMENTS`` numbers at a time). Drones less than ``separation`` apart are
separated by waits (prioritized planning): the drones are taken longest flight first; each
keeps the routes before it fixed and, from its earliest conflict with them, waits ``WAIT_STEP_S``
longer before the leg it is on (or, when it conflicts while at rest, before the leg that brought
it there) until it conflicts with none; waits count against its budget. A drone that cannot be
separated within its budget is refused with ``SEPARATION_CONFLICT``: conflicting routes are
never returned. The homes themselves must be ``separation`` apart (``INVALID_INPUT``).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, fields
from typing import Optional, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from vp_scene.camera import check_cameras
from vp_scene.ranged import CodedError, bounded, check_ranges, range_text

from .feasibility import Feasibility

__all__ = [
    "ROUTE_CODES",
    "OBJECTIVES",
    "RouteError",
    "FlightModel",
    "Route",
    "FleetRoutes",
    "leg_times",
    "time_routes",
    "closest_approach",
    "separate",
    "plan_routes",
    "launch_row",
    "SPAN_WEIGHT",
    "WAIT_STEP_S",
    "PAIR_ELEMENTS",
    "BISECTIONS",
]

#: The routes' objectives: the longest flight (the fleet's time on site) first, or the total.
OBJECTIVES = ("min_max", "min_total")
#: The refusals of :func:`plan_routes`, each its own code (also the dispatcher's error codes).
ROUTE_CODES = ("INVALID_FLIGHT_MODEL", "INVALID_INPUT", "DOES_NOT_FIT", "SEPARATION_CONFLICT", "NO_CLEAR_LEG")
#: Weight of the longest flight against the total in the solver's objective.
SPAN_WEIGHT = 100
#: s: the step by which a conflicting drone's wait grows.
WAIT_STEP_S = 0.25
#: Bound on the numbers of one chunk of the pairwise closest-approach computation.
PAIR_ELEMENTS = 1 << 22
#: Bisection steps on the capacity at most (:func:`_solve`).
BISECTIONS = 20
#: s: the solver's unit (its durations are integers).
_UNIT_S = 1e-3
#: m: transit legs keep ``standoff`` from the scene to this much (the sphere tracing's least step).
_CLEARANCE_TOL = 0.01


class RouteError(CodedError):
    """A refusal with its code (:data:`ROUTE_CODES`) and a one-line message."""


@dataclass(frozen=True)
class FlightModel:
    """How a drone flies (validated once, on construction: :class:`RouteError` INVALID_FLIGHT_MODEL
    naming the field, its value and its range; each field's range is in its metadata)."""

    cruise_speed: float = bounded(5.0, 0.0, 30.0, "m/s", "horizontal speed between waypoints", low_open=True)
    climb_rate: float = bounded(2.0, 0.0, 10.0, "m/s", "vertical speed, up and down", low_open=True)
    hover_s: float = bounded(2.0, 0.0, 600.0, "s", "hover at each view: settling under wind, then the photograph")
    flight_time_s: float = bounded(1200.0, 0.0, 7200.0, "s", "a battery's flight time", low_open=True)
    reserve: float = bounded(0.2, 0.0, 0.9, "", "fraction of the battery kept in reserve at landing")

    def __post_init__(self) -> None:
        check_ranges(self, "INVALID_FLIGHT_MODEL", RouteError)

    @classmethod
    def range_text(cls, name: str) -> str:
        """The field's range as text, e.g. ``(0, 30] m/s``."""
        return range_text({f.name: f for f in fields(cls)}[name])

    @property
    def budget_s(self) -> float:
        """The usable flight time, s: the battery's less the reserve."""
        return self.flight_time_s * (1.0 - self.reserve)


@dataclass(frozen=True)
class Route:
    """One drone's timed sortie. ``points`` (m, 3): home, the legs' corners, the views, home;
    ``view_of_point`` (m,) the view index of each point (-1 elsewhere); ``arrival`` and
    ``departure`` (m,) s from the sortie's start. A drone without views has one point, its home."""

    drone: int
    views: NDArray[np.int64]
    points: NDArray[np.float64]
    view_of_point: NDArray[np.int64]
    arrival: NDArray[np.float64]
    departure: NDArray[np.float64]

    @property
    def flight_time(self) -> float:
        """s from take-off to landing (0 without views)."""
        return float(self.arrival[-1] - self.departure[0])

    @property
    def landing(self) -> float:
        """s from the sortie's start to the landing."""
        return float(self.arrival[-1])

    @property
    def distance(self) -> float:
        """m flown."""
        return float(np.linalg.norm(np.diff(self.points, axis=0), axis=1).sum())

    def eta(self) -> NDArray[np.float64]:
        """The arrival time at each of :attr:`views`, in their order."""
        return self.arrival[self.view_of_point >= 0]


@dataclass(frozen=True)
class FleetRoutes:
    """The fleet's routes (one per drone, in the homes' order), the model they were timed with,
    the separation asked and the least distance between two drones over the sortie."""

    routes: tuple[Route, ...]
    model: FlightModel
    separation: float
    min_separation: float
    seconds: float = 0.0

    @property
    def time_on_site(self) -> float:
        """s from the start until the last drone has landed."""
        return max(r.landing for r in self.routes)

    def drone_of_view(self, num_views: int) -> NDArray[np.int64]:
        out = np.full(num_views, -1, dtype=np.int64)
        for r in self.routes:
            out[r.views] = r.drone
        return out

    def to_dict(self) -> dict:
        """A plain record, strict JSON (the CLI's and the dispatcher's fleet.json)."""
        return {
            "time_on_site": self.time_on_site, "separation": self.separation,
            "min_separation": self.min_separation if math.isfinite(self.min_separation) else None,  # one drone: none
            "model": {f.name: getattr(self.model, f.name) for f in fields(self.model)},
            "routes": [{"drone": r.drone, "views": r.views.tolist(), "flight_time": r.flight_time,
                        "distance": r.distance, "eta": r.eta().tolist(), "points": r.points.tolist(),
                        "arrival": r.arrival.tolist(), "departure": r.departure.tolist()} for r in self.routes]}


# ---------------------------------------------------------------- legs

def leg_times(a: ArrayLike, b: ArrayLike, model: FlightModel) -> NDArray[np.float64]:
    """tau(a, b) (...,) of straight pieces from a (..., 3) to b (..., 3) (module docstring)."""
    d = np.asarray(b, dtype=np.float64) - np.asarray(a, dtype=np.float64)
    return np.maximum(np.linalg.norm(d[..., :2], axis=-1) / model.cruise_speed, np.abs(d[..., 2]) / model.climb_rate)


def _segments_clear(a: NDArray[np.float64], b: NDArray[np.float64], tree: Optional[cKDTree],
                    standoff: float) -> NDArray[np.bool_]:
    """Whether each segment a_i b_i keeps ``standoff`` (to :data:`_CLEARANCE_TOL`) from every point
    of ``tree``: sphere tracing, all segments at once; a sample at distance r from the nearest
    point clears the next r - need of its segment."""
    n = len(a)
    clear = np.ones(n, dtype=bool)
    if tree is None or standoff <= 0 or n == 0:
        return clear
    need = standoff - _CLEARANCE_TOL
    length = np.linalg.norm(b - a, axis=1)
    unit = np.divide(b - a, length[:, None], out=np.zeros_like(a), where=length[:, None] > 0)
    t = np.zeros(n)
    active = np.arange(n)
    while active.size:
        x = a[active] + unit[active] * t[active, None]
        r, _ = tree.query(x, k=1)
        blocked = r < need
        clear[active[blocked]] = False
        done = t[active] >= length[active]
        t[active] = np.minimum(t[active] + np.maximum(r - need, _CLEARANCE_TOL), length[active])
        active = active[~blocked & ~done]
    return clear


class _Legs:
    """The legs between every two nodes (homes 0..D-1, then the views): their times and, on
    demand, their polylines (module docstring). A leg is direct when its pieces keep the stand-off;
    else it climbs above its start to the transit altitude (clear of every point by
    construction), crosses and descends, when both climbs keep the stand-off; else it is blocked
    (time inf)."""

    def __init__(self, homes: NDArray[np.float64], views: NDArray[np.float64], model: FlightModel,
                 obstacles: Optional[NDArray[np.float64]], standoff: float) -> None:
        self.nodes = np.concatenate([homes, views])
        self.num_homes = D = len(homes)
        n, N = len(self.nodes), len(views)
        self.tree = cKDTree(obstacles) if obstacles is not None and len(obstacles) and standoff > 0 else None
        self.standoff = standoff
        self.top = float(obstacles[:, 2].max()) if self.tree is not None else -math.inf
        self.transit_z = self.top + standoff if self.tree is not None else 0.0
        is_home = np.arange(n) < D
        p = self.nodes
        # direct legs: view -> view straight; home <-> view vertical above the home, level at the view's height
        direct_ok = np.ones((n, n), dtype=bool)
        iu, ju = np.triu_indices(n, 1)
        vv = ~is_home[iu] & ~is_home[ju]
        hv = is_home[iu] & ~is_home[ju]
        a = np.concatenate([p[iu[vv]], np.column_stack([p[iu[hv], :2], p[ju[hv], 2]])])
        b = np.concatenate([p[ju[vv]], p[ju[hv]]])
        ok = self._clear(a, b)
        direct_ok[iu[vv], ju[vv]] = ok[:vv.sum()]
        direct_ok[iu[hv], ju[hv]] = ok[vv.sum():]
        # the climbs: above each view to the transit altitude, above each home to the highest view or it
        up_to = np.where(is_home, max(self.transit_z, float(views[:, 2].max()) if N else 0.0), self.transit_z)
        up_ok = self._clear(p, np.column_stack([p[:, :2], np.maximum(up_to, p[:, 2])]))
        direct_ok[iu[hv], ju[hv]] &= up_ok[iu[hv]]
        direct_ok = np.triu(direct_ok, 1) | np.triu(direct_ok, 1).T
        detour_ok = up_ok[:, None] & up_ok[None, :]
        d = p[None] - p[:, None]                              # (n, n, 3): from i to j
        horizontal = np.linalg.norm(d[..., :2], axis=-1) / model.cruise_speed
        vertical = np.abs(d[..., 2]) / model.climb_rate
        home_leg = is_home[:, None] | is_home[None, :]
        direct = np.where(home_leg, horizontal + vertical, np.maximum(horizontal, vertical))
        z = np.maximum(self.transit_z, np.maximum(p[:, None, 2], p[None, :, 2]))
        over = horizontal + ((z - p[:, None, 2]) + (z - p[None, :, 2])) / model.climb_rate
        self.detour = ~direct_ok & detour_ok
        self.time = np.where(direct_ok, direct, np.where(detour_ok, over, math.inf))
        self.time[is_home[:, None] & is_home[None, :]] = 0.0
        np.fill_diagonal(self.time, 0.0)

    def _clear(self, a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Whether each segment a_i b_i keeps the stand-off; one wholly above the transit altitude
        less the tolerance at once (it clears every point)."""
        clear = np.ones(len(a), dtype=bool)
        if self.tree is None:
            return clear
        low = np.minimum(a[:, 2], b[:, 2]) < self.top + self.standoff - _CLEARANCE_TOL
        clear[low] = _segments_clear(a[low], b[low], self.tree, self.standoff)
        return clear

    def path(self, i: int, j: int) -> NDArray[np.float64]:
        """The polyline of leg i -> j, from node i to node j."""
        p, q = self.nodes[i], self.nodes[j]
        if self.detour[i, j]:
            z = max(self.transit_z, p[2], q[2])
            return np.array([p, [p[0], p[1], z], [q[0], q[1], z], q])
        if i < self.num_homes:  # take off above the home to the view's altitude
            return np.array([p, [p[0], p[1], q[2]], q])
        if j < self.num_homes:  # level above the home, then down
            return np.array([p, [q[0], q[1], p[2]], q])
        return np.array([p, q])


# ---------------------------------------------------------------- timing

def time_routes(orders: Sequence[Sequence[int]], homes: ArrayLike, views: ArrayLike, model: FlightModel,
                legs: Optional[_Legs] = None, waits: Optional[Sequence[Optional[Sequence[float]]]] = None) -> list[Route]:
    """Timed routes of drones visiting ``orders[d]`` (view indices) from their ``homes`` (D, 3):
    every drone leaves home at 0 and hovers ``model.hover_s`` at each view; ``waits[d][k]`` (s),
    when given, is added before it leaves its k-th point (its home first)."""
    h = np.asarray(homes, dtype=np.float64).reshape(-1, 3)
    v = np.asarray(views, dtype=np.float64).reshape(-1, 3)
    legs = legs or _Legs(h, v, model, None, 0.0)
    return [_time_route(d, orders[d], legs, model, None if waits is None else waits[d]) for d in range(len(h))]


def _time_route(d: int, order: Sequence[int], legs: _Legs, model: FlightModel,
                waits: Optional[Sequence[float]] = None) -> Route:
    D = legs.num_homes
    order = [int(x) for x in order]
    home = legs.nodes[d]
    if not order:
        return Route(d, np.zeros(0, dtype=np.int64), home[None].copy(), np.array([-1]), np.zeros(1), np.zeros(1))
    nodes = [d] + [D + x for x in order] + [d]
    points, view_of = [home], [-1]
    for a, b in zip(nodes[:-1], nodes[1:]):
        path = legs.path(a, b)
        points.extend(path[1:])
        view_of.extend([-1] * (len(path) - 2) + [b - D if b >= D else -1])
    points = np.array(points)
    view_of = np.array(view_of, dtype=np.int64)
    rest = np.where(view_of >= 0, model.hover_s, 0.0)
    if waits is not None:
        rest = rest + np.asarray(waits, dtype=np.float64)
    travel = leg_times(points[:-1], points[1:], model)
    arrival, departure = np.zeros(len(points)), np.zeros(len(points))
    departure[0] = rest[0]
    for k in range(1, len(points)):
        arrival[k] = departure[k - 1] + travel[k - 1]
        departure[k] = arrival[k] + (rest[k] if k < len(points) - 1 else 0.0)
    return Route(d, np.array(order, dtype=np.int64), points, view_of, arrival, departure)


def _knots(route: Route) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The route's times (2m,) and positions (2m, 3): at rest from each arrival to its departure."""
    t = np.stack([route.arrival, route.departure], axis=1).ravel()
    return t, np.repeat(route.points, 2, axis=0)


def _positions(routes: Sequence[Route], times: NDArray[np.float64]) -> NDArray[np.float64]:
    """(T, R, 3) positions of the routes at ``times`` (at home before and after their flights)."""
    out = np.empty((len(times), len(routes), 3))
    for r, route in enumerate(routes):
        t, p = _knots(route)
        for c in range(3):
            out[:, r, c] = np.interp(times, t, p[:, c])
    return out


def closest_approach(routes: Sequence[Route], others: Sequence[Route] = ()) -> tuple[float, float, int, int]:
    """The least distance between two drones at any moment and where: (distance, time, i, j),
    i and j indices into ``routes + others``; with ``others`` only the pairs of one of ``routes``
    and one of ``others`` (inf, nan, -1, -1 without a pair). Exact (module docstring), in chunks
    of instants of at most :data:`PAIR_ELEMENTS` numbers."""
    everyone = list(routes) + list(others)
    n = len(everyone)
    if others:
        ii, jj = np.meshgrid(np.arange(len(routes)), np.arange(len(routes), n), indexing="ij")
        ii, jj = ii.ravel(), jj.ravel()
    else:
        ii, jj = np.triu_indices(n, 1)
    if ii.size == 0:
        return math.inf, math.nan, -1, -1
    times = np.unique(np.concatenate([_knots(r)[0] for r in everyone]))
    if times.size == 1:
        times = np.concatenate([times, times + 1.0])
    best = (math.inf, math.nan, -1, -1)
    chunk = max(2, PAIR_ELEMENTS // (6 * ii.size))
    for start in range(0, len(times) - 1, chunk - 1):
        t = times[start:start + chunk]
        p = _positions(everyone, t)
        rel = p[:, ii] - p[:, jj]                       # (T, pairs, 3)
        r0, dr = rel[:-1], rel[1:] - rel[:-1]
        denom = np.einsum("tpc,tpc->tp", dr, dr)
        s = np.clip(np.divide(-np.einsum("tpc,tpc->tp", r0, dr), denom, out=np.zeros_like(denom), where=denom > 0),
                    0.0, 1.0)
        dist = np.linalg.norm(r0 + s[..., None] * dr, axis=-1)
        k = int(np.argmin(dist))
        ti, pi = np.unravel_index(k, dist.shape)
        if dist[ti, pi] < best[0]:
            when = t[ti] + s[ti, pi] * (t[ti + 1] - t[ti])
            best = (float(dist[ti, pi]), float(when), int(ii[pi]), int(jj[pi]))
    return best


def _first_conflict(route: Route, fixed: Sequence[Route], separation: float) -> Optional[float]:
    """The earliest moment ``route`` is nearer than ``separation`` to one of ``fixed`` (None: never)."""
    if not fixed or separation <= 0:
        return None
    times = np.unique(np.concatenate([_knots(r)[0] for r in [route, *fixed]]))
    if times.size == 1:
        times = np.concatenate([times, times + 1.0])
    p = _positions([route, *fixed], times)
    rel = p[:, :1] - p[:, 1:]                         # (T, F, 3)
    r0, dr = rel[:-1], rel[1:] - rel[:-1]
    a = np.einsum("tpc,tpc->tp", dr, dr)
    b = np.einsum("tpc,tpc->tp", r0, dr)
    c = np.einsum("tpc,tpc->tp", r0, r0) - (separation - 1e-9) ** 2
    # the first s in [0, 1] with |r0 + s dr| < separation: the smaller root of a s^2 + 2 b s + c = 0
    disc = b * b - a * c
    with np.errstate(invalid="ignore", divide="ignore"):
        s_in = np.where(c < 0, 0.0, np.where((disc > 0) & (a > 0), (-b - np.sqrt(np.maximum(disc, 0))) / a, np.inf))
    s_in = np.where((s_in >= 0) & (s_in <= 1), s_in, np.inf)
    hit = np.isfinite(s_in)
    if not hit.any():
        return None
    when = times[:-1, None] + s_in * (times[1:] - times[:-1])[:, None]
    return float(when[hit].min())


def separate(routes: Sequence[Route], model: FlightModel, separation: float, legs: _Legs) -> list[Route]:
    """The routes with waits such that no two drones come nearer than ``separation`` (module
    docstring); RouteError SEPARATION_CONFLICT when a drone cannot be separated within its budget."""
    routes = list(routes)
    fixed: list[Route] = []
    out: dict[int, Route] = {}
    for d in sorted(range(len(routes)), key=lambda d: (-routes[d].flight_time, d)):  # longest flight first
        route = routes[d]
        waits = np.zeros(len(route.points))
        while (t := _first_conflict(route, fixed, separation)) is not None:
            if len(route.points) == 1 or t < route.departure[0]:
                raise RouteError("SEPARATION_CONFLICT", f"drone {d} is within {separation:g} m of another at "
                                 f"{t:.1f} s while it stands at its home: move the homes apart")
            waits[_wait_before(route, t)] += WAIT_STEP_S
            route = _time_route(d, route.views, legs, model, waits)
            if route.flight_time > model.budget_s + 1e-9 or waits.sum() > model.budget_s:
                raise RouteError("SEPARATION_CONFLICT", f"drone {d} cannot be kept {separation:g} m from the others "
                                 f"within its budget of {model.budget_s:.0f} s (waits of {waits.sum():.1f} s so far): "
                                 "fewer drones, homes further apart or a smaller separation")
        out[d] = route
        fixed.append(route)
    return [out[d] for d in range(len(routes))]


def _wait_before(route: Route, t: float) -> int:
    """The point whose departure a wait delays to move the drone at time t: the start of the leg
    it flies then, or of the leg that brought it where it rests then (its landing included)."""
    k = int(np.searchsorted(route.departure, t, side="right")) - 1  # the last departure at or before t
    return max(0, min(k, len(route.points) - 2))


# ---------------------------------------------------------------- solving

def _check_inputs(views: ArrayLike, homes: ArrayLike, separation: float) -> tuple[NDArray, NDArray]:
    try:
        cams = check_cameras(views) if np.asarray(views).size else np.zeros((0, 6))
    except ValueError as exc:
        raise RouteError("INVALID_INPUT", f"views: {exc}") from None
    h = np.asarray(homes, dtype=np.float64)
    if h.ndim != 2 or h.shape[1] != 3 or len(h) == 0:
        raise RouteError("INVALID_INPUT", f"homes must have shape (D, 3) with D >= 1, got {h.shape}")
    if not np.all(np.isfinite(h)):
        raise RouteError("INVALID_INPUT", "homes contain NaN or infinite coordinates")
    if not (math.isfinite(separation) and separation >= 0):
        raise RouteError("INVALID_INPUT", f"separation must be finite and >= 0 m, got {separation}")
    if len(h) > 1:
        dist = np.where(np.eye(len(h), dtype=bool), math.inf, np.linalg.norm(h[:, None] - h[None], axis=-1))
        i, j = np.unravel_index(int(np.argmin(dist)), dist.shape)
        if dist[i, j] < separation - 1e-9:
            raise RouteError("INVALID_INPUT", f"the homes of drones {min(i, j)} and {max(i, j)} are "
                             f"{dist[i, j]:.2f} m apart, less than the separation {separation:g} m")
    return cams, h


def _solve(legs: _Legs, model: FlightModel, num_views: int, budget: Optional[float], lower: float,
           time_limit_s: float, objective: str = "min_max") -> Optional[list[list[int]]]:
    """Each drone's order of views (module docstring), None when none fits ``budget`` (None: no
    budget). The longest flight is minimized by bisection on the duration's hard capacity between
    ``lower`` and the longest of the last routes found, each capacity tried with OR-Tools'
    first-solution heuristic (parallel cheapest insertion: it spreads the views when the capacity
    is tight); the routes of the least capacity found are then improved by its local search
    (greedy descent on SPAN_WEIGHT x the longest + the total, to a local optimum). Deterministic:
    no step stops on the clock (``time_limit_s`` only caps each solve). ``min_total``: the least
    total flight time under ``budget`` (the local search on the total alone, no bisection)."""
    from ortools.constraint_solver import pywrapcp, routing_enums_pb2

    D = legs.num_homes
    n = D + num_views
    service = np.where(np.arange(n) >= D, model.hover_s, 0.0)
    transit = np.where(np.isfinite(legs.time), legs.time, 1e6) + service[:, None]
    np.fill_diagonal(transit, 0.0)
    units = np.rint(transit / _UNIT_S).astype(np.int64).tolist()

    def solve(cap_s: float, polish: bool, span: int = SPAN_WEIGHT) -> Optional[tuple[float, list[list[int]]]]:
        manager = pywrapcp.RoutingIndexManager(n, D, list(range(D)), list(range(D)))
        routing = pywrapcp.RoutingModel(manager)
        callback = routing.RegisterTransitMatrix(units)
        routing.SetArcCostEvaluatorOfAllVehicles(callback)
        routing.AddDimension(callback, 0, int(cap_s / _UNIT_S), True, "time")
        dim = routing.GetDimensionOrDie("time")
        dim.SetGlobalSpanCostCoefficient(span)
        params = pywrapcp.DefaultRoutingSearchParameters()
        params.first_solution_strategy = routing_enums_pb2.FirstSolutionStrategy.PARALLEL_CHEAPEST_INSERTION
        params.local_search_metaheuristic = routing_enums_pb2.LocalSearchMetaheuristic.GREEDY_DESCENT
        params.time_limit.FromMilliseconds(max(1, int(time_limit_s * 1000)))
        if not polish:
            params.solution_limit = 1                 # the heuristic's answer, or none at once:
            params.fallback_to_cp_sat_size_threshold = 0  # no CP-SAT search until the time limit
        solution = routing.SolveWithParameters(params)
        if solution is None:
            return None
        orders = []
        for d in range(D):
            index, order = solution.Value(routing.NextVar(routing.Start(d))), []
            while not routing.IsEnd(index):
                order.append(manager.IndexToNode(index) - D)
                index = solution.Value(routing.NextVar(index))
            orders.append(order)
        return max(solution.Value(dim.CumulVar(routing.End(d))) for d in range(D)) * _UNIT_S, orders

    cap = budget if budget is not None else float(transit.sum())
    if objective == "min_total":
        return (solve(cap, True, 0) or (None, None))[1]
    found = solve(cap, False)
    if found is None:
        return None
    low, high = lower, found[0]
    for _ in range(BISECTIONS):
        if high - low <= max(0.25, 0.01 * high):
            break
        mid = 0.5 * (low + high)
        tried = solve(mid, False)
        if tried is None:
            low = mid
        else:
            high = tried[0]
    polished = solve(high + _UNIT_S, True)
    return (polished or found)[1]


def plan_routes(views: ArrayLike, homes: ArrayLike, model: FlightModel = FlightModel(),
                separation: float = Feasibility.min_separation, obstacles: Optional[ArrayLike] = None,
                standoff: float = Feasibility.min_standoff, time_limit_s: float = 2.0,
                objective: str = "min_max") -> FleetRoutes:
    """Each drone's timed route through the views (N, 6) from its home (D, 3), all within the
    budget and ``separation`` apart at every moment (module docstring). ``obstacles`` (P, 3) or
    (K, P, 3): the scene's points the legs keep ``standoff`` from; ``time_limit_s``: the solver's;
    ``objective`` (:data:`OBJECTIVES`): the longest flight (the fleet's time on site) or the total.
    RouteError with its code (:data:`ROUTE_CODES`) and one line."""
    t0 = time.perf_counter()
    if objective not in OBJECTIVES:
        raise RouteError("INVALID_INPUT", f"objective must be one of {', '.join(OBJECTIVES)}, got {objective!r}")
    cams, h = _check_inputs(views, homes, separation)
    obs = None if obstacles is None else np.asarray(obstacles, dtype=np.float64).reshape(-1, 3)
    legs = _Legs(h, cams[:, :3], model, obs, standoff)
    D, N = len(h), len(cams)
    budget = model.budget_s
    if N:
        blocked = ~np.isfinite(legs.time[:D, D:])
        unreachable = np.flatnonzero(blocked.all(axis=0))
        if unreachable.size:
            raise RouteError("NO_CLEAR_LEG", f"view(s) {unreachable.tolist()} cannot be reached from any home keeping "
                             f"{standoff:g} m from the scene, neither level nor over it at {legs.transit_z:.2f} m")
        sortie = legs.time[:D, D:] + model.hover_s + legs.time[D:, :D].T   # (D, N): one view alone
        need = sortie.min(axis=0)
        worst = int(np.argmax(need))
        if need[worst] > budget:
            raise RouteError("DOES_NOT_FIT", f"view {worst} needs {need[worst]:.0f} s of flight from the nearest home "
                             f"(drone {int(np.argmin(sortie[:, worst]))}), the budget is {budget:.0f} s "
                             f"({model.flight_time_s:g} s less {100 * model.reserve:g} % reserve): "
                             f"{need[worst] - budget:.0f} s short")
        orders = _solve(legs, model, N, budget, float(need.max()), time_limit_s, objective)
        if orders is None:  # the heuristic found none under the budget: the routes without one tell
            orders = _solve(legs, model, N, None, float(need.max()), time_limit_s, objective)
            if orders is None:
                raise RouteError("DOES_NOT_FIT", f"the solver found no routes for the {N} views with {D} drones")
            longest = max(r.flight_time for r in time_routes(orders, h, cams[:, :3], model, legs))
            if longest > budget:
                raise RouteError("DOES_NOT_FIT", f"the {N} views do not fit in {D} flights of {budget:.0f} s "
                                 f"({model.flight_time_s:g} s less {100 * model.reserve:g} % reserve): the best routes "
                                 f"found need {longest:.0f} s, {longest - budget:.0f} s short (more drones, a larger "
                                 "battery or fewer views)")
    else:
        orders = [[] for _ in range(D)]
    routes = separate(time_routes(orders, h, cams[:, :3], model, legs), model, separation, legs)
    over = [r for r in routes if r.flight_time > budget + 1e-9]
    if over:
        r = max(over, key=lambda r: r.flight_time)
        raise RouteError("DOES_NOT_FIT", f"drone {r.drone}'s route takes {r.flight_time:.0f} s, the budget is "
                         f"{budget:.0f} s: {r.flight_time - budget:.0f} s short")
    least = closest_approach(routes)[0]
    if least < separation - 1e-6:  # separate() guarantees it; never hand out conflicting routes
        raise RouteError("SEPARATION_CONFLICT", f"two drones come {least:.3f} m close, the separation is {separation:g} m")
    return FleetRoutes(tuple(routes), model, float(separation), float(least), time.perf_counter() - t0)


def launch_row(n: int, centre: ArrayLike = (0.0, 0.0), south: float = 5.0, spacing: float = 1.0) -> NDArray[np.float64]:
    """Homes of n drones: on the ground, in a row along x, ``south`` m south (-y) of ``centre``
    (x, y), ``spacing`` m apart (the simulated fleet's, and the mission CLI's default)."""
    c = np.asarray(centre, dtype=np.float64).ravel()[:2]
    k = np.arange(n, dtype=np.float64)
    return np.stack([c[0] + (k - (n - 1) / 2.0) * spacing, np.full(n, c[1] - south), np.zeros(n)], axis=1)
