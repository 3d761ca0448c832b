"""Routes for a fleet (vp_planner.routes): the solver's min-max orders, the budget, the timing,
the closest approach and the separation's waits, the legs around the plants."""
import itertools
import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from vp_planner import routes as R
from vp_planner.routes import FlightModel, RouteError, closest_approach, plan_routes, separate, time_routes


def _views(points, target=(0.0, 0.0, 0.5)):
    c = np.asarray(points, dtype=float)
    return np.concatenate([c, np.asarray(target) - c], axis=1)


def _check(fleet, views, homes):
    """Every view flown exactly once, each route from its home to its home, in its budget."""
    seen = np.concatenate([r.views for r in fleet.routes])
    assert sorted(seen.tolist()) == list(range(len(views)))
    for r in fleet.routes:
        assert np.allclose(r.points[0], homes[r.drone]) and np.allclose(r.points[-1], homes[r.drone])
        assert np.all(np.diff(r.arrival) >= -1e-12) and np.all(r.departure >= r.arrival - 1e-12)
        assert np.allclose(r.points[r.view_of_point >= 0], views[r.views, :3])
        assert r.flight_time <= fleet.model.budget_s + 1e-9
    assert fleet.min_separation >= fleet.separation - 1e-9


def test_flight_model_ranges_one_line_each():
    m = FlightModel()
    assert m.budget_s == pytest.approx(1200 * 0.8)
    for field, bad, text in (("cruise_speed", 0.0, "(0, 30] m/s"), ("climb_rate", math.nan, "(0, 10] m/s"),
                             ("reserve", 1.0, "[0, 0.9]"), ("hover_s", -1.0, "[0, 600] s"),
                             ("flight_time_s", "x", "(0, 7200] s")):
        with pytest.raises(RouteError) as err:
            FlightModel(**{field: bad})
        assert err.value.code == "INVALID_FLIGHT_MODEL"
        assert str(err.value) == f"[INVALID_FLIGHT_MODEL] {field} must be in {text}, got {bad!r}"


def test_leg_times_limit_both_speeds():
    m = FlightModel(cruise_speed=4.0, climb_rate=1.0)
    t = R.leg_times([[0, 0, 0], [0, 0, 0]], [[8, 0, 1], [1, 0, 3]], m)
    assert t.tolist() == [2.0, 3.0]


def test_min_max_is_optimal_on_a_small_field():
    """Against every split and order of 5 views over 2 drones: the longest flight is the optimum's."""
    m = FlightModel(hover_s=1.0)
    homes = np.array([[-3.0, -6.0, 0.0], [3.0, -6.0, 0.0]])
    views = _views([[-4, 0, 2], [-1, 2, 1.5], [2, 3, 2.5], [4, -1, 1], [0, 5, 3]])
    fleet = plan_routes(views, homes, m, separation=0.0)
    _check(fleet, views, homes)
    legs = R._Legs(homes, views[:, :3], m, None, 0.0)
    best = math.inf
    for split in itertools.product((0, 1), repeat=5):
        longest = 0.0
        for d in (0, 1):
            mine = [i for i in range(5) if split[i] == d]
            longest = max(longest, min((R._time_route(d, o, legs, m).flight_time for o in itertools.permutations(mine)),
                                       default=0.0))
        best = min(best, longest)
    assert fleet.time_on_site == pytest.approx(best, abs=0.01)
    assert R.plan_routes(views, homes, m, separation=0.0).to_dict() == fleet.to_dict()  # deterministic


def test_timed_route_adds_legs_and_hovers():
    m = FlightModel(cruise_speed=5.0, climb_rate=2.0, hover_s=3.0)
    homes = np.array([[0.0, 0.0, 0.0]])
    views = _views([[10, 0, 2], [10, 5, 2]])
    r = time_routes([[0, 1]], homes, views[:, :3], m)[0]
    # up 2 m (1 s), 10 m level (2 s), hover 3, 5 m (1 s), hover 3, 10 + 5 m level back (2.24 s), down (1 s)
    assert r.points.tolist() == [[0, 0, 0], [0, 0, 2], [10, 0, 2], [10, 5, 2], [0, 0, 2], [0, 0, 0]]
    assert r.eta().tolist() == pytest.approx([3.0, 7.0])
    assert r.flight_time == pytest.approx(1 + 2 + 3 + 1 + 3 + math.hypot(10, 5) / 5 + 1)


def test_budget_refusals_say_the_shortfall():
    homes = np.array([[0.0, -5.0, 0.0]])
    far = _views([[0, 400, 2]])
    with pytest.raises(RouteError) as err:
        plan_routes(far, homes, FlightModel(flight_time_s=100.0, reserve=0.2))
    assert err.value.code == "DOES_NOT_FIT" and "\n" not in str(err.value)
    need = 2 * (1 + math.hypot(0, 405) / 5) + 2
    assert f"view 0 needs {need:.0f} s" in str(err.value) and f"{need - 80:.0f} s short" in str(err.value)
    # every view fits alone, not all of them in one flight
    many = _views([[x, 20, 2] for x in np.linspace(-20, 20, 12)])
    with pytest.raises(RouteError) as err:
        plan_routes(many, homes, FlightModel(flight_time_s=30.0, reserve=0.0, hover_s=2.0))
    assert err.value.code == "DOES_NOT_FIT" and "do not fit in 1 flights of 30 s" in str(err.value)
    assert " s short" in str(err.value)
    assert len(plan_routes(many, homes, FlightModel(flight_time_s=300.0)).routes[0].views) == 12


def test_crossing_drones_are_separated_by_a_wait():
    """Two drones whose legs cross at one moment: the check finds it, the fix waits one of them."""
    m = FlightModel(cruise_speed=5.0, climb_rate=2.0, hover_s=1.0)
    homes = np.array([[0.0, -5.0, 0.0], [-5.0, 0.0, 0.0]])
    views = _views([[0, 5, 2], [5, 0, 2]])
    naive = time_routes([[0], [1]], homes, views[:, :3], m)
    dist, when, i, j = closest_approach(naive)
    assert dist == pytest.approx(0.0, abs=1e-9) and when == pytest.approx(2.0) and {i, j} == {0, 1}
    legs = R._Legs(homes, views[:, :3], m, None, 0.0)
    fixed = separate(naive, m, 1.0, legs)
    assert closest_approach(fixed)[0] >= 1.0 - 1e-9
    waited = [r for r in fixed if r.flight_time > naive[r.drone].flight_time + 1e-9]
    assert len(waited) == 1 and waited[0].flight_time - naive[waited[0].drone].flight_time <= 1.0
    assert np.array_equal(fixed[0].points, naive[0].points)  # waits only: the same paths
    # an exact minimum: dense sampling never finds two drones nearer
    t = np.linspace(0, max(r.landing for r in fixed), 4001)
    p = R._positions(fixed, t)
    assert np.linalg.norm(p[:, 0] - p[:, 1], axis=1).min() >= closest_approach(fixed)[0] - 1e-9
    with pytest.raises(RouteError) as err:  # no room to wait
        separate(naive, FlightModel(cruise_speed=5.0, climb_rate=2.0, hover_s=1.0, flight_time_s=7.1, reserve=0.0),
                 1.0, legs)
    assert err.value.code == "SEPARATION_CONFLICT"


def test_routes_never_conflict():
    """Fields of 12 drones crossing toward views near each other: the routes keep the separation."""
    rng = np.random.default_rng(3)
    for _ in range(3):
        c = np.column_stack([rng.uniform(-3, 3, 30), rng.uniform(-3, 3, 30), rng.uniform(1, 3, 30)])
        homes = np.concatenate([R.launch_row(6, south=6.0), R.launch_row(6, south=-6.0)])
        fleet = plan_routes(_views(c), homes, FlightModel(hover_s=3.0), separation=1.0)
        _check(fleet, _views(c), homes)
        assert closest_approach(fleet.routes)[0] == pytest.approx(fleet.min_separation)
    with pytest.raises(RouteError) as err:
        plan_routes(_views(c), R.launch_row(3, spacing=0.4), separation=0.5)
    assert err.value.code == "INVALID_INPUT" and "0.40 m apart" in str(err.value)


def test_closest_approach_in_chunks(monkeypatch):
    rng = np.random.default_rng(1)
    c = np.column_stack([rng.uniform(-3, 3, 20), rng.uniform(-3, 3, 20), rng.uniform(1, 3, 20)])
    fleet = plan_routes(_views(c), R.launch_row(5), separation=0.5)
    whole = closest_approach(fleet.routes)
    monkeypatch.setattr(R, "PAIR_ELEMENTS", 64)
    assert closest_approach(fleet.routes) == pytest.approx(whole)


def test_legs_go_over_the_plants():
    """A view behind a plant: the level leg would cross it; the leg climbs over it, clear of it."""
    rng = np.random.default_rng(0)
    plant = np.column_stack([rng.normal(0, 0.15, 4000), rng.normal(0, 0.15, 4000), rng.uniform(0, 2, 4000)])
    homes = np.array([[0.0, -5.0, 0.0]])
    views = _views([[0, 1.5, 1.0]], target=(0, 0, 1.0))
    fleet = plan_routes(views, homes, FlightModel(), obstacles=plant, standoff=0.5)
    r = fleet.routes[0]
    assert r.points[:, 2].max() >= plant[:, 2].max() + 0.5 - 1e-9
    t = np.linspace(0, 1, 400)
    path = np.concatenate([a + t[:, None] * (b - a) for a, b in zip(r.points[:-1], r.points[1:])])
    gap = cKDTree(plant).query(path)[0].min()
    assert gap >= 0.5 - R._CLEARANCE_TOL - 1e-9
    assert plan_routes(views, homes, FlightModel()).routes[0].points[:, 2].max() == 1.0  # no plants: level
    leaf = np.column_stack([rng.uniform(-1, 1, 4000), rng.uniform(1, 2, 4000), np.full(4000, 1.6)])
    with pytest.raises(RouteError) as err:  # under a leaf, behind the stalk: no way up or across
        plan_routes(views, homes, FlightModel(), obstacles=np.concatenate([plant, leaf]), standoff=0.5)
    assert err.value.code == "NO_CLEAR_LEG" and "view(s) [0]" in str(err.value)
